"""Furnishing a planned room: the pieces that make its type recognisable, placed against its walls by seed.

Rules that keep every house flyable (the validator checks the result, these make it pass first time):
nothing stands in front of a door (a keep-out box 1.4 m deep), nothing that reaches flight altitude stands
on a wall that has a door, and every target keeps a clear view corridor from its front to a viewing point
0.7 m out, well inside the room.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

from vlnpilot.core.records import Pose
from vlnpilot.scene.furniture import FURNITURE, Piece, WallFrame, centrepiece
from vlnpilot.scene.layout import Plan, PlanRoom
from vlnpilot.scene.model import Solid, Spawn, Target
from vlnpilot.scene.validate import VIEW_M

WALL_IN = 0.05  # each room's half of a wall stands this far inside its floor polygon
DOOR_KEEP_DEPTH, DOOR_KEEP_SIDE = 1.3, 0.3  # in front of an open door; a closed one keeps CLOSED_KEEP_DEPTH
CLOSED_KEEP_DEPTH = 0.6
SHALLOW_M = 0.4  # pieces reaching flight altitude no further than this from the wall may share a door's wall
FLIGHT_BAND = (0.9, 1.1)  # heights at which a solid is an obstacle for the drone
PLACE_TRIES, REQUIRED_EXTRA_TRIES = 40, 120  # random placements tried per piece; more for a required one
Rect = tuple[float, float, float, float]  # xmin, ymin, xmax, ymax

# room kind -> pieces in placement order: (furniture kind, target id or None, required)
PROGRAMMES: dict[str, tuple[tuple[str, str | None, bool], ...]] = {
    "living_room": (("tv", "tv", True), ("sofa", None, True), ("bookshelf", None, False), ("plant", None, False),
                    ("floor_lamp", None, False), ("painting", None, False)),
    "kitchen": (("fridge", "refrigerator", True), ("counters", "stove", True), ("plant", None, False)),
    "bedroom": (("bed", "bed", True), ("wardrobe", "wardrobe", True), ("nightstand", None, False),
                ("painting", None, False)),
    "bedroom_2": (("mirror", "mirror", True), ("bed", None, True), ("wardrobe", None, False)),
    "bathroom": (("vanity", "sink", True), ("toilet", "toilet", True), ("shower", "shower", True)),
    "study": (("desk", "desk", True), ("bookshelf", "bookshelf", True), ("plant", None, False)),
    "hallway": (("plant", "plant", True), ("painting", None, False), ("painting", None, False)),
}
TARGET_NAMES: dict[str, tuple[str, tuple[str, ...]]] = {  # target id -> (name, aliases)
    "tv": ("TV", ("television", "tv screen")), "refrigerator": ("refrigerator", ("fridge",)),
    "stove": ("stove", ("cooker", "hob")), "bed": ("bed", ("double bed",)), "wardrobe": ("wardrobe", ("closet",)),
    "mirror": ("mirror", ("full-length mirror",)), "sink": ("sink", ("washbasin", "basin")),
    "toilet": ("toilet", ("wc",)), "shower": ("shower", ("shower cubicle",)), "desk": ("desk", ("writing desk",)),
    "bookshelf": ("bookshelf", ("bookcase", "shelves")), "plant": ("plant", ("pot plant", "houseplant")),
}
CENTREPIECES = {"living_room": ("coffee_table", "coffee"), "kitchen": ("dining_table", "dining")}


class FurnishError(Exception):
    """A required piece found no place; the generator retries with the next sub-seed."""


@dataclass
class Furnished:
    solids: list[Solid] = field(default_factory=list)
    targets: list[Target] = field(default_factory=list)
    tall: list[Rect] = field(default_factory=list)  # footprints that reach flight altitude
    low: list[Rect] = field(default_factory=list)


def interior(r: PlanRoom) -> Rect:
    return r.x0 + WALL_IN, r.y0 + WALL_IN, r.x1 - WALL_IN, r.y1 - WALL_IN


def wall_frames(r: PlanRoom) -> dict[str, WallFrame]:
    x0, y0, x1, y1 = interior(r)
    return {"S": WallFrame((x0, y0), (1, 0), (0, 1), x1 - x0), "N": WallFrame((x1, y1), (-1, 0), (0, -1), x1 - x0),
            "W": WallFrame((x0, y1), (0, -1), (1, 0), y1 - y0), "E": WallFrame((x1, y0), (0, 1), (-1, 0), y1 - y0)}


def door_side(r: PlanRoom, center: tuple[float, float], tol: float = 0.11) -> str | None:
    x, y = center
    for side, hit in (("S", abs(y - r.y0) < tol and r.x0 < x < r.x1), ("N", abs(y - r.y1) < tol and r.x0 < x < r.x1),
                      ("W", abs(x - r.x0) < tol and r.y0 < y < r.y1), ("E", abs(x - r.x1) < tol and r.y0 < y < r.y1)):
        if hit:
            return side
    return None


def door_keepouts(plan: Plan, r: PlanRoom) -> tuple[list[Rect], set[str]]:
    """Boxes in front of every door of the room (open or closed), and the sides that carry an open door."""
    rects, sides = [], set()
    for d in plan.doors:
        side = door_side(r, d.center)
        if side is None or r.id not in d.rooms:
            continue
        if d.open:
            sides.add(side)
        half, (cx, cy), deep = d.width / 2 + DOOR_KEEP_SIDE, d.center, DOOR_KEEP_DEPTH if d.open else CLOSED_KEEP_DEPTH
        rects.append({"S": (cx - half, r.y0, cx + half, r.y0 + deep),
                      "N": (cx - half, r.y1 - deep, cx + half, r.y1),
                      "W": (r.x0, cy - half, r.x0 + deep, cy + half),
                      "E": (r.x1 - deep, cy - half, r.x1, cy + half)}[side])
    return rects, sides


def overlaps(a: Rect, b: Rect, pad: float = 0.0) -> bool:
    return a[0] < b[2] + pad and b[0] < a[2] + pad and a[1] < b[3] + pad and b[1] < a[3] + pad


def inside(p: tuple[float, float], r: Rect, pad: float = 0.0) -> bool:
    return r[0] + pad <= p[0] <= r[2] - pad and r[1] + pad <= p[1] <= r[3] - pad


def furnish_room(rng: random.Random, plan: Plan, r: PlanRoom, programme: str) -> Furnished:
    out = Furnished()
    keep, door_sides = door_keepouts(plan, r)
    frames = wall_frames(r)
    for i, (kind, target, required) in enumerate(PROGRAMMES[programme]):
        if not required and rng.random() < 0.35:
            continue
        placed = _place(rng, r, frames, door_sides, keep, out, kind, f"{r.id}_{kind}_{i}", target, required)
        if placed is None and required:
            raise FurnishError(f"no room for the {kind} in the {r.id} ({r.x1 - r.x0:.1f} x {r.y1 - r.y0:.1f} m)")
    if r.kind in CENTREPIECES and rng.random() < 0.8:
        _centrepiece(rng, r, keep, out, *CENTREPIECES[r.kind])
    return out


def _place(rng: random.Random, r: PlanRoom, frames: dict[str, WallFrame], door_sides: set[str], keep: list[Rect],
           out: Furnished, kind: str, name: str, target: str | None, required: bool = False) -> Piece | None:
    """Try random walls and positions; a required piece gets more tries, at its smallest width."""
    builder, (w_lo, w_hi) = FURNITURE[kind]
    room = interior(r)
    for attempt in range(PLACE_TRIES + (REQUIRED_EXTRA_TRIES if required else 0)):
        side = rng.choice("SNWE")
        f, w = frames[side], round(rng.uniform(w_lo, w_hi), 2) if attempt < PLACE_TRIES else w_lo
        if f.length < w + 0.1:
            continue
        s = round(rng.uniform(w / 2 + 0.05, f.length - w / 2 - 0.05), 3)
        piece = builder(f, name, s, w, target)
        reach = _reach(f, piece)
        if reach > SHALLOW_M and side in door_sides:
            continue
        foot = f.rect(s - w / 2, s + w / 2, 0.0, max(piece.depth, 0.02))
        if any(overlaps(foot, k, 0.02) for k in keep) or any(overlaps(foot, o, 0.05) for o in out.tall + out.low):
            continue
        view = _view_corridor(f, s, piece)
        if view is not None:
            vp = f.xy(s, piece.depth + VIEW_M)
            if not inside(vp, room, 0.35) or any(overlaps(view, t, 0.05) for t in out.tall):
                continue
        out.low.append(foot)
        if reach > 0:
            out.tall.append(f.rect(s - w / 2, s + w / 2, 0.0, reach))
        if view is not None and target is not None:
            keep.append(view)  # later tall pieces keep out of the target's view
            name_, aliases = TARGET_NAMES[target]
            assert piece.front is not None, f"{target} has no front face"  # every target piece has one
            out.targets.append(Target(target, name_, r.id, piece.front, round(f.facing_deg, 1), aliases))
        out.solids.extend(piece.solids)
        return piece
    return None


def _reach(f: WallFrame, piece: Piece) -> float:
    """How far from the wall the piece's solids stand at flight altitude (0: it is all below or above)."""
    reach = 0.0
    for sol in piece.solids:
        hz = sol.size[1] if sol.shape == "cylinder" else sol.size[2]
        if not sol.collide or sol.pos[2] + hz < FLIGHT_BAND[0] or sol.pos[2] - hz > FLIGHT_BAND[1]:
            continue
        half_n = abs(f.n[0]) * sol.size[0] + abs(f.n[1]) * (sol.size[0] if sol.shape == "cylinder" else sol.size[1])
        depth = (sol.pos[0] - f.origin[0]) * f.n[0] + (sol.pos[1] - f.origin[1]) * f.n[1]
        reach = max(reach, depth + half_n)
    return round(reach, 3)


