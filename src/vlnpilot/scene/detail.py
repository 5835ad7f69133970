"""Rich detail (issue 25, docs/scenes.md): visual-only parts of known real-world size that give a camera scale.

`with_detail(scene, "rich")` returns the scene with skirting boards, 14 cm floorboards, 30 cm floor tiles and 15 cm
wall tiles, light switches at 1.1 m beside every doorway, handles at 1.0 m on the open door leaves, framed pictures,
clutter on tables, desks and counters, and mirrors that reflect. `plain` returns the scene itself (what every
recorded trial saw). The simulator builds its MJCF from it; `Simulator.scene`, the ground truth and the geometry
stay the plain scene's.

Every part is visual only (no contype) and named `detail_...`, which puts it in geom group `DETAIL_GROUP`: MuJoCo's
default visual options hide that group, so the segmentation (target visibility), the depth camera and the range
sensors never see it; only the RGB cameras switch it on. The same scene always gets the same detail (seeded by its
name).
"""

from __future__ import annotations

import math
import random
import zlib
from dataclasses import replace

from vlnpilot.core.errors import ConfigError
from vlnpilot.scene.model import EXTERIOR, Door, Material, Scene, Solid
from vlnpilot.scene.parts import _door_box, box, cyl

DETAILS = ("plain", "rich")
DEFAULT_DETAIL = "plain"
DETAIL_GROUP = 3  # off in MuJoCo's default mjvOption.geomgroup (1 1 1 0 0 0): only the RGB renders turn it on
PREFIX = "detail_"

# -- the real-world sizes the detail carries (metres) ---------------------------------------------------------
SKIRTING_H, SKIRTING_T = 0.08, 0.012
PLANK_W, PLANKS_PER_TEXTURE = 0.14, 8
FLOOR_TILE, WALL_TILE = 0.30, 0.15
SWITCH_Z, SWITCH_PLATE, SWITCH_FROM_OPENING = 1.10, 0.08, 0.22  # plate centre from the opening's edge
ARCHITRAVE_W, ARCHITRAVE_T, REVEAL = 0.07, 0.012, 0.006  # door casing trim: width, how proud, set back from the jamb
HANDLE_Z, HANDLE_L = 1.00, 0.12
PICTURE_Z = 1.50  # centre height
PICTURE_SIZES = ((0.40, 0.30), (0.50, 0.40), (0.60, 0.45), (0.30, 0.40), (0.70, 0.50))
CLUTTER_CLEARANCE = 0.08  # clutter stays this far below flight altitude: the drone never flies through a lamp


def check_detail(name: str) -> str:
    """The detail level, or a one-line refusal naming the choices."""
    if name not in DETAILS:
        raise ConfigError(f"unknown detail {name!r}; valid: {', '.join(DETAILS)}")
    return name


def is_detail(solid_name: str) -> bool:
    return solid_name.startswith(PREFIX)


def texrepeat(cell_m: float, cells_per_texture: int) -> tuple[float, float]:
    """The texrepeat (texuniform) that makes one cell `cell_m` wide: MuJoCo spans a texture over 2/texrepeat m."""
    r = round(2.0 / (cell_m * cells_per_texture), 4)
    return r, r


# floor and wall finishes that get a known scale: texture -> (rich texture, cell size, cells per texture)
_SCALED = {
    "floor_wood": ("floor_planks", PLANK_W, PLANKS_PER_TEXTURE),
    "floor_wood_light": ("floor_planks_light", PLANK_W, PLANKS_PER_TEXTURE),
    "floor_tiles": ("floor_tiles", FLOOR_TILE, 4),
    "bath_tiles": ("bath_tiles", WALL_TILE, 8),
}

