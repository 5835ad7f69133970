"""The pilot server: auth, limits, validation, error mapping, a round trip, and a schemathesis run."""

from __future__ import annotations

import base64
import io
import re

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from PIL import Image
from schemathesis.specs.openapi.checks import positive_data_acceptance

from fakes import FakeOpenAI, ScriptedPilot, sample_image
from fakes.scripted import INSTANCES
from vlnpilot.core.decision import Usage
from vlnpilot.pilots.base import PilotError
from vlnpilot.pilots.model import PilotReplyError
from vlnpilot.server import create_app
from vlnpilot.server.app import IMAGE_PATTERN, decode_image

TOKEN = "server-token-abc123"


def _b64(fmt: str = "JPEG", size: tuple[int, int] = (64, 48)) -> str:
    buf = io.BytesIO()
    Image.fromarray(sample_image(size[1], size[0])).save(buf, format=fmt)
    return base64.b64encode(buf.getvalue()).decode()


def _body(**overrides) -> dict:
    body = {
        "image": _b64(),
        "query": "Go to the kitchen",
        "topological_map": {"nodes": [{"id": "hall", "name": "Hall"}, {"id": "kitchen", "name": "Kitchen"}],
                            "edges": [{"from": "hall", "to": "kitchen"}]},
        "state": "Search Object",
        "previous_movement": "B1",
    }
    body.update(overrides)
    return body


class Factory:
    """A pilot factory that hands out one ScriptedPilot per spec and remembers it."""

    def __init__(self):
        self.pilots: dict[str, ScriptedPilot] = {}
        self.calls: list[tuple[str, dict]] = []

    def __call__(self, spec: str, **options) -> ScriptedPilot:
        self.calls.append((spec, options))
        return self.pilots.setdefault(spec, ScriptedPilot(model=f"scripted:{spec}"))


@pytest.fixture
def factory() -> Factory:
    return Factory()


@pytest.fixture
def client(factory) -> TestClient:
    app = create_app(factory, token=TOKEN, max_body_bytes=300_000, pilot_spec="openai",
                     allowed_pilots=["gemini:gemini-2.5-flash"])
    with TestClient(app, raise_server_exceptions=False) as c:
        c.headers["Authorization"] = f"Bearer {TOKEN}"
        yield c


def test_round_trip(client, factory):
    response = client.post("/v1/decide", json=_body(feedback=["movement 'Z9' is not allowed"], step=7))
    assert response.status_code == 200, response.text
    data = response.json()
    assert {k: data[k] for k in ("room", "movement", "state", "description", "door_position")} == {
        "room": "hall", "movement": "A1", "state": "Search Object", "description": "scripted", "door_position": "left"}
    assert data["usage"]["input_tokens"] == 10 and data["usage"]["cost_usd"] == 0.001
    assert data["model"] == "scripted:openai"
    pilot = factory.pilots["openai"]
    (seen,) = pilot.inputs
    assert seen.image.shape == (48, 64, 3) and seen.image.dtype.name == "uint8"
    assert seen.state.value == "Search Object" and seen.previous_movement == "B1"
    assert seen.feedback == ("movement 'Z9' is not allowed",) and seen.step == 7
    # the pilot is built once and reused
    client.post("/v1/decide", json=_body())
    assert len(factory.calls) == 1 and len(pilot.inputs) == 2


def test_png_and_data_url_images(client, factory):
    assert client.post("/v1/decide", json=_body(image=_b64("PNG"))).status_code == 200
    assert client.post("/v1/decide", json=_body(image="data:image/jpeg;base64," + _b64())).status_code == 200
    assert factory.pilots["openai"].inputs[0].image.shape == (48, 64, 3)


def test_request_may_pick_an_allowed_pilot(client, factory):
    assert client.post("/v1/decide", json=_body(pilot="gemini:gemini-2.5-flash")).status_code == 200
    assert "gemini:gemini-2.5-flash" in factory.pilots
    response = client.post("/v1/decide", json=_body(pilot="stdin"))
    assert response.status_code == 403 and response.json()["reason"] == "pilot_not_allowed"
    assert "allowed: openai, gemini:gemini-2.5-flash" in response.json()["detail"]


def test_plan_route_serves_only_allowed_pilots(client, factory):
    """/v1/plan checks the allow-list as /v1/decide does, and no `pilot` means the server's own."""
    plan = {"system": "plan", "context": "Go to the kitchen", "schema": {"type": "object"}}
    response = client.post("/v1/plan", json={**plan, "pilot": "stdin"})
    assert response.status_code == 403 and response.json()["reason"] == "pilot_not_allowed"
    assert "stdin" not in factory.pilots  # never built
    client.post("/v1/plan", json=plan)
    assert list(factory.pilots) == ["openai"]


