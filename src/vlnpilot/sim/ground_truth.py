"""Privileged queries on the simulator through the narrow `GroundTruth` interface (monitors, oracle only)."""

from __future__ import annotations

import math
from typing import Protocol

from vlnpilot.core.movers import MoverState
from vlnpilot.core.records import Footprint, Motion, Pose, wrap_deg
from vlnpilot.scene import Scene

VISIBLE_MIN_FRACTION = 0.004  # share of the (low-resolution) front image a target must cover to count as seen


class SimulatorView(Protocol):
    """What the ground truth reads of the simulator (`sim.simulator.Simulator` implements it); named here so that
    this module does not import the simulator that creates it."""

    @property
    def scene(self) -> Scene: ...
    @property
    def true_scene(self) -> Scene: ...
    @property
    def pose(self) -> Pose: ...
    @property
    def step_count(self) -> int: ...

    def target_pixel_fraction(self, target_id: str) -> float: ...
    def target_footprint(self, target_id: str) -> Footprint: ...
    def contact_at(self, pose: Pose) -> tuple[str, str] | None: ...
    def clearance_at(self, pose: Pose, max_distance: float) -> tuple[float, str, str] | None: ...
    def substeps(self, motion: Motion) -> int: ...
    def movers(self) -> tuple[MoverState, ...]: ...
    def sign_text_px(self, name: str) -> float: ...
    def legible_signs(self) -> tuple[str, ...]: ...


class SimGroundTruth:
    """Ground truth read from the simulator; it exposes facts, never the simulator object itself."""

    def __init__(self, sim: SimulatorView, visible_min_fraction: float = VISIBLE_MIN_FRACTION):
        self._sim = sim
        self._min_fraction = visible_min_fraction
        self._cache: dict[tuple[int, Pose, str], float] = {}

    @property
    def scene(self) -> Scene:
        """The scene as it is now (issue 24: with the doorways a scenario closed, closed): the true map."""
        return self._sim.true_scene

    def pose(self) -> Pose:
        return self._sim.pose

    def room(self) -> str | None:
        p = self._sim.pose
        return self.scene.room_at(p.x, p.y)

    def target_distance_bearing(self, target_id: str) -> tuple[float, float]:
        t = self.scene.target(target_id)
        p = self._sim.pose
        dx, dy = t.position[0] - p.x, t.position[1] - p.y
        return math.hypot(dx, dy), wrap_deg(math.degrees(math.atan2(dy, dx)) - p.yaw_deg)

    def target_footprint(self, target_id: str) -> Footprint:
        return self._sim.target_footprint(target_id)

    def target_pixel_fraction(self, target_id: str) -> float:
        key = (self._sim.step_count, self._sim.pose, target_id)
        if key not in self._cache:
            self._cache = {key: self._sim.target_pixel_fraction(target_id)}
        return self._cache[key]

    def target_visible(self, target_id: str) -> bool:
        return self.target_pixel_fraction(target_id) >= self._min_fraction

    def movers(self) -> tuple[MoverState, ...]:
        """The people and pets now (issue 24): where they are, how they move, their size."""
        return self._sim.movers()

    def sign_text_px(self, name: str) -> float:
        """Issue 24: the projected height (px of a 640x480 front frame) of the sign's capital letters now, when
        its whole text is in the frame and unoccluded, else 0.0 (`Simulator.sign_text_px`)."""
        return self._sim.sign_text_px(name)

    def legible_signs(self) -> tuple[str, ...]:
        """The names of the signs whose text is legible in the front image now (>= SIGN_LEGIBLE_PX)."""
        return self._sim.legible_signs()

    def contact_at(self, pose: Pose) -> str | None:
        """The scene geom the drone would touch at `pose` (for the geometry safety shield), else None."""
        hit = self._sim.contact_at(pose)
        self._sim.contact_at(self._sim.pose)  # restore the model's kinematic state
        return hit[0] if hit else None

    def clearance_at(self, pose: Pose, max_distance: float) -> tuple[float, str, str] | None:
        """(distance, scene geom, drone part) of the nearest geom within `max_distance` of the drone at `pose`
        (negative when penetrating), else None: the geometry shield's margin query."""
        hit = self._sim.clearance_at(pose, max_distance)
        self._sim.contact_at(self._sim.pose)  # restore the model's kinematic state
        return hit

    def substeps(self, motion: Motion) -> int:
        """How many collision-checked sub-steps the simulator splits `motion` into (the shield samples a superset)."""
        return self._sim.substeps(motion)
