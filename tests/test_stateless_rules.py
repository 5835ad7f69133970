"""Every rule of every prompt is decidable from that step's prompt and image: no rule refers to history the prompt
does not carry. The phrases that refer to history are listed beside the templates
(prompting/templates/history_phrases.txt); each may appear only where the same prompt carries what it refers to,
with its count (docs/pilot-memory.md)."""

from __future__ import annotations

import re
from importlib.resources import files

import pytest

from fakes import sample_input
from vlnpilot.core.commands import get_command
from vlnpilot.core.decision import Decision
from vlnpilot.core.fsm import ASKED_STATES, PROFILES, State, state_spec
from vlnpilot.prompting.context import CONTEXT_PRESETS, PilotContext
from vlnpilot.prompting.render import build_prompt, render_state_template, system_prompt

PHRASES_FILE = files("vlnpilot.prompting") / "templates" / "history_phrases.txt"


def history_phrases() -> list[tuple[re.Pattern[str], re.Pattern[str] | None]]:
    """(phrase, evidence or None) per line of history_phrases.txt."""
    out = []
    for line in PHRASES_FILE.read_text(encoding="utf-8").splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        phrase, _, evidence = (part.strip() for part in line.partition("<="))
        out.append((re.compile(phrase, re.I), re.compile(evidence, re.I | re.M) if evidence else None))
    return out


def unfounded(text: str) -> list[str]:
    """The history phrases in `text` whose evidence the same text does not carry."""
    return [f"{phrase.pattern!r} in {hit.group(0)!r}" for phrase, evidence in history_phrases()
            for hit in [phrase.search(text)] if hit and (evidence is None or not evidence.search(text))]


def _context(preset: str, state: State, moves: int) -> PilotContext:
    """The controller's context after `moves` moves flown in `state` (the first of them entered it)."""
    context = PilotContext(CONTEXT_PRESETS[preset], max_steps=40)
    decision = Decision(room="hall", movement="A1", state=state.value, description="a view")
    for step in range(1, moves + 1):
        context.update(step, state, decision, get_command(state_spec(state).moves[0]), state)
    return context


def rendered(profile: str, preset: str, state: State, moves: int, **overrides) -> str:
    """Everything a pilot reads at one step (the system prompt and the user text), as the controller renders it."""
    context = _context(preset, state, moves)
    pin = sample_input(state, profile=profile, step=moves + 1, context=context.lines(moves + 1),
                       in_state=context.in_state(), **overrides)
    return system_prompt() + "\n" + build_prompt(pin).user_text()


def test_the_phrase_list_reads_and_names_the_issues_examples():
    patterns = " ".join(p.pattern for p, _ in history_phrases())
    for example in ("since the crossing began", "in the last 3 steps", "count your moves", "flown in this state"):
        assert any(p.search(example) for p, _ in history_phrases()), example
    assert "crossing" in patterns


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("preset", sorted(CONTEXT_PRESETS))
@pytest.mark.parametrize("state", ASKED_STATES, ids=lambda s: s.name.lower())
@pytest.mark.parametrize("moves", [0, 3])
def test_no_rule_refers_to_history_the_prompt_does_not_carry(profile, preset, state, moves):
    assert unfounded(rendered(profile, preset, state, moves)) == []


def test_every_context_states_the_moves_flown_in_the_current_state():
    for preset in CONTEXT_PRESETS:
        text = rendered("paper", preset, State.GO_THROUGH_DOOR, 3)
        assert "## Flown in this state\n3 moves flown in this state so far (`A1`, `A1`, `A1`, oldest first): " \
               "forward 0.30 m, net rotation 0°." in text


def test_a_counting_rule_put_back_without_its_count_fails():
    spec = state_spec(State.SEARCH_OBJECT)
    template = (files("vlnpilot.prompting") / "templates" / "state_search_object.md").read_text(encoding="utf-8")
    for rule in ("- Count your moves before you turn.", "- Turn if the object has not been seen in the last 3 steps.",
                 "- Keep flying until about 1 m since the crossing began."):
        bad = template.replace("## POLICY RULES\n", f"## POLICY RULES\n\n{rule}\n")
        text = system_prompt() + render_state_template(bad, spec) + "## Flown in this state\n0 moves flown"
        assert unfounded(text), rule


def test_a_rule_on_the_moves_flown_in_this_state_needs_the_controllers_count():
    with_count = rendered("paper", "paper", State.GO_THROUGH_DOOR, 2)
    assert unfounded(with_count) == []
    without = with_count.replace("## Flown in this state\n2 moves", "## Flown in this state\nsome moves")
    assert any("flown in this state" in problem for problem in unfounded(without))
