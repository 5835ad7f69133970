"""Conversation memory of the model pilots (the `history` option), against the fake provider servers through the
official SDKs, and through the pilot server with the remote pilot."""

from __future__ import annotations

import json
from typing import Any

import pytest

from fakes import FakeAnthropic, FakeGemini, FakeOpenAI, ServerThread, sample_image, sample_input
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State
from vlnpilot.pilots.base import make_pilot
from vlnpilot.pilots.model import PilotReplyError
from vlnpilot.server import create_app

KEY = "secret-test-key-0123456789"
FAKES = {"openai": FakeOpenAI, "gemini": FakeGemini, "anthropic": FakeAnthropic}
# An episode of four steps: two in Search Object, then two in Reach Object (each step its own image).
EPISODE = [(1, State.SEARCH_OBJECT, None), (2, State.SEARCH_OBJECT, "B1"), (3, State.REACH_OBJECT, "B1"),
           (4, State.REACH_OBJECT, "A1")]


def step_input(step: int, state: State, previous: str | None, **overrides: Any):
    return sample_input(state, step=step, previous_movement=previous, image=sample_image(seed=step),
                        in_state=f"{step - 1} moves flown in this state so far", **overrides)


def chat(provider: str, body: dict[str, Any]) -> list[tuple[str, list[tuple[str, str]]]]:
    """The request's conversation after the system prompt: (role, [(kind, text or image data)]) per message, in
    order, with the cache marks left out (they mark a prefix, they are not part of it)."""
    def part(p: dict[str, Any]) -> tuple[str, str]:
        if p.get("type") == "text" or (provider == "gemini" and "text" in p):
            return "text", p["text"]
        return "image", json.dumps({k: v for k, v in p.items() if k != "cache_control"}, sort_keys=True)

    if provider == "gemini":
        return [("assistant" if m["role"] == "model" else m["role"], [part(p) for p in m["parts"]])
                for m in body["contents"]]
    messages = [m for m in body["messages"] if m["role"] != "system"]
    return [(m["role"], [("text", m["content"])] if isinstance(m["content"], str) else [part(p) for p in m["content"]])
            for m in messages]


def system(provider: str, body: dict[str, Any]) -> str:
    if provider == "openai":
        return body["messages"][0]["content"]
    if provider == "anthropic":
        return body["system"][0]["text"]
    return json.dumps(body["systemInstruction"], sort_keys=True)


def images(messages: list[tuple[str, list[tuple[str, str]]]]) -> int:
    return sum(kind == "image" for _, parts in messages for kind, _ in parts)


def steps(messages: list[tuple[str, list[tuple[str, str]]]]) -> list[int]:
    """The step number of each user message, from its step text."""
    out = []
    for role, parts in messages:
        if role == "user":
            text = "".join(t for kind, t in parts if kind == "text")
            out.append(int(text.split("## Step\n", 1)[1].split()[0]))
    return out