def _view_corridor(f: WallFrame, s: float, piece: Piece) -> Rect | None:
    if piece.front is None:
        return None
    return f.rect(s - 0.3, s + 0.3, piece.depth, piece.depth + VIEW_M + 0.2)


def _centrepiece(rng: random.Random, r: PlanRoom, keep: list[Rect], out: Furnished, name: str, style: str) -> None:
    w, d = round(rng.uniform(0.8, 1.2), 2), round(rng.uniform(0.5, 0.8), 2)
    cx = round((r.x0 + r.x1) / 2 + rng.uniform(-0.3, 0.3), 3)
    cy = round((r.y0 + r.y1) / 2 + rng.uniform(-0.3, 0.3), 3)
    foot = (cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2)
    if any(overlaps(foot, o, 0.1) for o in out.tall + out.low + keep):
        return
    out.low.append(foot)
    out.solids.extend(centrepiece(f"{r.id}_{name}", cx, cy, w, d, style))


_COMPASS = ("east", "north-east", "north", "north-west", "west", "south-west", "south", "south-east")


def place_spawn(rng: random.Random, r: PlanRoom, room_name: str, tall: list[Rect], altitude: float) -> Spawn | None:
    """A spawn in the room's middle, clear of tall furniture, facing a random direction."""
    x0, y0, x1, y1 = interior(r)
    mx, my = min(1.0, (x1 - x0) / 2 - 0.3), min(1.0, (y1 - y0) / 2 - 0.3)
    for _ in range(50):
        x, y = round(rng.uniform(x0 + mx, x1 - mx), 2), round(rng.uniform(y0 + my, y1 - my), 2)
        if any(inside((x, y), (t[0] - 0.35, t[1] - 0.35, t[2] + 0.35, t[3] + 0.35)) for t in tall):
            continue
        yaw = float(rng.randrange(-180, 180, 5))
        facing = _COMPASS[round((yaw % 360) / 45) % 8]
        return Spawn(r.id, r.id, Pose(x, y, altitude, yaw), f"{room_name}, facing {facing}")
    return None
