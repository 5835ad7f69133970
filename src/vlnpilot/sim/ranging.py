"""The range sensors (`vlnpilot.core.ranging.SENSORS`) simulated by MuJoCo ray casts from the drone's pose.

Each beam starts at the drone's centre plane, at its skin in the beam's direction (the front beam at the camera's
lens), and ignores the drone's own geoms; visual-only geoms (pictures, rugs) reflect a beam as they would a laser,
except the rich detail of `--detail rich` (scene/detail.py), which is not in the scene's geometry.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from vlnpilot.core.ranging import FRONT_BEAM_START_M, RangeReading, RangeSensor
from vlnpilot.core.records import Pose
from vlnpilot.scene.detail import DETAIL_GROUP
from vlnpilot.sim import drone

# Where each beam leaves the drone, in its body frame (x forward, y left, z up): (direction, start offset).
_BEAMS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "front": ((1.0, 0.0, 0.0), (FRONT_BEAM_START_M, 0.0, 0.0)),  # the front camera's lens
    "back": ((-1.0, 0.0, 0.0), (-drone.LENGTH / 2, 0.0, 0.0)),
    "left": ((0.0, 1.0, 0.0), (0.0, drone.WIDTH / 2, 0.0)),
    "right": ((0.0, -1.0, 0.0), (0.0, -drone.WIDTH / 2, 0.0)),
    "up": ((0.0, 0.0, 1.0), (0.0, 0.0, drone.HEIGHT / 2)),
}
# Every geom group but the rich detail's (visual only, not in the scene's geometry: docs/scenes.md).
_SENSED_GROUPS = np.array([int(g != DETAIL_GROUP) for g in range(mujoco.mjNGROUP)], np.uint8)


def beam_distance(model: mujoco.MjModel, data: mujoco.MjData, pose: Pose, direction: str, exclude_body: int,
                  max_m: float) -> float | None:
    """Exact distance (m) from the beam's start to the first surface it meets within `max_m`, else None."""
    return beam(model, data, pose, direction, exclude_body, max_m)[0]


def beam(model: mujoco.MjModel, data: mujoco.MjData, pose: Pose, direction: str, exclude_body: int,
         max_m: float) -> tuple[float | None, int]:
    """(distance within `max_m` or None, the geom the beam meets or -1): the ray cast behind a reading."""
    (dx, dy, dz), (ox, oy, oz) = _BEAMS[direction]
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    start = np.array([pose.x + ox * c - oy * s, pose.y + ox * s + oy * c, pose.z + oz])
    heading = np.array([dx * c - dy * s, dx * s + dy * c, dz])
    geom = np.zeros(1, np.int32)
    hit = mujoco.mj_ray(model, data, start, heading, _SENSED_GROUPS, 1, exclude_body, geom)
    return (float(hit), int(geom[0])) if 0 <= hit <= max_m else (None, -1)


def read_ranges(model: mujoco.MjModel, data: mujoco.MjData, pose: Pose, sensor: RangeSensor, exclude_body: int,
                rng: np.random.Generator | None) -> tuple[RangeReading, ...]:
    """Every beam of `sensor` at `pose`; with `rng`, Gaussian noise of the sensor's sigma, clipped to its range."""
    out = []
    for direction in sensor.directions:
        d = beam_distance(model, data, pose, direction, exclude_body, sensor.max_m)
        if d is not None and rng is not None:
            d = d + float(rng.normal(0.0, sensor.sigma(d)))
        if d is not None:
            d = None if d > sensor.max_m else max(d, sensor.min_m)
        out.append(RangeReading(direction, d, sensor.max_m))
    return tuple(out)
