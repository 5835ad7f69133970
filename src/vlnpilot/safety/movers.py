"""The mover shield (issue 24): no command may carry the drone within its margin of a person's or a pet's predicted
position over the command's duration; such a command is replaced by a hover, with the reason `mover:<name>`.

Prediction: each mover at constant velocity (`MoverState.at`) over the command's duration
(`tello_spec.motion_duration_s`: the motion, then the settle, during which the drone holds its end pose). The drone
moves in a straight line (a rotation does not move its centre), so between those instants both move linearly and
the closest approach is exact (no sampling). Distances are horizontal, between the drone's bounding circle
(`tello_spec.BOUNDING_RADIUS`) and the mover's footprint (`MoverState.radius`). Heights
(`SafetyConfig.mover_clearance`, `core.movers.reaches_height`): under "3d" (new runs) a person is a column from
floor to ceiling, and a pet conflicts only if the drone's bottom could come within `JUMP_MARGIN_M` (0.3 m) of its
top (0.35 m: far below the 1 m flight height); under "column" (the rule the events trials were flown with,
replayed as recorded) a pet is a column too.

Already within the margin (a person walked up to the hovering drone), a command is allowed only if it keeps the
drone at least as far from the mover as the hover it would be replaced by: the drone can always back away.
Movers yield too (`core.movers`: one about to come close stops), so a hovering drone is never walked into.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from vlnpilot.core import tello_spec
from vlnpilot.core.commands import HOVER, Command, Kind
from vlnpilot.core.movers import SHIELD_MARGIN_M, MoverState, reaches_height
from vlnpilot.core.records import Motion, Observation, Pose
from vlnpilot.safety.shields import Shield

MOVER_REASON = "mover:"  # an Intervention's reason for a hover substituted for a mover starts so


def _closest(r0: tuple[float, float], r1: tuple[float, float]) -> float:
    """The least distance from the origin to the segment r0 -> r1 (a relative position moving linearly)."""
    dx, dy = r1[0] - r0[0], r1[1] - r0[1]
    span = dx * dx + dy * dy
    t = 0.0 if span == 0 else min(1.0, max(0.0, -(r0[0] * dx + r0[1] * dy) / span))
    return math.hypot(r0[0] + t * dx, r0[1] + t * dy)


def motion_seconds(motion: Motion) -> tuple[float, float]:
    """(seconds in motion, seconds in all) of a motion: the settle after it holds the end pose."""
    total = tello_spec.motion_duration_s(motion.forward_m, motion.lateral_m, motion.vertical_m, motion.yaw_deg)
    return (0.0 if motion.is_null else max(0.0, total - tello_spec.SETTLE_S)), total


def least_clearance(pose: Pose, motion: Motion, mover: MoverState, *, hover: bool = False) -> float:
    """The least horizontal gap (m) between the drone's bounding circle and the mover's footprint while `motion`
    is flown from `pose` and the mover walks on at its present velocity (negative: they would overlap).
    `hover`: the drone holds `pose` instead, for as long as `motion` would take (what the shield would substitute)."""
    moving, total = motion_seconds(motion)
    end = pose if hover else motion.apply(pose)
    track = ((0.0, pose), (moving, end), (total, end))  # the drone's centre, linear between these instants
    gaps = []
    for (t0, p0), (t1, p1) in zip(track, track[1:], strict=False):
        m0, m1 = mover.at(t0), mover.at(t1)
        gaps.append(_closest((m0.x - p0.x, m0.y - p0.y), (m1.x - p1.x, m1.y - p1.y)))
    return min(gaps) - tello_spec.BOUNDING_RADIUS - mover.radius


class NoWalls(Shield):
    """What the mover shield wraps under `--shield assist` (the door assist and guard alone): it sees no walls."""

    name = "assist"

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        return None


class MoverShield(Shield):
    """Wraps the environment's shield (geometry or depth): movers first, then the walls; keeps the inner name, so
    a run's recorded shield is the same with or without people in the scene."""

    def __init__(self, inner: Shield, movers: Callable[[], tuple[MoverState, ...]],
                 margins: dict[str, float] | None = None):
        super().__init__(inner.config)
        self.inner, self._movers = inner, movers
        self.margins = dict(SHIELD_MARGIN_M if margins is None else margins)
        self.name = inner.name
        self.clearance = inner.config.mover_clearance

    def reset(self, obs: Observation) -> None:
        self.inner.reset(obs)

    def observe(self, obs: Observation) -> None:
        self.inner.observe(obs)

    def mover_hazard(self, pose: Pose, motion: Motion) -> str | None:
        """`mover:<name>: ...` if the motion would bring the drone within the margin of a mover (and closer than the
        hover would), else None."""
        if motion.is_null:
            return None
        bottom = min(pose.z, motion.apply(pose).z) - tello_spec.HEIGHT / 2  # no move of the table climbs or sinks
        for mover in self._movers():
            if not reaches_height(mover, bottom, self.clearance):
                continue  # a pet far below the drone: it does not block the way
            margin = self.margins[mover.kind]
            limit = min(margin, least_clearance(pose, motion, mover, hover=True))  # never worse than the hover
            gap = least_clearance(pose, motion, mover)
            if gap < limit - 1e-9:
                return (f"{MOVER_REASON}{mover.name}: the drone would come {max(gap, 0.0) * 100:.0f} cm from a "
                        f"{mover.kind} walking on as it does now (keeps {margin * 100:.0f} cm)")
        return None

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        return self.mover_hazard(pose, motion) or self.inner.hazard(pose, motion)

    def filter(self, pose: Pose, command: Command) -> tuple[Command, str | None]:
        """A mover in the way: hover (never a shortened move towards it); else the inner shield's choice, unless
        that is itself unsafe near a mover."""
        if command.kind is Kind.NONE:
            return command, None
        why = self.mover_hazard(pose, command.motion())
        if why is not None:
            return HOVER, why
        safe, why = self.inner.filter(pose, command)
        if safe.kind is not Kind.NONE and (near := self.mover_hazard(pose, safe.motion())) is not None:
            return HOVER, near
        return safe, why
