"""The controller: no invalid decision is ever executed (property test), re-asks, and every termination reason."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vlnpilot.core.commands import COMMANDS, get_command
from vlnpilot.core.decision import Decision, DecisionError, PilotInput, PilotTraits
from vlnpilot.core.environment import Capabilities
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.fsm import FINAL_STATES, State, parse_state, state_spec
from vlnpilot.core.records import Pose
from vlnpilot.episode.config import OUTCOMES, EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.pilots.transport import TRANSIENT_REASONS
from vlnpilot.scene.model import Spawn
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

NEAR_WALL = Spawn("near_wall", "living_room", Pose(3.6, 1.8, 1.0, 0.0), "0.3 m from the living room's east wall")


@pytest.fixture(scope="module")
def geo() -> Simulator:
    with Simulator("cabin", SimConfig(render=False)) as sim:
        yield sim


# -- helpers -------------------------------------------------------------------------------------------------
Answer = Decision | BaseException | Callable[[PilotInput], Decision]


def answer(movement: str, state: str | State, room: str = "unknown") -> Decision:
    return Decision(room=room, movement=movement, state=str(state), description="scripted")


@dataclass
class ScriptedPilot:
    """Answers from a script (a Decision, an exception to raise, or a function of the input), then `default`."""

    script: list[Answer]
    default: Answer | None = None
    name: str = "scripted"
    model: str | None = "script-1"
    inputs: list[PilotInput] = field(default_factory=list)

    def decide(self, pilot_input: PilotInput) -> Decision:
        self.inputs.append(pilot_input)
        item = self.script.pop(0) if self.script else self.default
        if item is None:
            raise AssertionError("script exhausted")
        if isinstance(item, BaseException):
            raise item
        return item(pilot_input) if callable(item) else item


class SpyEnv:
    """Wraps the simulator and logs every command that reaches it, with the pilot's step at that moment."""

    capabilities = Capabilities(ground_truth=True, rear_view=True, contact_sensing=True)

    def __init__(self, sim: Simulator, pilot: ScriptedPilot):
        self.sim, self.pilot, self.scene = sim, pilot, sim.scene
        self.executed: list[tuple[int, str]] = []

    def reset(self, spawn: Any = None, seed: int | None = None):
        self.executed.clear()
        return self.sim.reset(spawn, seed)

    def step(self, command: Any):
        code = command.code if hasattr(command, "code") else get_command(command).code
        self.executed.append((self.pilot.inputs[-1].step, code))
        return self.sim.step(command)

    def ground_truth(self):
        return self.sim.ground_truth()


class BlindEnv:
    """An Environment without ground truth (like a real drone)."""

    capabilities = Capabilities(rear_view=True, contact_sensing=True)

    def __init__(self, sim: Simulator):
        self.sim, self.scene = sim, sim.scene

    def reset(self, spawn: Any = None, seed: int | None = None):
        return self.sim.reset(spawn, seed)

    def step(self, command: Any):
        return self.sim.step(command)


def valid_code(decision: Decision, state: State) -> str | None:
    """The command the controller may execute for this answer in `state`, or None if it must reject it."""
    spec = state_spec(state)
    try:
        code, nxt = get_command(decision.movement).code, parse_state(decision.state)
    except UnknownNameError:
        return None
    return code if spec.allows(code, nxt) and nxt in spec.next_states else None


# -- the property: no invalid decision is ever executed ------------------------------------------------------
MOVES = [*COMMANDS, "a1", " b2 ", "c3", "A4", "B0", "forward", "", "E ", "up", "A1A1"]
STATES = [*(s.value for s in State), "search object", "SEARCH_OPEN_DOOR", "Search open Door", "Flying", "", "Land"]

Action = tuple  # ("valid", i, j, allow_final) | ("raw", movement, state) | ("malformed",) | ("error",) | ("fatal",)
actions = st.lists(
    st.one_of(  # valid and free-form answers twice as likely as errors
        *[st.tuples(st.just("valid"), st.integers(0, 20), st.integers(0, 20), st.booleans())] * 2,
        *[st.tuples(st.just("raw"), st.sampled_from(MOVES), st.sampled_from(STATES))] * 2,
        st.tuples(st.just("malformed")),
        st.tuples(st.just("error")),
        st.tuples(st.just("fatal")),
    ),
    max_size=30,
)


