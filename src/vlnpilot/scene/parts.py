"""Building parts shared by every scene: boxes, cylinders, walls with openings, doorways with frames and
leaves, windows. Pure data (scene.model solids); the cabin and the procedural houses are built from them.
"""

from __future__ import annotations

import math

from vlnpilot.scene.model import Door, Solid

WALL_H = 2.6  # default storey height (the cabin's ceiling)
JAMB, CASING = 0.05, 0.02  # door-frame jamb thickness; how far the casing stands proud of the wall


def box(name: str, x0: float, x1: float, y0: float, y1: float, z0: float, z1: float, mat: str, *,
        collide: bool = True, target: str | None = None) -> Solid:
    """An axis-aligned box given by its extents (easier to read than centre and half-sizes)."""
    lo_x, hi_x, lo_y, hi_y, lo_z, hi_z = min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1), min(z0, z1), max(z0, z1)
    return Solid(name, "box", ((lo_x + hi_x) / 2, (lo_y + hi_y) / 2, (lo_z + hi_z) / 2),
                 ((hi_x - lo_x) / 2, (hi_y - lo_y) / 2, (hi_z - lo_z) / 2), mat, collide=collide, target=target)


def cyl(name: str, x: float, y: float, z0: float, z1: float, r: float, mat: str, *, collide: bool = True,
        target: str | None = None) -> Solid:
    return Solid(name, "cylinder", (x, y, (z0 + z1) / 2), (r, (z1 - z0) / 2, 0.0), mat, collide=collide,
                 target=target)


def ellipsoid(name: str, x: float, y: float, z: float, rx: float, ry: float, rz: float, mat: str, *,
              collide: bool = True, target: str | None = None) -> Solid:
    return Solid(name, "ellipsoid", (x, y, z), (rx, ry, rz), mat, collide=collide, target=target)


Opening = tuple[float, float, float, float]  # centre along the wall, width, bottom z, top z


def wall(name: str, axis: str, a0: float, a1: float, c0: float, c1: float, mat: str,
         openings: tuple[Opening, ...] = (), face: int = 1, height: float = WALL_H) -> list[Solid]:
    """A wall running along `axis` ('x' or 'y') from a0 to a1, spanning c0..c1 across, with openings cut out.

    `face` says which side faces the room (+1: the c1 side, -1: the c0 side). That side gets a visual
    plane 'skin' carrying the finish: MuJoCo maps 2-D textures correctly on planes but smears them on the
    vertical faces of boxes (tiles would lose their grout lines).
    """
    solids: list[Solid] = []
    c_face = (c1 if face > 0 else c0) + 0.001 * face
    normal = (0.0, float(face), 0.0) if axis == "x" else (float(face), 0.0, 0.0)
    x_axis = (-normal[1], normal[0], 0.0)  # up x normal, so that x cross up = normal

    def part(i: int, b0: float, b1: float, z0: float, z1: float) -> None:
        if b1 - b0 < 1e-6 or z1 - z0 < 1e-6:
            return
        n = f"{name}_{i}"
        mid, half = (b0 + b1) / 2, (b1 - b0) / 2
        if axis == "x":
            solids.append(box(n, b0, b1, c0, c1, z0, z1, mat))
            centre = (mid, c_face, (z0 + z1) / 2)
        else:
            solids.append(box(n, c0, c1, b0, b1, z0, z1, mat))
            centre = (c_face, mid, (z0 + z1) / 2)
        solids.append(Solid(f"{n}_skin", "plane", centre, (half, (z1 - z0) / 2, 0.0), mat, collide=False,
                            xyaxes=(*x_axis, 0.0, 0.0, 1.0)))

    cursor, i = a0, 0
    for centre, width, zb, zt in sorted(openings):
        lo, hi = centre - width / 2, centre + width / 2
        part(i, cursor, lo, 0.0, height)
        part(i + 1, lo, hi, 0.0, zb)
        part(i + 2, lo, hi, zt, height)
        cursor, i = hi, i + 3
    part(i, cursor, a1, 0.0, height)
    return solids


