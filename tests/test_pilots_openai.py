"""OpenAI pilot specifics: structured-output request, JSON-mode fallback, local servers, oracle fakes."""

from __future__ import annotations

import threading

import pytest

from fakes import FakeOpenAI, RecordedRequest, auto_decision, sample_input
from vlnpilot.core.fsm import State
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.openai import SCHEMA_NAME, OpenAIPilot

KEY = "sk-test-0123456789abcdef"


@pytest.fixture
def fake():
    with FakeOpenAI() as server:
        yield server


@pytest.fixture(autouse=True)
def _clean_env(monkeypatch):
    monkeypatch.delenv("OPENAI_BASE_URL", raising=False)


def test_request_shape(fake):
    pilot = make_pilot("openai:gpt-4.1-mini", base_url=fake.base_url, api_key=KEY)
    assert isinstance(pilot, OpenAIPilot) and pilot.model == "gpt-4.1-mini"
    pilot.decide(sample_input())
    body = fake.last.json
    assert body["model"] == "gpt-4.1-mini"
    assert [m["role"] for m in body["messages"]] == ["system", "user"]
    image_part = body["messages"][1]["content"][-1]  # the image last (issue 27)
    assert image_part["type"] == "image_url"
    assert image_part["image_url"]["url"].startswith("data:image/jpeg;base64,/9j/")
    assert image_part["image_url"]["detail"] == "low"
    fmt = body["response_format"]
    assert fmt["type"] == "json_schema"
    assert fmt["json_schema"]["name"] == SCHEMA_NAME and fmt["json_schema"]["strict"] is True
    assert fmt["json_schema"]["schema"]["additionalProperties"] is False
    assert body["max_tokens"] == 512  # a custom base_url: the widely supported parameter
    assert "prompt_cache_key" not in body  # only the official API is sent OpenAI's own parameter
    assert fake.last.headers["authorization"] == f"Bearer {KEY}"


def test_official_api_uses_max_completion_tokens():
    from vlnpilot.prompting.render import build_prompt

    pilot = OpenAIPilot(api_key=KEY, detail="high", max_output_tokens=300)
    kwargs = pilot._kwargs(_prompt(), "json_schema")
    assert kwargs["max_completion_tokens"] == 300 and "max_tokens" not in kwargs
    assert kwargs["messages"][1]["content"][-1]["image_url"]["detail"] == "high"
    # one cache key per episode: the same for every step of it, another for another query
    key = kwargs["prompt_cache_key"]
    assert key.startswith("vlnpilot-")
    assert pilot._kwargs(_prompt(), "json_schema")["prompt_cache_key"] == key
    other = build_prompt(sample_input(query="Find the sofa"))
    assert pilot._kwargs(other, "json_schema")["prompt_cache_key"] != key


def _prompt():
    from vlnpilot.prompting.render import build_prompt

    return build_prompt(sample_input())


def test_falls_back_to_json_mode_once_when_json_schema_is_rejected(fake):
    fake.supports_json_schema = False
    pilot = make_pilot("openai", base_url=fake.base_url, api_key=KEY)
    first = pilot.decide(sample_input())
    assert first.movement
    assert [r.json["response_format"]["type"] for r in fake.requests] == ["json_schema", "json_object"]
    pilot.decide(sample_input())  # remembered: no second rejected attempt
    assert [r.json["response_format"]["type"] for r in fake.requests][2:] == ["json_object"]


def test_json_mode_reply_is_validated_locally(fake):
    fake.supports_json_schema = False
    pilot = make_pilot("openai", base_url=fake.base_url, api_key=KEY, response_format="json_object")
    fake.push("wrong_enum", fields={"state": "Go Through Door"})
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.reason == "invalid_enum" and "Go Through Door" in str(info.value)
    assert len(fake.requests) == 1


def test_no_fallback_when_the_format_is_forced(fake):
    fake.supports_json_schema = False
    pilot = make_pilot("openai", base_url=fake.base_url, api_key=KEY, response_format="json_schema")
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    assert info.value.fatal and info.value.reason == "bad_request"
    assert len(fake.requests) == 1


def test_response_format_none_sends_none(fake):
    pilot = make_pilot("openai", base_url=fake.base_url, api_key=KEY, response_format="none")
    pilot.decide(sample_input())
    assert "response_format" not in fake.last.json


def test_local_server_needs_no_key(fake, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    monkeypatch.setenv("OPENAI_BASE_URL", fake.base_url)
    pilot = make_pilot("openai:qwen2.5-vl-7b")
    assert pilot.base_url == fake.base_url
    decision = pilot.decide(sample_input())
    assert decision.model == "qwen2.5-vl-7b" and decision.usage.cost_usd == 0


def test_quota_exhausted_is_fatal(fake):
    fake.push("rate_limit", code="insufficient_quota", message="You exceeded your current quota, please check "
              "your plan and billing details.")
    with pytest.raises(PilotError) as info:
        make_pilot("openai", base_url=fake.base_url, api_key=KEY, max_retries=0).decide(sample_input())
    assert info.value.fatal and info.value.reason == "quota"
    assert "billing" in str(info.value)


def test_bad_options_are_config_errors():
    from vlnpilot.core.errors import ConfigError

    with pytest.raises(ConfigError):
        OpenAIPilot(api_key=KEY, detail="ultra")
    with pytest.raises(ConfigError):
        OpenAIPilot(api_key=KEY, timeout=0)
    with pytest.raises(ConfigError):
        OpenAIPilot(api_key=KEY, response_format="xml")


def test_oracle_callback_and_delay_with_concurrent_clients():
    """The hooks the episode and benchmark tests use: an oracle that sees the parsed request, a fixed delay."""
    seen: list[RecordedRequest] = []

    def oracle(request: RecordedRequest) -> dict:
        seen.append(request)
        answer = auto_decision(request)
        answer["movement"] = [m for m in request.allowed_movements if m != "E"][-1]  # E: final states only
        answer["description"] = f"oracle in {request.current_state}"
        return answer

    with FakeOpenAI(oracle=oracle, delay=0.3, rendezvous=8) as fake:  # 8 answers wait until 8 calls overlap
        pilot = make_pilot("openai", base_url=fake.base_url, api_key=KEY)
        results = []

        def run() -> None:
            results.append(pilot.decide(sample_input(State.RECOGNIZE_ROOM)))

        threads = [threading.Thread(target=run) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert len(results) == 8 and len(seen) == 8  # a serial client would have broken the rendezvous (a 500)
    assert all(d.movement == "C3" and d.description == "oracle in Recognize Room" for d in results)
    assert all(d.usage.latency_s >= 0.29 for d in results)


def test_oracle_may_return_raw_text():
    with FakeOpenAI(oracle=lambda request: "no JSON here") as fake:
        pilot = make_pilot("openai", base_url=fake.base_url, api_key=KEY)
        with pytest.raises(PilotError) as info:
            pilot.decide(sample_input())
    assert info.value.reason == "not_json"
