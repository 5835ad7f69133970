"""The shell of a procedural house from its plan: floor, ceiling, walls with door and window openings,
doorways (frames, leaves) and windows, and the finishes and lights that vary by room type and seed.

Each room owns the half of every wall that faces it (WALL_IN thick, inside its floor polygon) with its own
finish; exterior stretches are thickened outwards by T_EXT, as in the cabin.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from vlnpilot.scene.cabin import MATERIALS as CABIN_MATERIALS
from vlnpilot.scene.furnish import WALL_IN
from vlnpilot.scene.layout import Plan, PlanDoor, PlanRoom
from vlnpilot.scene.model import EXTERIOR, Door, Light, Material, Solid
from vlnpilot.scene.parts import JAMB, WALL_H, box, doorway, wall, window

T_EXT = 0.15
Interval = tuple[float, float]


def to_door(d: PlanDoor) -> Door:
    return Door(d.id, d.rooms, d.center, d.width, 2.05 if d.rooms[1] == EXTERIOR else 2.0, d.normal_deg, d.open)


def _covered(plan: Plan, r: PlanRoom, side: str) -> list[Interval]:
    """Stretches of a room's side shared with another room (the rest is exterior wall)."""
    out = []
    for o in plan.rooms:
        if o is r:
            continue
        if side in "SN":
            line_ok = (o.y1 == r.y0) if side == "S" else (o.y0 == r.y1)
            lo, hi = max(r.x0, o.x0), min(r.x1, o.x1)
        else:
            line_ok = (o.x1 == r.x0) if side == "W" else (o.x0 == r.x1)
            lo, hi = max(r.y0, o.y0), min(r.y1, o.y1)
        if line_ok and hi - lo > 1e-6:
            out.append((lo, hi))
    return sorted(out)


def _split(span: Interval, covered: list[Interval]) -> list[tuple[float, float, bool]]:
    """(a0, a1, exterior?) pieces of a side, in order."""
    pieces, cursor = [], span[0]
    for lo, hi in covered:
        if lo > cursor + 1e-6:
            pieces.append((cursor, lo, True))
        pieces.append((lo, hi, False))
        cursor = hi
    if span[1] > cursor + 1e-6:
        pieces.append((cursor, span[1], True))
    return pieces


def _side_geometry(r: PlanRoom, side: str, exterior: bool) -> tuple[str, float, float, int, Interval]:
    """(axis, c0, c1, face, along-span) of a room's wall half on one side."""
    out = T_EXT if exterior else 0.0
    if side == "S":
        return "x", r.y0 - out, r.y0 + WALL_IN, 1, (r.x0, r.x1)
    if side == "N":
        return "x", r.y1 - WALL_IN, r.y1 + out, -1, (r.x0, r.x1)
    if side == "W":
        return "y", r.x0 - out, r.x0 + WALL_IN, 1, (r.y0, r.y1)
    return "y", r.x1 - WALL_IN, r.x1 + out, -1, (r.y0, r.y1)


def _on_side(r: PlanRoom, side: str, pt: tuple[float, float], tol: float = 0.11) -> float | None:
    """Position along the side of a point on it (a door centre), else None."""
    x, y = pt
    if side in "SN":
        line = r.y0 if side == "S" else r.y1
        return x if abs(y - line) < tol and r.x0 < x < r.x1 else None
    line = r.x0 if side == "W" else r.x1
    return y if abs(x - line) < tol and r.y0 < y < r.y1 else None


def shell(rng: random.Random, plan: Plan) -> list[Solid]:
    bx0, by0, bx1, by1 = plan.bounds
    s = [box("floor", bx0 - T_EXT, bx1 + T_EXT, by0 - T_EXT, by1 + T_EXT, -0.10, -0.002, "dark_wood"),
         box("ceiling", bx0 - T_EXT, bx1 + T_EXT, by0 - T_EXT, by1 + T_EXT, WALL_H, WALL_H + 0.1, "ceiling")]
    for r in plan.rooms:
        s.append(box(f"floor_{r.id}", r.x0, r.x1, r.y0, r.y1, -0.002, 0.0, f"floor_{r.id}", collide=False))
        for side in "SNWE":
            s += _room_side(rng, plan, r, side)
    for d in plan.doors:
        door = to_door(d)
        solids = doorway(door, WALL_IN + (T_EXT if d.rooms[1] == EXTERIOR else WALL_IN),
                         leaf_into=0 if d.open else None, hinge=d.hinge)
        s += [x for x in solids if d.leaf or not d.open or not x.name.endswith("_leaf")]
    return s


