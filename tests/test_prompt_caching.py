"""Prompt caching (issue 27): each request puts the episode's stable text first and the image last, so that the
providers' prefix caches serve it, and the cached tokens each API reports land in the call's usage.

Through the official SDKs against the fakes, whose prompt caches serve a prefix seen in the last five minutes
(tests/fakes/prompt_cache.py: OpenAI and Gemini any prefix of 1,024 tokens or more, Anthropic its `cache_control`
breakpoints), on an injected clock.
"""

from __future__ import annotations

import pytest

from fakes import FakeAnthropic, FakeGemini, FakeOpenAI, sample_input
from vlnpilot.core.fsm import State
from vlnpilot.pilots.base import make_pilot
from vlnpilot.prompting.render import build_prompt

KEY = "secret-test-key-0123456789"
FAKES = {"openai": FakeOpenAI, "gemini": FakeGemini, "anthropic": FakeAnthropic}


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(params=sorted(FAKES))
def provider(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def fake(provider: str, clock: Clock):
    with FAKES[provider]() as server:
        server.prompt_cache.clock = clock
        yield server


def _pilot(provider: str, fake):
    return make_pilot(provider, base_url=fake.base_url, api_key=KEY, timeout=5.0, max_retries=0)


def _stable_tokens(state: State = State.SEARCH_OBJECT) -> int:
    """The fakes' count (4 characters a token) of what stays the same within a state: system, context, state prompt."""
    prompt = build_prompt(sample_input(state))
    return sum(len(t) // 4 for t in (prompt.system, prompt.context, prompt.state_prompt))


def test_the_second_step_of_an_episode_is_served_from_the_cache(provider: str, fake) -> None:
    pilot = _pilot(provider, fake)
    first = pilot.decide(sample_input(step=3)).usage
    second = pilot.decide(sample_input(step=4, previous_movement="B2")).usage

    assert first.cached_tokens == 0
    # the cached prefix reaches through the state prompt: only the step text and the image are new
    assert second.cached_tokens >= _stable_tokens() - (128 if provider == "openai" else 0)
    assert second.cached_tokens < second.input_tokens
    assert second.cost_usd < first.cost_usd
    if provider == "anthropic":  # the breakpoints are written once, then read
        assert first.cache_write_tokens >= _stable_tokens() and second.cache_write_tokens == 0
    else:
        assert first.cache_write_tokens == second.cache_write_tokens == 0
    if provider == "openai":  # reported in steps of 128 beyond the first 1,024, as the API does
        assert (second.cached_tokens - 1024) % 128 == 0


def test_the_image_comes_last_in_every_request(provider: str, fake) -> None:
    _pilot(provider, fake).decide(sample_input())
    assert fake.last.parts[-1] == "image" and fake.last.parts.count("image") == 1


def test_a_prefix_unused_for_five_minutes_is_gone(provider: str, fake, clock: Clock) -> None:
    pilot = _pilot(provider, fake)
    pilot.decide(sample_input(step=3))
    clock.now += 301.0
    assert pilot.decide(sample_input(step=4)).usage.cached_tokens == 0


def test_a_new_state_starts_a_new_prefix(provider: str, fake) -> None:
    """The answer schema is per state and each provider reads it first (OpenAI's response format, Anthropic's tool,
    Gemini's generation config): a step in a new state is served from the cache from its second step on."""
    pilot = _pilot(provider, fake)
    pilot.decide(sample_input(State.SEARCH_OBJECT, step=3))
    usage = pilot.decide(sample_input(State.REACH_OBJECT, step=4)).usage
    assert usage.cached_tokens == 0
    again = pilot.decide(sample_input(State.REACH_OBJECT, step=5)).usage
    assert again.cached_tokens >= _stable_tokens(State.REACH_OBJECT) - 128


def test_the_step_record_keeps_the_cache_counts(fake, provider: str) -> None:
    pilot = _pilot(provider, fake)
    pilot.decide(sample_input(step=3))
    recorded = pilot.decide(sample_input(step=4)).usage.model_dump()
    assert recorded["cached_tokens"] > 0 and "cache_write_tokens" in recorded
