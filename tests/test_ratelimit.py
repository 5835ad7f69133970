"""The shared rate budget (pilots/ratelimit.py): the option, the providers' headers, AIMD, sharing between
workers, and the official SDKs against fakes that limit like the providers (tests/fakes/limits.py)."""

from __future__ import annotations

import numpy as np
import pytest

from cli_support import run_main
from fakes import FakeAnthropic, FakeGemini, FakeOpenAI
from vlnpilot.core.decision import PilotInput
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State, parse_state
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.pilots.ratelimit import (
    RateBudget,
    RateLimit,
    budget_file,
    parse_rate_limit,
    parse_reset,
    read_limit_headers,
    share_budgets,
)
from vlnpilot.tasks.task import parse_query


class Clock:
    """Time that moves only when a waiter sleeps."""

    def __init__(self) -> None:
        self.now, self.slept = 1000.0, 0.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds
        self.slept += seconds


@pytest.fixture
def clock():
    return Clock()


@pytest.fixture
def shared(tmp_path, clock):
    share_budgets(tmp_path / "rate", clock=clock, sleep=clock.sleep)
    yield tmp_path / "rate"
    share_budgets(None)


def pin() -> PilotInput:
    return PilotInput(image=np.zeros((8, 8, 3), np.uint8), query="Go to the bedroom", topological_map={},
                      state=State.RECOGNIZE_ROOM, previous_movement=None)


# ------------------------------------------------------------------ the option and the headers
def test_rate_limit_option_parses_and_refuses_in_one_line():
    assert parse_rate_limit("300,150000") == RateLimit(300, 150000)
    assert parse_rate_limit("60") == RateLimit(60, None)
    assert parse_rate_limit(None) is None
    for bad in ("abc", "0,100", "60,-1", "1,2,3", "60,"):
        with pytest.raises(ConfigError, match="--rate-limit must be RPM or RPM,TPM") as info:
            parse_rate_limit(bad)
        assert "\n" not in str(info.value)


def test_cli_bench_refuses_a_bad_rate_limit_with_exit_2(tmp_path, monkeypatch, capsys):
    code, out, err = run_main(monkeypatch, capsys, "bench", "--rate-limit", "fast", "--out", str(tmp_path / "b"))
    assert code == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "--rate-limit must be RPM or RPM,TPM" in lines[0], err
    assert not (tmp_path / "b").exists()  # refused before anything ran


def test_headers_of_openai_and_anthropic_are_read():
    openai = read_limit_headers({"x-ratelimit-limit-requests": "500", "x-ratelimit-limit-tokens": "30000",
                                 "x-ratelimit-remaining-requests": "499", "x-ratelimit-remaining-tokens": "29000"})
    assert (openai.limit_rpm, openai.limit_tpm, openai.left_requests, openai.left_tokens) == (500, 30000, 499, 29000)
    anthropic = read_limit_headers({"anthropic-ratelimit-requests-limit": "50",
                                    "anthropic-ratelimit-tokens-limit": "40000"})
    assert (anthropic.limit_rpm, anthropic.limit_tpm) == (50, 40000)
    assert read_limit_headers({"content-type": "application/json"}) is None
    assert parse_reset("6m0s") == 360.0 and parse_reset("20ms") == 0.02 and parse_reset("1.5s") == 1.5
    assert parse_reset("2026-01-01T00:01:00Z", now=1767225600.0) == 60.0


# ------------------------------------------------------------------ AIMD and sharing
def test_budget_spaces_requests_backs_off_on_429_and_grows_on_success(tmp_path, clock):
    budget = RateBudget(tmp_path / "b.json", RateLimit(60, None), clock, clock.sleep)
    assert budget.acquire() == 0.0  # a full bucket: one second of 60 rpm
    assert budget.acquire() == pytest.approx(1.0)  # then one request a second
    budget.observe(429, {})
    assert budget.snapshot()["rate_rpm"] == 30  # multiplicative decrease
    assert budget.acquire() == pytest.approx(2.0)  # the bucket was emptied; at 30 rpm a request every 2 s
    budget.observe(200, {})
    assert budget.snapshot()["rate_rpm"] == 31  # additive increase: 1 % of the limit, at least 1 rpm
    for _ in range(100):
        budget.observe(200, {})
    assert budget.snapshot()["rate_rpm"] == 60  # never above the limit


