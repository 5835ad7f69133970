"""A scenario's events in the simulator (issue 24): their bodies in the MJCF, their triggers, and what they do.

`EventWorld` is built from a scene that carries a `Scenario` (`scene.scenario`). It adds mocap bodies to the
model (people, pets, door leaves, signs), fires each event once when its trigger is due (a step count, the
episode's clock, the drone entering a room), advances movers and swinging doors on the clock, dims lights, and
keeps the TRUE scene: the scene with every closed doorway marked closed (the ground truth's map; the pilot's map
in the prompt is the scene as it was given).
"""

from __future__ import annotations

import io
import math
import textwrap
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from vlnpilot.core.movers import CONTACT_PREFIX, FiredEvent, MoverState
from vlnpilot.core.records import Pose
from vlnpilot.scene.events import EventSpec, Scenario
from vlnpilot.scene.mjcf import WORLD_CONAFFINITY, WORLD_CONTYPE
from vlnpilot.scene.model import Door, Scene
from vlnpilot.sim.movers import Walker, make_walker

HIDDEN_Z = -20.0  # where a body waits before its event fires (below the floor, out of every view)
SIGN_ASPECT = 0.6  # a sign's height / width; 1.0 m wide is legible in the 640x480 front image from about 2 m
SIGN_PX = (640, 384)
DOOR_OPEN_DEG = 90.0  # an open leaf stands square to its wall (as the scenes build it), and swings 90° shut
LEAF_THICKNESS = 0.04
WALL_CLEAR = 0.09  # a sign's face this far off the wall's centre line (walls are ~0.14 m thick)
COLLIDE = f'contype="{WORLD_CONTYPE}" conaffinity="{WORLD_CONAFFINITY}"'
# Clothes, skin and hair colours a person is dressed in (seeded by the scenario's seed).
SHIRTS = ((0.75, 0.15, 0.15), (0.15, 0.35, 0.7), (0.2, 0.55, 0.3), (0.85, 0.6, 0.1), (0.55, 0.25, 0.6))
TROUSERS = ((0.12, 0.14, 0.25), (0.25, 0.22, 0.2), (0.35, 0.35, 0.38), (0.1, 0.1, 0.1))
SKINS = ((0.96, 0.8, 0.69), (0.78, 0.57, 0.44), (0.55, 0.38, 0.26), (0.36, 0.24, 0.16))
FURS = ((0.55, 0.35, 0.18), (0.15, 0.12, 0.1), (0.85, 0.75, 0.55), (0.5, 0.5, 0.5))


def _f(*values: float) -> str:
    return " ".join(f"{v:.4g}" for v in values)


def _rgba(rgb: tuple[float, float, float]) -> str:
    return _f(*rgb, 1.0)


def person_geoms(name: str, shirt: tuple[float, float, float], trousers: tuple[float, float, float],
                 skin: tuple[float, float, float]) -> list[str]:
    """A standing person about 1.75 m tall in its body frame (facing +x, feet on the floor at z = 0)."""
    hair = (0.12, 0.08, 0.05)

    def g(part: str, rest: str, rgb: tuple[float, float, float]) -> str:
        return f'<geom name="{CONTACT_PREFIX}{name}:{part}" {rest} rgba="{_rgba(rgb)}" {COLLIDE}/>'

    return [
        g("leg_l", 'type="capsule" fromto="0 0.09 0.1 0 0.09 0.84" size="0.07"', trousers),
        g("leg_r", 'type="capsule" fromto="0 -0.09 0.1 0 -0.09 0.84" size="0.07"', trousers),
        g("shoe_l", 'type="box" pos="0.05 0.09 0.04" size="0.12 0.05 0.04"', (0.1, 0.1, 0.1)),
        g("shoe_r", 'type="box" pos="0.05 -0.09 0.04" size="0.12 0.05 0.04"', (0.1, 0.1, 0.1)),
        g("hips", 'type="box" pos="0 0 0.9" size="0.11 0.16 0.08"', trousers),
        g("torso", 'type="box" pos="0 0 1.2" size="0.11 0.16 0.24"', shirt),
        g("arm_l", 'type="capsule" fromto="0 0.205 1.4 0.02 0.205 0.88" size="0.045"', shirt),
        g("arm_r", 'type="capsule" fromto="0 -0.205 1.4 0.02 -0.205 0.88" size="0.045"', shirt),
        g("hand_l", 'type="sphere" pos="0.02 0.205 0.84" size="0.045"', skin),
        g("hand_r", 'type="sphere" pos="0.02 -0.205 0.84" size="0.045"', skin),
        g("neck", 'type="capsule" fromto="0 0 1.44 0 0 1.52" size="0.05"', skin),
        g("head", 'type="ellipsoid" pos="0.01 0 1.63" size="0.1 0.09 0.115"', skin),
        g("hair", 'type="ellipsoid" pos="-0.01 0 1.68" size="0.1 0.095 0.075"', hair),
        g("nose", 'type="sphere" pos="0.1 0 1.62" size="0.02"', skin),
    ]


