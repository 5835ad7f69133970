"""Is a scene flyable? Checks on an occupancy grid of the solids at flight altitude, inflated by the drone's
bounding radius plus the geometry shield's margin (so a free cell is a place the drone's centre may be).

Used by the house generator, which refuses a house with the first failed check's reason and retries; it
reads nothing but the Scene, so it applies to any scene (the cabin passes its issue-level checks too).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vlnpilot.core import tello_spec
from vlnpilot.scene.model import Scene

CELL_M = 0.04
SHIELD_MARGIN_M = 0.05  # the geometry shield's default margin (safety.ShieldConfig.margin_m)
CLEARANCE_M = tello_spec.BOUNDING_RADIUS + SHIELD_MARGIN_M
VIEW_M = 0.7  # standing distance in front of a target (the oracle's view_m), within the 1 m success distance
APPROACH_M = 0.45  # the oracle's approach point before a doorway


class HouseInvalid(Exception):
    """A failed check; the message is the reason the generator records before it retries."""


@dataclass
class Grid:
    blocked: np.ndarray  # [ix, iy], True where the drone's centre may not be
    x0: float
    y0: float

    def cell(self, x: float, y: float) -> tuple[int, int]:
        return int((x - self.x0) / CELL_M), int((y - self.y0) / CELL_M)

    def free(self, x: float, y: float) -> bool:
        i, j = self.cell(x, y)
        return 0 <= i < self.blocked.shape[0] and 0 <= j < self.blocked.shape[1] and not self.blocked[i, j]

    def segment_free(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        n = max(1, int(math.dist(a, b) / (CELL_M / 2)))
        return all(self.free(a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n) for k in range(n + 1))


def occupancy(scene: Scene, inflate: float, skip_target: str | None = None) -> Grid:
    """Cells covered by a collidable solid that reaches the drone's height band, grown by `inflate`."""
    (bx0, by0), (bx1, by1) = scene.bounds
    x0, y0 = bx0 - 0.2, by0 - 0.2
    blocked = np.zeros((int((bx1 - x0 + 0.2) / CELL_M) + 1, int((by1 - y0 + 0.2) / CELL_M) + 1), bool)
    z, band = scene.flight_altitude, tello_spec.HEIGHT / 2 + SHIELD_MARGIN_M
    for s in scene.solids:
        if not s.collide or s.shape == "plane" or (skip_target and s.target == skip_target):
            continue
        hx, hy, hz = _half_extents(s.shape, s.size)
        if s.pos[2] + hz < z - band or s.pos[2] - hz > z + band:
            continue
        i0, j0 = int((s.pos[0] - hx - inflate - x0) / CELL_M), int((s.pos[1] - hy - inflate - y0) / CELL_M)
        i1, j1 = int((s.pos[0] + hx + inflate - x0) / CELL_M), int((s.pos[1] + hy + inflate - y0) / CELL_M)
        blocked[max(i0, 0) : i1 + 1, max(j0, 0) : j1 + 1] = True
    return Grid(blocked, x0, y0)


def _half_extents(shape: str, size: tuple[float, float, float]) -> tuple[float, float, float]:
    if shape == "cylinder":
        return size[0], size[0], size[1]
    if shape == "sphere":
        return size[0], size[0], size[0]
    return size  # box, ellipsoid (its bounding box)


def reachable(grid: Grid, start: tuple[float, float]) -> np.ndarray:
    """Cells reachable from `start` by 4-connected moves through free cells (numpy flood fill)."""
    free = ~grid.blocked
    seen = np.zeros_like(free)
    seen[grid.cell(*start)] = True
    while True:
        grown = seen.copy()
        grown[1:, :] |= seen[:-1, :]
        grown[:-1, :] |= seen[1:, :]
        grown[:, 1:] |= seen[:, :-1]
        grown[:, :-1] |= seen[:, 1:]
        grown &= free
        if (grown == seen).all():
            return seen
        seen = grown


def viewing_point(scene: Scene, target_id: str) -> tuple[float, float]:
    t = scene.target(target_id)
    a = math.radians(t.facing_deg)
    return t.position[0] + VIEW_M * math.cos(a), t.position[1] + VIEW_M * math.sin(a)