@pytest.mark.parametrize("auth", [None, "Bearer wrong-token", "Basic abc", f"Bearer {TOKEN}x"])
def test_401_without_or_with_a_wrong_token(client, auth):
    headers = {"Authorization": auth} if auth else {}
    if auth is None:
        client.headers.pop("Authorization")
    response = client.post("/v1/decide", json=_body(), headers=headers)
    assert response.status_code == 401
    assert response.json()["reason"] == "unauthorized"
    assert response.headers["www-authenticate"] == "Bearer"
    assert TOKEN not in response.text


def test_no_token_configured_means_no_auth(factory):
    with TestClient(create_app(factory, token=None)) as c:
        assert c.post("/v1/decide", json=_body()).status_code == 200


def test_healthz_and_docs_need_no_token(factory):
    with TestClient(create_app(factory, token=TOKEN, pilot_spec="gemini")) as c:
        assert c.get("/healthz").json() == {"status": "ok", "pilot": "gemini"}
        assert c.get("/docs").status_code == 200
        spec = c.get("/openapi.json").json()
        assert "/v1/decide" in spec["paths"]


def test_413_body_over_the_limit(client):
    big = _body(query="x" * 10, image="A" * 400_000)
    response = client.post("/v1/decide", json=big)
    assert response.status_code == 413
    assert response.json()["reason"] == "too_large"


def test_413_streamed_body_without_content_length(client):
    def chunks():
        yield b'{"image": "'
        for _ in range(40):
            yield b"A" * 10_000
        yield b'"}'

    response = client.post("/v1/decide", content=chunks(), headers={"Content-Type": "application/json"})
    assert response.status_code == 413


@pytest.mark.parametrize(("overrides", "reason", "words"), [
    ({"image": "not base64 at all!!"}, "bad_request", "image"),  # the schema's pattern: base64 JPEG or PNG
    ({"image": base64.b64encode(b"GIF89a just a gif").decode()}, "bad_request", "image"),
    ({"image": base64.b64encode(b"\xff\xd8\xff\xe0 truncated jpeg" * 6).decode()}, "bad_image", "cannot be decoded"),
    ({"image": base64.b64encode(b"\xff\xd8\xff\xe0 truncated jpeg").decode()}, "bad_request", "image"),  # too short
    ({"state": "Flying Upside Down"}, "bad_request", "state"),
    ({"state": "Start"}, "bad_request", "state"),
    ({"previous_movement": "Z9"}, "bad_request", "previous_movement"),
    ({"profile": "turbo"}, "bad_request", "profile"),
    ({"query": ""}, "bad_request", "query"),
    ({"step": -1}, "bad_request", "step"),
    ({"extra": 1}, "bad_request", "extra"),
])
def test_422_with_the_reason(client, overrides, reason, words):
    response = client.post("/v1/decide", json=_body(**overrides))
    assert response.status_code == 422, response.text
    body = response.json()
    assert body["reason"] == reason
    assert words.lower() in body["detail"].lower()


def test_422_missing_field_and_not_json(client):
    body = _body()
    del body["image"]
    response = client.post("/v1/decide", json=body)
    assert response.status_code == 422 and "image" in response.json()["detail"]
    response = client.post("/v1/decide", content=b"{not json", headers={"Content-Type": "application/json"})
    assert response.status_code == 422


def test_decode_image_rejects_huge_dimensions():
    buf = io.BytesIO()
    Image.new("L", (5000, 2)).save(buf, format="PNG")
    with pytest.raises(Exception) as info:
        decode_image(base64.b64encode(buf.getvalue()).decode())
    assert getattr(info.value, "status", None) == 422


@pytest.mark.parametrize(("error", "status"), [
    (PilotError("the OpenAI API rejected the key (401): check OPENAI_API_KEY", fatal=True, reason="auth"), 502),
    (PilotError("the OpenAI API is unavailable (500)", reason="unavailable"), 503),
    (PilotError("the OpenAI API is rate limiting (429)", reason="rate_limited"), 503),
    (PilotError("the OpenAI API did not answer within 30 s", reason="timeout"), 503),
    (PilotReplyError("movement 'Z9' is not allowed", reason="invalid_enum", raw_text='{"movement": "Z9"}',
                     usage=Usage(input_tokens=7)), 502),
    (RuntimeError("boom in the pilot"), 502),
])
def test_provider_failures_map_to_502_or_503(client, factory, error, status):
    client.post("/v1/decide", json=_body())
    factory.pilots["openai"].push(error)
    response = client.post("/v1/decide", json=_body())
    assert response.status_code == status
    body = response.json()
    assert "Traceback" not in response.text and body["detail"]
    if isinstance(error, PilotError):
        assert body["reason"] == error.reason and body["fatal"] == error.fatal
    else:
        assert body["reason"] == "pilot_crashed" and "boom" not in body["detail"]
    if isinstance(error, PilotReplyError):
        assert body["raw_text"] == '{"movement": "Z9"}' and body["usage"]["input_tokens"] == 7