DETAIL_MATERIALS: tuple[Material, ...] = (
    Material("detail_skirting", rgba=(0.95, 0.94, 0.90, 1.0), specular=0.3),
    Material("detail_architrave", rgba=(0.97, 0.96, 0.93, 1.0), specular=0.3),
    Material("detail_switch", rgba=(0.97, 0.97, 0.95, 1.0), specular=0.4),
    Material("detail_handle", rgba=(0.80, 0.80, 0.82, 1.0), specular=0.9, shininess=0.8),
    Material("detail_frame", rgba=(0.20, 0.14, 0.09, 1.0), specular=0.3),
    Material("detail_mirror", rgba=(0.22, 0.23, 0.25, 1.0), specular=0.3, shininess=0.9, reflectance=0.95),
    *(Material(f"detail_art_{i}", texture=f"art_{i}") for i in range(4)),
    Material("detail_ceramic", rgba=(0.95, 0.95, 0.93, 1.0), specular=0.6, shininess=0.6),
    Material("detail_mug", rgba=(0.20, 0.35, 0.60, 1.0), specular=0.5),
    Material("detail_board", rgba=(0.62, 0.45, 0.28, 1.0)),
    Material("detail_lampshade", rgba=(0.98, 0.93, 0.80, 1.0), emission=0.5),
    Material("detail_brass", rgba=(0.70, 0.58, 0.30, 1.0), specular=0.7, shininess=0.6),
    *(Material(f"detail_book_{i}", rgba=c) for i, c in enumerate(
        ((0.60, 0.12, 0.10, 1.0), (0.10, 0.25, 0.50, 1.0), (0.15, 0.40, 0.20, 1.0), (0.85, 0.70, 0.30, 1.0),
         (0.30, 0.30, 0.32, 1.0)))),
)


def with_detail(scene: Scene, detail: str = DEFAULT_DETAIL) -> Scene:
    """The scene as `detail` renders it: `plain` is `scene` itself; `rich` adds the visual-only parts."""
    if check_detail(detail) == "plain":
        return scene
    rng = random.Random(zlib.crc32(scene.name.encode("utf-8")))
    parts = skirting(scene) + architraves(scene) + switches(scene) + handles(scene) + mirrors(scene)
    parts += pictures(scene, rng, parts)
    parts += clutter(scene, rng, parts)
    return replace(scene, solids=scene.solids + tuple(parts), materials=_materials(scene) + DETAIL_MATERIALS)


def _materials(scene: Scene) -> tuple[Material, ...]:
    """The scene's materials with the floors and tiles at a known scale."""
    out = []
    for m in scene.materials:
        if m.texture in _SCALED and m.texuniform:
            texture, cell, cells = _SCALED[m.texture]
            m = replace(m, texture=texture, texrepeat=texrepeat(cell, cells))
        out.append(m)
    return tuple(out)


# -- geometry helpers -------------------------------------------------------------------------------------------
Box = tuple[float, float, float, float, float, float]  # xmin, ymin, zmin, xmax, ymax, zmax


def _volume(s: Solid) -> Box:
    """`_aabb` of a solid with a volume (a surface or a placed part: never a plane)."""
    box = _aabb(s)
    if box is None:
        raise ValueError(f"{s.name} is a plane: it has no volume")
    return box


def _aabb(s: Solid) -> Box | None:
    """A world box around a solid (None for the planes: the wall skins carry no volume)."""
    if s.shape == "plane":
        return None
    hx, hy, hz = s.size
    if s.shape == "sphere":
        hx = hy = hz = s.size[0]
    elif s.shape in ("cylinder", "capsule"):
        hx, hy, hz = s.size[0], s.size[0], s.size[1] + (s.size[0] if s.shape == "capsule" else 0.0)
    if s.yaw_deg or s.euler_deg:  # turned: the radius bounds it
        hx = hy = hz = math.sqrt(hx * hx + hy * hy + hz * hz)
    x, y, z = s.pos
    return x - hx, y - hy, z - hz, x + hx, y + hy, z + hz


def _overlaps(a: Box, b: Box, eps: float = 1e-4) -> bool:
    return all(a[i] < b[i + 3] - eps and b[i] < a[i + 3] - eps for i in range(3))


