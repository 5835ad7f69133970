"""What the world is: rooms, doors, targets, spawn points and the solids that furnish them.

Pure data (plus geometry queries). MJCF generation lives in `mjcf.py`; nothing here imports the simulator.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from vlnpilot.core.errors import UnknownNameError
from vlnpilot.core.records import Pose

if TYPE_CHECKING:  # events.py reads the scene; the scene only names its scenario
    from vlnpilot.scene.events import Scenario

Point2 = tuple[float, float]
Vec3 = tuple[float, float, float]

EXTERIOR = "exterior"


def _norm(text: str) -> str:
    """Normalise a name for matching: lower case, '_' '-' '/' as spaces, single spaces."""
    for ch in "_-/":
        text = text.replace(ch, " ")
    return " ".join(text.lower().split())


@dataclass(frozen=True)
class Room:
    id: str
    name: str  # display name, as the model reads it in the topological map
    polygon: tuple[Point2, ...]  # floor polygon, counter-clockwise, walls' centre lines
    aliases: tuple[str, ...] = ()
    color: tuple[float, float, float] = (0.6, 0.6, 0.6)  # floor-plan colour (the paper's room diagram)

    def contains(self, x: float, y: float) -> bool:
        """Point-in-polygon (ray casting); points on an edge count as inside."""
        inside = False
        pts = self.polygon
        for (x1, y1), (x2, y2) in zip(pts, pts[1:] + pts[:1], strict=True):
            if min(y1, y2) <= y <= max(y1, y2) and min(x1, x2) <= x <= max(x1, x2):
                cross = (x2 - x1) * (y - y1) - (y2 - y1) * (x - x1)
                if abs(cross) < 1e-12:
                    return True
            if (y1 > y) != (y2 > y):
                xin = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
                if x < xin:
                    inside = not inside
        return inside

    @property
    def centroid(self) -> Point2:
        xs, ys = zip(*self.polygon, strict=True)
        return sum(xs) / len(xs), sum(ys) / len(ys)

    def names(self) -> tuple[str, ...]:
        return (self.id, self.name, *self.aliases)


def target_kind(target_id: str) -> str:
    """A target's kind from its id: 'desk_2' -> 'desk' (the houses number their targets; the cabin does not)."""
    return target_id.split("_")[0]


@dataclass(frozen=True)
class Door:
    """A doorway in a wall. `normal_deg` points from rooms[0] into rooms[1]; the opening is `width` wide."""

    id: str
    rooms: tuple[str, str]
    center: Point2
    width: float
    height: float
    normal_deg: float
    open: bool = True

    @property
    def normal(self) -> Point2:
        a = math.radians(self.normal_deg)
        return math.cos(a), math.sin(a)

    def joins(self, room_id: str) -> bool:
        return room_id in self.rooms

    def other_side(self, room_id: str) -> str:
        a, b = self.rooms
        return b if room_id == a else a

    def frame_of(self, x: float, y: float) -> tuple[float, float]:
        """(depth, lateral) of a point in the door's frame: depth along the normal, lateral to its left."""
        nx, ny = self.normal
        dx, dy = x - self.center[0], y - self.center[1]
        return dx * nx + dy * ny, -dx * ny + dy * nx


@dataclass(frozen=True)
class Target:
    """An object that a query can ask for. `facing_deg` is the direction its front faces (outward)."""

    id: str
    name: str
    room: str
    position: Vec3
    facing_deg: float
    aliases: tuple[str, ...] = ()

    def names(self) -> tuple[str, ...]:
        return (self.id, self.name, *self.aliases)


@dataclass(frozen=True)
class Spawn:
    id: str
    room: str
    pose: Pose
    description: str = ""


@dataclass(frozen=True)
class Material:
    name: str
    rgba: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    texture: str | None = None  # a texture name from textures.TEXTURES
    texrepeat: tuple[float, float] = (1.0, 1.0)
    texuniform: bool = False
    specular: float = 0.2
    shininess: float = 0.2
    emission: float = 0.0
    reflectance: float = 0.0


@dataclass(frozen=True)
class Solid:
    """One primitive of the world. `size` uses MuJoCo's half-size conventions for the shape.

    `collide=False` marks purely visual parts (rugs, pictures, skins). `label` groups solids that form
    one thing (e.g. 'bedroom_door_frame_left', 'target:mirror'); contacts are reported by solid name.
    """

    name: str
    shape: str  # box | cylinder | sphere | ellipsoid | capsule | plane (visual skins only)
    pos: Vec3
    size: Vec3
    material: str
    yaw_deg: float = 0.0
    euler_deg: Vec3 | None = None  # full orientation, overrides yaw when given
    collide: bool = True
    target: str | None = None  # id of the target this solid belongs to
    xyaxes: tuple[float, ...] | None = None  # planes: in-plane x and y axes (the normal is x cross y)