def approach_points(scene: Scene, room_id: str) -> list[tuple[float, float]]:
    """A point before every open door of the room, on the door's centre line, inside the room."""
    pts = []
    for d in scene.open_doors():
        if d.joins(room_id):
            sign = -1.0 if d.rooms[0] == room_id else 1.0
            pts.append((d.center[0] + sign * APPROACH_M * d.normal[0], d.center[1] + sign * APPROACH_M * d.normal[1]))
    return pts


def validate(scene: Scene, *, straight_legs: bool = True) -> None:
    """Raise HouseInvalid naming the first check that fails.

    `straight_legs` adds the generator's own, stricter promise: every leg a door-to-door pilot flies in a room
    is a straight clear line (the cabin, hand-made, has a few legs that need a turn on the way)."""
    need = 2 * (tello_spec.BOUNDING_RADIUS + SHIELD_MARGIN_M)
    for d in scene.open_doors():
        if d.width < need:
            raise HouseInvalid(f"door {d.id} is {d.width:.2f} m wide, less than the drone plus margins ({need:.2f} m)")
    grid = occupancy(scene, CLEARANCE_M)
    for s in scene.spawns:
        if not grid.free(s.pose.x, s.pose.y):
            raise HouseInvalid(f"spawn {s.id} at ({s.pose.x:.2f}, {s.pose.y:.2f}) is within the drone's clearance of "
                               "a solid")
    if not scene.spawns:
        raise HouseInvalid("the scene has no spawn")
    start = scene.spawns[0].pose
    seen = reachable(grid, (start.x, start.y))

    def reached(p: tuple[float, float]) -> bool:
        i, j = grid.cell(*p)
        return grid.free(*p) and bool(seen[i, j])

    for r in scene.rooms:
        if not any(reached(p) for p in approach_points(scene, r.id)):
            raise HouseInvalid(f"room {r.id} cannot be reached through an open door by a drone-sized path")
    for s in scene.spawns:
        if not reached((s.pose.x, s.pose.y)):
            raise HouseInvalid(f"spawn {s.id} is cut off from spawn {scene.spawns[0].id}")
    for t in scene.targets:
        vp = viewing_point(scene, t.id)
        if not reached(vp):
            raise HouseInvalid(f"target {t.id}: its viewing point {VIEW_M} m in front is not reachable")
        if not occupancy(scene, 0.0, skip_target=t.id).segment_free(vp, _just_before(t.position, vp)):
            raise HouseInvalid(f"target {t.id} is hidden from its viewing point")
    if straight_legs:
        _straight_legs(scene, grid)


def _just_before(p: tuple[float, float, float], vp: tuple[float, float]) -> tuple[float, float]:
    d = math.dist(p[:2], vp)
    return p[0] + (vp[0] - p[0]) * 0.05 / d, p[1] + (vp[1] - p[1]) * 0.05 / d


def _straight_legs(scene: Scene, grid: Grid) -> None:
    """The straight legs a door-to-door pilot flies in each room: spawn, door approaches, viewing points."""
    for r in scene.rooms:
        doors = approach_points(scene, r.id)
        others = [(s.pose.x, s.pose.y) for s in scene.spawns if s.room == r.id]
        others += [viewing_point(scene, t.id) for t in scene.targets if t.room == r.id]
        for i, a in enumerate(doors):
            for b in doors[i + 1 :] + others:
                if not grid.segment_free(a, b):
                    raise HouseInvalid(f"room {r.id}: no straight flyable leg from ({a[0]:.2f}, {a[1]:.2f}) to "
                                       f"({b[0]:.2f}, {b[1]:.2f})")
    for d in scene.open_doors():
        side_a, side_b = (approach_points(scene, room) for room in d.rooms)
        pa = min(side_a, key=lambda p: math.dist(p, d.center))
        pb = min(side_b, key=lambda p: math.dist(p, d.center))
        if not grid.segment_free(pa, pb):
            raise HouseInvalid(f"door {d.id}: the crossing on its centre line is not clear")