def _room_side(rng: random.Random, plan: Plan, r: PlanRoom, side: str) -> list[Solid]:
    out: list[Solid] = []
    bx0, by0, bx1, by1 = plan.bounds
    doors = [(a, d) for d in plan.doors if r.id in d.rooms and (a := _on_side(r, side, d.center)) is not None]
    for k, (a0, a1, ext) in enumerate(_split(_side_geometry(r, side, False)[4], _covered(plan, r, side))):
        axis, c0, c1, face, _ = _side_geometry(r, side, ext)
        openings = [(a, d.width + 2 * JAMB, 0.0, to_door(d).height + JAMB) for a, d in doors if a0 < a < a1]
        win = None
        if ext and a1 - a0 > 2.2 and not openings and rng.random() < 0.8:
            centre, width = round(rng.uniform(a0 + 1.0, a1 - 1.0), 2), round(rng.uniform(0.7, 1.1), 2)
            z0 = round(rng.uniform(0.85, 1.1), 2)
            win = (centre, width, z0, round(z0 + rng.uniform(0.7, 0.95), 2))
            openings.append(win)
        lo_end, hi_end = (bx0, bx1) if axis == "x" else (by0, by1)
        ea0 = a0 - T_EXT if ext and abs(a0 - lo_end) < 1e-6 else a0  # close the house's outer corners
        ea1 = a1 + T_EXT if ext and abs(a1 - hi_end) < 1e-6 else a1
        name = f"wall_{r.id}_{side}{k}"
        out += wall(name, axis, ea0, ea1, c0, c1, f"wall_{r.id}", tuple(sorted(openings)), face)
        if win is not None:
            at, outside = (c1, c0) if face > 0 else (c0, c1)
            out += window(f"{name}_window", axis, at, *win, outside)
    return out


# -- finishes and light ------------------------------------------------------------------------------
_FLOORS = {"wet": ("floor_tiles", (1.2, 1.2)), "dry": ("floor_wood", (1.0, 1.0)),
           "dry_light": ("floor_wood_light", (1.0, 1.0))}
_PAINTS = ((0.93, 0.91, 0.86), (0.85, 0.89, 0.93), (0.92, 0.86, 0.80), (0.86, 0.91, 0.84), (0.95, 0.95, 0.95),
           (0.88, 0.84, 0.90), (0.80, 0.84, 0.88))


def _tint(rng: random.Random, lo: float = 0.85) -> tuple[float, float, float, float]:
    return (round(rng.uniform(lo, 1.0), 3), round(rng.uniform(lo, 1.0), 3), round(rng.uniform(lo, 1.0), 3), 1.0)


def room_materials(rng: random.Random, r: PlanRoom) -> list[Material]:
    """Floor and wall finish of one room: tiles in wet rooms; wood, logs, plaster or paint elsewhere."""
    wet = r.kind in ("kitchen", "bathroom")
    tex, rep = _FLOORS["wet" if wet else rng.choice(("dry", "dry_light"))]
    floor = Material(f"floor_{r.id}", rgba=_tint(rng), texture=tex, texrepeat=rep, texuniform=True)
    if r.kind == "bathroom" or (r.kind == "kitchen" and rng.random() < 0.5):
        walls = Material(f"wall_{r.id}", rgba=_tint(rng, 0.8), texture="bath_tiles", texrepeat=(1.5, 1.5),
                         texuniform=True, specular=0.5)
    elif rng.random() < 0.25:
        walls = Material(f"wall_{r.id}", rgba=_tint(rng), texture=rng.choice(("log_wall", "log_wall_light")),
                         texrepeat=(0.8, 0.8), texuniform=True)
    else:  # plaster or paint: a plain colour, plaster a little rougher
        paint = _PAINTS[rng.randrange(len(_PAINTS))]
        walls = Material(f"wall_{r.id}", rgba=(*paint, 1.0), specular=rng.choice((0.05, 0.2)))
    return [floor, walls]


