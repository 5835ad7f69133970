"""Chaos: the pilot server under abuse (issue 16): an allow-list, a bounded cache, honest auth, clean 4xx."""

from __future__ import annotations

import base64
import io
import os
import sys

import pytest
from fastapi.testclient import TestClient
from PIL import Image

from fakes import FakeOpenAI, sample_image
from vlnpilot import cli
from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots.base import make_pilot
from vlnpilot.server import create_app
from vlnpilot.server.app import serve

pytestmark = pytest.mark.chaos
JPEG = base64.b64encode(bytes.fromhex("ffd8ffe000104a46494600")).decode()  # a JPEG header and nothing else


def body(**overrides) -> dict:
    buf = io.BytesIO()
    Image.fromarray(sample_image(48, 64)).save(buf, format="JPEG")
    out = {"image": base64.b64encode(buf.getvalue()).decode(), "query": "Go to the kitchen",
           "topological_map": {"nodes": [], "edges": []}, "state": "Recognize Room"}
    return {**out, **overrides}


def rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def test_2000_distinct_pilot_names_leave_memory_and_file_handles_flat(monkeypatch) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", "sk-not-a-real-key-0000")  # would let a leaky server build 2,000 clients
    app = create_app(pilot_spec="openai:gpt-4.1", allowed_pilots=["openai:gpt-4.1-mini"])
    with TestClient(app) as c:
        for i in range(50):  # warm up: imports, the first pools
            c.post("/v1/decide", json=body(pilot=f"openai:warm-{i}"))
        rss0, fds0 = rss_bytes(), open_fds()
        statuses = {c.post("/v1/decide", json=body(pilot=f"openai:model-{i}")).status_code for i in range(2000)}
        rss1, fds1 = rss_bytes(), open_fds()
    assert statuses == {403}
    assert len(app.state.pilots) == 0  # nothing was built for them
    assert fds1 - fds0 <= 2, (fds0, fds1)  # stated bound: 2 handles, 16 MB
    assert rss1 - rss0 <= 16 * 2**20, (rss0, rss1)


def test_refusal_lists_the_allowed_specs_and_the_default_is_the_started_pilot() -> None:
    app = create_app(pilot_spec="test-scripted", allowed_pilots=["test-scripted:v2"])
    with TestClient(app) as c:
        assert c.post("/v1/decide", json=body()).status_code == 200
        assert c.post("/v1/decide", json=body(pilot="test-scripted:v2")).status_code == 200
        refused = c.post("/v1/decide", json=body(pilot="openai"))
    assert refused.status_code == 403 and refused.json()["reason"] == "pilot_not_allowed"
    assert "allowed: test-scripted, test-scripted:v2" in refused.json()["detail"]


def test_the_cache_is_bounded_and_closes_the_clients_it_evicts() -> None:
    built = []

    def factory(spec: str, **options):
        built.append(make_pilot(spec, **options))
        return built[-1]

    with FakeOpenAI() as fake:
        specs = ["openai:m1", "openai:m2", "openai:m3"]
        app = create_app(factory, pilot_spec=specs[0], allowed_pilots=specs[1:], max_cached_pilots=2,
                         pilot_options={"base_url": fake.base_url, "api_key": "sk-not-a-real-key-0000"})
        with TestClient(app) as c:
            for spec in specs:
                assert c.post("/v1/decide", json=body(pilot=spec)).status_code == 200
            assert len(app.state.pilots) == 2
            assert [p._client.is_closed() for p in built] == [True, False, False]  # m1 evicted and closed
        assert all(p._client.is_closed() for p in built)  # shutdown closes the rest


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.20", "::", "example.org"])
def test_no_token_off_loopback_is_refused(monkeypatch, host) -> None:
    monkeypatch.delenv("VLN_PILOT_TOKEN", raising=False)
    with pytest.raises(ConfigError, match="VLN_PILOT_TOKEN"):
        serve(host, 8123, "test-scripted")


def test_serve_refuses_the_oracle_in_one_line(monkeypatch, capsys) -> None:
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "serve", "--pilot", "oracle"])
    with pytest.raises(SystemExit) as info:
        cli.main()
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1 and "ground truth" in err


def test_openapi_declares_bearer_auth_only_when_it_is_on() -> None:
    def security(app) -> tuple[object, object]:
        doc = app.openapi()
        return doc.get("components", {}).get("securitySchemes"), doc["paths"]["/v1/decide"]["post"].get("security")

    assert security(create_app(pilot_spec="test-scripted")) == (None, None)
    schemes, required = security(create_app(pilot_spec="test-scripted", token="tok-123456"))
    assert schemes and required


@pytest.mark.parametrize("image", ["0", "AAAA", JPEG, JPEG + "QUJD", base64.b64encode(b"\x89PNG\r\n\x1a\n").decode()])
def test_bad_images_get_a_clean_422(image) -> None:
    with TestClient(create_app(pilot_spec="test-scripted")) as c:
        response = c.post("/v1/decide", json=body(image=image))
    detail = response.json()["detail"]
    assert response.status_code == 422 and "image" in detail
    assert " object at 0x" not in detail and "<_io" not in detail


def test_wrong_content_type_is_415_naming_the_expected_type() -> None:
    with TestClient(create_app(pilot_spec="test-scripted")) as c:
        form = c.post("/v1/decide", data={"image": "x"})
        text = c.post("/v1/decide", content=b"{}", headers={"content-type": "text/plain"})
    for response in (form, text):
        assert response.status_code == 415 and "application/json" in response.json()["detail"]



def test_serve_allow_names_the_extra_specs(monkeypatch, capsys) -> None:
    import uvicorn

    apps = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: apps.append(app))
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "serve", "--pilot", "test-scripted", "--allow", "test-scripted:v2",
                                      "--allow", "openai:gpt-4.1-mini"])
    with pytest.raises(SystemExit) as info:
        cli.main()
    assert info.value.code == 0
    assert apps[0].state.pilots.allowed == ["test-scripted", "test-scripted:v2", "openai:gpt-4.1-mini"]
