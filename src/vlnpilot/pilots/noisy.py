"""`noisy-oracle`: the oracle with the failure modes the paper reports for real models, drawn with seeded odds.

Per episode (from `reseed(seed)`, which the controller calls with `EpisodeConfig.seed`, or else from the `seed`
option's stream) it draws, for every open door in the scene and once for the object:

* **offset** (`p_offset`): it believes the doorway's centre line is `offset_m` (uniform in the range, random
  side) beside the real one, lines up on that belief and crosses "centred" with a propeller in the frame's path
  (or meets the door leaf or jamb on the way) - the paper's propeller-tip contacts.
* **strict** (`p_strict`): it wants the doorway (Oriented Towards Door) or the object (Reach Object) centred
  within `strict_deg` / `strict_lateral_m`, finer than the 15° and 10 cm moves can achieve, so it re-centres
  back and forth (the Gemini oscillation) until the step limit.
* **early** (`p_early`, once per episode): it declares a final state too early - Stay on Room at its first
  Recognize Room, or Reach Object then Describe Object once the object is within `early_distance_m`.

It reads the controller's feedback as a cooperative model would (`heed_feedback`): told by the shield or the
door assist that it is off-centre or blocked, it re-estimates the doorway (drops its offset); told by the
oscillation guard that its alignment is good enough, it relaxes to the oracle's tolerance.
Defaults give roughly the paper's Gemini collision and step-limit counts on the paper suite (Table 4).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Annotated, Any

import numpy as np
from pydantic import Field, field_validator

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Pose, wrap_deg
from vlnpilot.pilots.base import register_pilot
from vlnpilot.pilots.oracle import OracleOptions, OraclePilot
from vlnpilot.safety import ASSIST_NOTE, GUARD_NOTE, SHIELD_NOTE
from vlnpilot.scene.model import Door

OBJECT_KEY = "object"
Probability = Annotated[float, Field(ge=0.0, le=1.0)]


class NoisyOracleOptions(OracleOptions):
    """The failure odds and sizes of the noisy oracle (see the module docstring), besides the oracle's options."""

    model: str = "ground-truth+noise"
    seed: int = 0
    p_offset: Probability = 0.25
    offset_m: tuple[float, float] = (0.36, 0.46)  # (low, high) of the believed centre line's offset
    p_strict: Probability = 0.34
    strict_deg: float = 2.0
    strict_lateral_m: float = 0.01
    p_early: Probability = 0.03
    early_distance_m: float = 1.8
    heed_feedback: bool = True

    @field_validator("offset_m", mode="before")
    @classmethod
    def _pair(cls, value: Any) -> Any:  # "0.3,0.4" from the command line
        return tuple(value.split(",")) if isinstance(value, str) else value

    @field_validator("offset_m")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not 0 <= value[0] <= value[1]:
            raise ValueError("must be (low, high) with 0 <= low <= high")
        return value


