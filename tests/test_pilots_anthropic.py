"""Anthropic pilot specifics: the forced tool, prompt-cache breakpoints, cache-aware usage and cost."""

from __future__ import annotations

import pytest

from fakes import FakeAnthropic, sample_input
from vlnpilot.pilots.anthropic import TOOL_NAME, AnthropicPilot, _reply
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.model import Reply
from vlnpilot.pilots.pricing import cost_usd

KEY = "sk-ant-test-0123456789"


@pytest.fixture
def fake():
    with FakeAnthropic() as server:
        yield server


def test_request_shape(fake):
    pilot = make_pilot("anthropic", base_url=fake.base_url, api_key=KEY)
    assert isinstance(pilot, AnthropicPilot) and pilot.model == "claude-sonnet-4-6"
    pilot.decide(sample_input())
    body = fake.last.json
    headers = fake.last.headers
    assert KEY in (headers.get("x-api-key", ""), headers.get("authorization", "").removeprefix("Bearer "))
    assert body["tool_choice"] == {"type": "tool", "name": TOOL_NAME}
    assert [t["name"] for t in body["tools"]] == [TOOL_NAME]
    assert body["tools"][0]["input_schema"]["properties"]["movement"]["enum"][0] == "A1"
    assert body["max_tokens"] == 512
    # cache breakpoints on the stable prefix, none on the image or the step text
    assert body["system"][0]["cache_control"] == {"type": "ephemeral"}
    blocks = body["messages"][0]["content"]
    assert [b["type"] for b in blocks] == ["text", "text", "text", "image"]  # the image last (issue 27)
    assert [("cache_control" in b) for b in blocks] == [True, True, False, False]
    assert blocks[3]["source"]["media_type"] == "image/jpeg"


def test_cache_off_and_strict_tool(fake):
    make_pilot("anthropic", base_url=fake.base_url, api_key=KEY, cache=False, strict_tool=True).decide(sample_input())
    body = fake.last.json
    assert "cache_control" not in str(body)
    assert body["tools"][0]["strict"] is True


def test_usage_counts_cache_reads_and_writes():
    class Usage:
        input_tokens, cache_read_input_tokens, cache_creation_input_tokens, output_tokens = 100, 1000, 2000, 50

    class Message:
        usage = Usage()
        content = []
        stop_reason = "end_turn"

    reply = _reply(Message())
    assert isinstance(reply, Reply)
    assert (reply.input_tokens, reply.cached_tokens, reply.cache_write_tokens) == (3100, 1000, 2000)
    cost = cost_usd("claude-sonnet-4-6", 3100, 1000, 50, cache_write_tokens=2000)
    assert cost.known
    assert cost.usd == pytest.approx((100 * 3.0 + 1000 * 0.30 + 2000 * 3.75 + 50 * 15.0) / 1e6)


def test_text_instead_of_the_tool_is_parsed(fake):
    fake.push("text", text='{"room": "hall", "movement": "B2", "state": "Reach Object", "description": "x", '
                           '"door_position": "center"}')
    decision = make_pilot("anthropic", base_url=fake.base_url, api_key=KEY).decide(sample_input())
    assert decision.movement == "B2" and decision.door_position == "center"


def test_overloaded_529_is_retried(fake):
    fake.push("status", status_code=529, retry_after=0.01)
    make_pilot("anthropic", base_url=fake.base_url, api_key=KEY).decide(sample_input())
    assert len(fake.requests) == 2


def test_truncated_tool_call(fake):
    fake.push("truncated")
    with pytest.raises(PilotError) as info:
        make_pilot("anthropic", base_url=fake.base_url, api_key=KEY).decide(sample_input())
    assert info.value.reason == "truncated" and "max_output_tokens" in str(info.value)