def _free(region: Box, solids: list[Solid] | tuple[Solid, ...], ignore: str = "") -> bool:
    return not any(s.name != ignore and (b := _aabb(s)) is not None and _overlaps(region, b) for s in solids)


def _skins(scene: Scene) -> list[tuple[Solid, tuple[float, float, float], tuple[float, float, float]]]:
    """The wall skins (visual planes on a wall's room face) with their along-wall axis and their normal."""
    out = []
    for s in scene.solids:
        if s.shape == "plane" and s.name.endswith("_skin") and s.xyaxes:
            ax = (float(s.xyaxes[0]), float(s.xyaxes[1]), float(s.xyaxes[2]))
            n = (ax[1], -ax[0], 0.0)  # x cross up, up = (0, 0, 1)
            out.append((s, ax, n))
    return out


def _wall_box(name: str, skin: Solid, ax, n, a0: float, a1: float, d0: float, d1: float, z0: float, z1: float,
              mat: str) -> Solid:
    """A box on a skin's face: a0..a1 along the wall (from the skin's centre), d0..d1 out of it, z0..z1."""
    cx, cy = skin.pos[0], skin.pos[1]
    xs = [cx + a * ax[0] + d * n[0] for a in (a0, a1) for d in (d0, d1)]
    ys = [cy + a * ax[1] + d * n[1] for a in (a0, a1) for d in (d0, d1)]
    return box(name, min(xs), max(xs), min(ys), max(ys), z0, z1, mat, collide=False)


# -- the parts ---------------------------------------------------------------------------------------------------
def skirting(scene: Scene) -> list[Solid]:
    """A skirting board (SKIRTING_H tall) along the foot of every wall skin that reaches the floor."""
    out = []
    for skin, ax, n in _skins(scene):
        bottom = skin.pos[2] - skin.size[1]
        if abs(bottom) < 1e-3:
            half = skin.size[0]
            out.append(_wall_box(f"{PREFIX}skirting_{skin.name}", skin, ax, n, -half, half, 0.0, SKIRTING_T, 0.0,
                                 SKIRTING_H, "detail_skirting"))
    return out


def _wall_beside(scene: Scene, point: tuple[float, float], normal: tuple[float, float], z: float, reach: float):
    """The skin facing `normal` whose face holds `point` (within 0.3 m of depth) at height z, with its axes."""
    for skin, ax, n in _skins(scene):
        if n[0] * normal[0] + n[1] * normal[1] < 0.99:
            continue
        dx, dy = point[0] - skin.pos[0], point[1] - skin.pos[1]
        along, depth = dx * ax[0] + dy * ax[1], dx * n[0] + dy * n[1]
        if abs(depth) < 0.3 and abs(along) + reach <= skin.size[0] and abs(z - skin.pos[2]) + reach <= skin.size[1]:
            return skin, ax, n, along
    return None


def switches(scene: Scene) -> list[Solid]:
    """A switch plate at SWITCH_Z on the latch side of every doorway, on each side that is a room."""
    out = []
    for door in scene.doors:
        hinge = _hinge_side(scene, door)
        lateral = -hinge * (door.width / 2 + SWITCH_FROM_OPENING)
        for k, room in enumerate(door.rooms):
            if room == EXTERIOR:
                continue
            into = -1.0 if k == 0 else 1.0  # the normal points from rooms[0] to rooms[1]
            nx, ny = door.normal
            px, py = door.center[0] - ny * lateral, door.center[1] + nx * lateral
            found = _wall_beside(scene, (px, py), (into * nx, into * ny), SWITCH_Z, SWITCH_PLATE)
            if found is None:
                continue
            skin, ax, n, along = found
            h = SWITCH_PLATE / 2
            out.append(_wall_box(f"{PREFIX}switch_{door.id}_{room}", skin, ax, n, along - h, along + h, 0.0, 0.01,
                                 SWITCH_Z - h, SWITCH_Z + h, "detail_switch"))
            out.append(_wall_box(f"{PREFIX}switch_{door.id}_{room}_rocker", skin, ax, n, along - 0.012,
                                 along + 0.012, 0.01, 0.016, SWITCH_Z - 0.02, SWITCH_Z + 0.02, "detail_switch"))
    return out