def pet_geoms(name: str, fur: tuple[float, float, float]) -> list[str]:
    """A dog about 0.35 m tall (facing +x)."""

    def g(part: str, rest: str, rgb: tuple[float, float, float] = fur) -> str:
        return f'<geom name="{CONTACT_PREFIX}{name}:{part}" {rest} rgba="{_rgba(rgb)}" {COLLIDE}/>'

    legs = [g(f"leg_{i}", f'type="capsule" fromto="{x} {y} 0.03 {x} {y} 0.17" size="0.025"')
            for i, (x, y) in enumerate(((0.1, 0.06), (0.1, -0.06), (-0.1, 0.06), (-0.1, -0.06)))]
    return [*legs,
            g("body", 'type="capsule" fromto="-0.12 0 0.21 0.11 0 0.22" size="0.075"'),
            g("head", 'type="sphere" pos="0.18 0 0.3" size="0.06"'),
            g("snout", 'type="capsule" fromto="0.2 0 0.28 0.25 0 0.27" size="0.03"', (0.15, 0.1, 0.08)),
            g("ear_l", 'type="box" pos="0.16 0.045 0.35" size="0.015 0.012 0.03"'),
            g("ear_r", 'type="box" pos="0.16 -0.045 0.35" size="0.015 0.012 0.03"'),
            g("tail", 'type="capsule" fromto="-0.18 0 0.25 -0.22 0 0.32" size="0.015"')]


@cache
def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    for path in ("/usr/share/fonts/truetype/dejavu/DejaVuSans-Bold.ttf", "DejaVuSans-Bold.ttf"):
        try:
            return ImageFont.truetype(path, size)
        except OSError:
            continue
    return ImageFont.load_default(size)


@dataclass(frozen=True)
class SignLayout:
    """How a sign's text is laid out on its face texture (SIGN_PX): the font size, the lines and their boxes."""

    size: int
    lines: tuple[str, ...]
    boxes: tuple[tuple[float, float, float, float], ...]

    @property
    def line_px(self) -> float:
        return self.size * 1.2

    @property
    def cap_px(self) -> float:
        """The height of a capital letter on the texture (px): what legibility is judged by."""
        box = _font(self.size).getbbox("H")
        return float(box[3] - box[1])

    @property
    def block_px(self) -> tuple[float, float]:
        """(width, height) of the text block on the texture, centred on it."""
        return max(b[2] - b[0] for b in self.boxes), self.line_px * len(self.lines)


@cache
def sign_layout(text: str) -> SignLayout:
    """The text word-wrapped and as large as fits the face (within its border)."""
    w, h = SIGN_PX
    draw = ImageDraw.Draw(Image.new("RGB", (8, 8)))
    for size in range(72, 14, -4):
        font = _font(size)
        chars = max(6, int((w - 60) / (size * 0.62)))
        lines = textwrap.wrap(text, chars) or [""]
        boxes = [draw.textbbox((0, 0), line, font=font) for line in lines]
        width = max(b[2] - b[0] for b in boxes)
        if width <= w - 60 and size * 1.2 * len(lines) <= h - 50:
            break
    return SignLayout(size, tuple(lines), tuple((float(b[0]), float(b[1]), float(b[2]), float(b[3])) for b in boxes))


