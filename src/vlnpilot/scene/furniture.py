"""Parametric furniture, after the cabin's pieces: each builder stands a piece against a wall at a given
position and width, in the wall's own frame, so that one builder serves every wall of every room.

A `WallFrame` maps (s along the wall, d into the room, z) to the world; a builder returns a `Piece`: its
solids, its footprint in the wall frame and, for pieces that can be a query's target, the centre of its
front face (the point a viewer looks at).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from vlnpilot.scene.model import Solid
from vlnpilot.scene.parts import box, cyl, ellipsoid

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class WallFrame:
    """A wall's interior face seen from the room: `origin` is its left end, `u` runs along it, `n` into the room."""

    origin: tuple[float, float]
    u: tuple[float, float]
    n: tuple[float, float]
    length: float

    def xy(self, s: float, d: float) -> tuple[float, float]:
        return (self.origin[0] + s * self.u[0] + d * self.n[0], self.origin[1] + s * self.u[1] + d * self.n[1])

    @property
    def facing_deg(self) -> float:
        return math.degrees(math.atan2(self.n[1], self.n[0]))

    def rect(self, s0: float, s1: float, d0: float, d1: float) -> tuple[float, float, float, float]:
        """World (xmin, ymin, xmax, ymax) of a wall-frame rectangle (walls are axis-aligned)."""
        (ax, ay), (bx, by) = self.xy(s0, d0), self.xy(s1, d1)
        return min(ax, bx), min(ay, by), max(ax, bx), max(ay, by)

    def box(self, name: str, s0: float, s1: float, d0: float, d1: float, z0: float, z1: float, mat: str,
            **kw) -> Solid:
        x0, y0, x1, y1 = self.rect(s0, s1, d0, d1)
        return box(name, x0, x1, y0, y1, z0, z1, mat, **kw)

    def cyl(self, name: str, s: float, d: float, z0: float, z1: float, r: float, mat: str, **kw) -> Solid:
        return cyl(name, *self.xy(s, d), z0, z1, r, mat, **kw)

    def ellipsoid(self, name: str, s: float, d: float, z: float, rs: float, rd: float, rz: float, mat: str,
                  **kw) -> Solid:
        along_x = abs(self.u[0]) > 0.5
        rx, ry = (rs, rd) if along_x else (rd, rs)
        return ellipsoid(name, *self.xy(s, d), z, rx, ry, rz, mat, **kw)


@dataclass(frozen=True)
class Piece:
    solids: tuple[Solid, ...]
    depth: float  # how far it stands out from the wall
    tall: bool  # reaches flight altitude (an obstacle for the drone), so it stays off walls with doors
    front: Vec3 | None = None  # world centre of the front face, for a target


Builder = Callable[[WallFrame, str, float, float, "str | None"], Piece]


def _front(f: WallFrame, s: float, d: float, z: float) -> Vec3:
    x, y = f.xy(s, d)
    return (round(x, 4), round(y, 4), z)