def architraves(scene: Scene) -> list[Solid]:
    """A casing trim ARCHITRAVE_W wide around every doorway on each side that is a room, ARCHITRAVE_T proud of the
    frame and set REVEAL back from the opening: the edge that tells a jamb's inner face from the casing."""
    out = []
    for door in scene.doors:
        frame = next((x for x in scene.solids if x.name == f"{door.id}_frame_left"), None)
        if frame is None:
            continue
        half_d = frame.size[0] if abs(door.normal[0]) > 0.5 else frame.size[1]
        centre = door.frame_of(frame.pos[0], frame.pos[1])[0]
        inner, outer = door.width / 2 + REVEAL, door.width / 2 + REVEAL + ARCHITRAVE_W
        low, high = door.height + REVEAL, door.height + REVEAL + ARCHITRAVE_W  # the head, above the opening
        for k, room in enumerate(door.rooms):
            if room == EXTERIOR:
                continue
            sign = -1.0 if k == 0 else 1.0
            d0 = centre + sign * half_d
            d1 = d0 + sign * ARCHITRAVE_T
            name = f"{PREFIX}architrave_{door.id}_{room}"
            out += [_door_box(door, f"{name}_left", d0, d1, inner, outer, 0.0, high, "detail_architrave",
                              collide=False),
                    _door_box(door, f"{name}_right", d0, d1, -outer, -inner, 0.0, high, "detail_architrave",
                              collide=False),
                    _door_box(door, f"{name}_top", d0, d1, -outer, outer, low, high, "detail_architrave",
                              collide=False)]
    return out


def _leaf(scene: Scene, door: Door) -> Solid | None:
    return next((s for s in scene.solids if s.name == f"{door.id}_leaf"), None)


def _hinge_side(scene: Scene, door: Door) -> float:
    """+1 if an open leaf hangs on the door's left (seen along its normal), -1 on its right; +1 without a leaf."""
    leaf = _leaf(scene, door)
    if leaf is None or not door.open:
        return 1.0
    return 1.0 if door.frame_of(leaf.pos[0], leaf.pos[1])[1] >= 0 else -1.0


def handles(scene: Scene) -> list[Solid]:
    """A lever handle at HANDLE_Z on both faces of every open door leaf, at its latch end (closed doors have
    theirs)."""
    out = []
    for door in scene.doors:
        leaf = _leaf(scene, door)
        if leaf is None or not door.open:
            continue
        along_x = abs(door.normal[0]) > 0.5
        half_d, half_s = (leaf.size[0], leaf.size[1]) if along_x else (leaf.size[1], leaf.size[0])
        d_mid, s_mid = door.frame_of(leaf.pos[0], leaf.pos[1])
        latch = d_mid + math.copysign(half_d, d_mid) - math.copysign(0.06, d_mid)  # 6 cm in from its free edge
        inward = -math.copysign(1.0, d_mid)  # towards the hinge
        for side in (-1.0, 1.0):
            face = s_mid + side * half_s
            out.append(_door_box(door, f"{PREFIX}handle_{door.id}_{'ab'[side > 0]}_rose", latch - 0.025,
                                 latch + 0.025, face, face + side * 0.012, HANDLE_Z - 0.025, HANDLE_Z + 0.025,
                                 "detail_handle", collide=False))
            d0, d1 = sorted((latch, latch + inward * HANDLE_L))
            out.append(_door_box(door, f"{PREFIX}handle_{door.id}_{'ab'[side > 0]}_lever", d0, d1,
                                 face + side * 0.04, face + side * 0.058, HANDLE_Z - 0.009, HANDLE_Z + 0.009,
                                 "detail_handle", collide=False))
            out.append(_door_box(door, f"{PREFIX}handle_{door.id}_{'ab'[side > 0]}_neck", latch - 0.009,
                                 latch + 0.009, face, face + side * 0.04, HANDLE_Z - 0.009, HANDLE_Z + 0.009,
                                 "detail_handle", collide=False))
    return out