def realise(action: Action) -> Answer:
    kind = action[0]
    if kind == "valid":
        _, i, j, allow_final = action

        def pick(pin: PilotInput) -> Decision:
            spec = state_spec(pin.state)
            nexts = [s for s in spec.next_states if allow_final or s not in FINAL_STATES] or list(spec.next_states)
            return answer(spec.moves[i % len(spec.moves)], nexts[j % len(nexts)])

        return pick
    if kind == "raw":
        return answer(action[1], action[2])
    if kind == "malformed":
        return DecisionError("no JSON object found in the reply")
    if kind == "error":
        return PilotError("provider hiccup", reason="unavailable")
    return PilotError("invalid API key", fatal=True, reason="auth")


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(script=actions, spawn=st.sampled_from(["living_room", "bedroom", "bathroom"]),
       query=st.sampled_from(["Go to the bathroom", "Find the mirror in the bedroom"]))
def test_no_invalid_decision_is_ever_executed(geo: Simulator, script: list[Action], spawn: str, query: str) -> None:
    fallback = ("valid", 3, 0, False)
    pilot = ScriptedPilot([realise(a) for a in script], default=realise(fallback))
    env = SpyEnv(geo, pilot)
    config = EpisodeConfig(max_steps=6)
    result = run_episode(env, pilot, parse_query(query, geo.scene), config, spawn=spawn)
    assert result.outcome in OUTCOMES

    calls: dict[int, list[PilotInput]] = {}
    for pin in pilot.inputs:
        calls.setdefault(pin.step, []).append(pin)
    executed = dict(env.executed)
    assert len(executed) == len(env.executed), "at most one command per step"
    assert sorted(calls) == list(range(1, result.steps + 1))

    # Replay the pilot's answers in order to know, per step, which attempts were valid.
    replay = ScriptedPilot([realise(a) for a in script], default=realise(fallback))
    invalid_steps = 0
    fatal_seen = False
    for step, pins in calls.items():
        assert 1 <= len(pins) <= 1 + config.max_reasks
        state = pins[0].state
        assert all(p.state is state for p in pins)
        outcomes = []
        for pin in pins:
            try:
                outcomes.append(("ok", replay.decide(pin)))
            except PilotError as exc:
                outcomes.append(("fatal" if exc.fatal else "error", exc))
            except DecisionError as exc:
                outcomes.append(("error", exc))
        codes = [valid_code(d, state) if kind == "ok" else None for kind, d in outcomes]
        # every attempt but the last was rejected, and each rejection was fed back on the re-ask
        assert all(c is None for c in codes[:-1])
        for pin, prev in zip(pins[1:], outcomes[:-1], strict=True):
            assert any("rejected" in line for line in pin.feedback)
            assert prev[0] != "fatal"
            assert getattr(prev[1], "reason", None) not in TRANSIENT_REASONS  # never re-asked: the SDK retried it
        if outcomes[-1][0] == "fatal":
            fatal_seen = True
            assert step not in executed and step == result.steps and result.outcome == "pilot_error"
            continue
        if codes[-1] is not None:
            assert executed[step] == codes[-1]
            assert codes[-1] in state_spec(state).answer_moves  # E only with a final state (valid_code)
        else:  # no valid answer after the re-asks (or at once after a transient failure): hover, count it
            transient = getattr(outcomes[-1][1], "reason", None) in TRANSIENT_REASONS
            assert len(pins) == 1 + config.max_reasks or transient
            assert executed[step] == "E"
            invalid_steps += 1
    assert result.invalid_decisions == invalid_steps
    assert result.pilot_calls == len(pilot.inputs)
    if result.outcome == "pilot_error" and not fatal_seen:
        assert invalid_steps >= config.max_failed_steps
    if result.outcome == "max_steps":
        assert result.steps == config.max_steps