# Each builder: (frame, name, centre s, width w, target id) -> Piece. Widths come from FURNITURE below.
def bed(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    L, a, b = 2.0, c - w / 2, c + w / 2
    s = [f.box(f"{n}_frame", a, b, 0.05, L, 0.10, 0.32, "wood", target=t),
         f.box(f"{n}_headboard", a - 0.03, b + 0.03, 0.0, 0.08, 0.0, 1.0, "wood", target=t),
         f.box(f"{n}_mattress", a + 0.03, b - 0.03, 0.08, L - 0.03, 0.32, 0.52, "mattress", target=t),
         f.box(f"{n}_blanket", a - 0.01, b + 0.01, 0.6, L + 0.01, 0.30, 0.55, "blanket", target=t)]
    for i, side in enumerate((-1, 1)):
        s.append(f.ellipsoid(f"{n}_pillow_{i}", c + side * w / 4, 0.3, 0.60, w / 4 - 0.04, 0.15, 0.08, "pillow",
                             target=t))
    return Piece(tuple(s), L, False, _front(f, c, L, 0.45))


def wardrobe(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    d = 0.6
    s = [f.box(n, c - w / 2, c + w / 2, 0.0, d, 0.0, 2.05, "wood", target=t),
         f.box(f"{n}_gap", c - 0.005, c + 0.005, d, d + 0.006, 0.05, 2.0, "dark_wood", collide=False, target=t)]
    for i, side in enumerate((-1, 1)):
        s.append(f.box(f"{n}_handle_{i}", c + side * 0.07 - 0.01, c + side * 0.07 + 0.01, d, d + 0.03, 0.9, 1.2,
                       "chrome", target=t))
    return Piece(tuple(s), d + 0.03, True, _front(f, c, d + 0.03, 1.0))


def sofa(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    a, b = c - w / 2, c + w / 2
    s = (f.box(f"{n}_base", a, b, 0.0, 0.85, 0.10, 0.42, "sofa", target=t),
         f.box(f"{n}_seat", a + 0.15, b - 0.15, 0.2, 0.8, 0.42, 0.50, "sofa", target=t),
         f.box(f"{n}_back", a, b, 0.0, 0.22, 0.10, 0.88, "sofa", target=t),
         f.box(f"{n}_arm_0", a, a + 0.15, 0.0, 0.85, 0.10, 0.62, "sofa", target=t),
         f.box(f"{n}_arm_1", b - 0.15, b, 0.0, 0.85, 0.10, 0.62, "sofa", target=t),
         f.box(f"{n}_cushion_0", a + 0.25, a + 0.6, 0.22, 0.36, 0.50, 0.80, "cushion", target=t),
         f.box(f"{n}_cushion_1", b - 0.6, b - 0.25, 0.22, 0.36, 0.50, 0.80, "cushion_alt", target=t))
    return Piece(s, 0.85, False, _front(f, c, 0.85, 0.45))


def tv(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    a, b = c - w / 2, c + w / 2
    s = (f.box(f"{n}_stand", a, b, 0.0, 0.45, 0.0, 0.48, "wood"),
         f.box(f"{n}_foot", c - 0.1, c + 0.1, 0.08, 0.30, 0.48, 0.70, "black", target=t),
         f.box(f"{n}_body", a + 0.02, b - 0.02, 0.10, 0.16, 0.70, 1.38, "black", target=t),
         f.box(f"{n}_screen", a + 0.05, b - 0.05, 0.16, 0.165, 0.73, 1.35, "tv_screen", collide=False, target=t))
    return Piece(s, 0.45, True, _front(f, c, 0.165, 1.04))


def counters(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    """Kitchen run: base cabinets, worktop and splash-back with a stove (cooktop, oven, hood) in the middle."""
    a, b, d = c - w / 2, c + w / 2, 0.6
    s = [f.box(f"{n}_cabinets", a, b, 0.0, d, 0.0, 0.86, "cabinet"),
         f.box(f"{n}_worktop", a, b, 0.0, d + 0.03, 0.86, 0.90, "countertop"),
         f.box(f"{n}_splashback", a, b, 0.0, 0.012, 0.90, 1.45, "kitchen_tiles", collide=False),
         f.box(f"{n}_stove_top", c - 0.3, c + 0.3, 0.02, d, 0.90, 0.915, "black", target=t),
         f.box(f"{n}_oven_door", c - 0.28, c + 0.28, d, d + 0.02, 0.12, 0.72, "black", collide=False, target=t),
         f.box(f"{n}_hood", c - 0.3, c + 0.3, 0.0, 0.35, 1.65, 1.95, "stainless", target=t)]
    for i, (ds, dd) in enumerate(((-0.15, 0.17), (0.15, 0.17), (-0.15, 0.43), (0.15, 0.43))):
        s.append(f.cyl(f"{n}_burner_{i}", c + ds, dd, 0.915, 0.925, 0.075, "dark_grey", collide=False, target=t))
    for i, (s0, s1) in enumerate(((a, c - 0.32), (c + 0.32, b))):
        if s1 - s0 > 0.3:
            s.append(f.box(f"{n}_wall_cabinet_{i}", s0, s1, 0.0, 0.35, 1.50, 2.20, "cabinet"))
    return Piece(tuple(s), d + 0.03, True, _front(f, c, d + 0.03, 0.9))


def fridge(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    a, b, d = c - w / 2, c + w / 2, 0.7
    s = [f.box(f"{n}_body", a, b, 0.02, d, 0.0, 1.85, "fridge", target=t),
         f.box(f"{n}_door_gap", a, b, d, d + 0.006, 1.24, 1.255, "dark_grey", collide=False, target=t),
         f.box(f"{n}_dispenser", a + 0.1, a + 0.32, d, d + 0.006, 1.62, 1.78, "dark_grey", collide=False,
               target=t)]
    for i, (z0, z1) in enumerate(((0.75, 1.18), (1.32, 1.62))):
        s.append(f.box(f"{n}_handle_{i}", b - 0.09, b - 0.06, d, d + 0.05, z0, z1, "chrome", target=t))
    return Piece(tuple(s), d + 0.05, True, _front(f, c, d, 0.95))


def toilet(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    s = (f.box(f"{n}_tank", c - 0.23, c + 0.23, 0.02, 0.24, 0.40, 0.80, "ceramic", target=t),
         f.ellipsoid(f"{n}_bowl", c, 0.48, 0.22, 0.19, 0.26, 0.22, "ceramic", target=t),
         f.box(f"{n}_seat", c - 0.17, c + 0.17, 0.26, 0.74, 0.40, 0.44, "ceramic", target=t))
    return Piece(s, 0.74, False, _front(f, c, 0.74, 0.42))


def vanity(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    """A sink on a vanity cabinet, with a faucet and a mirror above it."""
    a, b = c - w / 2, c + w / 2
    s = (f.box(f"{n}_cabinet", a, b, 0.0, 0.52, 0.0, 0.80, "painted_wood", target=t),
         f.box(f"{n}_top", a - 0.02, b + 0.02, 0.0, 0.56, 0.80, 0.85, "marble", target=t),
         f.cyl(f"{n}_basin", c, 0.30, 0.85, 0.91, 0.18, "ceramic", target=t),
         f.cyl(f"{n}_water", c, 0.30, 0.91, 0.915, 0.14, "water", collide=False, target=t),
         f.cyl(f"{n}_faucet", c, 0.08, 0.85, 1.05, 0.016, "chrome", target=t),
         f.box(f"{n}_spout", c - 0.01, c + 0.01, 0.08, 0.20, 1.02, 1.05, "chrome", target=t),
         f.box(f"{n}_mirror", a + 0.05, b - 0.05, 0.0, 0.01, 1.25, 1.85, "mirror_glass", collide=False))
    return Piece(s, 0.56, False, _front(f, c, 0.56, 0.88))


def shower(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    a, b, d = c - w / 2, c + w / 2, 0.9
    s = (f.box(f"{n}_tray", a, b, 0.0, d, 0.0, 0.08, "ceramic", target=t),
         f.cyl(f"{n}_pipe", c, 0.04, 0.08, 1.95, 0.015, "chrome", target=t),
         f.box(f"{n}_head", c - 0.05, c + 0.05, 0.02, 0.16, 1.92, 1.97, "chrome", target=t),
         f.box(f"{n}_curtain", a, b, d - 0.03, d, 0.40, 1.95, "curtain", target=t),
         f.box(f"{n}_rail", a, b, d - 0.02, d - 0.01, 1.95, 1.97, "chrome", collide=False, target=t))
    return Piece(s, d, True, _front(f, c, d, 1.1))


def desk(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    a, b, d = c - w / 2, c + w / 2, 0.65
    s = [f.box(f"{n}_top", a, b, 0.0, d, 0.72, 0.76, "wood", target=t),
         f.box(f"{n}_drawers", b - 0.42, b - 0.02, 0.02, d - 0.05, 0.0, 0.72, "wood", target=t),
         f.box(f"{n}_monitor", c - 0.28, c + 0.28, 0.12, 0.15, 0.95, 1.28, "black", target=t),
         f.box(f"{n}_monitor_foot", c - 0.04, c + 0.04, 0.08, 0.18, 0.76, 0.95, "dark_grey", target=t),
         f.box(f"{n}_chair_seat", c - 0.22, c + 0.22, d + 0.05, d + 0.5, 0.44, 0.49, "dark_grey"),
         f.box(f"{n}_chair_back", c - 0.22, c + 0.22, d + 0.46, d + 0.5, 0.49, 0.90, "dark_grey"),
         f.cyl(f"{n}_chair_post", c, d + 0.27, 0.05, 0.44, 0.03, "metal")]
    s.append(f.cyl(f"{n}_leg", a + 0.04, d - 0.04, 0.0, 0.72, 0.025, "metal", target=t))
    return Piece(tuple(s), d + 0.5, False, _front(f, c, d, 0.8))


def bookshelf(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    a, b, d = c - w / 2, c + w / 2, 0.35
    s = (f.box(n, a, b, 0.0, d, 0.0, 1.9, "wood", target=t),
         f.box(f"{n}_books", a + 0.05, b - 0.05, d, d + 0.005, 0.05, 1.85, "books", collide=False, target=t))
    return Piece(s, d, True, _front(f, c, d, 1.0))


def plant(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    r = w / 2
    s = (f.cyl(f"{n}_pot", c, r, 0.0, 0.40, 0.16, "pot", target=t),
         f.ellipsoid(f"{n}_leaves", c, r, 0.85, r, r, 0.45, "plant", target=t))
    return Piece(s, w, True, _front(f, c, w, 0.75))


def mirror(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    s = (f.box(f"{n}_frame", c - w / 2, c + w / 2, 0.0, 0.05, 0.40, 2.00, "mirror_frame", target=t),
         f.box(f"{n}_glass", c - w / 2 + 0.05, c + w / 2 - 0.05, 0.05, 0.06, 0.45, 1.95, "mirror_glass", target=t))
    return Piece(s, 0.06, True, _front(f, c, 0.06, 1.2))


def nightstand(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    s = (f.box(n, c - w / 2, c + w / 2, 0.0, 0.42, 0.0, 0.55, "wood"),
         f.cyl(f"{n}_lamp_base", c, 0.21, 0.55, 0.78, 0.04, "metal"),
         f.cyl(f"{n}_lamp_shade", c, 0.21, 0.78, 0.96, 0.11, "lampshade"))
    return Piece(s, 0.42, True, None)


def floor_lamp(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    s = (f.cyl(f"{n}_pole", c, 0.25, 0.0, 1.5, 0.015, "metal"),
         f.cyl(f"{n}_shade", c, 0.25, 1.5, 1.75, 0.16, "lampshade"))
    return Piece(s, 0.45, True, None)


def painting(f: WallFrame, n: str, c: float, w: float, t: str | None) -> Piece:
    return Piece((f.box(n, c - w / 2, c + w / 2, 0.0, 0.02, 1.25, 1.25 + 0.65 * w, "painting", collide=False),),
                 0.0, False, None)


# kind -> (builder, width range in metres). One table: the generator draws a width from it per seed.
FURNITURE: dict[str, tuple[Builder, tuple[float, float]]] = {
    "bed": (bed, (1.4, 1.8)), "wardrobe": (wardrobe, (0.9, 1.4)), "sofa": (sofa, (1.6, 2.2)),
    "tv": (tv, (1.0, 1.4)), "counters": (counters, (1.8, 2.6)), "fridge": (fridge, (0.7, 0.8)),
    "toilet": (toilet, (0.5, 0.5)), "vanity": (vanity, (0.7, 0.9)), "shower": (shower, (0.8, 1.0)),
    "desk": (desk, (1.1, 1.5)), "bookshelf": (bookshelf, (0.8, 1.2)), "plant": (plant, (0.45, 0.6)),
    "mirror": (mirror, (0.6, 0.7)), "nightstand": (nightstand, (0.4, 0.45)),
    "floor_lamp": (floor_lamp, (0.35, 0.35)), "painting": (painting, (0.6, 1.0)),
}


def centrepiece(name: str, cx: float, cy: float, w: float, d: float, mat: str) -> list[Solid]:
    """A low table on a rug in the middle of a room (below flight altitude)."""
    s = [box(f"{name}_rug", cx - w / 2 - 0.3, cx + w / 2 + 0.3, cy - d / 2 - 0.3, cy + d / 2 + 0.3, 0.0, 0.006, "rug",
             collide=False),
         box(f"{name}_top", cx - w / 2, cx + w / 2, cy - d / 2, cy + d / 2, 0.70 if mat == "dining" else 0.38,
             0.74 if mat == "dining" else 0.42, "wood")]
    top = s[1].pos[2] - s[1].size[2]
    for i, (sx, sy) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
        s.append(cyl(f"{name}_leg_{i}", cx + sx * (w / 2 - 0.05), cy + sy * (d / 2 - 0.05), 0.0, top, 0.02,
                     "dark_wood"))
    return s
