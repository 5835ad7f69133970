"""What the front camera shows of a target from a given standpoint: the measurements behind the prompts' visual
rules (how wide an object looks at the success distance), shared by the calibration tests and bench scripts."""

from __future__ import annotations

import math

import numpy as np

from vlnpilot.core.footprint import footprint_distance
from vlnpilot.core.records import Pose
from vlnpilot.sim.simulator import Simulator

VIEW_ANGLES = {"front": 0.0, "45°": 45.0, "side": 90.0}  # from the object's facing direction, around its footprint


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


def _centroid(sim: Simulator, target_id: str) -> tuple[float, float]:
    xs = [x for poly in sim.target_footprint(target_id) for x, _ in poly]
    ys = [y for poly in sim.target_footprint(target_id) for _, y in poly]
    return (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2


def view_pose(sim: Simulator, target_id: str, distance: float, angle_deg: float, side: int = 1) -> Pose:
    """The pose `distance` from the nearest point of the target's footprint (what the monitor measures), on the
    ray from the footprint's centre at `angle_deg` from its facing direction (to the left for side=1), looking
    at that centre: the front (0), an angle (45) or the side (90) of the object."""
    t = sim.scene.target(target_id)
    cx, cy = _centroid(sim, target_id)
    a = math.radians(t.facing_deg + side * angle_deg)
    footprint = sim.target_footprint(target_id)
    lo, hi = 0.0, 20.0  # bisect the distance along the ray from the centre
    for _ in range(40):
        mid = (lo + hi) / 2
        probe = Pose(cx + mid * math.cos(a), cy + mid * math.sin(a), 1.0, 0.0)
        lo, hi = (mid, hi) if footprint_distance(probe, footprint) < distance else (lo, mid)
    x, y = cx + hi * math.cos(a), cy + hi * math.sin(a)
    return Pose(x, y, sim.scene.flight_altitude, math.degrees(math.atan2(cy - y, cx - x)))


def free_pose(sim: Simulator, target_id: str, pose: Pose) -> bool:
    """Can the drone hover at `pose`, in the target's room, touching nothing?"""
    return sim.scene.room_at(pose.x, pose.y) == sim.scene.target(target_id).room and sim.contact_at(pose) is None
