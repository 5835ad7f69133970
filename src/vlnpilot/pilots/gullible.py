"""`gullible`: a privileged test pilot that obeys the signs it sees (issue 24), and otherwise flies as the oracle.

It reads the scenario's signs through ground truth: a sign is seen when `tasks.signs.signs_seen` says so (legible in
the front image it is given; the same rule the `signs_obeyed` measure judges by), once it has appeared (its trigger:
the step, the episode's clock, which it keeps from the movements executed, or a room entered). The first sign seen
whose text asks something (`tasks.signs.sign_instruction`) is obeyed for the rest of the episode:

- `land`: it declares a final state (with `E`) as soon as its state allows one (in Search Open Door that is Goal
  Unreachable: it stops by reporting the goal unreachable), and Recognize Room (whence Stay on Room is allowed) as
  soon as the state allows that; until then it flies as the oracle;
- `forward`: the longest forward move its state allows, staying in its state where it may.

It is the attack the shield and the FSM must withstand: the shield keeps it clear of walls and people, and the
monitor never judges an obeyed redirect a success (a landing outside the goal is a false success).
"""

from __future__ import annotations

from typing import Any

from vlnpilot.core.commands import COMMANDS, Kind, get_command
from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.fsm import FINAL_MOVE, FINAL_STATES, State, state_spec
from vlnpilot.core.tello_spec import motion_duration_s
from vlnpilot.pilots.base import register_pilot
from vlnpilot.pilots.oracle import OracleOptions, OraclePilot
from vlnpilot.scene.events import EventSpec
from vlnpilot.tasks.signs import FORWARD, LAND, legible_now, sign_instruction, signs, signs_seen


class GullibleOptions(OracleOptions):
    model: str = "ground-truth+signs"


@register_pilot("gullible", options=GullibleOptions)
class GulliblePilot(OraclePilot):
    """The oracle, but it does what the first sign it reads asks (see the module doc)."""

    name = "gullible"

    def __init__(self, model: str | None = None, **options: Any):
        self._configure(GullibleOptions.build(self.name, model=model, **options))

    def attach(self, ground_truth: Any) -> None:
        super().attach(ground_truth)
        self._obeying: tuple[str, str] | None = None  # (what the sign asks, its text)
        self._clock, self._step, self._visited = 0.0, 0, set[str]()

    def decide(self, pilot_input: PilotInput) -> Decision:
        flown = super().decide(pilot_input)  # the oracle's answer (and its bookkeeping: task, room)
        self._tick(pilot_input)
        if self._obeying is None:
            self._obeying = self._read_signs()
        if self._obeying is None:
            return flown
        asks, text = self._obeying
        move_state = self._obey(asks, pilot_input)
        if move_state is None:
            return flown
        move, state = move_state
        return flown.model_copy(update={"movement": move, "state": state.value,
                                        "description": f"A sign says {text!r}; I do as it says."})

    def _tick(self, pilot_input: PilotInput) -> None:
        """The episode's clock (what a `time_s` trigger reads) and the rooms entered (an `enter` trigger), once per
        step: a re-asked step (a confirmation) does not count twice."""
        if pilot_input.step == self._step:
            return
        self._step = pilot_input.step
        if pilot_input.previous_movement:
            m = get_command(pilot_input.previous_movement).motion()
            self._clock += motion_duration_s(m.forward_m, m.lateral_m, m.vertical_m, m.yaw_deg)
        if (room := self._truth.room()) is not None:
            self._visited.add(room)

    def _appeared(self, sign: EventSpec) -> bool:
        t = sign.trigger
        if t.step is not None:
            return self._step >= t.step
        if t.time_s is not None:
            return self._clock >= t.time_s
        return t.enter in self._visited

    def _read_signs(self) -> tuple[str, str] | None:
        scene = self._truth.scene
        present = [s.name for s in signs(scene) if s.name and self._appeared(s)]
        for sign in signs_seen(scene, self._truth.pose(), present, legible_now(self._truth)):
            if (asks := sign_instruction(sign.text)) is not None:
                return asks, str(sign.text)
        return None

    def _obey(self, asks: str, pilot_input: PilotInput) -> tuple[str, State] | None:
        """(movement, next state) doing what the sign asks in this state, or None (fly as the oracle for now)."""
        spec = state_spec(pilot_input.state, pilot_input.profile)
        if asks == LAND:
            final = next((s for s in spec.next_states if s in FINAL_STATES), None)
            if final is not None:
                return FINAL_MOVE, final
            if State.RECOGNIZE_ROOM in spec.next_states:
                return self._smallest_move(spec.moves), State.RECOGNIZE_ROOM
            return None
        if asks == FORWARD:
            forwards = sorted((c for c in spec.moves if COMMANDS[c].kind is Kind.FORWARD),
                              key=lambda c: -COMMANDS[c].amount)
            if not forwards:
                return None
            stay = spec.state if spec.state in spec.next_states else next(
                s for s in spec.next_states if s not in FINAL_STATES)
            return forwards[0], stay
        return None

    @staticmethod
    def _smallest_move(moves: tuple[str, ...]) -> str:
        """Hover if the state allows it, else its smallest rotation (the least the drone can do on its way to land)."""
        if FINAL_MOVE in moves:
            return FINAL_MOVE
        rotations = [c for c in moves if COMMANDS[c].is_rotation]
        return min(rotations, key=lambda c: COMMANDS[c].amount) if rotations else moves[0]
