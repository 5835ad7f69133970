"""Gemini pilot specifics: JSON schema config, thinking budget, Google's RetryInfo, key env vars."""

from __future__ import annotations

import pytest

from fakes import FakeGemini, sample_input
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.gemini import GeminiPilot

KEY = "AIza-test-0123456789abcdefghij"


@pytest.fixture
def fake():
    with FakeGemini() as server:
        yield server


def test_request_shape(fake):
    pilot = make_pilot("gemini:gemini-2.5-flash-lite", base_url=fake.base_url, api_key=KEY)
    assert isinstance(pilot, GeminiPilot)
    decision = pilot.decide(sample_input())
    req = fake.last
    assert req.path.endswith("/models/gemini-2.5-flash-lite:generateContent")
    assert req.model == "gemini-2.5-flash-lite" and decision.model == "gemini-2.5-flash-lite"
    assert req.headers["x-goog-api-key"] == KEY
    config = req.json["generationConfig"]
    assert config["responseMimeType"] == "application/json"
    assert config["responseJsonSchema"]["required"] == ["room", "movement", "state", "description", "door_position"]
    assert config["maxOutputTokens"] == 512
    thinking = config["thinkingConfig"]
    assert thinking.get("thinkingBudget", thinking.get("thinking_budget")) == 0  # thinking off by default
    assert "drone" in req.json["systemInstruction"]["parts"][0]["text"].lower()


def test_thinking_budget_adds_to_the_output_budget(fake):
    make_pilot("gemini", base_url=fake.base_url, api_key=KEY, thinking_budget=1024).decide(sample_input())
    config = fake.last.json["generationConfig"]
    assert config["maxOutputTokens"] == 512 + 1024
    make_pilot("gemini", base_url=fake.base_url, api_key=KEY, thinking_budget=None).decide(sample_input())
    assert "thinkingConfig" not in fake.last.json["generationConfig"]


def test_retry_info_in_the_error_body_is_honoured(fake, retry_waits):
    fake.push("rate_limit", retry_info=0.7)  # no Retry-After header: only google.rpc.RetryInfo
    make_pilot("gemini", base_url=fake.base_url, api_key=KEY, max_retries=1).decide(sample_input())
    assert len(fake.requests) == 2
    assert retry_waits == [0.7]


def test_408_and_409_are_retried(fake):
    fake.push("status", status_code=408, retry_after=0.01).push("status", status_code=409, retry_after=0.01)
    make_pilot("gemini", base_url=fake.base_url, api_key=KEY, max_retries=2).decide(sample_input())
    assert len(fake.requests) == 3


def test_google_api_key_is_the_second_choice(fake, monkeypatch):
    monkeypatch.delenv("GEMINI_API_KEY", raising=False)
    monkeypatch.setenv("GOOGLE_API_KEY", "AIza-google-key-000000000000")
    make_pilot("gemini", base_url=fake.base_url).decide(sample_input())
    assert fake.last.headers["x-goog-api-key"] == "AIza-google-key-000000000000"
    monkeypatch.setenv("GEMINI_API_KEY", KEY)
    make_pilot("gemini", base_url=fake.base_url).decide(sample_input())
    assert fake.last.headers["x-goog-api-key"] == KEY


def test_prompt_blocked_is_a_refusal(fake):
    fake.push("refusal", block_reason="SAFETY")
    with pytest.raises(PilotError) as info:
        make_pilot("gemini", base_url=fake.base_url, api_key=KEY).decide(sample_input())
    assert info.value.reason == "refusal" and "SAFETY" in str(info.value)


def test_bad_thinking_option():
    from vlnpilot.core.errors import ConfigError

    with pytest.raises(ConfigError):
        GeminiPilot(api_key=KEY, thinking_budget="lots")
    with pytest.raises(ConfigError):
        GeminiPilot(api_key=KEY, media_resolution="4k")