def test_pilot_that_cannot_be_built(factory):
    def broken(spec, **options):
        raise PilotError("no OpenAI API key: set OPENAI_API_KEY", fatal=True, reason="missing_key")

    with TestClient(create_app(broken)) as c:
        response = c.post("/v1/decide", json=_body())
    assert response.status_code == 502
    assert response.json()["reason"] == "missing_key" and "OPENAI_API_KEY" in response.json()["detail"]


def test_registered_test_pilot_through_make_pilot():
    app = create_app(pilot_spec="test-scripted:v2", allowed_pilots=["test-scripted"])
    with TestClient(app) as c:
        response = c.post("/v1/decide", json=_body())
    assert response.status_code == 200
    assert response.json()["model"] == "v2"
    assert INSTANCES and INSTANCES[-1].model == "v2"


def test_openai_pilot_behind_the_server_against_the_fake():
    """End to end: HTTP client -> our server -> OpenAI SDK -> fake OpenAI server."""
    with FakeOpenAI() as fake:
        app = create_app(pilot_spec="openai:gpt-4.1", pilot_options={"base_url": fake.base_url, "api_key": "sk-x1"})
        with TestClient(app) as c:
            ok = c.post("/v1/decide", json=_body(state="Recognize Room"))
            fake.push("bad_key")
            bad = c.post("/v1/decide", json=_body())
            fake.push("wrong_enum")
            wrong = c.post("/v1/decide", json=_body())
    assert ok.status_code == 200 and ok.json()["usage"]["cost_usd"] > 0
    assert fake.requests[0].allowed_movements == ["A1", "B1", "B2", "B3", "C1", "C2", "C3", "E"]
    assert bad.status_code == 502 and bad.json()["fatal"] is True and "OPENAI_API_KEY" in bad.json()["detail"]
    assert wrong.status_code == 502 and wrong.json()["reason"] == "invalid_enum"


# ---------------------------------------------------------------------------------------------- schemathesis
# Every generated request must get a documented status and a body matching the documented schema, never a
# 5xx. The schema's `image` pattern (base64 starting like a JPEG or PNG) makes "0" and other non-images
# schema-invalid. A pattern-valid string may still be a truncated JPEG, which JSON Schema cannot express, so
# positive_data_acceptance (every schema-valid request accepted) runs in a second pass whose hook gives positive
# bodies a real JPEG; that pass skips the coverage phase, which bypasses hooks.

_st_app = create_app(pilot_spec="test-scripted", token=TOKEN, max_body_bytes=200_000)
_schema = schemathesis.openapi.from_asgi("/openapi.json", _st_app)
_positive = schemathesis.openapi.from_asgi("/openapi.json", _st_app)
_positive.config.phases.coverage.enabled = False
_VALID_IMAGE = re.compile(IMAGE_PATTERN)


@_positive.hook
def map_body(ctx, body):
    if isinstance(body, dict) and isinstance(body.get("image"), str) and _VALID_IMAGE.match(body["image"]):
        body = {**body, "image": _b64(size=(8, 6))}
    if isinstance(body, dict) and isinstance(body.get("history"), list):  # earlier turns' images, the same way
        body = {**body, "history": [map_body(ctx, turn) for turn in body["history"]]}
    return body


@_schema.parametrize()
@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
def test_schemathesis(case):
    case.call_and_validate(headers={"Authorization": f"Bearer {TOKEN}"}, excluded_checks=[positive_data_acceptance])


@_positive.parametrize()
@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
def test_schemathesis_accepts_every_schema_valid_request(case):
    case.call_and_validate(headers={"Authorization": f"Bearer {TOKEN}"}, checks=[positive_data_acceptance])


def test_serve_runs_uvicorn_with_the_env_token(monkeypatch):
    import uvicorn

    from vlnpilot.server import serve

    calls = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: calls.append((app, kw)))
    monkeypatch.setenv("VLN_PILOT_TOKEN", TOKEN)
    serve("127.0.0.1", 8123, "test-scripted", allowed_pilots=["test-scripted"])
    (app, kw), = calls
    assert kw["host"] == "127.0.0.1" and kw["port"] == 8123
    with TestClient(app) as c:
        assert c.post("/v1/decide", json=_body()).status_code == 401
        assert c.get("/healthz").json()["pilot"] == "test-scripted"