@pytest.fixture(params=sorted(FAKES))
def provider(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def fake(provider: str):
    with FAKES[provider]() as server:
        yield server


def fly(provider: str, fake: Any, **options: Any) -> list[tuple[Any, Any]]:
    """Fly EPISODE; (the decision, the request's body) per step."""
    pilot = make_pilot(provider, base_url=fake.base_url, api_key=KEY, timeout=5.0, max_retries=0, **options)
    out = []
    for step, state, previous in EPISODE:
        decision = pilot.decide(step_input(step, state, previous))
        out.append((decision, fake.requests[-1].json))
    pilot.close()
    return out


def test_history_sends_the_earlier_turns_in_order_with_bounded_images(provider, fake):
    flown = fly(provider, fake, history=2, history_images=1)
    last = chat(provider, flown[-1][1])
    assert [role for role, _ in last] == ["user", "assistant", "user", "assistant", "user"]
    assert steps(last) == [2, 3, 4]  # the last two earlier turns, oldest first, then this step
    answers = [parts[0][1] for role, parts in last if role == "assistant"]
    assert answers == [flown[1][0].raw_text, flown[2][0].raw_text]  # the model's own earlier answers
    assert images(last) == 2  # this step's image and the last earlier one (history_images=1)
    assert [kind for kind, _ in last[0][1]].count("image") == 0 and "not sent again" in json.dumps(last[0][1])
    assert [kind for kind, _ in last[2][1]].count("image") == 1
    text = json.dumps(last)
    assert text.count("## User query") == 1  # the episode's context once, at the start of the oldest turn
    assert text.count("## State: **Reach Object**") == 1  # a state prompt is not repeated by the next turn


def test_every_earlier_image_is_sent_when_asked_and_none_by_default(provider, fake):
    assert images(chat(provider, fly(provider, fake, history=3, history_images=3)[-1][1])) == 4
    assert images(chat(provider, fly(provider, fake, history=3)[-1][1])) == 1


def test_with_history_the_second_call_begins_with_the_first(provider, fake):
    flown = fly(provider, fake, history=4, history_images=4)
    first, second = (chat(provider, body) for _, body in flown[:2])
    assert system(provider, flown[0][1]) == system(provider, flown[1][1])
    assert second[:len(first)] == first  # the provider's prefix cache hits on the whole first request
    third = chat(provider, flown[2][1])
    assert third[:len(second)] == second
    # Without earlier images the prefix still holds the context and the state prompt of the first turn.
    lean = [chat(provider, body) for _, body in fly(provider, fake, history=4)[:2]]
    assert lean[1][0][1][:2] == lean[0][0][1][:2]


def test_without_history_each_call_is_one_user_message(provider, fake):
    for _, body in fly(provider, fake):
        assert [role for role, _ in chat(provider, body)] == ["user"]


def test_a_new_episode_starts_a_new_conversation(provider, fake):
    pilot = make_pilot(provider, base_url=fake.base_url, api_key=KEY, timeout=5.0, max_retries=0, history=3)
    for step, state, previous in EPISODE[:3]:
        pilot.decide(step_input(step, state, previous))
    pilot.decide(step_input(1, State.SEARCH_OBJECT, None))
    assert [role for role, _ in chat(provider, fake.requests[-1].json)] == ["user"]


def test_a_rejected_answer_is_not_remembered_and_a_second_answer_replaces_the_first(provider, fake):
    pilot = make_pilot(provider, base_url=fake.base_url, api_key=KEY, timeout=5.0, max_retries=0, history=3)
    pilot.decide(step_input(1, State.SEARCH_OBJECT, None))
    fake.push("not_json")
    with pytest.raises(PilotReplyError):
        pilot.decide(step_input(2, State.SEARCH_OBJECT, "B1"))
    second = pilot.decide(step_input(2, State.SEARCH_OBJECT, "B1", feedback=("Your previous answer was rejected",)))
    again = pilot.decide(step_input(2, State.SEARCH_OBJECT, "B1", feedback=("Confirmation",)))
    pilot.decide(step_input(3, State.SEARCH_OBJECT, "B1"))
    last = chat(provider, fake.requests[-1].json)
    assert steps(last) == [1, 2, 3]
    assert [p[0][1] for r, p in last if r == "assistant"][-1] == again.raw_text
    assert "Confirmation" in json.dumps(last[2]) and second.raw_text


def test_history_options_are_checked_in_one_line():
    for options, fragment in (({"history": "lots"}, "history is 'none' or a number"),
                              ({"history": "2", "history_images": "3"}, "cannot exceed"),
                              ({"history_images": "1"}, "cannot exceed")):
        with pytest.raises(ConfigError) as err:
            make_pilot("openai", api_key=KEY, **options)
        assert fragment in str(err.value) and "\n" not in str(err.value)
    assert make_pilot("openai", api_key=KEY, history="4", history_images="2").memory == "history=4,images=2"
    assert make_pilot("gemini", api_key=KEY).memory == "none"


def test_the_remote_pilot_sends_its_conversation_through_the_server():
    with FakeOpenAI() as fake:
        def factory(spec: str, **options: Any):
            return make_pilot(spec, base_url=fake.base_url, api_key=KEY, timeout=5.0, max_retries=0, **options)

        with ServerThread(create_app(factory, pilot_spec="openai")) as url:
            remote = make_pilot("remote", url=url, history=2, history_images=1)
            flown = [remote.decide(step_input(step, state, previous)) for step, state, previous in EPISODE]
            plain = make_pilot("remote", url=url)  # another client of the same server pilot: no memory of the first
            plain.decide(step_input(4, State.REACH_OBJECT, "A1"))
            remote.close()
            plain.close()
        with_memory, without = (chat("openai", r.json) for r in fake.requests[-2:])
    assert steps(with_memory) == [2, 3, 4] and images(with_memory) == 2
    assert [p[0][1] for r, p in with_memory if r == "assistant"] == [flown[1].raw_text, flown[2].raw_text]
    assert "3 moves flown in this state so far" in json.dumps(with_memory[-1])  # in_state passes through
    assert [role for role, _ in without] == ["user"]