@dataclass(frozen=True)
class Light:
    name: str
    pos: Vec3
    diffuse: Vec3 = (0.5, 0.5, 0.5)
    directional: bool = False
    direction: Vec3 = (0.0, 0.0, -1.0)
    attenuation: Vec3 = (1.0, 0.0, 0.0)


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    rooms: tuple[Room, ...]
    doors: tuple[Door, ...]
    targets: tuple[Target, ...]
    spawns: tuple[Spawn, ...]
    solids: tuple[Solid, ...] = field(repr=False, default=())
    materials: tuple[Material, ...] = field(repr=False, default=())
    lights: tuple[Light, ...] = field(repr=False, default=())
    bounds: tuple[Point2, Point2] = ((0.0, 0.0), (1.0, 1.0))  # (xmin, ymin), (xmax, ymax) incl. walls
    ceiling_height: float = 2.6
    flight_altitude: float = 1.0
    headlight: float = 0.35
    # Issue 24: the events that happen while the drone flies (a `scene.events.Scenario`), None in a still scene.
    # Part of what the scene is (its fingerprint names it, so a recording replays only with its scenario).
    scenario: Scenario | None = field(repr=False, compare=False, default=None)

    # -- look-ups ---------------------------------------------------------------------------------
    def room(self, room_id: str) -> Room:
        for r in self.rooms:
            if r.id == room_id:
                return r
        raise UnknownNameError("room", room_id, [r.id for r in self.rooms])

    def door(self, door_id: str) -> Door:
        for d in self.doors:
            if d.id == door_id:
                return d
        raise UnknownNameError("door", door_id, [d.id for d in self.doors])

    def target(self, target_id: str) -> Target:
        for t in self.targets:
            if t.id == target_id:
                return t
        raise UnknownNameError("target", target_id, [t.id for t in self.targets])

    def spawn(self, spawn_id: str) -> Spawn:
        for s in self.spawns:
            if s.id == spawn_id:
                return s
        raise UnknownNameError("spawn", spawn_id, [s.id for s in self.spawns])

    def find_room(self, text: str) -> Room | None:
        """The room whose id, name or an alias equals `text` (normalised), else None."""
        key = _norm(text)
        for r in self.rooms:
            if key in {_norm(n) for n in r.names()}:
                return r
        return None

    def find_target(self, text: str) -> Target | None:
        key = _norm(text)
        for t in self.targets:
            if key in {_norm(n) for n in t.names()}:
                return t
        return None

    # -- geometry ---------------------------------------------------------------------------------
    def room_at(self, x: float, y: float) -> str | None:
        """Id of the room whose floor polygon holds (x, y), or None outside every room."""
        for r in self.rooms:
            if r.contains(x, y):
                return r.id
        return None

    def open_doors(self) -> tuple[Door, ...]:
        return tuple(d for d in self.doors if d.open and EXTERIOR not in d.rooms)

    def doors_between(self, a: str, b: str) -> tuple[Door, ...]:
        return tuple(d for d in self.open_doors() if set(d.rooms) == {a, b})

    def room_path(self, start: str, goal: str) -> list[str]:
        """Shortest sequence of rooms from start to goal through open doors (breadth-first)."""
        self.room(start), self.room(goal)
        frontier, parent = [start], {start: start}
        while frontier:
            nxt = []
            for r in frontier:
                for d in self.open_doors():
                    if d.joins(r):
                        o = d.other_side(r)
                        if o not in parent:
                            parent[o] = r
                            nxt.append(o)
            frontier = nxt
        if goal not in parent:
            raise ValueError(f"no open-door path from {start} to {goal}")
        path = [goal]
        while path[-1] != start:
            path.append(parent[path[-1]])
        return path[::-1]

    def topological_map(self) -> dict[str, Any]:
        """The JSON graph the prompts carry: nodes are rooms, edges are open doors."""
        return {
            "nodes": [{"id": r.id, "name": r.name, "aliases": list(r.aliases)} for r in self.rooms],
            "edges": [
                {"from": d.rooms[0], "to": d.rooms[1], "via": d.id, "type": "open door"} for d in self.open_doors()
            ],
        }

    def fingerprint(self) -> str:
        """A short hash of everything the scene is made of: a recording names the exact scene it flew.

        The solids, materials and lights are hashed too: the dataclass repr leaves them out (for readable
        logs), and a moved bed must change the fingerprint as much as a moved door."""
        content: tuple[object, ...] = (self, self.solids, self.materials, self.lights)
        if self.scenario is not None:  # the fingerprints of still scenes stay as they were
            content = (*content, json.dumps(self.scenario.to_dict(), sort_keys=True))  # what was set
        return hashlib.sha256(repr(content).encode("utf-8")).hexdigest()[:12]

    def info(self) -> dict[str, Any]:
        """Everything `vln-pilot scene info --json` prints."""
        return {
            "name": self.name,
            "description": self.description,
            "flight_altitude_m": self.flight_altitude,
            "rooms": [{"id": r.id, "name": r.name, "aliases": list(r.aliases), "polygon": [list(p) for p in r.polygon]}
                      for r in self.rooms],
            "doors": [{"id": d.id, "rooms": list(d.rooms), "center": list(d.center), "width_m": d.width,
                       "height_m": d.height, "open": d.open} for d in self.doors],
            "targets": [{"id": t.id, "name": t.name, "aliases": list(t.aliases), "room": t.room,
                         "position": list(t.position), "facing_deg": t.facing_deg} for t in self.targets],
            "spawns": [{"id": s.id, "room": s.room, "pose": s.pose.as_dict(), "description": s.description}
                       for s in self.spawns],
            "topological_map": self.topological_map(),
        }
