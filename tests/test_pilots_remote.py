"""The remote pilot against a real pilot server (uvicorn on 127.0.0.1) and against scripted HTTP replies."""

from __future__ import annotations

import json

import httpx
import pytest

from fakes import ScriptedPilot, ServerThread, free_port, sample_input
from vlnpilot.core.decision import Usage
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.model import PilotReplyError
from vlnpilot.pilots.remote import RemotePilot
from vlnpilot.server import create_app

TOKEN = "remote-token-xyz789"


@pytest.fixture(scope="module")
def served():
    pilots: dict[str, ScriptedPilot] = {}

    def factory(spec: str, **options) -> ScriptedPilot:
        return pilots.setdefault(spec, ScriptedPilot(model=spec))

    app = create_app(factory, token=TOKEN, pilot_spec="openai:gpt-4.1", allowed_pilots=["gemini:gemini-2.5-flash"])
    with ServerThread(app) as url:
        yield url, pilots


def test_round_trip_through_a_real_server(served, monkeypatch):
    url, pilots = served
    monkeypatch.setenv("VLN_PILOT_URL", url)
    monkeypatch.setenv("VLN_PILOT_TOKEN", TOKEN)
    pilot = make_pilot("remote")
    assert isinstance(pilot, RemotePilot) and pilot.url == url
    context = ("Odometry in the current state (it restarts at every state change): forward 0.30 m.",)
    decision = pilot.decide(sample_input(State.REACH_OBJECT, feedback=("too far left",), context=context))
    assert decision.movement == "A1" and decision.model == "openai:gpt-4.1"
    assert decision.usage.input_tokens == 10 and decision.usage.latency_s > 0
    seen = pilots["openai:gpt-4.1"].inputs[-1]
    assert seen.state is State.REACH_OBJECT and seen.feedback == ("too far left",)
    assert seen.context == context  # the plus context reaches a pilot behind the server
    assert seen.image.shape == (48, 64, 3)
    assert TOKEN not in repr(pilot)


def test_spec_model_selects_the_server_side_pilot(served):
    url, pilots = served
    pilot = make_pilot("remote:gemini:gemini-2.5-flash", url=url, token=TOKEN)
    assert pilot.model == "gemini:gemini-2.5-flash"
    assert pilot.decide(sample_input()).model == "gemini:gemini-2.5-flash"
    assert "gemini:gemini-2.5-flash" in pilots


def test_wrong_token_is_fatal(served, monkeypatch):
    url, _ = served
    monkeypatch.delenv("VLN_PILOT_TOKEN", raising=False)
    with pytest.raises(PilotError) as info:
        RemotePilot(url=url, token="nope").decide(sample_input())
    assert info.value.fatal and info.value.reason == "auth" and "VLN_PILOT_TOKEN" in str(info.value)


def test_provider_errors_come_back_as_the_same_pilot_errors(served):
    url, pilots = served
    pilot = RemotePilot(url=url, token=TOKEN)
    pilot.decide(sample_input())
    scripted = pilots["openai:gpt-4.1"]
    scripted.push(PilotReplyError("movement 'Z9' is not allowed", reason="invalid_enum", raw_text="{}",
                                  usage=Usage(input_tokens=3)))
    with pytest.raises(PilotReplyError) as info:
        pilot.decide(sample_input())
    assert info.value.reason == "invalid_enum" and info.value.usage.input_tokens == 3 and not info.value.fatal
    n = len(scripted.inputs)
    scripted.push(PilotError("rate limited", reason="rate_limited"))
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.reason == "rate_limited" and not info.value.fatal
    assert len(scripted.inputs) == n + 1  # the server already retried: no second request
    scripted.push(PilotError("the OpenAI API rejected the key (401): check OPENAI_API_KEY", fatal=True,
                             reason="auth"))
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.fatal and "OPENAI_API_KEY" in str(info.value)


def test_connection_refused_is_retried_then_reported():
    pilot = RemotePilot(url=f"http://127.0.0.1:{free_port()}", max_retries=1, retry_base_delay=0.01)
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.reason == "connection_error" and not info.value.fatal


def _mock(responses: list[httpx.Response], seen: list[httpx.Request]) -> httpx.MockTransport:
    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        return responses.pop(0)

    return httpx.MockTransport(handler)


def test_bare_5xx_and_429_are_retried_with_retry_after():
    ok = {"room": "hall", "movement": "C1", "state": "Reach Object", "usage": {"input_tokens": 1}}
    seen: list[httpx.Request] = []
    responses = [httpx.Response(503, text="upstream restarting", headers={"Retry-After": "0.01"}),
                 httpx.Response(429, headers={"retry-after-ms": "10"}),
                 httpx.Response(200, json=ok)]
    pilot = RemotePilot(url="http://pilot.test", max_retries=2, transport=_mock(responses, seen))
    decision = pilot.decide(sample_input())
    assert decision.movement == "C1" and len(seen) == 3
    body = json.loads(seen[0].content)
    assert body["state"] == "Search Object" and body["previous_movement"] == "B1"
    assert body["image"].startswith("/9j/")  # base64 JPEG
    assert "pilot" not in body  # no model: the server's default


def test_retries_are_bounded():
    seen: list[httpx.Request] = []
    responses = [httpx.Response(502, text="bad gateway")] * 5
    pilot = RemotePilot(url="http://pilot.test", max_retries=2, retry_base_delay=0.01,
                        transport=_mock(list(responses), seen))
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert len(seen) == 3 and info.value.reason == "unavailable"


def test_422_and_malformed_decisions():
    seen: list[httpx.Request] = []
    pilot = RemotePilot(url="http://pilot.test", transport=_mock(
        [httpx.Response(422, json={"detail": "state: bad", "reason": "bad_request", "fatal": True}),
         httpx.Response(200, json={"nonsense": True})], seen))
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.fatal and "422" in str(info.value) and len(seen) == 1
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.reason == "bad_response"


def test_bad_url_is_a_config_error():
    with pytest.raises(ConfigError):
        RemotePilot(url="ftp://example")