def _door_box(door: Door, name: str, d0: float, d1: float, s0: float, s1: float, z0: float, z1: float,
              mat: str, **kw) -> Solid:
    """A box given in the door's frame: depth d along the normal, lateral s to the left (axis-aligned doors)."""
    nx, ny = door.normal
    lx, ly = -ny, nx
    xs = [door.center[0] + d * nx + s * lx for d in (d0, d1) for s in (s0, s1)]
    ys = [door.center[1] + d * ny + s * ly for d in (d0, d1) for s in (s0, s1)]
    return box(name, min(xs), max(xs), min(ys), max(ys), z0, z1, mat, **kw)


def doorway(door: Door, wall_t: float, *, leaf_into: int | None, hinge: str) -> list[Solid]:
    """Frame (two jambs and a header, standing proud of the wall) and the door leaf.

    `leaf_into` is the index in door.rooms of the room the open leaf swings into (None: closed door);
    `hinge` is 'left' or 'right' seen along the door normal. Contact names: `<door>_frame_left`, ...
    """
    w, h, half_d = door.width, door.height, wall_t / 2 + CASING
    solids = [
        _door_box(door, f"{door.id}_frame_left", -half_d, half_d, w / 2, w / 2 + JAMB, 0, h + JAMB, "door_frame"),
        _door_box(door, f"{door.id}_frame_right", -half_d, half_d, -w / 2 - JAMB, -w / 2, 0, h + JAMB, "door_frame"),
        _door_box(door, f"{door.id}_frame_top", -half_d, half_d, -w / 2, w / 2, h, h + JAMB, "door_frame"),
    ]
    leaf_t, leaf_w = 0.04, w - 0.02
    if leaf_into is None:  # closed: the leaf fills the opening
        solids.append(_door_box(door, f"{door.id}_leaf", -leaf_t / 2, leaf_t / 2, -w / 2, w / 2, 0.01, h - 0.01,
                                "front_door"))
        knob_s = -w / 2 + 0.08 if hinge == "left" else w / 2 - 0.08
        for side in (-1, 1):
            solids.append(_door_box(door, f"{door.id}_handle_{'in' if side < 0 else 'out'}",
                                    side * leaf_t / 2, side * (leaf_t / 2 + 0.06), knob_s - 0.02, knob_s + 0.02,
                                    0.98, 1.02, "chrome"))
        return solids
    sign = -1.0 if leaf_into == 0 else 1.0  # depth direction of the room the leaf opens into
    s_hinge = w / 2 if hinge == "left" else -w / 2
    s_face = s_hinge - leaf_t if hinge == "left" else s_hinge + leaf_t
    d_start = sign * (wall_t / 2 + CASING)
    solids.append(_door_box(door, f"{door.id}_leaf", d_start, d_start + sign * leaf_w, s_hinge, s_face, 0.01,
                            h - 0.01, "door_leaf"))
    return solids


def window(name: str, axis: str, at: float, centre: float, width: float, z0: float, z1: float,
           outside: float) -> list[Solid]:
    """A window in an exterior wall: a bright view pane at the outer face and a white frame with a mullion."""
    def b(n: str, a0: float, a1: float, c0: float, c1: float, zz0: float, zz1: float, mat: str) -> Solid:
        return box(n, a0, a1, c0, c1, zz0, zz1, mat) if axis == "x" else box(n, c0, c1, a0, a1, zz0, zz1, mat)

    lo, hi, f = centre - width / 2, centre + width / 2, 0.04
    pane_c0, pane_c1 = sorted((outside - 0.01 * math.copysign(1, outside - at), outside))
    fr0, fr1 = sorted((at, outside))
    return [
        b(f"{name}_pane", lo, hi, pane_c0, pane_c1, z0, z1, "window_view"),
        b(f"{name}_frame_bottom", lo, hi, fr0, fr1, z0, z0 + f, "window_frame"),
        b(f"{name}_frame_top", lo, hi, fr0, fr1, z1 - f, z1, "window_frame"),
        b(f"{name}_frame_a", lo, lo + f, fr0, fr1, z0, z1, "window_frame"),
        b(f"{name}_frame_b", hi - f, hi, fr0, fr1, z0, z1, "window_frame"),
        b(f"{name}_mullion", centre - f / 2, centre + f / 2, fr0, fr1, z0, z1, "window_frame"),
        b(f"{name}_transom", lo, hi, fr0, fr1, (z0 + z1) / 2 - f / 2, (z0 + z1) / 2 + f / 2, "window_frame"),
    ]
