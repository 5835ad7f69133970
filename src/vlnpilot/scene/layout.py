"""Floor plans for the procedural houses: the "corridor spine" method.

Every room is an axis-aligned rectangle (wall centre lines). Up to three rooms lie in a single row, each
joined to the next by a doorway. From four rooms on, a hallway runs east-west through the house with a
row of rooms on each side (ProcTHOR-style room-spec tree: house -> hallway -> rooms); every room opens onto
the hallway, except a kitchen that may instead open onto the living room beside it. Closed doors (the front
door; sometimes a door between neighbours) are distractors: they are not edges of the topological map.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

HALLWAY = "hallway"
DOOR_W, DOOR_H = 0.80, 2.00
DOOR_CORNER_GAP = 0.55  # a door with a leaf sits this far (centre) from the corner its leaf folds against
DOOR_END_GAP = 1.0  # a door without a leaf keeps its centre this far from either end of the wall
HALL_END_M = 0.9  # doors keep this much further from the hallway's east end, where its target stands


@dataclass
class PlanRoom:
    id: str
    kind: str  # living_room | kitchen | bedroom | bathroom | study | hallway
    x0: float
    y0: float
    x1: float
    y1: float


@dataclass
class PlanDoor:
    id: str
    rooms: tuple[str, str]  # normal points from rooms[0] into rooms[1]; the leaf swings into rooms[0]
    center: tuple[float, float]
    normal_deg: float
    open: bool = True
    leaf: bool = True
    hinge: str = "left"  # seen along the normal
    width: float = DOOR_W


@dataclass
class Plan:
    rooms: list[PlanRoom]
    doors: list[PlanDoor] = field(default_factory=list)
    method: str = "row"

    def room(self, room_id: str) -> PlanRoom:
        return next(r for r in self.rooms if r.id == room_id)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        return (min(r.x0 for r in self.rooms), min(r.y0 for r in self.rooms), max(r.x1 for r in self.rooms),
                max(r.y1 for r in self.rooms))


def _r(v: float) -> float:
    return round(v, 3)


def plan_house(rng: random.Random, room_ids: list[tuple[str, str]], kitchen_joined: bool) -> Plan:
    """A plan for (id, kind) rooms; a hallway among them selects the spine method."""
    if any(kind == HALLWAY for _, kind in room_ids):
        return _spine(rng, [r for r in room_ids if r[1] != HALLWAY], kitchen_joined)
    return _row(rng, room_ids)


def _row(rng: random.Random, rooms: list[tuple[str, str]]) -> Plan:
    rng.shuffle(rooms)
    depth, x = _r(rng.uniform(3.3, 4.0)), 0.0
    plan = Plan([], method="row")
    for rid, kind in rooms:
        w = _r(rng.uniform(3.2, 4.0))
        plan.rooms.append(PlanRoom(rid, kind, x, 0.0, _r(x + w), depth))
        x = _r(x + w)
    for a, b in zip(plan.rooms, plan.rooms[1:], strict=False):
        plan.doors.append(_door(rng, f"door_{a.id}_{b.id}", a, b, "x", a.x1, (0.0, depth), leaf_room=a))
    _front_door(rng, plan, plan.rooms[0])
    return plan


def _spine(rng: random.Random, rooms: list[tuple[str, str]], kitchen_joined: bool) -> Plan:
    rng.shuffle(rooms)
    if kitchen_joined:  # keep the kitchen right after the living room, in the same row
        order = [r for r in rooms if r[1] not in ("living_room", "kitchen")]
        order.insert(rng.randrange(len(order) + 1), next(r for r in rooms if r[1] == "living_room"))
        i = next(i for i, r in enumerate(order) if r[1] == "living_room")
        order.insert(i + 1, next(r for r in rooms if r[1] == "kitchen"))
        rooms = order
    half = (len(rooms) + 1) // 2
    north, south = rooms[:half], rooms[half:]
    if kitchen_joined and [r[1] for r in north[-1:] + south[:1]] == ["living_room", "kitchen"]:
        north, south = rooms[: half + 1], rooms[half + 1 :]  # never split the joined pair across the hallway
    widths = {rid: _r(rng.uniform(3.2, 4.0)) for rid, _ in rooms}
    length = max(sum(widths[r] for r, _ in row) for row in (north, south) if row)
    hall_w, d_south, d_north = _r(rng.uniform(1.3, 1.6)), _r(rng.uniform(3.3, 4.0)), _r(rng.uniform(3.3, 4.0))
    if not south:
        d_south = 0.0
    y_hall0, y_hall1 = d_south, _r(d_south + hall_w)
    plan = Plan([PlanRoom(HALLWAY, HALLWAY, 0.0, y_hall0, _r(length), y_hall1)], method="spine")
    hall = plan.rooms[0]
    for row, y0, y1 in ((north, y_hall1, _r(y_hall1 + d_north)), (south, 0.0, d_south)):
        x = 0.0
        for i, (rid, kind) in enumerate(row):
            x1 = _r(length) if i == len(row) - 1 else _r(x + widths[rid])
            plan.rooms.append(PlanRoom(rid, kind, x, y0, x1, y1))
            x = x1
    for r in plan.rooms[1:]:
        joined = kitchen_joined and r.kind == "kitchen"
        wall_y = hall.y1 if r.y0 >= hall.y1 else hall.y0
        if joined:
            living = next(o for o in plan.rooms if o.kind == "living_room")
            a, b = (living, r) if living.x1 == r.x0 else (r, living)
            plan.doors.append(_door(rng, f"door_{living.id}_{r.id}", living, r, "x", a.x1, (r.y0, r.y1),
                                    leaf_room=r))
            continue
        at_east_end = r.x1 == hall.x1  # keep the hallway's east end free for its target
        plan.doors.append(_door(rng, f"door_{r.id}_{HALLWAY}", r, hall, "y", wall_y, (r.x0, r.x1), leaf_room=r,
                                east_margin=HALL_END_M if at_east_end else 0.0))
    _closed_neighbour_door(rng, plan)
    _front_door(rng, plan, hall)
    return plan


def _door(rng: random.Random, door_id: str, a: PlanRoom, b: PlanRoom, axis: str, at: float,
          span: tuple[float, float], leaf_room: PlanRoom, east_margin: float = 0.0) -> PlanDoor:
    """A doorway in the wall between a and b (`axis` 'x': a wall of constant x at `at`, running along y).

    rooms[0] is `leaf_room`. A door with a leaf sits near a corner and its leaf, swung into rooms[0], folds
    back against the side wall (as in real houses, and out of the drone's way); a bare doorway may sit
    anywhere along the wall.
    """
    lo, hi = span
    leaf, near_lo = rng.random() < 0.6, rng.random() < 0.5 or east_margin > 0
    hi -= east_margin if not leaf else 0.0
    if leaf:
        along = lo + DOOR_CORNER_GAP if near_lo else hi - DOOR_CORNER_GAP
    else:
        along = rng.uniform(lo + DOOR_END_GAP, hi - DOOR_END_GAP)
    other = b if leaf_room is a else a
    low_side = (leaf_room.x0 < at) if axis == "x" else (leaf_room.y0 < at)  # is rooms[0] below the wall line?
    normal = (0.0 if low_side else 180.0) if axis == "x" else (90.0 if low_side else -90.0)
    nx, ny = round(math.cos(math.radians(normal))), round(math.sin(math.radians(normal)))
    left_along = nx if axis == "x" else -ny  # the along-wall component of the normal's left (-ny, nx)
    hinge = "left" if left_along * (-1 if near_lo else 1) > 0 else "right"
    center = (at, _r(along)) if axis == "x" else (_r(along), at)
    return PlanDoor(door_id, (leaf_room.id, other.id), center, normal, True, leaf, hinge)


def _closed_neighbour_door(rng: random.Random, plan: Plan) -> None:
    """Sometimes a closed door between two neighbours of one row: visible, but not a way through."""
    pairs = [(a, b) for a in plan.rooms for b in plan.rooms
             if a.kind != HALLWAY and b.kind != HALLWAY and a.x1 == b.x0 and a.y0 == b.y0
             and not any(set(d.rooms) == {a.id, b.id} for d in plan.doors)]
    if pairs and rng.random() < 0.5:
        a, b = pairs[rng.randrange(len(pairs))]
        far = a.y1 - DOOR_END_GAP - 0.4 if a.y0 > 0 else a.y0 + DOOR_END_GAP + 0.4  # away from the hallway wall
        plan.doors.append(PlanDoor(f"door_{a.id}_{b.id}", (a.id, b.id), (a.x1, _r(far)), 0.0, open=False,
                                   leaf=True, hinge="left"))


def _front_door(rng: random.Random, plan: Plan, room: PlanRoom) -> None:
    """The closed front door, in the west wall of `room` (an exterior wall: rooms start at x = 0)."""
    y = _r(rng.uniform(room.y0 + 0.6, room.y1 - 0.6)) if room.y1 - room.y0 > 1.2 else _r((room.y0 + room.y1) / 2)
    plan.doors.append(PlanDoor("front_door", (room.id, "exterior"), (-0.05, y), 180.0, open=False, leaf=True,
                               hinge="left", width=0.9))