def mirrors(scene: Scene) -> list[Solid]:
    """A reflective plane on the room face of every mirror's glass (MuJoCo reflects on planes)."""
    out = []
    for s in scene.solids:
        if s.material != "mirror_glass" or s.shape != "box":
            continue
        thin_x = s.size[0] < s.size[1]
        room = next((r for r in scene.rooms if r.contains(s.pos[0], s.pos[1])), None)
        cx, cy = room.centroid if room else (s.pos[0] - 1.0, s.pos[1] - 1.0)
        sign = math.copysign(1.0, (cx - s.pos[0]) if thin_x else (cy - s.pos[1]))
        n = (sign, 0.0, 0.0) if thin_x else (0.0, sign, 0.0)
        ax = (-n[1], n[0], 0.0)
        thick, width = (s.size[0], s.size[1]) if thin_x else (s.size[1], s.size[0])
        pos = (s.pos[0] + n[0] * (thick + 0.001), s.pos[1] + n[1] * (thick + 0.001), s.pos[2])
        out.append(Solid(f"{PREFIX}mirror_{s.name}", "plane", pos, (width, s.size[2], 0.0), "detail_mirror",
                         collide=False, xyaxes=(*ax, 0.0, 0.0, 1.0)))
    return out


def pictures(scene: Scene, rng: random.Random, placed: list[Solid]) -> list[Solid]:
    """One or two framed pictures per room, centred at PICTURE_Z on walls clear of furniture and openings."""
    out: list[Solid] = []
    skins = _skins(scene)
    for room in scene.rooms:
        mine = [(s, ax, n) for s, ax, n in skins if s.size[0] > 0.5
                and room.contains(s.pos[0] + 0.2 * n[0], s.pos[1] + 0.2 * n[1])]
        rng.shuffle(mine)
        wanted = rng.choice((1, 2))
        for skin, ax, n in mine:
            if wanted == 0:
                break
            w, h = rng.choice(PICTURE_SIZES)
            if skin.size[0] < w / 2 + 0.15 or abs(PICTURE_Z - skin.pos[2]) + h / 2 + 0.05 > skin.size[1]:
                continue
            along = rng.uniform(-skin.size[0] + w / 2 + 0.1, skin.size[0] - w / 2 - 0.1)
            z0, z1 = PICTURE_Z - h / 2, PICTURE_Z + h / 2
            frame = _wall_box(f"{PREFIX}picture_{skin.name}_frame", skin, ax, n, along - w / 2, along + w / 2,
                              0.0, 0.02, z0, z1, "detail_frame")
            clear = _wall_box("clearance", skin, ax, n, along - w / 2 - 0.05, along + w / 2 + 0.05, 0.0, 0.25,
                              z0 - 0.05, z1 + 0.05, "detail_frame")
            if not _free(_volume(clear), (*scene.solids, *placed, *out)):
                continue
            art = f"detail_art_{rng.randrange(4)}"
            out += [frame, _wall_box(f"{PREFIX}picture_{skin.name}_canvas", skin, ax, n, along - w / 2 + 0.03,
                                     along + w / 2 - 0.03, 0.02, 0.025, z0 + 0.03, z1 - 0.03, art)]
            wanted -= 1
    return out


# surfaces that take clutter, by the words of their name; the stove's top and the vanity's (the sink) are left alone
_SURFACE_WORDS, _NOT_SURFACE_WORDS = {"top", "worktop", "nightstand"}, {"stove", "frame", "vanity", "window"}


