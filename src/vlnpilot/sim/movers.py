"""People and pets walking a path (issue 24): the route through rooms and doorways, and the walk on the clock.

Pure Python (no MuJoCo): `sim/events.py` places the bodies where these say. A mover enters at the start of its
path when its event fires, then walks at its speed, stops in a doorway for a while if asked, and yields like
people do: when its next `YIELD_LOOKAHEAD_S` would bring its footprint within `YIELD_DISTANCE_M` of the drone it
waits where it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vlnpilot.core.movers import MOVER_HEIGHT, MOVER_RADIUS, YIELD_DISTANCE_M, YIELD_LOOKAHEAD_S, MoverState
from vlnpilot.scene.events import EventSpec
from vlnpilot.scene.model import Scene

Point = tuple[float, float]
DOOR_APPROACH_M = 1.0  # a walker lines up with a doorway this far before and after it
YIELD_WAIT_S = 3.0  # a mover that stopped for the drone waits this long (episode clock), then gives way
# Walking on past a drone it waited for: its footprint's edge stays this far from the drone's centre (the drone's
# outline reaches 0.07 m from it, core.tello_spec.BOUNDING_RADIUS: some 0.15 m of air is left).
PASS_CLEARANCE_M = 0.22


def route(spec: EventSpec, scene: Scene) -> tuple[list[Point], int | None]:
    """The waypoints of a mover's path, and the index of the doorway it pauses in (None: no pause).

    Consecutive rooms are joined through the door between them (in front of it, its centre, beyond it); a door
    named on its own is crossed from the side of the point before it; [x, y] points are taken as they are."""
    points: list[Point] = []
    pause_at: int | None = None
    wants_pause = spec.kind == "person" and spec.pause_in_doorway_s > 0
    doors = {d.id: d for d in scene.open_doors()}
    items = list(spec.path)

    def cross(door_id: str, from_point: Point | None, from_room: str | None = None) -> None:
        nonlocal pause_at
        d = doors[door_id]
        nx, ny = d.normal
        a = (d.center[0] - nx * DOOR_APPROACH_M, d.center[1] - ny * DOOR_APPROACH_M)  # on rooms[0]'s side
        b = (d.center[0] + nx * DOOR_APPROACH_M, d.center[1] + ny * DOOR_APPROACH_M)
        if from_room is not None and from_room == d.rooms[1]:
            a, b = b, a
        elif from_room is None and from_point is not None and math.dist(from_point, b) < math.dist(from_point, a):
            a, b = b, a
        points.extend([a, d.center])
        if wants_pause and pause_at is None and spec.pause_door in (None, door_id):
            pause_at = len(points) - 1
        points.append(b)

    for i, item in enumerate(items):
        if not isinstance(item, str):
            points.append((float(item[0]), float(item[1])))
        elif item in doors:
            cross(item, points[-1] if points else None)
        else:  # a room: reached through the door from the previous room, or its centre when alone
            prev = items[i - 1] if i else None
            if isinstance(prev, str) and prev != item and prev not in doors:
                cross(scene.doors_between(prev, item)[0].id, points[-1] if points else None, prev)
            elif not any(isinstance(n, str) and n not in doors and n != item for n in items):
                points.append(scene.room(item).centroid)
    deduped = [p for k, p in enumerate(points) if k == 0 or math.dist(p, points[k - 1]) > 1e-6]
    if pause_at is not None:  # the index after dropping repeated points
        pause_at = next(k for k, p in enumerate(deduped) if p == points[pause_at])
    if len(deduped) == 1:
        return deduped, None
    return deduped, pause_at


@dataclass
class Walker:
    """One mover's walk: where it is on its route, and whether it is waiting (paused in a doorway, yielding)."""

    name: str
    kind: str
    waypoints: list[Point]
    speed: float
    pause_at: int | None = None
    pause_s: float = 0.0
    repeat: bool = False
    leave: bool = False  # gone from the scene once the route is walked
    started: bool = False
    x: float = 0.0
    y: float = 0.0
    target: int = 1  # the waypoint it walks to
    step_dir: int = 1  # +1 along the route, -1 back (repeat)
    pause_left: float = 0.0
    paused_done: bool = False
    yielding: bool = False
    waited_s: float = 0.0  # how long it has waited for the drone (reset when it walks on)
    passing: bool = False  # after waiting: walks on past the drone with PASS_CLEARANCE_M to spare
    retreat_to: int | None = None  # stepping back to this waypoint to stand aside ...
    resume: int = 1  # ... then walking on to this one
    heading: float = 0.0  # radians, where it faces
    vx: float = 0.0
    vy: float = 0.0
    done: bool = field(default=False)

    def __post_init__(self) -> None:
        self.x, self.y = self.waypoints[0]
        if len(self.waypoints) > 1:
            nx, ny = self.waypoints[1]
            self.heading = math.atan2(ny - self.y, nx - self.x)
        else:
            self.done = True

    @property
    def present(self) -> bool:
        """In the scene: its event fired, and it has not left."""
        return self.started and not (self.leave and self.done)

    @property
    def radius(self) -> float:
        return MOVER_RADIUS[self.kind]

    def state(self) -> MoverState:
        return MoverState(self.name, self.kind, self.x, self.y, self.vx, self.vy, self.radius, MOVER_HEIGHT[self.kind])

    def advance(self, dt: float, drone: Point, drone_z: float = 1.0) -> None:
        """Walk for `dt` seconds with the drone at `drone` (x, y) and height `drone_z`: yield, pause or go on along
        the route. A mover yields only to a drone low enough to touch it (a pet walks under a flying drone)."""
        self.vx = self.vy = 0.0
        self.yielding = False
        if not self.started or self.done or dt <= 0:
            return
        if self.pause_left > 0:
            self.pause_left = max(0.0, self.pause_left - dt)
            return
        tx, ty = self.waypoints[self.target]
        dist = math.hypot(tx - self.x, ty - self.y)
        ux, uy = ((tx - self.x) / dist, (ty - self.y) / dist) if dist > 1e-9 else (0.0, 0.0)
        # (stepping back it walks away from the drone, but yields all the same should the drone come round behind it)
        if drone_z < MOVER_HEIGHT[self.kind] + YIELD_DISTANCE_M and self._must_yield(
                ux, uy, drone, PASS_CLEARANCE_M if self.passing else YIELD_DISTANCE_M):
            self.yielding = True
            self.waited_s += dt
            if self.waited_s >= YIELD_WAIT_S - 1e-9:
                self._give_way(ux, uy, drone)
            return
        self.waited_s = 0.0
        self.heading = math.atan2(uy, ux) if dist > 1e-9 else self.heading
        step = self.speed * dt
        if step < dist:
            self.x, self.y = self.x + ux * step, self.y + uy * step
            self.vx, self.vy = ux * self.speed, uy * self.speed
            return
        self.x, self.y = tx, ty
        self.vx, self.vy = ux * self.speed, uy * self.speed
        self._arrived(dt - dist / self.speed, drone, drone_z)

    def _must_yield(self, ux: float, uy: float, drone: Point, distance: float = YIELD_DISTANCE_M) -> bool:
        """Whether walking on for YIELD_LOOKAHEAD_S would bring its footprint within `distance` of the drone
        (only while it closes in: a mover walking away never waits for the drone)."""
        now = math.hypot(drone[0] - self.x, drone[1] - self.y)
        ahead = self.speed * YIELD_LOOKAHEAD_S
        later = math.hypot(drone[0] - (self.x + ux * ahead), drone[1] - (self.y + uy * ahead))
        # the closest approach along the next stretch, not only its end
        t = max(0.0, min(ahead, (drone[0] - self.x) * ux + (drone[1] - self.y) * uy))
        closest = math.hypot(drone[0] - (self.x + ux * t), drone[1] - (self.y + uy * t))
        return min(closest, later) - self.radius < distance and min(closest, later) < now

    def _give_way(self, ux: float, uy: float, drone: Point) -> None:
        """It waited YIELD_WAIT_S for the drone: walk on past it if the stretch to the next waypoint keeps
        PASS_CLEARANCE_M from it, else step back along the path (to the waypoint before the one it left), else
        (at the start of its path) leave the scene the way it came."""
        self.waited_s = 0.0
        tx, ty = self.waypoints[self.target]
        length = math.hypot(tx - self.x, ty - self.y)
        t = max(0.0, min(length, (drone[0] - self.x) * ux + (drone[1] - self.y) * uy))
        if math.hypot(drone[0] - (self.x + ux * t), drone[1] - (self.y + uy * t)) - self.radius >= PASS_CLEARANCE_M:
            self.passing = True
            return
        back = self.target - self.step_dir
        while 0 <= back < len(self.waypoints) and math.dist(self.waypoints[back], (self.x, self.y)) < 0.05:
            back -= self.step_dir
        if 0 <= back < len(self.waypoints):
            self.retreat_to, self.resume, self.target = back, self.target, back
        else:
            self.leave = self.done = True

    def _arrived(self, left_s: float, drone: Point, drone_z: float) -> None:
        """At waypoint `target`: pause there (the doorway), turn to the next, or stop (or walk back: repeat); or,
        having stepped back for the drone, stand aside for YIELD_WAIT_S and then walk on where it was going."""
        self.passing = False
        if self.target == self.retreat_to:
            self.retreat_to, self.target = None, self.resume
            self.pause_left = YIELD_WAIT_S
            return
        if self.target == self.pause_at and not self.paused_done:
            self.paused_done = True
            self.pause_left = self.pause_s
            self.vx = self.vy = 0.0
            self._next_target()
            return
        self._next_target()
        if not self.done and left_s > 0:
            self.advance(left_s, drone, drone_z)

    def _next_target(self) -> None:
        nxt = self.target + self.step_dir
        if 0 <= nxt < len(self.waypoints):
            self.target = nxt
        elif self.repeat:
            self.step_dir = -self.step_dir
            self.target += self.step_dir
            self.paused_done = False
        else:
            self.done = True


def make_walker(spec: EventSpec, scene: Scene, speed_factor: float = 1.0) -> Walker:
    """A walker for a person or pet event; `speed_factor` is the seeded variation of its speed."""
    points, pause_at = route(spec, scene)
    return Walker(str(spec.name), spec.kind, points, spec.speed * speed_factor, pause_at,
                  spec.pause_in_doorway_s if spec.kind == "person" else 0.0, spec.repeat, spec.leave)
