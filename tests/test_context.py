"""The pilot context beyond the paper: presets, dead-reckoned odometry, budget, memory, and the confirmation
before a final state (asked once, recorded, replayed)."""

from __future__ import annotations

import pytest

from vlnpilot.core.commands import get_command
from vlnpilot.core.decision import Decision
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.fsm import State
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.prompting.context import CONTEXT_PRESETS, ContextConfig, PilotContext, context_name, context_preset
from vlnpilot.prompting.render import build_prompt
from vlnpilot.tasks.task import parse_query

S = State


def answer(move: str, state: State, room: str = "bedroom") -> Decision:
    return Decision(room=room, movement=move, state=state.value, description="a doorway ahead",
                    door_position="center")


def test_presets_paper_is_the_paper_and_plus_is_everything() -> None:
    assert context_preset("paper") == ContextConfig() and context_preset("PAPER").is_paper
    plus = context_preset("plus")
    assert plus.odometry and plus.budget and plus.memory and plus.confirm_final
    assert context_name(plus) == "plus" and context_name(ContextConfig(budget=True)) == "custom"
    assert PilotContext(CONTEXT_PRESETS["paper"], 50).lines(1) == ()
    with pytest.raises(UnknownNameError, match="paper, plus"):
        context_preset("pluss")
    with pytest.raises(ConfigError, match="0 to 10"):
        ContextConfig(memory=11)


def test_odometry_restarts_per_state_and_counts_the_move_that_starts_a_crossing() -> None:
    ctx = PilotContext(context_preset("plus"), 50)
    assert "no door crossed yet" in ctx.lines(1)[2]
    ctx.update(1, S.ORIENTED_TOWARDS_DOOR, answer("A1", S.ORIENTED_TOWARDS_DOOR), get_command("A1"),
               S.ORIENTED_TOWARDS_DOOR)
    ctx.update(2, S.ORIENTED_TOWARDS_DOOR, answer("A1", S.GO_THROUGH_DOOR), get_command("A1"), S.GO_THROUGH_DOOR)
    ctx.update(3, S.GO_THROUGH_DOOR, answer("A1", S.GO_THROUGH_DOOR), get_command("A1"), S.GO_THROUGH_DOOR)
    ctx.update(4, S.GO_THROUGH_DOOR, answer("D1", S.GO_THROUGH_DOOR), get_command("D1"), S.GO_THROUGH_DOOR)
    budget, in_state, since_door, *_ = ctx.lines(5)
    assert "step 5 of 50; 45 steps remain" in budget
    assert "forward 0.10 m, sideways 0.10 m left" in in_state  # step 3's A1 and step 4's D1, in Go Through Door
    assert "forward 0.20 m, sideways 0.10 m left" in since_door  # plus step 2's A1, which began the crossing
    ctx.update(5, S.GO_THROUGH_DOOR, answer("A1", S.POSITION_IN_CENTER), get_command("A1"), S.POSITION_IN_CENTER)
    ctx.update(6, S.POSITION_IN_CENTER, answer("C2", S.POSITION_IN_CENTER), get_command("C2"), S.POSITION_IN_CENTER)
    _, in_state, since_door, *_ = ctx.lines(7)
    assert "forward 0.00 m, net rotation 45° left" in in_state
    assert "forward 0.30 m" in since_door and "45° left" in since_door


def test_memory_keeps_the_last_decisions_and_says_when_the_safety_layer_changed_one() -> None:
    ctx = PilotContext(ContextConfig(memory=2), 50)
    for step, (move, executed) in enumerate((("B1", "B1"), ("A1", "E"), ("C1", "C1")), start=1):
        ctx.update(step, S.SEARCH_OPEN_DOOR, answer(move, S.SEARCH_OPEN_DOOR), get_command(executed),
                   S.SEARCH_OPEN_DOOR)
    lines = ctx.lines(4)
    assert lines[0] == "Your last decisions, oldest first:" and len(lines) == 3
    assert "step 2:" in lines[1] and "you chose A1 (executed E)" in lines[1] and "step 3:" in lines[2]


def test_the_context_reaches_the_prompt() -> None:
    ctx = PilotContext(context_preset("plus"), 50)
    from fakes.inputs import sample_input

    text = build_prompt(sample_input(S.GO_THROUGH_DOOR, context=ctx.lines(3))).step_text
    assert "## Pilot context" in text and "- Step budget: this is step 3 of 50" in text
    assert "dead-reckoned from the executed commands" in text  # explained where it appears


def test_the_paper_context_never_mentions_a_pilot_context() -> None:
    """Under the paper's five inputs there is no pilot context: no prompt text may announce one (real pilots
    flying the paper context waited for the odometry the system prompt said 'may follow')."""
    from fakes.inputs import sample_input

    for state in (S.RECOGNIZE_ROOM, S.GO_THROUGH_DOOR, S.REACH_OBJECT):
        prompt = build_prompt(sample_input(state, context=PilotContext(context_preset("paper"), 50).lines(3)))
        for text in (prompt.system, prompt.context, prompt.state_prompt, prompt.step_text):
            assert "pilot context" not in text.lower() and "odometry" not in text.lower()


class Hesitant:
    """Declares the goal at once, then changes its mind when asked to confirm, then declares it again."""

    name, model = "hesitant", "scripted"

    def __init__(self) -> None:
        self.calls: list[tuple[int, tuple[str, ...]]] = []

    def decide(self, pin):  # noqa: ANN001, ANN201
        self.calls.append((pin.step, pin.feedback))
        confirming = any(f.startswith("Confirmation:") for f in pin.feedback)
        if pin.step == 1:
            return answer("B1", S.RECOGNIZE_ROOM if confirming else S.STAY_ON_ROOM)  # looks around once more
        return answer("E", S.STAY_ON_ROOM)


def test_a_final_state_is_confirmed_once_and_may_be_changed(geo_sim, tmp_path) -> None:
    task = parse_query("Go to the bedroom", geo_sim.scene)
    pilot = Hesitant()
    result = run_episode(geo_sim, pilot, task, EpisodeConfig(context="plus", max_steps=5), spawn="bedroom",
                         recorder=Recorder(tmp_path / "run"))
    assert result.outcome == "success" and result.steps == 2  # step 1 changed its mind, step 2 confirmed
    assert [step for step, _ in pilot.calls] == [1, 1, 2, 2]  # one confirmation per final declaration
    summary, steps = load_run(tmp_path / "run")
    assert summary["config"]["context"]["preset"] == "plus"
    first = steps[0]["confirmation"]
    assert first["first"]["state"] == "Stay on Room" and first["confirmed"] is False
    assert steps[-1]["confirmation"]["confirmed"] is True
    # the replay pilot answers the confirmation exactly as recorded
    again = run_episode(geo_sim, make_pilot(f"replay:{tmp_path / 'run'}"), task,
                        EpisodeConfig(context="plus", max_steps=5), spawn="bedroom")
    assert (again.outcome, again.steps, again.pilot_calls) == (result.outcome, result.steps, result.pilot_calls)


def test_the_paper_context_never_asks_to_confirm(geo_sim) -> None:
    pilot = Hesitant()
    result = run_episode(geo_sim, pilot, parse_query("Go to the bedroom", geo_sim.scene),
                         EpisodeConfig(max_steps=5), spawn="bedroom")
    assert result.steps == 1 and pilot.calls == [(1, ())]