def _surfaces(scene: Scene) -> list[Solid]:
    out = []
    for s in scene.solids:
        words = set(s.name.split("_"))
        if (s.shape == "box" and s.collide and not s.yaw_deg and not s.euler_deg and min(s.size[:2]) >= 0.15
                and (words & _SURFACE_WORDS or {"tv", "stand"} <= words) and not words & _NOT_SURFACE_WORDS
                and 0.3 <= s.pos[2] + s.size[2] <= 0.95):
            out.append(s)
    return out


def _item(kind: str, name: str, x: float, y: float, z: float, rng: random.Random) -> list[Solid]:
    """One piece of clutter standing at (x, y) on a top at height z (real sizes)."""
    if kind == "cup":
        return [cyl(name, x, y, z, z + 0.095, 0.04, rng.choice(("detail_mug", "detail_ceramic")), collide=False)]
    if kind == "bowl":
        return [cyl(name, x, y, z, z + 0.06, 0.08, "detail_ceramic", collide=False)]
    if kind == "board":
        return [box(name, x - 0.18, x + 0.18, y - 0.12, y + 0.12, z, z + 0.02, "detail_board", collide=False)]
    if kind == "books":
        out, top = [], z
        for i in range(rng.randint(1, 3)):
            w, d, t = rng.uniform(0.15, 0.22), rng.uniform(0.2, 0.28), rng.uniform(0.02, 0.04)
            out.append(box(f"{name}_{i}", x - w / 2, x + w / 2, y - d / 2, y + d / 2, top, top + t,
                           f"detail_book_{rng.randrange(5)}", collide=False))
            top += t
        return out
    # a table lamp: brass base and stem, a lit shade
    return [cyl(f"{name}_base", x, y, z, z + 0.03, 0.07, "detail_brass", collide=False),
            cyl(f"{name}_stem", x, y, z + 0.03, z + 0.2, 0.01, "detail_brass", collide=False),
            cyl(f"{name}_shade", x, y, z + 0.2, z + 0.34, 0.11, "detail_lampshade", collide=False)]


_HEIGHTS = {"board": 0.02, "books": 0.12, "bowl": 0.06, "cup": 0.095, "lamp": 0.34}
_FOOTPRINT = {"board": (0.2, 0.14), "books": (0.13, 0.16), "bowl": (0.09, 0.09), "cup": (0.05, 0.05),
              "lamp": (0.12, 0.12)}


def clutter(scene: Scene, rng: random.Random, placed: list[Solid]) -> list[Solid]:
    """One to three things on every table, desk, counter and nightstand: books, cups, bowls, a board, a lamp;
    each clear of what already stands there and below flight altitude."""
    out: list[Solid] = []
    ceiling = scene.flight_altitude - CLUTTER_CLEARANCE
    for top in _surfaces(scene):
        x0, y0, zb, x1, y1, z = _volume(top)
        kinds = [k for k, h in _HEIGHTS.items() if z + h <= ceiling]
        for i in range(rng.randint(1, 3) if kinds else 0):
            kind = rng.choice(kinds)
            hx, hy = _FOOTPRINT[kind]
            if x1 - x0 < 2 * hx + 0.1 or y1 - y0 < 2 * hy + 0.1:
                continue
            for _ in range(8):  # a few tries for a free spot
                x, y = rng.uniform(x0 + hx + 0.05, x1 - hx - 0.05), rng.uniform(y0 + hy + 0.05, y1 - hy - 0.05)
                region = (x - hx - 0.02, y - hy - 0.02, z + 0.001, x + hx + 0.02, y + hy + 0.02, z + _HEIGHTS[kind])
                if _free(region, (*scene.solids, *placed, *out), ignore=top.name):
                    out += _item(kind, f"{PREFIX}{kind}_{top.name}_{i}", x, y, z, rng)
                    break
    return out
