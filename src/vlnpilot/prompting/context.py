"""What the pilot is told beyond the paper's five inputs: odometry, the step budget, a short memory and a
confirmation before a final state; and, in every context, the moves flown in the current state (`in_state_text`:
what the previous states and movements imply, so that no rule needs the pilot's memory; docs/pilot-memory.md).

A real VLM flying from images alone cannot tell how far it has flown: a doorway fills the wide-angle view
(and its frame leaves the image) about half a metre *before* the drone reaches it, and 10 cm moves barely change
the picture. Everything here is known to a real drone without ground truth: odometry is dead reckoning from the
executed commands (a Tello has it from its own commands and IMU), the budget and the memory are the controller's.

Presets: `paper` gives exactly the paper's five inputs (the default, so Table 4 stays a reproduction); `plus`
switches every item on. Each item is a field of `ContextConfig`, so any mix can be flown and is recorded.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, replace
from typing import Any

from vlnpilot.core.commands import Command
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.fsm import State
from vlnpilot.core.ranging import RangeReading, RangeSensor, readings_text
from vlnpilot.tasks.success import longer_move_rule, range_meaning, range_rule

CONFIRM_NOTE = ("Confirmation: you chose the final state '{state}', which ends {what} and cannot be undone. "
                "Look at the image again. Answer '{state}' again only if the image really shows it{why}; "
                "otherwise choose another state and movement.")
_CONFIRM_WHY = {
    State.STAY_ON_ROOM: " (the drone is inside the goal room, not in or just before a doorway)",
    # The stop rule by name, not restated: with a range sensor it is stated in range terms (a pilot reported the
    # width wording here contradicting it).
    State.DESCRIBE_OBJECT: " (the object is straight ahead and visible, and it passes Reach Object's stop rule, "
                           "as that prompt stated it, again)",
}


@dataclass(frozen=True)
class ContextConfig:
    """Items of pilot context beyond the paper's inputs (all off: the paper)."""

    odometry: bool = False  # forward/sideways distance and net rotation since the state began and since the last door
    budget: bool = False  # steps used and left
    memory: int = 0  # the pilot's own last N decisions (state, move, next state, room, description)
    confirm_final: bool = False  # ask once more, with a warning, before a final state is accepted
    ranges: bool = False  # the drone's range readings, in metres, and the stop rule in their terms (if it has any)

    def __post_init__(self) -> None:
        if not isinstance(self.memory, int) or not 0 <= self.memory <= 10:
            raise ConfigError(f"context memory must be an integer from 0 to 10, got {self.memory!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @property
    def is_paper(self) -> bool:
        return self == ContextConfig()


CONTEXT_PRESETS: dict[str, ContextConfig] = {
    "paper": ContextConfig(),
    "plus": ContextConfig(odometry=True, budget=True, memory=4, confirm_final=True, ranges=True),
}


# What `vln-pilot run` and `bench` use when neither the option nor a suite names one: the context the trials measured
# best, with a stateless pilot too (docs/pilot-memory.md). The library's EpisodeConfig keeps "paper", the paper's.
DEFAULT_CONTEXT = "plus"


def context_preset(name: str | ContextConfig) -> ContextConfig:
    """A preset by name (`paper`, `plus`), or a ContextConfig as is."""
    if isinstance(name, ContextConfig):
        return name
    try:
        return CONTEXT_PRESETS[str(name).strip().lower()]
    except KeyError:
        raise UnknownNameError("context preset", name, list(CONTEXT_PRESETS)) from None


def context_name(config: ContextConfig) -> str:
    """The preset's name, or 'custom'."""
    return next((name for name, preset in CONTEXT_PRESETS.items() if preset == config), "custom")


@dataclass(frozen=True)
class Travel:
    """Dead-reckoned travel in the drone's own frame: forward and sideways metres, net rotation (+ = left)."""

    forward_m: float = 0.0
    lateral_m: float = 0.0  # + = left
    rotation_deg: float = 0.0

    def add(self, command: Command) -> Travel:
        m = command.motion()
        return replace(self, forward_m=self.forward_m + m.forward_m, lateral_m=self.lateral_m + m.lateral_m,
                       rotation_deg=self.rotation_deg + m.yaw_deg)

    def text(self) -> str:
        side = "left" if self.lateral_m > 0 else "right"
        turn = "left" if self.rotation_deg > 0 else "right"
        parts = [f"forward {self.forward_m:.2f} m"]
        if abs(self.lateral_m) >= 0.005:
            parts.append(f"sideways {abs(self.lateral_m):.2f} m {side}")
        parts.append(f"net rotation {abs(self.rotation_deg):.0f}° {turn}" if abs(self.rotation_deg) >= 0.5
                     else "net rotation 0°")
        return ", ".join(parts)


LISTED_MOVES = 8  # the moves of the current state that its line names (all of them are counted)


def in_state_text(moves: tuple[str, ...], travel: Travel) -> str:
    """The controller's line on the current state: the moves flown in it so far, their codes and where they took the
    drone. Every context states it: it is what the previous states and movements (paper inputs) imply."""
    if not moves:
        return "0 moves flown in this state so far (this is its first step): forward 0.00 m, net rotation 0°."
    shown = moves[-LISTED_MOVES:]
    which = "" if len(shown) == len(moves) else f"the last {len(shown)}: "
    codes = ", ".join(f"`{c}`" for c in shown)
    return (f"{len(moves)} move{'s' if len(moves) != 1 else ''} flown in this state so far ({which}{codes}, oldest "
            f"first): {travel.text()}.")


class PilotContext:
    """Tracks the episode for the context items and renders them as lines of the step prompt."""

    def __init__(self, config: ContextConfig, max_steps: int, sensor: RangeSensor | None = None,
                 goal_target: str | None = None, longer_moves: bool = False):
        self.config, self.max_steps = config, max_steps
        self.longer_moves = longer_moves  # the profile allows A2 in Reach Object (`ranged`)
        self.sensor, self.goal_target = sensor, goal_target  # a pilot is told only of the sensors its drone has
        self._in_state = Travel()
        self._moves: tuple[str, ...] = ()  # the executed commands of the current state, oldest first
        self._since_door: Travel | None = None  # None until the first Go Through Door
        self._state = State.RECOGNIZE_ROOM  # the state the next step is asked in
        self._memory: deque[str] = deque(maxlen=config.memory)

    def update(self, step: int, state: State, decision: Any, executed: Command, next_state: State) -> None:
        """After a step: `executed` was flown in `state`, and the FSM moves on to `next_state`."""
        self._in_state = self._in_state.add(executed)
        self._moves += (executed.code,)
        if self._since_door is not None:
            self._since_door = self._since_door.add(executed)
        self._state = next_state
        if next_state is not state:
            self._in_state, self._moves = Travel(), ()
            if next_state is State.GO_THROUGH_DOOR:  # the crossing began with this step's move
                self._since_door = Travel().add(executed)
        if decision is not None and self.config.memory:
            changed = "" if decision.movement == executed.code else f" (executed {executed.code})"
            self._memory.append(f"step {step}: in {state.value}, you chose {decision.movement}{changed} -> "
                                f"{next_state.value}; room {decision.room}; you saw: {_short(decision.description)}")

    def in_state(self) -> str:
        """The line every context gets on the current state (`PilotInput.in_state`). In Go Through Door it adds the
        crossing so far, which began with the move that entered the state: the one number its rule counts (pilots
        reported two origins, "flown in this state" and "since the crossing began", one move apart)."""
        text = in_state_text(self._moves, self._in_state)
        if self._state is State.GO_THROUGH_DOOR and self._since_door is not None:
            crossing = self._since_door.forward_m
            text += f" The crossing so far, the move that entered this state included: forward {crossing:.2f} m."
        return text

    def lines(self, step: int, state: State | None = None, readings: tuple[RangeReading, ...] = ()) -> tuple[str, ...]:
        """The context lines of this step's prompt (empty for the paper context)."""
        c, out = self.config, []
        if c.ranges and self.sensor is not None and readings:
            out.append(f"Range sensor ({self.sensor.shown_as}), now: {readings_text(readings)}.")
            out.append(range_meaning(self.sensor))
            if self.goal_target and "front" in self.sensor.directions and state in _OBJECT_STATES:
                out.append(range_rule(self.goal_target))
                if self.longer_moves and state is State.REACH_OBJECT:
                    out.append(longer_move_rule(self.sensor))
        if c.budget:
            out.append(f"Step budget: this is step {step} of {self.max_steps}; {self.max_steps - step} steps "
                       "remain after this one.")
        if c.odometry:
            out.append(f"Odometry in the current state (it restarts at every state change): {self._in_state.text()}.")
            if self._since_door is None:
                out.append("Odometry since the last door crossing began (entering Go Through Door): no door "
                           "crossed yet.")
            else:
                out.append("Odometry since the last door crossing began (entering Go Through Door): "
                           f"{self._since_door.text()}.")
        if c.memory and self._memory:
            out.append("Your last decisions, oldest first:")
            out += [f"  {m}" for m in self._memory]
        return tuple(out)


_OBJECT_STATES = (State.SEARCH_OBJECT, State.REACH_OBJECT)


def confirmation_note(state: State, stages_left: int = 0) -> str:
    """The warning before a final state; in a mission with stages left it ends the stage, not the episode (pilots
    reported "ends the episode" contradicting the mission plan's next stage)."""
    what = "the episode" if stages_left == 0 else "this stage (if it is judged a success, the next stage starts)"
    return CONFIRM_NOTE.format(state=state.value, what=what, why=_CONFIRM_WHY.get(state, ""))


def _short(text: str, limit: int = 140) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"
