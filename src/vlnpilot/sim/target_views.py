"""What the front camera shows of a target from a given standpoint: the measurements behind the prompts' visual
rules (how wide an object looks at the success distance), shared by the calibration tests and bench scripts."""

from __future__ import annotations

import math

import numpy as np

from vlnpilot.core.records import Pose
from vlnpilot.sim.simulator import Simulator


def standpoint(sim: Simulator, target_id: str, distance: float) -> Pose:
    """The pose `distance` in front of the target, on its facing axis, looking at it."""
    t = sim.scene.target(target_id)
    a = math.radians(t.facing_deg)
    return Pose(t.position[0] + distance * math.cos(a), t.position[1] + distance * math.sin(a),
                sim.scene.flight_altitude, t.facing_deg + 180.0)


def free_standpoint(sim: Simulator, target_id: str, distance: float) -> bool:
    """Can the drone hover `distance` in front of the target, in its room, touching nothing?"""
    pose = standpoint(sim, target_id, distance)
    return sim.scene.room_at(pose.x, pose.y) == sim.scene.target(target_id).room and sim.contact_at(pose) is None


def view(sim: Simulator, pose: Pose) -> np.ndarray:
    """The front camera's segmentation (geom ids per pixel) from `pose`."""
    sim.reset(pose)
    return sim.segmentation()


def facing_view(sim: Simulator, target_id: str, distance: float) -> np.ndarray:
    """The segmentation from `distance` in front of the target, on its facing axis, looking at it."""
    return view(sim, standpoint(sim, target_id, distance))


def width_fraction(seg: np.ndarray, ids) -> float:
    """The fraction of the image width between the leftmost and rightmost columns showing any of `ids`."""
    cols = np.flatnonzero(np.isin(seg, list(ids)).any(axis=0))
    return 0.0 if cols.size == 0 else (cols[-1] - cols[0] + 1) / seg.shape[1]