def test_headers_win_over_the_option_and_tokens_are_charged(tmp_path, clock):
    budget = RateBudget(tmp_path / "b.json", RateLimit(60, 1000), clock, clock.sleep)
    budget.observe(200, {"x-ratelimit-limit-requests": "120", "x-ratelimit-limit-tokens": "6000"})
    state = budget.snapshot()
    assert (state["limit_rpm"], state["rate_rpm"], state["limit_tpm"], state["source"]) == (120, 120, 6000, "headers")
    budget.acquire()
    budget.charge(1000 + 3000)  # the balance (at most 1000, the option's) goes 3000 below zero
    assert budget.acquire() == pytest.approx(30.0)  # 3000 tokens at 6000 per minute


def test_two_workers_share_one_budget_through_the_file(tmp_path, clock):
    path = tmp_path / "rate" / "OpenAI-gpt-4.1.json"
    one, two = (RateBudget(path, RateLimit(60, None), clock, clock.sleep) for _ in range(2))
    assert one.acquire() == 0.0
    assert two.acquire() == pytest.approx(1.0)  # the other worker took the only request of the bucket
    one.observe(429, {})
    assert two.snapshot()["rate_rpm"] == 30 and two.snapshot()["throttled"] == 1


def test_a_retry_after_pauses_every_worker_of_the_budget(tmp_path, clock):
    """One worker's 429 says Retry-After: 20; the other worker, which was not refused, waits for it as well."""
    path = tmp_path / "rate" / "OpenAI-gpt-4.1.json"
    refused, other = (RateBudget(path, RateLimit(600, None), clock, clock.sleep) for _ in range(2))
    refused.acquire()
    refused.observe(429, {"retry-after": "20"})
    assert other.acquire() == pytest.approx(20.0)  # not the bucket's 0.2 s at the halved 300 rpm
    clock.now += 60.0
    assert other.acquire() == 0.0  # the pause is over
    refused.observe(429, {"retry-after-ms": "1500"})
    assert other.acquire() == pytest.approx(1.5)
    refused.observe(429, {})  # no Retry-After: only the back-off, no pause
    assert other.acquire() < 1.0


# ------------------------------------------------------------------ the SDKs against limiting fakes
@pytest.mark.parametrize("fake_cls, spec, key", [(FakeOpenAI, "openai:gpt-4.1", "sk-test"),
                                                 (FakeAnthropic, "anthropic:claude-sonnet-4-6", "sk-ant-test")])
def test_sdk_pilots_read_the_headers_and_back_off_on_429(fake_cls, spec, key, shared, clock):
    with fake_cls().limit(rpm=3, tpm=1_000_000, clock=lambda: 0.0) as fake:
        pilot = make_pilot(spec, base_url=fake.base_url, api_key=key, max_retries=0)
        for _ in range(3):
            pilot.decide(pin())
        provider = type(pilot).provider
        state = RateBudget(budget_file(shared, provider, pilot.model), clock=clock).snapshot()
        assert (state["limit_rpm"], state["limit_tpm"], state["source"]) == (3, 1_000_000, "headers")
        assert 20.0 <= clock.slept < 21.0  # the third request waited its turn at 3 rpm (and for its tokens)
        with pytest.raises(PilotError) as info:  # the fake's window is full (its clock stands still)
            pilot.decide(pin())
        assert info.value.reason == "rate_limited" and fake.throttled == 1
        state = RateBudget(budget_file(shared, provider, pilot.model), clock=clock).snapshot()
        assert state["throttled"] == 1 and state["rate_rpm"] == 1.5
        pilot.close()