# -- re-asks -------------------------------------------------------------------------------------------------
def test_invalid_answer_is_reasked_with_the_reason_then_executed_when_valid(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("A3", "Recognize Room"),  # A3 is not allowed in Recognize Room
                           answer("C1", "Go Through Door"),  # transition not allowed
                           answer("c1", "recognize room")],  # valid, in a model's spelling
                          default=answer("C1", "Recognize Room"))
    env = SpyEnv(geo, pilot)
    result = run_episode(env, pilot, parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=1),
                         spawn="living_room")
    assert [p.step for p in pilot.inputs] == [1, 1, 1]
    assert pilot.inputs[0].feedback == ()
    assert "movement 'A3' is not allowed" in pilot.inputs[1].feedback[0]
    assert "A1, B1, B2, B3, C1, C2, C3" in pilot.inputs[1].feedback[0]
    assert "next state 'Go Through Door' is not allowed" in pilot.inputs[2].feedback[0]
    assert env.executed == [(1, "C1")]
    assert result.invalid_decisions == 0 and result.outcome == "max_steps"


def test_a_decision_is_validated_once(geo: Simulator, monkeypatch: pytest.MonkeyPatch) -> None:
    """A pilot that validates its own decisions (ModelPilot) is not validated again; any other pilot is."""
    import vlnpilot.episode.ask as episode_ask

    seen: list[str] = []

    def spy(decision: Decision, state: State, profile: str = "paper") -> str | None:
        seen.append(decision.movement)
        return None

    monkeypatch.setattr(episode_ask, "validate_decision", spy)
    query, config = parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=2)
    run_episode(geo, ScriptedPilot([], default=answer("C1", "Recognize Room")), query, config, spawn="bedroom")
    assert seen == ["C1", "C1"]
    seen.clear()
    trusted = ScriptedPilot([], default=answer("C1", "Recognize Room"))
    trusted.traits = PilotTraits(validates_decisions=True)  # type: ignore[attr-defined]
    result = run_episode(geo, trusted, query, config, spawn="bedroom")
    assert seen == [] and result.steps == 2 and result.invalid_decisions == 0


def test_pilot_inputs_carry_state_and_previous_movement(geo: Simulator) -> None:
    pilot = ScriptedPilot([], default=answer("C2", "Recognize Room"))
    run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=3),
                spawn="bedroom")
    first, second = pilot.inputs[0], pilot.inputs[1]
    assert first.state is State.RECOGNIZE_ROOM and first.previous_movement is None and first.step == 1
    assert first.query == "Go to the bathroom" and first.topological_map == geo.scene.topological_map()
    assert second.previous_movement == "C2" and second.step == 2


# -- every termination reason --------------------------------------------------------------------------------
def test_success(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("C1", "Stay on Room", "bedroom")])
    result = run_episode(geo, pilot, parse_query("Go to the bedroom", geo.scene), spawn="bedroom")
    assert (result.outcome, result.steps, result.final_state) == ("success", 1, "Stay on Room")
    assert result.success and result.spl == 1.0


def test_success_with_the_oracle_through_the_registry(geo: Simulator) -> None:
    result = run_episode(geo, make_pilot("oracle"), parse_query("Find the sink", geo.scene), spawn="bathroom")
    assert result.outcome == "success" and result.final_state == "Describe Object"


def test_false_success_when_stay_on_room_is_declared_in_the_wrong_room(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("C1", "Stay on Room", "bathroom")])
    result = run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), spawn="bedroom")
    assert result.outcome == "false_success" and not result.success
    assert "drone is in bedroom; goal room bathroom" in result.reason
    assert result.spl == 0.0 and result.final_room == "bedroom"


def test_false_success_when_the_object_is_not_reached(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("C1", "Search Object"), answer("C1", "Reach Object"),
                           answer("E", "Describe Object")])
    result = run_episode(geo, pilot, parse_query("Find the mirror in the bedroom", geo.scene), spawn="living_room")
    assert result.outcome == "false_success" and "mirror at" in result.reason


