"""Core immutable records shared by every layer: poses, motions, observations."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from vlnpilot.core.movers import FiredEvent, MoverState


@dataclass(frozen=True)
class Pose:
    """World-frame pose: metres, z up, yaw in degrees counter-clockwise from +x."""

    x: float
    y: float
    z: float
    yaw_deg: float

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw_deg"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"Pose.{name} must be finite, got {getattr(self, name)!r}")

    @property
    def yaw_rad(self) -> float:
        return math.radians(self.yaw_deg)

    def heading(self) -> tuple[float, float]:
        """Unit vector the drone faces, in the horizontal plane."""
        return math.cos(self.yaw_rad), math.sin(self.yaw_rad)

    def distance_xy(self, other: Pose) -> float:
        return math.hypot(self.x - other.x, self.y - other.y)

    def as_dict(self) -> dict[str, float]:
        return {"x": round(self.x, 4), "y": round(self.y, 4), "z": round(self.z, 4), "yaw_deg": round(self.yaw_deg, 3)}


def wrap_deg(angle: float) -> float:
    """Wrap an angle to (-180, 180]."""
    a = (angle + 180.0) % 360.0 - 180.0
    return 180.0 if a == -180.0 else a


@dataclass(frozen=True)
class Motion:
    """A body-frame displacement: forward (+x body), lateral (+ = left), vertical, yaw (+ = left/CCW)."""

    forward_m: float = 0.0
    lateral_m: float = 0.0
    vertical_m: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("forward_m", "lateral_m", "vertical_m", "yaw_deg"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"Motion.{name} must be finite, got {getattr(self, name)!r}")

    @property
    def is_null(self) -> bool:
        return self.forward_m == self.lateral_m == self.vertical_m == self.yaw_deg == 0.0

    def apply(self, pose: Pose, fraction: float = 1.0) -> Pose:
        """The pose reached after `fraction` of this motion (translation in the start heading, then yaw)."""
        c, s = pose.heading()
        f, l = self.forward_m * fraction, self.lateral_m * fraction
        return Pose(
            pose.x + f * c - l * s,
            pose.y + f * s + l * c,
            pose.z + self.vertical_m * fraction,
            wrap_deg(pose.yaw_deg + self.yaw_deg * fraction),
        )


@dataclass(frozen=True)
class Observation:
    """What the drone senses after a reset or a step. Images are HxWx3 uint8 arrays."""

    front_rgb: np.ndarray = field(repr=False)
    rear_rgb: np.ndarray = field(repr=False)
    pose: Pose
    collided: bool | None = False  # None: unknown, the robot senses no contact (the Tello)
    contact: str | None = None  # what the drone touched, e.g. 'door_living_bedroom_frame_left'
    step: int = 0
    contact_part: str | None = None  # which part of the drone touched it, e.g. 'prop_front_left'
    info: dict[str, Any] = field(default_factory=dict, compare=False)  # robot facts to record (frame age, battery)
    # False: the robot found that the step's command did not happen (a rotation whose reply was lost and whose
    # yaw did not change): the step is recorded with nothing executed.
    executed: bool = field(default=True, compare=False)
    # Issue 24, ground truth for the record (never shown to a model pilot): the scenario's events that fired during
    # this step (or at the reset), and the movers' states after it.
    events: tuple[FiredEvent, ...] = field(default=(), compare=False)
    movers: tuple[MoverState, ...] = field(default=(), compare=False)


Point2D = tuple[float, float]
# Where an object stands on the floor, seen from above: convex polygons (x, y corners, counter-clockwise), one per
# part of the object; the success monitor measures to the nearest of their points.
Footprint = tuple[tuple[Point2D, ...], ...]


@runtime_checkable
class MotionSampling(Protocol):
    """How an environment checks a motion for contact, so that a shield can predict exactly what it will do."""

    def substeps(self, motion: Motion) -> int:
        """At how many evenly spaced poses (at i/n, i = 1..n) a motion is checked; 1: only where it ends."""