def test_gemini_without_headers_backs_off_from_the_rate_it_sent(shared, clock):
    with FakeGemini().limit(rpm=2, clock=lambda: 0.0) as fake:
        pilot = make_pilot("gemini:gemini-2.5-flash", base_url=fake.base_url, api_key="AIza-test", max_retries=0)
        pilot.decide(pin())
        pilot.decide(pin())
        with pytest.raises(PilotError):
            pilot.decide(pin())
        state = RateBudget(budget_file(shared, "Gemini", pilot.model), clock=clock).snapshot()
        assert state["source"] is None and state["throttled"] == 1 and state["rate_rpm"] == 6  # the floor
        pilot.close()


def test_a_429_neither_fails_the_episode_nor_counts_as_a_step(geo_sim):
    oracle = OraclePilot()
    oracle.attach(geo_sim.ground_truth())

    def answer(request):
        return oracle.decide(PilotInput(image=np.zeros((2, 2, 3), np.uint8), query="Go to the bedroom",
                                        topological_map={}, state=parse_state(request.current_state),
                                        previous_movement=None)).core()

    task = parse_query("Go to the bedroom", geo_sim.scene)
    with FakeOpenAI(oracle=answer) as fake:
        fake.push("rate_limit", times=5)  # more than max_failed_steps (3) and the SDK's retries (0)
        pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-test", max_retries=0)
        result = run_episode(geo_sim, pilot, task, EpisodeConfig(max_steps=50), spawn="living_room")
        answered = sum(1 for _ in fake.requests) - 5
    assert result.outcome == "success", result.reason
    assert result.steps == answered  # the five 429s are no steps
    assert result.invalid_decisions == 0


def test_progress_line_shows_the_rate_the_allowed_rate_and_the_limit(tmp_path, clock):
    from vlnpilot.bench.rate_column import rate_line

    budget = RateBudget(budget_file(tmp_path, "OpenAI", "gpt-4.1"), RateLimit(60, None), clock, clock.sleep)
    budget.acquire()
    budget.acquire()
    budget.observe(429, {})
    line = rate_line(tmp_path, clock)
    assert line == "OpenAI-gpt-4.1: 2/min (allowed 30, limit 60 option, 1 x 429)"
    assert rate_line(tmp_path / "none", clock) == "" and rate_line(None) == ""


def test_a_bench_shares_the_budget_in_its_directory_and_429s_fail_nothing(tmp_path, monkeypatch):
    import io
    import json

    from rich.console import Console

    from bench_records import TINY
    from vlnpilot.bench.command import bench_command
    from vlnpilot.bench.results import ResultsLog

    monkeypatch.setenv("OPENAI_API_KEY", "sk-test")
    suite = tmp_path / "tiny.yaml"
    suite.write_text(TINY.replace("repetitions: 2", "repetitions: 1").replace("max_steps: 30", "max_steps: 4"))
    with FakeOpenAI().limit(rpm=1000, tpm=10_000_000) as fake:
        fake.push("rate_limit", times=2)
        out = bench_command(suite=str(suite), pilots="openai:gpt-4.1", out=tmp_path / "b", executor="inline",
                            base_url=fake.base_url, pilot_options={"max_retries": "0"},
                            progress=False, console=Console(file=io.StringIO()), rate_limit="100,50000")
    records = ResultsLog(out / "results.jsonl").read()
    assert len(records) == 2 and all(r["result"]["outcome"] != "pilot_error" for r in records)
    state = json.loads((out / "rate" / "OpenAI-gpt-4.1.json").read_text())
    assert (state["limit_rpm"], state["source"], state["throttled"]) == (1000, "headers", 2)
    share_budgets(None)


def test_no_request_left_closes_the_budget_until_the_reset(tmp_path, clock):
    budget = RateBudget(tmp_path / "b.json", None, clock, clock.sleep)
    budget.observe(200, {"x-ratelimit-limit-requests": "60", "x-ratelimit-remaining-requests": "0",
                         "x-ratelimit-reset-requests": "30s"})
    assert budget.acquire() == pytest.approx(30.0)  # not the bucket's 1 s: the provider's window is full
