"""Contract tests of the three SDK pilots (openai, gemini, anthropic) against fake provider servers.

The official SDKs talk real HTTP to fakes on 127.0.0.1 that speak each provider's wire protocol.
"""

from __future__ import annotations

import io
import logging
import threading

import pytest
from PIL import Image

from fakes import FakeAnthropic, FakeGemini, FakeOpenAI, free_port, sample_input
from vlnpilot.core.decision import Decision
from vlnpilot.core.fsm import State, state_spec
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.model import PilotReplyError
from vlnpilot.prompting.render import decision_schema

KEY = "secret-test-key-0123456789"  # not shaped like a real key: only the pilot's own scrubbing can hide it
FAKES = {"openai": FakeOpenAI, "gemini": FakeGemini, "anthropic": FakeAnthropic}
KEY_ENVS = {"openai": ["OPENAI_API_KEY"], "gemini": ["GEMINI_API_KEY", "GOOGLE_API_KEY"],
            "anthropic": ["ANTHROPIC_API_KEY"]}
DEFAULT_MODELS = {"openai": "gpt-4.1", "gemini": "gemini-2.5-flash", "anthropic": "claude-sonnet-4-6"}


@pytest.fixture(params=sorted(FAKES))
def provider(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def fake(provider: str):
    with FAKES[provider](cached_tokens=64) as server:
        yield server


@pytest.fixture
def pilot_factory(provider: str, fake, monkeypatch: pytest.MonkeyPatch):
    for var in ("OPENAI_BASE_URL", "ANTHROPIC_BASE_URL", "GOOGLE_GEMINI_BASE_URL"):
        monkeypatch.delenv(var, raising=False)

    def make(**options):
        options = {"base_url": fake.base_url, "api_key": KEY, "timeout": 2.0, "max_retries": 2, **options}
        return make_pilot(provider, **options)

    return make


def test_round_trip_sends_image_schema_and_fills_usage(provider, fake, pilot_factory):
    pilot = pilot_factory()
    assert pilot.name == provider and pilot.model == DEFAULT_MODELS[provider]
    decision = pilot.decide(sample_input(State.SEARCH_OBJECT))

    assert isinstance(decision, Decision)
    assert decision.movement in state_spec(State.SEARCH_OBJECT).moves
    assert decision.state in ("Search Object", "Reach Object")
    assert decision.model == DEFAULT_MODELS[provider]
    assert decision.raw_text and decision.raw_text.lstrip().startswith("{")
    usage = decision.usage
    assert usage.input_tokens > 0 and usage.output_tokens > 0 and usage.cached_tokens == 64
    assert usage.latency_s > 0 and usage.cost_usd > 0

    assert len(fake.requests) == 1
    req = fake.last
    # the image: one base64 JPEG that decodes to the camera frame's size
    assert req.image_media_types == ["image/jpeg"]
    assert req.images[0][:3] == b"\xff\xd8\xff"
    assert Image.open(io.BytesIO(req.images[0])).size == (64, 48)
    # cache-friendly order: system apart, then context, state prompt, step text, the image last (issue 27)
    assert req.parts == ["text", "text", "text", "image"]
    assert "drone" in req.system.lower()
    assert "Find the red cup" in req.texts[0]
    assert "Current FSM state" in req.texts[-1] and req.current_state == "Search Object"
    # the state's schema, with its enums, goes to the provider
    expected = decision_schema(State.SEARCH_OBJECT, "paper", ["hall", "kitchen", "bedroom"])
    assert req.schema is not None
    assert req.allowed_movements == expected["properties"]["movement"]["enum"]
    assert req.allowed_states == expected["properties"]["state"]["enum"]
    assert req.enum("door_position") == ["left", "center", "right", "not_visible"]


@pytest.mark.parametrize("state", [State.RECOGNIZE_ROOM, State.GO_THROUGH_DOOR, State.REACH_OBJECT])
def test_schema_follows_the_state(state, fake, pilot_factory):
    decision = pilot_factory().decide(sample_input(state))
    spec = state_spec(state)
    assert fake.last.allowed_movements == list(spec.answer_moves)
    assert fake.last.allowed_states == [s.value for s in spec.next_states]
    assert decision.movement in spec.moves


def test_rate_limit_is_retried_then_succeeds(fake, pilot_factory):
    fake.push("rate_limit", times=2, retry_after=0.05)
    decision = pilot_factory(max_retries=2).decide(sample_input())
    assert decision.movement
    assert len(fake.requests) == 3


def test_rate_limit_retries_are_bounded(fake, pilot_factory):
    fake.push("rate_limit", times=10, retry_after=0.05)
    with pytest.raises(PilotError) as info:
        pilot_factory(max_retries=2).decide(sample_input())
    assert len(fake.requests) == 3  # 1 + max_retries
    assert info.value.reason == "rate_limited" and not info.value.fatal
    assert "429" in str(info.value)


def test_retry_after_is_honoured(fake, pilot_factory, retry_waits):
    # 0.7 s is longer than any first backoff step (<= 0.5 s): waiting exactly that proves Retry-After was used.
    fake.push("rate_limit", retry_after=0.7)
    pilot_factory(max_retries=1).decide(sample_input())
    assert len(fake.requests) == 2
    assert retry_waits == [0.7]


def test_server_errors_back_off_and_stop(fake, pilot_factory, retry_waits):
    fake.push("server_error", times=5)
    with pytest.raises(PilotError) as info:
        pilot_factory(max_retries=1).decide(sample_input())
    assert len(fake.requests) == 2
    assert info.value.reason == "unavailable" and not info.value.fatal
    assert len(retry_waits) == 1 and 0.375 <= retry_waits[0] <= 0.5  # one capped-exponential step, 25% jitter


def test_hang_past_the_timeout(fake, pilot_factory):
    fake.push("hang", times=3, seconds=5)
    with pytest.raises(PilotError) as info:
        pilot_factory(timeout=0.3, max_retries=1).decide(sample_input())
    # a hang answers after 5 s: a timeout error after exactly two attempts means the 0.3 s timeout ended both
    assert info.value.reason == "timeout" and not info.value.fatal
    assert len(fake.requests) == 2


def test_bad_key_is_fatal_and_not_retried(provider, fake, pilot_factory):
    fake.push("bad_key")
    pilot = pilot_factory()
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    err = info.value
    assert err.fatal and err.reason == "auth"
    assert len(fake.requests) == 1
    assert "rejected the key" in str(err) and KEY_ENVS[provider][0] in str(err)
    assert KEY not in str(err) and KEY not in repr(err.args)
    assert err.__cause__ is None and err.__suppress_context__


@pytest.mark.parametrize("status", [400, 403, 404])
def test_client_errors_are_fatal_and_not_retried(status, fake, pilot_factory):
    fake.push("status", status_code=status, message=f"nope, and your key was {KEY}")
    with pytest.raises(PilotError) as info:
        pilot_factory().decide(sample_input())
    assert info.value.fatal
    assert len(fake.requests) == 1
    assert f"({status})" in str(info.value)
    assert KEY not in str(info.value)


REPLY_FAULTS = {
    "not_json": "not_json",
    "wrong_enum": "invalid_enum",
    "missing_field": "missing_field",
    "refusal": "refusal",
    "truncated": "truncated",
    "content_filter": "content_filter",
}


@pytest.mark.parametrize("action", sorted(REPLY_FAULTS))
def test_unusable_replies_raise_clear_non_fatal_errors(provider, action, fake, pilot_factory):
    fake.push(action)
    with pytest.raises(PilotReplyError) as info:
        pilot_factory().decide(sample_input())
    err = info.value
    expected = REPLY_FAULTS[action]
    if provider == "anthropic" and action == "content_filter":
        expected = "refusal"  # Anthropic has no separate filter signal: it stops with stop_reason "refusal"
    assert err.reason == expected and not err.fatal
    assert len(fake.requests) == 1  # a bad reply is not retried by the pilot: the controller re-asks
    assert err.usage.input_tokens > 0  # the tokens were paid for and are reported
    assert err.feedback
    if action == "wrong_enum":
        assert "Z9" in str(err) and "A1" in str(err)  # names the bad value and the allowed ones


def test_malformed_http_body_is_a_pilot_error(fake, pilot_factory):
    fake.push("bad_body")
    with pytest.raises(PilotError) as info:
        pilot_factory(max_retries=0).decide(sample_input())
    assert info.value.reason == "bad_response" and not info.value.fatal


def test_prose_around_the_json_is_accepted(fake, pilot_factory):
    fake.push("prose")
    decision = pilot_factory().decide(sample_input())
    assert decision.movement in state_spec(State.SEARCH_OBJECT).moves


def test_connection_refused(provider, pilot_factory):
    pilot = pilot_factory(base_url=f"http://127.0.0.1:{free_port()}" + ("/v1" if provider == "openai" else ""),
                          max_retries=0)
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.reason in ("connection_error", "timeout") and not info.value.fatal


def test_missing_key_is_fatal_and_names_the_env_var(provider, monkeypatch):
    for var in [*KEY_ENVS[provider], "OPENAI_BASE_URL"]:
        monkeypatch.delenv(var, raising=False)
    with pytest.raises(PilotError) as info:
        make_pilot(provider)
    assert info.value.fatal and info.value.reason == "missing_key"
    for var in KEY_ENVS[provider]:
        assert var in str(info.value)


def test_key_from_env(provider, fake, monkeypatch):
    monkeypatch.setenv(KEY_ENVS[provider][-1], KEY)
    for var in KEY_ENVS[provider][:-1]:
        monkeypatch.delenv(var, raising=False)
    pilot = make_pilot(provider, base_url=fake.base_url)
    pilot.decide(sample_input())
    headers = fake.last.headers
    sent = headers.get("authorization", "") + headers.get("x-api-key", "") + headers.get("x-goog-api-key", "")
    assert KEY in sent


def test_key_never_appears_in_repr_logs_or_decisions(fake, pilot_factory, caplog):
    caplog.set_level(logging.DEBUG)
    pilot = pilot_factory(max_retries=0)
    decision = pilot.decide(sample_input())
    fake.push("status", status_code=400, message=f"echo {KEY}")
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    fake.push("bad_key")
    with pytest.raises(PilotError) as info2:
        pilot.decide(sample_input())
    for text in (repr(pilot), str(pilot), decision.raw_text or "", decision.model_dump_json(), str(info.value),
                 str(info2.value), caplog.text):
        assert KEY not in text


def test_unknown_model_costs_zero_and_is_flagged(fake, pilot_factory):
    pilot = pilot_factory(model="my-local-vlm-7b")
    assert pilot.price_known is False
    decision = pilot.decide(sample_input())
    assert decision.usage.cost_usd == 0 and decision.usage.input_tokens > 0
    assert fake.last.model == "my-local-vlm-7b"


def test_price_file_overrides_the_table(fake, pilot_factory, tmp_path):
    prices = tmp_path / "prices.yaml"
    prices.write_text("models:\n  my-local-vlm-7b: {input: 1000000, cached: 0, output: 0}\n")
    pilot = pilot_factory(model="my-local-vlm-7b", prices=str(prices))
    assert pilot.price_known
    decision = pilot.decide(sample_input())
    fresh = decision.usage.input_tokens - decision.usage.cached_tokens
    assert decision.usage.cost_usd == pytest.approx(fresh, rel=1e-6)  # 1 USD per fresh input token


def test_concurrent_decisions(fake, pilot_factory):
    fake._rendezvous = threading.Barrier(6)  # each answer waits until all 6 calls are in flight together
    pilot = pilot_factory(max_retries=0)  # a broken rendezvous must fail the test, not be retried away
    results: list[Decision] = []
    errors: list[BaseException] = []

    def run() -> None:
        try:
            results.append(pilot.decide(sample_input()))
        except BaseException as exc:  # noqa: BLE001
            errors.append(exc)

    threads = [threading.Thread(target=run) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(results) == 6  # serial calls would have broken the rendezvous (a 500 each)