# The houses' furniture wears the cabin's materials (cabin.MATERIALS is the one table), in this order; the
# cushions go by their role here. A few take a seed-varied colour, drawn in the order they appear.
_FURNITURE = ("ceiling", "door_frame", "door_leaf", "front_door", "metal", "chrome", "stainless", "black", "dark_grey",
              "tv_screen", "wood", "dark_wood", "painted_wood", "cabinet", "countertop", "kitchen_tiles", "sofa",
              "cushion_red", "cushion_yellow", "rug", "books", "lampshade", "window_view", "window_frame", "fridge",
              "mattress", "blanket", "pillow", "mirror_glass", "mirror_frame", "painting", "ceramic", "water",
              "marble", "curtain", "plant", "pot")
_ROLE_NAMES = {"cushion_red": "cushion", "cushion_yellow": "cushion_alt"}


def furniture_materials(rng: random.Random) -> list[Material]:
    """Shared materials of the furniture: the cabin's, with seed-varied colours (fabric, wood, cabinets, ...)."""
    fabric = (round(rng.uniform(0.3, 1.0), 3), round(rng.uniform(0.3, 1.0), 3), round(rng.uniform(0.3, 1.0), 3), 1.0)
    cab = (round(rng.uniform(0.4, 0.95), 3), round(rng.uniform(0.5, 0.95), 3), round(rng.uniform(0.5, 0.95), 3), 1.0)
    seeded: dict[str, Callable[[], dict[str, Any]]] = {
        "door_leaf": lambda: {"rgba": _tint(rng, 0.7)}, "wood": lambda: {"rgba": _tint(rng, 0.7)},
        "painted_wood": lambda: {"rgba": _tint(rng, 0.8)}, "cabinet": lambda: {"rgba": cab},
        "sofa": lambda: {"rgba": fabric}, "rug": lambda: {"rgba": _tint(rng, 0.6)},
        "blanket": lambda: {"rgba": _tint(rng, 0.5)}, "curtain": lambda: {"rgba": _tint(rng, 0.6), "specular": 0.1},
        "plant": lambda: {"rgba": (0.20, round(rng.uniform(0.4, 0.6), 3), 0.22, 1.0)},
    }
    cabin_table = {m.name: m for m in CABIN_MATERIALS}
    out = []
    for name in _FURNITURE:  # in order: the seeded colours are drawn as they come
        changes = seeded[name]() if name in seeded else {}
        out.append(replace(cabin_table[name], name=_ROLE_NAMES.get(name, name), **changes))
    return out


def lights(rng: random.Random, plan: Plan) -> list[Light]:
    """A ceiling light per room (intensity and position by seed) and a sun whose direction varies by seed."""
    out = []
    for r in plan.rooms:
        level = round(rng.uniform(0.35, 0.55), 3)
        x = round(rng.uniform(r.x0 + 0.3 * (r.x1 - r.x0), r.x1 - 0.3 * (r.x1 - r.x0)), 2)
        y = round(rng.uniform(r.y0 + 0.3 * (r.y1 - r.y0), r.y1 - 0.3 * (r.y1 - r.y0)), 2)
        colour = (level, round(level * 0.95, 3), round(level * 0.85, 3))
        out.append(Light(f"light_{r.id}", (x, y, WALL_H - 0.25), colour, attenuation=(0.6, 0.15, 0.0)))
    dx, dy = round(rng.uniform(-0.6, 0.6), 3), round(rng.uniform(-0.6, 0.6), 3)
    sun = round(rng.uniform(0.1, 0.25), 3)
    bx0, by0, bx1, by1 = plan.bounds
    out.append(Light("sun", ((bx0 + bx1) / 2, (by0 + by1) / 2, WALL_H - 0.05), (sun, sun, sun), directional=True,
                     direction=(dx, dy, -1.0)))
    return out