def test_collision_flying_a1_into_a_wall(geo: Simulator) -> None:
    pilot = ScriptedPilot([], default=answer("A1", "Recognize Room"))
    result = run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), spawn=NEAR_WALL)
    assert result.outcome == "collision" and result.collisions == 1
    assert result.contact and result.contact in result.reason
    assert result.steps <= 5  # 0.3 m to the wall, minus the drone's half size
    assert geo.pose.x < 4.0  # stopped at the last free pose, never inside the wall


def test_max_steps(geo: Simulator) -> None:
    pilot = ScriptedPilot([], default=answer("C1", "Recognize Room"))
    result = run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=4),
                         spawn="living_room")
    assert (result.outcome, result.steps, result.pilot_calls) == ("max_steps", 4, 4)
    assert "4 steps" in result.reason


def test_pilot_error_on_a_fatal_error_asks_once_and_moves_nothing_more(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("C1", "Recognize Room"), PilotError("401: invalid API key", fatal=True,
                                                                       reason="auth")])
    env = SpyEnv(geo, pilot)
    result = run_episode(env, pilot, parse_query("Go to the bathroom", geo.scene), spawn="living_room")
    assert (result.outcome, result.steps, result.pilot_calls) == ("pilot_error", 2, 2)
    assert result.reason == "auth: 401: invalid API key"
    assert env.executed == [(1, "C1")]


def test_pilot_error_when_no_step_got_a_decision_before_the_step_limit(geo: Simulator) -> None:
    """An unreachable provider: every call a transient connection error, too few in a row to end the episode."""
    pilot = ScriptedPilot([], default=PilotError("connection refused", reason="connection_error"))
    result = run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=2),
                         spawn="living_room")
    assert (result.outcome, result.steps) == ("pilot_error", 2)
    assert result.reason == "no valid decision in any of the 2 steps"


def test_the_step_limit_stays_max_steps_when_one_step_got_a_decision(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("C1", "Recognize Room")],
                          default=PilotError("connection refused", reason="connection_error"))
    result = run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=2),
                         spawn="living_room")
    assert result.outcome == "max_steps"


def test_pilot_error_after_repeated_invalid_answers(geo: Simulator) -> None:
    pilot = ScriptedPilot([], default=answer("A3", "Land"))
    env = SpyEnv(geo, pilot)
    config = EpisodeConfig()
    result = run_episode(env, pilot, parse_query("Go to the bathroom", geo.scene), config, spawn="living_room")
    assert result.outcome == "pilot_error"
    assert result.steps == config.max_failed_steps == 3
    assert result.invalid_decisions == 3 and result.pilot_calls == 3 * (1 + config.max_reasks)
    assert env.executed == [(1, "E"), (2, "E"), (3, "E")]  # it hovered, never flew A3
    assert "no valid decision in 3 consecutive steps" in result.reason


def test_malformed_answers_then_a_valid_one_reset_the_streak(geo: Simulator) -> None:
    bad = [DecisionError("not JSON")] * 3
    pilot = ScriptedPilot([*bad, *bad, answer("C1", "Recognize Room"), *bad, *bad],
                          default=answer("C1", "Recognize Room"))
    result = run_episode(geo, pilot, parse_query("Go to the bathroom", geo.scene), EpisodeConfig(max_steps=6),
                         spawn="living_room")
    assert result.outcome == "max_steps" and result.invalid_decisions == 4


# -- configuration and environments --------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs", [{"max_steps": 0}, {"max_steps": -3}, {"max_steps": 2.5}, {"profile": "turbo"},
                                    {"max_reasks": -1}])
def test_episode_config_rejects_bad_values(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ConfigError):
        EpisodeConfig(**kwargs)


def test_environment_without_ground_truth(geo: Simulator) -> None:
    pilot = ScriptedPilot([answer("C1", "Stay on Room")])
    result = run_episode(BlindEnv(geo), pilot, parse_query("Go to the bathroom", geo.scene), spawn="bedroom")
    assert result.outcome == "declared" and not result.success and "no ground truth" in result.reason  # unjudged
    with pytest.raises(ConfigError, match="needs ground truth"):
        run_episode(BlindEnv(geo), OraclePilot(), parse_query("Go to the bathroom", geo.scene), spawn="bedroom")