def sign_png(text: str, screen: bool) -> bytes:
    """The sign's face: the text, word-wrapped and as large as fits; a dark screen with light text, or a white
    printed sign with black text and a border."""
    w, h = SIGN_PX
    bg, fg = ((15, 20, 30), (235, 245, 255)) if screen else ((248, 246, 238), (15, 15, 15))
    img = Image.new("RGB", (w, h), bg)
    draw = ImageDraw.Draw(img)
    draw.rectangle((6, 6, w - 7, h - 7), outline=(90, 90, 100) if screen else (170, 30, 30), width=10)
    layout = sign_layout(text)
    font = _font(layout.size)
    y = (h - layout.line_px * len(layout.lines)) / 2
    for line, box in zip(layout.lines, layout.boxes, strict=True):
        draw.text(((w - (box[2] - box[0])) / 2, y), line, fill=fg, font=font)
        y += layout.line_px
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def sign_geoms(name: str, material: str, width: float, screen: bool, stand_m: float) -> list[str]:
    """A board with the text on its face (the body's +x side), framed; on a pole `stand_m` high when it stands
    on the floor (0: on a wall)."""
    w, h = width, width * SIGN_ASPECT
    frame = "0.1 0.1 0.12 1" if screen else "0.35 0.25 0.15 1"
    out = [f'<geom name="sign:{name}" type="box" pos="-0.02 0 0" size="{_f(0.015, w / 2 + 0.03, h / 2 + 0.03)}" '
           f'rgba="{frame}" {COLLIDE}/>',
           f'<geom name="sign:{name}:face" type="plane" pos="0 0 0" size="{_f(w / 2, h / 2, 0.5)}" '
           f'xyaxes="0 1 0 0 0 1" material="{material}" contype="0" conaffinity="0"/>']
    if stand_m > 0:
        out.append(f'<geom name="sign:{name}:pole" type="cylinder" '
                   f'fromto="-0.04 0 {-stand_m:.3f} -0.04 0 {-h / 2:.3f}" size="0.02" '
                   f'rgba="0.3 0.3 0.32 1" {COLLIDE}/>')
        out.append(f'<geom name="sign:{name}:foot" type="cylinder" pos="-0.04 0 {-stand_m + 0.01:.3f}" '
                   f'size="0.2 0.01" rgba="0.3 0.3 0.32 1" {COLLIDE}/>')
    return out


def _yaw_quat(yaw_rad: float) -> np.ndarray:
    return np.array([math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)])


@dataclass
class _Leaf:
    door: Door
    hinge: tuple[float, float]
    closed_yaw: float  # radians, the leaf's x axis across the doorway
    open_turn: float  # radians from closed to open (+ or - a quarter turn)
    static_leaf: str | None  # the scene's own open leaf, hidden while this one stands in for it
    angle_deg: float = DOOR_OPEN_DEG  # from closed (0) to open
    swing_dps: float = 0.0  # closing speed once fired

    @property
    def yaw(self) -> float:
        return self.closed_yaw + self.open_turn * self.angle_deg / DOOR_OPEN_DEG


@dataclass(frozen=True)
class SignPlacement:
    x: float
    y: float
    z: float
    yaw_rad: float  # the sign's face looks along this heading (into the room)