@register_pilot("noisy-oracle", options=NoisyOracleOptions)
class NoisyOraclePilot(OraclePilot):
    """The oracle with seeded offset, oscillation and early-final failures (see the module docstring)."""

    name = "noisy-oracle"

    def __init__(self, model: str | None = None, **options: Any):
        o = NoisyOracleOptions.build(self.name, model=model, **options)
        self._configure(o)
        self.seed = o.seed
        self.p_offset, self.offset_m, self.p_strict = o.p_offset, o.offset_m, o.p_strict
        self.strict_deg, self.strict_lateral_m = o.strict_deg, o.strict_lateral_m
        self.p_early, self.early_distance_m, self.heed_feedback = o.p_early, o.early_distance_m, o.heed_feedback
        self._rng = np.random.default_rng(self.seed)
        self._plan: dict | None = None
        self._fixed: set[str] = set()  # doors whose centre it re-estimated after feedback
        self._relaxed: set[str] = set()  # doors / the object it stopped over-centring after feedback
        self._early_done = False
        self._current_key: str | None = None

    def reseed(self, seed: int) -> None:
        """Draw this episode's failures from (`seed` option, episode seed): same seed, same failures."""
        self._rng = np.random.default_rng([self.seed, int(seed)])

    def attach(self, ground_truth) -> None:
        super().attach(ground_truth)
        self._plan, self._fixed, self._relaxed, self._early_done, self._current_key = None, set(), set(), False, None

    # -- the draws -------------------------------------------------------------------------------------------------
    def _draw_plan(self) -> dict:
        rng, lo, hi = self._rng, *self.offset_m
        offsets: dict[str, float] = {}
        strict: set[str] = set()
        for door in sorted(self._truth.scene.open_doors(), key=lambda d: d.id):  # fixed order: reproducible draws
            u_off, mag, side, u_strict = rng.random(), rng.uniform(lo, hi), rng.random(), rng.random()
            if u_off < self.p_offset:
                offsets[door.id] = mag if side < 0.5 else -mag
            if u_strict < self.p_strict:
                strict.add(door.id)
        if rng.random() < self.p_strict:
            strict.add(OBJECT_KEY)
        return {"offsets": offsets, "strict": strict, "early": bool(rng.random() < self.p_early)}

    def drawn_failures(self) -> dict:
        """This episode's drawn failures (after the first decision): door offsets, strict keys, early flag.

        Not named `plan`: a pilot with a `plan` method is taken for a mission planner (pilots.planning.can_plan)."""
        return dict(self._plan or {})

    # -- the policy ----------------------------------------------------------------------------------------------------
    def decide(self, pilot_input: PilotInput) -> Decision:
        if self._plan is None and self._gt is not None:
            self._plan = self._draw_plan()
        if self.heed_feedback and self._current_key is not None:
            for line in pilot_input.feedback:
                if line.startswith(GUARD_NOTE):
                    self._relaxed.add(self._current_key)
                if line.startswith((SHIELD_NOTE, ASSIST_NOTE)) and self._current_key != OBJECT_KEY:
                    self._fixed.add(self._current_key)
        return super().decide(pilot_input)

    def _next_door(self, room: str, goal: str) -> tuple[Door, tuple[float, float]] | None:
        nd = super()._next_door(room, goal)
        if nd is None:
            return None
        door, normal = nd
        self._current_key = door.id
        off = (self._plan or {}).get("offsets", {}).get(door.id)
        if off is None or door.id in self._fixed:
            return nd
        nx, ny = door.normal
        believed = replace(door, center=(door.center[0] - off * ny, door.center[1] + off * nx))
        return believed, normal

    def _strict(self, key: str) -> bool:
        return key in (self._plan or {}).get("strict", set()) and key not in self._relaxed

    def _policy(self, state: State, pose: Pose, allowed: tuple[str, ...]) -> tuple[str, State, str]:
        S, task = State, self._goal
        plan = self._plan or {}
        if task.goal_target is not None and state in (S.SEARCH_OBJECT, S.REACH_OBJECT):
            self._current_key = OBJECT_KEY
        if plan.get("early") and not self._early_done:
            if state is S.RECOGNIZE_ROOM and task.goal_target is None:
                self._early_done = True
                rot = "B1" if "B1" in allowed else allowed[0]
                return rot, S.STAY_ON_ROOM, "This looks like the room I was asked to reach."
            if task.goal_target is not None and state in (S.SEARCH_OBJECT, S.REACH_OBJECT):
                dist, _ = self._truth.target_distance_bearing(task.goal_target)
                if dist <= self.early_distance_m:
                    if state is S.SEARCH_OBJECT:
                        move, _, _ = super()._policy(state, pose, allowed)
                        return move, S.REACH_OBJECT, f"The {task.goal_target} is right there."
                    self._early_done = True
                    return "E", S.DESCRIBE_OBJECT, f"The {task.goal_target} is in front of me."
        if state is S.REACH_OBJECT and self._strict(OBJECT_KEY):
            _, err = self._truth.target_distance_bearing(self._target())
            if abs(err) > self.strict_deg:
                return ("C1" if err > 0 else "B1"), S.REACH_OBJECT, "Centring the object precisely."
        return super()._policy(state, pose, allowed)

    def _orient(self, pose: Pose, door: Door, normal: tuple[float, float], allowed: tuple[str, ...]):
        if not self._strict(door.id):
            return super()._orient(pose, door, normal, allowed)
        S = State
        nx, ny = normal
        dx, dy = pose.x - door.center[0], pose.y - door.center[1]
        depth, lateral = dx * nx + dy * ny, -dx * ny + dy * nx
        heading_err = wrap_deg(math.degrees(math.atan2(ny, nx)) - pose.yaw_deg)
        px, py = self._approach_point(door, normal)
        near = math.hypot(px - pose.x, py - pose.y) <= 0.08 or (abs(lateral) <= 0.25 and depth < -0.15)
        if not near or abs(heading_err) > 22.5:
            return super()._orient(pose, door, normal, allowed)
        if abs(heading_err) > self.strict_deg:  # wants the door exactly centred: 15° steps overshoot
            return ("C1" if heading_err > 0 else "B1"), S.ORIENTED_TOWARDS_DOOR, "The door is not exactly centred."
        if abs(lateral) > self.strict_lateral_m:  # 10 cm steps overshoot too
            return ("D2" if lateral > 0 else "D1"), S.ORIENTED_TOWARDS_DOOR, "Fine-tuning my position to the door."
        return "A1", S.GO_THROUGH_DOOR, "Perfectly centred on the doorway; going through."

