"""Chaos: every HTTP attempt of a pilot call, the SDKs' own retries included, reaches the step record (issue 26,
item 12), through the official SDKs against the fake servers on 127.0.0.1."""

from __future__ import annotations

import json

import httpx
import pytest

from fakes import FakeAnthropic, FakeGemini, FakeOpenAI, sample_input
from vlnpilot.core.rundir import Recorder
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.remote import RemotePilot
from vlnpilot.tasks.task import parse_query

pytestmark = pytest.mark.chaos
FAKES = {"openai": FakeOpenAI, "gemini": FakeGemini, "anthropic": FakeAnthropic}
SPECS = {"openai": "openai:gpt-4.1", "gemini": "gemini:gemini-2.5-flash", "anthropic": "anthropic:claude-sonnet-4-6"}
KEYS = {"openai": "sk-not-a-real-key-0000", "gemini": "AIza-not-a-real-key", "anthropic": "sk-ant-not-a-real-key"}


class Ticks:
    """An injected clock: each reading is one second after the previous one."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 1.0
        return self.now


def pilot_for(provider: str, fake, **options):
    pilot = make_pilot(SPECS[provider], base_url=fake.base_url, api_key=KEYS[provider], max_retries=2, **options)
    pilot._attempts.clock = Ticks()
    return pilot


def refuse_twice(fake) -> None:
    fake.push("status", status_code=429, retry_after=0.01).push("status", status_code=500, retry_after=0.01)


@pytest.mark.parametrize("provider", list(FAKES))
def test_a_429_then_a_500_then_success_are_three_attempts_in_order(provider, retry_waits) -> None:
    with FAKES[provider]() as fake:
        refuse_twice(fake)
        decision = pilot_for(provider, fake).decide(sample_input())
        sent = len(fake.requests)
    attempts = decision.usage.attempts
    assert sent == 3 and [a.get("status") for a in attempts] == [429, 500, 200]
    assert all(a["latency_s"] == 1.0 and a["wait_s"] == 1.0 for a in attempts)  # one tick each, by the clock
    assert "attempts" not in decision.usage.model_dump()  # `usage` reads as before


@pytest.mark.parametrize("provider", list(FAKES))
def test_a_call_that_fails_after_its_retries_keeps_its_attempts(provider, retry_waits) -> None:
    with FAKES[provider]() as fake:
        fake.push("status", status_code=503, retry_after=0.01, times=3)
        with pytest.raises(PilotError) as info:
            pilot_for(provider, fake).decide(sample_input())
    assert [a.get("status") for a in info.value.usage.attempts] == [503, 503, 503]


def test_the_remote_pilot_records_its_attempts(retry_waits) -> None:
    ok = {"room": "hall", "movement": "C1", "state": "Reach Object"}
    responses = [httpx.Response(429, headers={"retry-after-ms": "10"}), httpx.Response(500),
                 httpx.Response(200, json=ok)]
    pilot = RemotePilot(url="http://pilot.test", max_retries=2,
                        transport=httpx.MockTransport(lambda request: responses.pop(0)))
    pilot._attempts.clock = Ticks()
    decision = pilot.decide(sample_input())
    assert [a.get("status") for a in decision.usage.attempts] == [429, 500, 200]


def test_a_refused_connection_is_an_attempt_with_its_error_kind(retry_waits) -> None:
    pilot = RemotePilot(url="http://127.0.0.1:9", max_retries=1)  # the discard port: nothing listens
    with pytest.raises(PilotError) as info:
        pilot.decide(sample_input())
    attempts = info.value.usage.attempts
    assert [a.get("error") for a in attempts] == ["transport_error", "connection_error"]
    assert all(a["latency_s"] is None for a in attempts)


def test_the_step_record_has_each_calls_attempts_and_its_wall_time(geo_sim, tmp_path, retry_waits) -> None:
    with FakeOpenAI() as fake:
        refuse_twice(fake)
        run_episode(geo_sim, pilot_for("openai", fake), parse_query("Go to the bedroom", geo_sim.scene),
                    EpisodeConfig(max_steps=1), spawn="living_room", recorder=Recorder(tmp_path / "run"))
    steps = [json.loads(line) for line in (tmp_path / "run" / "episode.jsonl").read_text().splitlines()]
    steps = [s for s in steps if "step" in s]
    assert [[a.get("status") for a in call] for call in steps[0]["attempts"]] == [[429, 500, 200]]
    assert all(s["wall_s"] >= 0 for s in steps)


def test_a_call_abandoned_at_the_step_deadline_keeps_its_attempts(geo_sim, tmp_path, retry_waits) -> None:
    with FakeOpenAI() as fake:
        fake.push("status", status_code=500, retry_after=0.01).push("hang", times=5, seconds=3.0)
        run_episode(geo_sim, pilot_for("openai", fake), parse_query("Go to the bedroom", geo_sim.scene),
                    EpisodeConfig(max_steps=1, step_deadline_s=1.0), spawn="living_room",
                    recorder=Recorder(tmp_path / "run"))
    steps = [json.loads(line) for line in (tmp_path / "run" / "episode.jsonl").read_text().splitlines()]
    first = next(s for s in steps if s.get("step") == 1)
    (call,) = [[a.get("status") or a.get("error") for a in call] for call in first["attempts"]]
    assert call[-1] == "abandoned" and set(call[:-1]) <= {500}  # the hung one; the 500 before it, if it came in time