def sign_placement(spec: EventSpec, scene: Scene) -> SignPlacement:
    """Where a sign hangs: on the room's named wall (its bounding box side), `along` it, facing into the room;
    or, free-standing, `at` (x, y) facing `facing_deg`."""
    if spec.at is not None:
        return SignPlacement(spec.at[0], spec.at[1], spec.height_m, math.radians(spec.facing_deg))
    xs, ys = zip(*scene.room(str(spec.room)).polygon, strict=True)
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    half = spec.width_m / 2 + 0.05
    a = spec.along
    if spec.wall in ("north", "south"):
        x = min(max(x0 + a * (x1 - x0), x0 + half), x1 - half)
        y = y1 - WALL_CLEAR if spec.wall == "north" else y0 + WALL_CLEAR
        return SignPlacement(x, y, spec.height_m, -math.pi / 2 if spec.wall == "north" else math.pi / 2)
    y = min(max(y0 + a * (y1 - y0), y0 + half), y1 - half)
    x = x1 - WALL_CLEAR if spec.wall == "east" else x0 + WALL_CLEAR
    return SignPlacement(x, y, spec.height_m, math.pi if spec.wall == "east" else 0.0)


# A sign's text counts as legible in the front image when a capital letter spans at least this many pixels of a
# 640x480 frame (the frame the pilots get), whole and unoccluded (issue 24 follow-up: a sign is seen only if legible).
SIGN_LEGIBLE_PX = 12.0
LEGIBILITY_FRAME = (640, 480)
SIGN_VISIBLE_SHARE = 0.98  # of the text block's pixels that must show the sign's face (not a person, furniture, ...)


@dataclass(frozen=True)
class SignView:
    """A sign's text as the front camera shows it: the projected height of a capital letter (px of a 640x480
    frame; the smaller of its height and its width, so a sign seen edge-on is not legible), whether the whole text
    block is in the frame and before the sign's face, and the text block's corners in the frame (u right, v down)."""

    text_px: float
    in_frame: bool
    corners: tuple[tuple[float, float], ...]

    @property
    def legible(self) -> bool:
        return self.in_frame and self.text_px >= SIGN_LEGIBLE_PX


def sign_view(spec: EventSpec, scene: Scene, pose: Pose) -> SignView:
    """How the front camera at `pose` (level, looking along its yaw) shows the sign's text: pure projection, no
    occlusion (`Simulator.sign_text_px` adds it)."""
    from vlnpilot.sim.drone import CAMERA_FORWARD_M, FRONT_FOVY

    where = sign_placement(spec, scene)
    layout = sign_layout(str(spec.text))
    m_per_px = spec.width_m / SIGN_PX[0]  # the face's texture spans its width (and 0.6 of it high)
    cap = layout.cap_px * m_per_px
    half_w, half_h = layout.block_px[0] * m_per_px / 2, layout.block_px[1] * m_per_px / 2
    cy, sy = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    cam = (pose.x + cy * CAMERA_FORWARD_M, pose.y + sy * CAMERA_FORWARD_M, pose.z)
    fw, fh = LEGIBILITY_FRAME
    focal = (fh / 2) / math.tan(math.radians(FRONT_FOVY) / 2)
    ax, ay = -math.sin(where.yaw_rad), math.cos(where.yaw_rad)  # along the face (to its left as one faces it)

    def project(lateral: float, up: float) -> tuple[float, float, float]:
        dx, dy = where.x + ax * lateral - cam[0], where.y + ay * lateral - cam[1]
        dz = where.z + up - cam[2]
        depth = dx * cy + dy * sy
        right = dx * sy - dy * cy
        return fw / 2 + focal * right / max(depth, 1e-6), fh / 2 - focal * dz / max(depth, 1e-6), depth

    facing = (cam[0] - where.x) * math.cos(where.yaw_rad) + (cam[1] - where.y) * math.sin(where.yaw_rad) > 0
    corners = [project(sl * half_w, su * half_h) for sl, su in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    in_frame = facing and all(d > 0.05 and 0 <= u <= fw and 0 <= v <= fh for u, v, d in corners)
    top, bottom = project(0.0, cap / 2), project(0.0, -cap / 2)
    left, right = project(-cap / 2, 0.0), project(cap / 2, 0.0)
    if min(top[2], bottom[2], left[2], right[2]) <= 0.05 or not facing:
        return SignView(0.0, False, tuple((u, v) for u, v, _ in corners))
    size = min(abs(bottom[1] - top[1]), math.hypot(right[0] - left[0], right[1] - left[1]))
    return SignView(size, in_frame, tuple((u, v) for u, v, _ in corners))


class EventWorld:
    """The scenario's events in one simulator: MJCF bodies, triggers, movers, doors, lights and signs."""

    def __init__(self, scene: Scene):
        assert scene.scenario is not None
        self.scene = scene
        self.scenario: Scenario = scene.scenario
        self.specs = {str(e.name): e for e in self.scenario.events}
        self.walkers: dict[str, Walker] = {}
        self.leaves: dict[str, _Leaf] = {}
        self.fired: dict[str, FiredEvent] = {}
        self.closed: set[str] = set()
        self.light_levels: dict[str, float] = {}  # room -> fraction of its light
        self.seconds = 0.0
        self._mocap: dict[str, int] = {}
        self._model: mujoco.MjModel | None = None
        self._data: mujoco.MjData | None = None
        self._base_lights: np.ndarray | None = None
        self._base_headlight: tuple[np.ndarray, np.ndarray] | None = None
        self._light_rooms: list[str | None] = []
        for e in self.scenario.events:
            if e.kind == "door_closes":
                self.leaves[str(e.name)] = self._leaf(scene, scene.door(str(e.door)))
        self.true_scene = scene

    @property
    def has_movers(self) -> bool:
        return bool(self.scenario.movers)

    @staticmethod
    def _leaf(scene: Scene, door: Door) -> _Leaf:
        """The leaf that will close `door`: where the scene's open leaf stands (its hinge side, the room it opens
        into), else hinged on the left and opening into rooms[0]."""
        static = next((s for s in scene.solids if s.name == f"{door.id}_leaf"), None)
        depth, lateral = door.frame_of(static.pos[0], static.pos[1]) if static is not None else (-1.0, 1.0)
        side = 1.0 if lateral >= 0 else -1.0  # the hinge's side, + = left of the normal
        nx, ny = door.normal
        lx, ly = -ny, nx
        hinge = (door.center[0] + side * lx * door.width / 2, door.center[1] + side * ly * door.width / 2)
        closed = math.atan2(-side * ly, -side * lx)  # from the hinge across the opening
        opened = math.atan2(ny, nx) if depth >= 0 else math.atan2(-ny, -nx)
        turn = (opened - closed + math.pi) % (2 * math.pi) - math.pi
        return _Leaf(door, hinge, closed, turn, static.name if static is not None else None)

    # -- the model ------------------------------------------------------------------------------------
    def mjcf(self) -> tuple[str, str, dict[str, bytes]]:
        """(worldbody XML, asset XML, asset files) of the scenario's bodies; each body is a mocap body."""
        rng = np.random.default_rng([self.scenario.seed, 24])
        bodies, assets_xml, files = [], [], {}
        for e in self.scenario.events:
            name = str(e.name)
            if e.kind == "person":
                geoms = person_geoms(name, SHIRTS[rng.integers(len(SHIRTS))], TROUSERS[rng.integers(len(TROUSERS))],
                                     SKINS[rng.integers(len(SKINS))])
            elif e.kind == "pet":
                geoms = pet_geoms(name, FURS[rng.integers(len(FURS))])
            elif e.kind == "door_closes":
                d = self.leaves[name].door
                w, h = d.width - 0.03, min(d.height, 2.0) - 0.02
                geoms = [f'<geom name="door_leaf:{d.id}" type="box" pos="{_f(w / 2 + 0.01, 0, h / 2 + 0.01)}" '
                         f'size="{_f(w / 2, LEAF_THICKNESS / 2, h / 2)}" rgba="0.55 0.36 0.2 1" {COLLIDE}/>',
                         f'<geom name="door_leaf:{d.id}:handle" type="sphere" '
                         f'pos="{_f(w - 0.06, 0.04, 1.0)}" size="0.03" rgba="0.8 0.75 0.5 1" contype="0" '
                         'conaffinity="0"/>']
            elif e.kind == "sign":
                tex = f"sign_{name}"
                files[f"{tex}.png"] = sign_png(str(e.text), e.screen)
                assets_xml.append(f'<texture name="{tex}" type="2d" file="{tex}.png"/>')
                assets_xml.append(f'<material name="{tex}" texture="{tex}" texrepeat="1 1" '
                                  f'emission="{0.6 if e.screen else 0.15}" specular="0.1"/>')
                geoms = sign_geoms(name, tex, e.width_m, e.screen, e.height_m if e.at is not None else 0.0)
            else:
                continue
            bodies.append(f'<body name={quoteattr("event:" + name)} mocap="true" pos="0 0 {HIDDEN_Z}">'
                          + "".join(geoms) + "</body>")
        return "\n    ".join(bodies), "\n    ".join(assets_xml), files

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Find the bodies and lights in the compiled model."""
        self._model, self._data = model, data
        for name in self.specs:
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"event:{name}")
            if body >= 0:
                self._mocap[name] = int(model.body_mocapid[body])
        for leaf in self.leaves.values():  # the scene's own open leaf gives way to the one that will swing
            if leaf.static_leaf is not None:
                g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, leaf.static_leaf)
                model.geom_rgba[g, 3] = 0.0
                model.geom_contype[g] = model.geom_conaffinity[g] = 0
        self._base_lights = model.light_diffuse.copy()
        self._base_headlight = (model.vis.headlight.ambient.copy(), model.vis.headlight.diffuse.copy())
        directional = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
        self._light_rooms = [None if model.light_type[i] == directional
                             else self.scene.room_at(float(p[0]), float(p[1])) for i, p in enumerate(model.light_pos)]

    # -- the episode ----------------------------------------------------------------------------------
    def reset(self, seed: int | None) -> None:
        rng = np.random.default_rng([self.scenario.seed, 0 if seed is None else seed, 24])
        self.walkers = {str(e.name): make_walker(e, self.scene, float(rng.uniform(0.9, 1.1)))
                        for e in self.scenario.movers}
        for leaf in self.leaves.values():
            leaf.angle_deg, leaf.swing_dps = DOOR_OPEN_DEG, 0.0
        self.fired, self.closed, self.light_levels, self.seconds = {}, set(), {}, 0.0
        self.true_scene = self.scene
        self.place()

    def due(self, step: int, room: str | None) -> tuple[FiredEvent, ...]:
        """Fire every event whose trigger is due (each once): after `step` commands, at the clock's time, with
        the drone in `room`."""
        out = []
        for name, e in self.specs.items():
            t = e.trigger
            if name in self.fired or not ((t.step is not None and step >= t.step)
                                          or (t.time_s is not None and self.seconds + 1e-6 >= t.time_s)
                                          or (t.enter is not None and room == t.enter)):
                continue
            self._fire(e)
            self.fired[name] = FiredEvent(name, e.kind, step, self.seconds, t.describe(), e.params())
            out.append(self.fired[name])
        if out:
            self.place()
        return tuple(out)

    def _fire(self, e: EventSpec) -> None:
        name = str(e.name)
        if e.is_mover:
            self.walkers[name].started = True
        elif e.kind == "door_closes":
            leaf = self.leaves[name]
            leaf.swing_dps = DOOR_OPEN_DEG / e.swing_s
            self.closed.add(leaf.door.id)
            self.true_scene = replace(self.scene, doors=tuple(replace(d, open=False) if d.id in self.closed else d
                                                              for d in self.scene.doors))
        elif e.kind == "lights_out":
            self.light_levels[str(e.room)] = e.light_level()[0]

    def advance(self, dt: float, drone: tuple[float, float, float],
                blocked: Callable[[str], bool] | None = None) -> None:
        """Move the movers and the swinging doors by `dt` seconds of the clock (the drone at `drone`, x y z).
        `blocked(name)` says whether a door leaf now touches the drone: then it stops short, as a door does."""
        self.seconds += dt
        for w in self.walkers.values():
            w.advance(dt, drone[:2], drone[2])
        for name, leaf in self.leaves.items():
            if leaf.swing_dps and leaf.angle_deg > 0:
                before = leaf.angle_deg
                leaf.angle_deg = max(0.0, leaf.angle_deg - leaf.swing_dps * dt)
                self._place_leaf(name, leaf)
                if blocked is not None and blocked(name):
                    leaf.angle_deg = before
        self.place()

    def movers(self) -> tuple[MoverState, ...]:
        """The movers in the scene now: those whose event has fired (each enters at the start of its path)."""
        return tuple(w.state() for w in self.walkers.values() if w.present)

    @property
    def max_speed(self) -> float:
        return max((w.speed for w in self.walkers.values()), default=0.0)

    def near(self, x: float, y: float, reach: float, seconds: float) -> bool:
        """Whether a mover or a swinging leaf could come within `reach` of (x, y) in the next `seconds`."""
        for w in self.walkers.values():
            if w.present and math.hypot(w.x - x, w.y - y) - w.radius <= reach + w.speed * seconds + 0.05:
                return True
        return any(leaf.swing_dps and leaf.angle_deg > 0
                   and math.hypot(leaf.hinge[0] - x, leaf.hinge[1] - y) <= reach + leaf.door.width + 0.05
                   for leaf in self.leaves.values())

    @property
    def animating(self) -> bool:
        """Whether anything moves on the clock now (a walker on its way, a door swinging)."""
        return any(w.started and not w.done for w in self.walkers.values()) or any(
            leaf.swing_dps and leaf.angle_deg > 0 for leaf in self.leaves.values())

    # -- the bodies in the model ------------------------------------------------------------------------
    def place(self) -> None:
        """Put every event body where it is now (signs stay hidden until they fire)."""
        d = self._data
        if d is None:
            return
        for name, w in self.walkers.items():
            i = self._mocap[name]
            d.mocap_pos[i] = (w.x, w.y, 0.0 if w.present else HIDDEN_Z)
            d.mocap_quat[i] = _yaw_quat(w.heading)
        for name, leaf in self.leaves.items():
            self._place_leaf(name, leaf)
        for name, e in self.specs.items():
            if e.kind == "sign":
                i = self._mocap[name]
                if name in self.fired:
                    p = sign_placement(e, self.scene)
                    d.mocap_pos[i] = (p.x, p.y, p.z)
                    d.mocap_quat[i] = _yaw_quat(p.yaw_rad)
                else:
                    d.mocap_pos[i] = (0.0, 0.0, HIDDEN_Z)

    def _place_leaf(self, name: str, leaf: _Leaf) -> None:
        d = self._data
        if d is None:
            return
        i = self._mocap[name]
        d.mocap_pos[i] = (*leaf.hinge, 0.0)
        d.mocap_quat[i] = _yaw_quat(leaf.yaw)

    def light(self, drone_room: str | None) -> None:
        """Dim the lights: a darkened room's own lights, and every light and the headlight while the camera is in
        it (the renderer casts no shadows, so the lights next door would otherwise light it)."""
        m = self._model
        if m is None or self._base_lights is None or self._base_headlight is None:
            return
        here = self.light_levels.get(drone_room or "", 1.0)
        for i, room in enumerate(self._light_rooms):
            m.light_diffuse[i] = self._base_lights[i] * min(here, self.light_levels.get(room or "", 1.0))
        ambient, diffuse = self._base_headlight
        m.vis.headlight.ambient[:] = ambient * here
        m.vis.headlight.diffuse[:] = diffuse * here

    def contact_name(self, geom_name: str) -> str:
        """A mover's geom as the contact the observation names (`mover:person-1`); other geoms as they are."""
        if geom_name.startswith(CONTACT_PREFIX):
            return geom_name.split(":")[0] + ":" + geom_name.split(":")[1]
        return geom_name
