"""The embedded MuJoCo simulator: a kinematic Tello in a furnished scene, rendered headless.

The drone is moved kinematically, as the paper's commands are discrete displacements: each motion is
executed in small sub-steps with a collision check against all scene geometry; at the first contact the
drone stops at the last free pose (refined by bisection), so it never penetrates anything.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from vlnpilot.sim import gl

gl.choose_backend()  # before MuJoCo's first import fixes its GL backend (only if unset, only without a display)
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from vlnpilot.core.cameras import check_camera, check_camera_lag  # noqa: E402
from vlnpilot.core.commands import Command, get_command  # noqa: E402
from vlnpilot.core.environment import Capabilities, GroundTruth  # noqa: E402
from vlnpilot.core.errors import ConfigError, UnknownNameError  # noqa: E402
from vlnpilot.core.movers import FiredEvent, MoverState  # noqa: E402
from vlnpilot.core.ranging import RangeReading, range_sensor  # noqa: E402
from vlnpilot.core.records import Footprint, Motion, Observation, Pose, wrap_deg  # noqa: E402
from vlnpilot.core.tello_spec import motion_duration_s  # noqa: E402
from vlnpilot.scene import Scene, Spawn, load_scene  # noqa: E402
from vlnpilot.scene.detail import DEFAULT_DETAIL, DETAIL_GROUP, check_detail  # noqa: E402
from vlnpilot.scene.mjcf import scene_to_mjcf  # noqa: E402
from vlnpilot.sim import drone, gl_fork  # noqa: E402
from vlnpilot.sim.camera_model import (  # noqa: E402
    STILL,
    GLPixels,
    TelloCamera,
    frame_motion,
    lagged_fraction,
    make_camera,
)
from vlnpilot.sim.events import (  # noqa: E402
    LEGIBILITY_FRAME,
    SIGN_LEGIBLE_PX,
    SIGN_VISIBLE_SHARE,
    EventWorld,
    sign_view,
)
from vlnpilot.sim.gl_readback import read_rgba  # noqa: E402
from vlnpilot.sim.mirrors import mirror_geoms, reflect_in_view  # noqa: E402
from vlnpilot.sim.ranging import read_ranges  # noqa: E402

MAX_RESOLUTION = (960, 720)
MOVER_TICK_M = 0.05  # a scenario's movers move at most this far between two contact checks
JITTER_DRAWS = 8  # spawn jitter draws tried before the unjittered spawn (a draw may touch a wall or a door)


@dataclass(frozen=True)
class SimConfig:
    """Simulator settings. Sub-step sizes bound how far a motion can go between two collision checks."""

    width: int = 640
    height: int = 480
    rear_width: int = 640
    rear_height: int = 480
    render: bool = True  # False: observations carry 1x1 black images (fast, for image-free pilots)
    rear_camera: bool = True  # False: no chase render, `rear_rgb` is a 1x1 placeholder (nothing records the rear)
    substep_m: float = 0.02
    substep_deg: float = 4.0
    bisect_iterations: int = 6
    spawn_jitter_m: float = 0.0  # seeded random offset of the spawn position (per repetition variety; `_jittered`)
    spawn_jitter_deg: float = 0.0
    shadows: bool = False  # MuJoCo's shadow map costs ~10x a frame on a CPU
    visibility_width: int = 160  # segmentation render used by the ground truth
    visibility_height: int = 120
    sensors: str = "none"  # range sensors the drone carries (vlnpilot.core.ranging.SENSORS): none | tof | multiranger
    range_noise: bool = True  # the sensor's modelled noise on each reading (off: exact ray-cast distances)
    camera: str = "ideal"  # what the front camera delivers (core.cameras.CAMERAS): ideal | tello
    camera_lag_ms: float | None = None  # the tello camera's frame lag (None: its default, docs/camera.md)
    randomize: int | None = None  # domain randomisation seed (sim/randomize.py); None: the scene as built
    detail: str = DEFAULT_DETAIL  # scene detail the RGB cameras see (scene/detail.py): plain | rich

    def __post_init__(self) -> None:
        range_sensor(self.sensors)  # a bad name is refused here, in one line
        check_detail(self.detail)
        object.__setattr__(self, "camera", check_camera(self.camera))
        check_camera_lag(self.camera, self.camera_lag_ms)
        if self.randomize is not None and (isinstance(self.randomize, bool) or not isinstance(self.randomize, int)
                                           or not 0 <= self.randomize < 2**31):
            raise ConfigError(f"randomize must be a seed in 0..{2**31 - 1}, got {self.randomize!r}")
        max_w, max_h = MAX_RESOLUTION
        for w, h, what in ((self.width, self.height, "front"), (self.rear_width, self.rear_height, "rear")):
            if not (16 <= w <= max_w and 16 <= h <= max_h):
                raise ConfigError(f"{what} camera resolution {w}x{h} is outside 16x16..{max_w}x{max_h}")
        if self.substep_m <= 0 or self.substep_deg <= 0:
            raise ConfigError("substep sizes must be positive")


def no_image() -> np.ndarray:
    """The placeholder of a camera not rendered: 1x1 black (recordings skip it)."""
    return np.zeros((1, 1, 3), np.uint8)


def yaw_quat(yaw_deg: float) -> np.ndarray:
    half = math.radians(yaw_deg) / 2
    return np.array([math.cos(half), 0.0, 0.0, math.sin(half)])


def _geom_outline(m: mujoco.MjModel, d: mujoco.MjData, geom: int) -> tuple[tuple[float, float], ...]:
    """The floor outline (convex hull of the x, y of its 8 corners) of a geom's bounding box, in world frame."""
    centre, half = m.geom_aabb[geom, :3], m.geom_aabb[geom, 3:]
    signs = np.array([(i, j, k) for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    corners = d.geom_xpos[geom] + (centre + signs * half) @ d.geom_xmat[geom].reshape(3, 3).T
    return convex_hull([(float(x), float(y)) for x, y, _ in corners])


def convex_hull(points: list[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
    """Andrew's monotone chain: the hull's corners counter-clockwise, without collinear ones."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return tuple(pts)

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 1e-12:
                out.pop()
            out.append(p)
        return out

    return tuple(half(pts)[:-1] + half(pts[::-1])[:-1])


class Simulator:
    """Implements the Environment contract (`reset(spawn, seed)`, `step(command)`, `scene`, `capabilities`),
    with ground truth (`ground_truth()`) and a front depth camera (`front_depth`, `front_fovy_deg`, `substeps`)."""

    capabilities = Capabilities(ground_truth=True, depth=True, rear_view=True, contact_sensing=True)  # all of them
    front_fovy_deg = drone.FRONT_FOVY  # of the front camera, for the depth shield (`DepthSensing`)

    def __init__(self, scene: str | Scene = "cabin", config: SimConfig | None = None):
        self.scene: Scene = load_scene(scene)
        self.config = config or SimConfig()
        # a scenario's events (issue 24): their bodies join the model, and the world keeps their state
        self.events = EventWorld(self.scene) if self.scene.scenario is not None else None
        extra_bodies, extra_assets, asset_files = self.events.mjcf() if self.events else ("", "", {})
        xml, assets = scene_to_mjcf(self.scene, bodies=drone.drone_body_xml() + extra_bodies,
                                    assets_xml=drone.drone_assets_xml() + extra_assets,
                                    max_render=MAX_RESOLUTION, shadows=self.config.shadows, detail=self.config.detail,
                                    asset_files=asset_files)
        self._rgb_option = mujoco.MjvOption()  # the RGB cameras alone show the detail group
        self._rgb_option.geomgroup[DETAIL_GROUP] = 1
        self.range_sensor = range_sensor(self.config.sensors)
        if self.range_sensor is not None:  # this drone carries range sensors: it says so
            self.capabilities = replace(Simulator.capabilities, range_sensor=self.range_sensor.name)
        self.model = mujoco.MjModel.from_xml_string(xml, assets)
        self.data = mujoco.MjData(self.model)
        self._mirrors = mirror_geoms(self.model)  # a frame reflects the nearest in view, if any (sim/mirrors.py)
        if self.events is not None:
            self.events.bind(self.model, self.data)
            if self.events.has_movers:
                self.capabilities = replace(self.capabilities, movers=True)
        m = self.model
        self._qpos_adr = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, drone.JOINT)]
        body_id = self._body_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, drone.BODY)
        self._rear_cam = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, drone.REAR_CAMERA)
        self._rear_cam_pos = m.cam_pos[self._rear_cam].copy()
        self._ray_geom = np.zeros(1, np.int32)
        self.drone_geoms = frozenset(int(g) for g in np.flatnonzero(m.geom_bodyid == body_id))
        self._geom_names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}" for g in range(m.ngeom)]
        self.target_geoms = {
            t.id: frozenset(g for g, n in enumerate(self._geom_names) if n in self._target_solid_names(t.id))
            for t in self.scene.targets
        }
        self._world_aabb: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # for clearance_at
        self._moving_geoms = np.zeros(0, dtype=int)
        self._footprints: dict[str, Footprint] = {}
        self._drone_colliders: list[int] = []
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._seg_renderer: mujoco.Renderer | None = None
        self._pose = Pose(0.0, 0.0, self.scene.flight_altitude, 0.0)
        self._step = 0
        self._seconds = 0.0
        self._rng = np.random.default_rng(0)
        self._range_rng = np.random.default_rng([0, 23])
        self.seed: int | None = None
        self.spawn: Spawn | None = None
        self.camera = make_camera(self.config.camera, self.config.camera_lag_ms)
        self._last_move: tuple[Pose, Motion, float] | None = None  # start, motion, fraction flown: the frame's lag
        self._randomizer = None
        self.randomization = None  # this world's draw (sim.randomize.Randomization), recorded with the run
        if self.config.randomize is not None:
            from vlnpilot.sim.randomize import Randomizer

            drone_mats = frozenset(i for i in range(m.nmat) if m.material(i).name.startswith("drone_"))
            front = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, drone.FRONT_CAMERA)
            self._randomizer = Randomizer(m, front, drone_mats)
            self.randomization = self._randomizer.apply(self.config.randomize)

    def _target_solid_names(self, target_id: str) -> set[str]:
        return {s.name for s in self.scene.solids if s.target == target_id}

    # -- pose and collision ------------------------------------------------------------------------
    @property
    def pose(self) -> Pose:
        return self._pose

    @property
    def step_count(self) -> int:
        return self._step

    def geom_name(self, geom_id: int) -> str:
        return self._geom_names[geom_id]

    def _set_qpos(self, pose: Pose) -> None:
        a = self._qpos_adr
        self.data.qpos[a : a + 3] = (pose.x, pose.y, pose.z)
        self.data.qpos[a + 3 : a + 7] = yaw_quat(pose.yaw_deg)

    def contact_at(self, pose: Pose) -> tuple[str, str] | None:
        """(world geom, drone part) of the deepest contact if the drone at `pose` touches the scene, else None."""
        self._set_qpos(pose)
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_collision(self.model, self.data)
        best: tuple[float, int, int] | None = None
        for c in self.data.contact[: self.data.ncon]:
            g1, g2 = int(c.geom1), int(c.geom2)
            if (g1 in self.drone_geoms) == (g2 in self.drone_geoms) or c.dist >= 0:
                continue
            world, part = (g2, g1) if g1 in self.drone_geoms else (g1, g2)
            if best is None or c.dist < best[0]:
                best = (float(c.dist), world, part)
        if best is None:
            return None
        return self._contact_name(best[1]), self._geom_names[best[2]]

    def _contact_name(self, geom: int) -> str:
        """A scene geom as a contact names it: a mover's parts as the mover (`mover:person-1`)."""
        name = self._geom_names[geom]
        return self.events.contact_name(name) if self.events is not None else name

    def clearance_at(self, pose: Pose, max_distance: float) -> tuple[float, str, str] | None:
        """(signed distance, world geom, drone part) of the nearest scene geom closer than `max_distance` to the
        drone at `pose` (negative: penetrating), else None. Exact per geom pair (`mj_geomDistance`), for the
        safety shield's margin; leaves the model's kinematic state at `pose`."""
        if self._world_aabb is None:
            self._world_aabb = self._static_world_aabbs()
        ids, lo, hi = self._world_aabb
        p = np.array([pose.x, pose.y, pose.z])
        r = math.hypot(drone.LENGTH / 2, drone.WIDTH / 2) + max_distance
        ext = np.array([r, r, drone.HEIGHT / 2 + max_distance])
        cand = ids[np.all((lo <= p + ext) & (hi >= p - ext), axis=1)]
        self._set_qpos(pose)
        if self._moving_geoms.size:  # a scenario's bodies: where they are now (their bounding spheres)
            mujoco.mj_kinematics(self.model, self.data)
            near = np.linalg.norm(self.data.geom_xpos[self._moving_geoms] - p, axis=1)
            cand = np.concatenate([cand, self._moving_geoms[near - self.model.geom_rbound[self._moving_geoms]
                                                            <= float(np.max(ext))]])
        if cand.size == 0:
            return None
        mujoco.mj_kinematics(self.model, self.data)
        best: tuple[float, int, int] | None = None
        for g in cand.tolist():
            for part in self._drone_colliders:
                d = mujoco.mj_geomDistance(self.model, self.data, part, g, max_distance, None)
                if d < max_distance and (best is None or d < best[0]):
                    best = (float(d), g, part)
        if best is None:
            return None
        return best[0], self._contact_name(best[1]), self._geom_names[best[2]]

    def _static_world_aabbs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World-frame boxes around every static scene geom the drone can collide with (a scenario's moving
        bodies, mocap, are kept apart in `_moving_geoms` and looked up where they are at each query)."""
        m = self.model
        mujoco.mj_kinematics(m, self.data)
        self._drone_colliders = [g for g in sorted(self.drone_geoms) if m.geom_contype[g] or m.geom_conaffinity[g]]
        dt, da = drone.DRONE_CONTYPE, drone.DRONE_CONAFFINITY
        solid = [g for g in range(m.ngeom) if g not in self.drone_geoms
                 and ((m.geom_contype[g] & da) or (m.geom_conaffinity[g] & dt))]
        moving = [g for g in solid if m.body_mocapid[m.geom_bodyid[g]] >= 0]
        self._moving_geoms = np.array(moving, dtype=int)
        ids = np.array([g for g in solid if g not in set(moving)], dtype=int)
        xmat = self.data.geom_xmat[ids].reshape(-1, 3, 3)
        centre = self.data.geom_xpos[ids] + np.einsum("nij,nj->ni", xmat, m.geom_aabb[ids, :3])
        half = np.einsum("nij,nj->ni", np.abs(xmat), m.geom_aabb[ids, 3:])
        return ids, centre - half, centre + half

    def substeps(self, motion: Motion) -> int:
        """How many collision-checked sub-steps `sweep` splits `motion` into (the poses at i/n, i = 1..n)."""
        cfg = self.config
        trans = math.hypot(motion.forward_m, motion.lateral_m) + abs(motion.vertical_m)
        return max(1, math.ceil(trans / cfg.substep_m), math.ceil(abs(motion.yaw_deg) / cfg.substep_deg))

    def sweep(self, start: Pose, motion: Motion) -> tuple[Pose, tuple[str, str] | None]:
        """Execute `motion` from `start` in sub-steps; stop at the last free pose before the first contact.
        With a scenario, its movers and doors move on the clock at the same time (`_event_ticks`)."""
        flown, hit = self._sweep(start, motion)
        return motion.apply(start, flown), hit

    def _sweep(self, start: Pose, motion: Motion) -> tuple[float, tuple[str, str] | None]:
        """`sweep` as the fraction of `motion` flown before the first contact (1.0: all of it)."""
        cfg = self.config
        own = self.substeps(motion)
        n = self._event_ticks(motion) if self.events is not None else own
        duration = motion_duration_s(motion.forward_m, motion.lateral_m, motion.vertical_m, motion.yaw_deg)
        free = 0.0
        for i in range(1, n + 1):
            frac = i / n
            pose = motion.apply(start, frac)
            if self.events is not None:
                self._advance_events(duration / n, motion.apply(start, (i - 1) / n))
                if i % (n // own) and not self.events.near(pose.x, pose.y, drone.BOUNDING_RADIUS + 0.05, 0.0):
                    free = frac  # a tick between the drone's own sub-steps: only something moving could touch it
                    continue
            hit = self.contact_at(pose)
            if hit is None:
                free = frac
                continue
            lo, hi = free, frac  # lo is free, hi collides: bisect for the last free pose
            for _ in range(cfg.bisect_iterations):
                mid = (lo + hi) / 2
                mid_hit = self.contact_at(motion.apply(start, mid))
                if mid_hit is None:
                    lo = mid
                else:
                    hi, hit = mid, mid_hit
            return lo, hit
        return 1.0, None

    def _event_ticks(self, motion: Motion) -> int:
        """Sub-steps of a motion with a scenario: the drone's own, and enough that no mover moves more than
        MOVER_TICK_M between two contact checks (a superset of `substeps`' poses when movers move)."""
        n = self.substeps(motion)
        ev = self.events
        if ev is None or not ev.animating:
            return n
        duration = motion_duration_s(motion.forward_m, motion.lateral_m, motion.vertical_m, motion.yaw_deg)
        reach = math.hypot(motion.forward_m, motion.lateral_m) + drone.BOUNDING_RADIUS
        if not ev.near(self._pose.x, self._pose.y, reach, duration):  # nothing that moves can meet the drone
            return n
        return n * max(1, math.ceil(duration * max(ev.max_speed, 1.0) / (MOVER_TICK_M * n)))

    def _advance_events(self, dt: float, drone_pose: Pose) -> None:
        """The scenario's clock moves on by `dt` with the drone at `drone_pose`; a closing door leaf that would
        touch the drone stops short of it."""
        ev = self.events
        assert ev is not None

        def leaf_blocked(name: str) -> bool:
            hit = self.contact_at(drone_pose)
            return hit is not None and hit[0].startswith("door_leaf:")

        ev.advance(dt, (drone_pose.x, drone_pose.y, drone_pose.z), leaf_blocked)

    # -- the scenario's world (issue 24) ----------------------------------------------------------------
    @property
    def seconds(self) -> float:
        """Seconds on the episode's clock: the executed commands' durations (`core.tello_spec`)."""
        return self._seconds if self.events is None else self.events.seconds

    def movers(self) -> tuple[MoverState, ...]:
        """The people and pets now (ground truth, `MoverSensing`); () without a scenario."""
        return self.events.movers() if self.events is not None else ()

    @property
    def true_scene(self) -> Scene:
        """The scene as it is now: every doorway a scenario closed is closed (the ground truth's map)."""
        return self.events.true_scene if self.events is not None else self.scene

    # -- Environment contract --------------------------------------------------------------------------
    def reset(self, spawn: str | Spawn | Pose | None = None, seed: int | None = None) -> Observation:
        """Place the drone at a spawn (name, Spawn or Pose) at flight altitude; `seed` drives spawn jitter."""
        if spawn is None:
            spawn = self.scene.spawns[0]
        if isinstance(spawn, str):
            spawn = self.scene.spawn(spawn)
        pose = spawn.pose if isinstance(spawn, Spawn) else spawn
        self.spawn = spawn if isinstance(spawn, Spawn) else None
        self.seed = seed
        self._rng = np.random.default_rng(seed)
        self._range_rng = np.random.default_rng([0 if seed is None else seed, 23])  # apart: spawns stay as seeded
        if self.events is not None:
            self.events.reset(seed)  # before the jitter: a jittered pose is checked against the scenario's bodies
        pose = self._jittered(pose)
        fired: tuple[FiredEvent, ...] = ()
        if self.events is not None:
            fired = self.events.due(0, self.scene.room_at(pose.x, pose.y))
        hit = self.contact_at(pose)
        if hit is not None:
            raise ConfigError(f"spawn pose {pose.as_dict()} touches {hit[0]}")
        self._pose, self._step, self._last_move, self._seconds = pose, 0, None, 0.0
        if self._randomizer is not None and self.config.randomize is not None:
            self.randomization = self._randomizer.apply(self.config.randomize)  # from the base values: repeatable
        exposure = self.randomization.exposure_gain if self.randomization is not None else 1.0
        self.camera.reset(seed, exposure, world=self.config.randomize)
        return self._observe(collided=False, contact=None, fired=fired)

    def _jittered(self, pose: Pose) -> Pose:
        """`pose` moved by the seeded spawn jitter: the first free draw of up to JITTER_DRAWS (so a seed whose first
        draw was free keeps its pose), else `pose` itself. The yaw stays in (-180, 180]."""
        cfg = self.config
        if not (cfg.spawn_jitter_m or cfg.spawn_jitter_deg):
            return pose
        for _ in range(JITTER_DRAWS):
            dx, dy = self._rng.uniform(-cfg.spawn_jitter_m, cfg.spawn_jitter_m, 2)
            dyaw = self._rng.uniform(-cfg.spawn_jitter_deg, cfg.spawn_jitter_deg)
            moved = replace(pose, x=pose.x + dx, y=pose.y + dy, yaw_deg=wrap_deg(pose.yaw_deg + dyaw))
            if self.contact_at(moved) is None:
                return moved
        return pose

    def step(self, command: Command | str) -> Observation:
        """Execute one command of the table (A1...E) and observe."""
        cmd = command if isinstance(command, Command) else get_command(command)
        return self.move(cmd.motion())

    def move(self, motion: Motion) -> Observation:
        """Execute an arbitrary body-frame motion with the collision sweep (the real Tello's `go`)."""
        if not isinstance(motion, Motion):
            raise ConfigError(f"expected a Motion, got {type(motion).__name__}")
        for v in (motion.forward_m, motion.lateral_m, motion.vertical_m, motion.yaw_deg):
            if not math.isfinite(v):
                raise ConfigError(f"refusing a non-finite motion: {motion}")
        flown, hit = self._sweep(self._pose, motion)
        self._last_move = (self._pose, motion, flown)
        self._pose = motion.apply(self._pose, flown)
        self._step += 1
        self._seconds += motion_duration_s(motion.forward_m, motion.lateral_m, motion.vertical_m, motion.yaw_deg)
        pose = self._pose
        fired = self.events.due(self._step, self.scene.room_at(pose.x, pose.y)) if self.events is not None else ()
        return self._observe(collided=hit is not None, contact=hit, fired=fired)

    def place(self, pose: Pose) -> Observation:
        """Put the drone at `pose` without a collision sweep (a viewer that follows another simulator: the Tello
        emulator's video) and observe; the camera sees the move from the last pose (its streak) and goes on adapting
        its exposure."""
        start = self._pose
        if pose != start:
            c, s = start.heading()
            dx, dy = pose.x - start.x, pose.y - start.y
            motion = Motion(forward_m=dx * c + dy * s, lateral_m=-dx * s + dy * c, vertical_m=pose.z - start.z,
                            yaw_deg=wrap_deg(pose.yaw_deg - start.yaw_deg))
            self._last_move = (start, motion, 1.0)
        else:
            self._last_move = None
        self._pose = pose
        return self._observe(collided=False, contact=None)

    def _sync(self, chase: bool = True) -> None:
        """Put the model at the drone's pose (collision queries may have moved it) and, with `chase`, place the chase
        camera (only its own render needs it)."""
        self._set_qpos(self._pose)
        if self.events is not None:  # the lights of the room the camera is in (lights_out)
            self.events.light(self.scene.room_at(self._pose.x, self._pose.y))
        mujoco.mj_forward(self.model, self.data)
        if chase:
            self._place_chase_camera()

    def _place_chase_camera(self) -> None:
        """Pull the rear camera in front of any wall behind the drone, so the chase view never shows a wall's inside."""
        m, d = self.model, self.data
        m.cam_pos[self._rear_cam] = self._rear_cam_pos
        start = d.xpos[self._body_id]
        offset = d.xmat[self._body_id].reshape(3, 3) @ self._rear_cam_pos
        length = float(np.linalg.norm(offset))
        hit = mujoco.mj_ray(m, d, start, offset / length, None, 1, self._body_id, self._ray_geom)
        if 0 <= hit < length + 0.05:
            m.cam_pos[self._rear_cam] = self._rear_cam_pos * max(hit - 0.08, 0.05) / length
        mujoco.mj_camlight(m, d)

    def _observe(self, collided: bool, contact: tuple[str, str] | None,
                 fired: tuple[FiredEvent, ...] = ()) -> Observation:
        rear_camera = self.config.rear_camera
        self._sync(chase=rear_camera)  # once for both renders
        rear = self._draw(drone.REAR_CAMERA) if rear_camera else no_image()
        front = self._front_frame()
        return Observation(front_rgb=front, rear_rgb=rear, pose=self._pose, collided=collided,
                           contact=contact[0] if contact else None, step=self._step,
                           contact_part=contact[1] if contact else None, events=fired, movers=self.movers())

    # -- rendering ------------------------------------------------------------------------------------------
    def camera_settings(self) -> dict[str, object]:
        """What the front camera delivers, as recorded with a run (`config.camera`; docs/camera.md)."""
        out: dict[str, object] = {"model": self.camera.name}
        if isinstance(self.camera, TelloCamera):
            out["lag_ms"] = self.camera.params.lag_ms
        if self.randomization is not None:
            out["randomize"] = self.randomization.to_dict()
        return out

    def _place_cameras(self, pose: Pose) -> None:
        """The drone's body and cameras at `pose`, for a render only (kinematics, no collision pass)."""
        self._set_qpos(pose)
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)

    def _front_frame(self) -> np.ndarray:
        """The front camera's frame as its camera model delivers it: a Tello's frame is rendered at the pose
        `lag_ms` before the last move ended, streaked by the move if it was still under way."""
        if not self.config.render:
            return no_image()
        motion = STILL
        if isinstance(self.camera, TelloCamera) and self._last_move is not None:
            start, move, flown = self._last_move
            at = lagged_fraction(move, flown, self.camera.params)
            if at is not None and at < flown:  # still under way when the frame was exposed: streaked
                motion = frame_motion(move, self.camera.params, self.camera.focal_px)
            lagged = move.apply(start, at or 0.0)
            if lagged != self._pose:
                self._place_cameras(lagged)
                try:
                    return self.camera.frame(self._front_render(), motion)
                finally:
                    self._place_cameras(self._pose)  # back where the drone is (no collision pass: nothing moved)
        return self.camera.frame(self._front_render(), motion)

    def _renderer(self, width: int, height: int) -> mujoco.Renderer:
        key = (width, height)
        if key not in self._renderers:
            self._renderers[key] = self._new_renderer(width, height)
        return self._renderers[key]

    def _new_renderer(self, width: int, height: int) -> mujoco.Renderer:
        gl_fork.opening_renderer()  # refused, in one line, in a child forked with live GL state (it would hang)
        try:
            return mujoco.Renderer(self.model, height, width)
        except Exception as exc:  # the GL stack raises many kinds; report one clear error
            raise gl.backend_error(exc) from exc

    def render(self, camera: str = drone.FRONT_CAMERA, width: int | None = None, height: int | None = None,
               depth: bool = False) -> np.ndarray:
        """RGB (HxWx3 uint8) or depth (HxW float32, metres) image from a named camera at the current pose."""
        if not self.config.render and not depth:
            return no_image()
        self._sync(chase=camera == drone.REAR_CAMERA)
        return self._draw(camera, width, height, depth)

    def _draw(self, camera: str, width: int | None = None, height: int | None = None, depth: bool = False
              ) -> np.ndarray:
        """`render` on a model already at the drone's pose (`_sync`)."""
        if not self.config.render and not depth:
            return no_image()
        r = self._renderer(*self._size(camera, width, height))
        if depth:
            r.enable_depth_rendering()
        try:
            self._update_view(r, camera, depth)
            return r.render()  # a new array each call
        finally:
            if depth:
                r.disable_depth_rendering()

    def _front_render(self) -> np.ndarray | GLPixels:
        """The front render as the camera model takes it: the Tello model reads OpenGL's RGBA rows as they are
        (`GLPixels`: no flip, no repack), the ideal camera the RGB image."""
        if not isinstance(self.camera, TelloCamera) or not self.config.render:
            return self._draw(drone.FRONT_CAMERA)
        r = self._renderer(*self._size(drone.FRONT_CAMERA))
        self._update_view(r, drone.FRONT_CAMERA)
        raw = read_rgba(r, self.model)
        return raw if raw is not None else r.render()

    def _size(self, camera: str, width: int | None = None, height: int | None = None) -> tuple[int, int]:
        cfg = self.config
        front = camera == drone.FRONT_CAMERA
        return width or (cfg.width if front else cfg.rear_width), height or (cfg.height if front else cfg.rear_height)

    def _update_view(self, r: mujoco.Renderer, camera: str, depth: bool = False) -> None:
        """`r`'s scene as `camera` sees it at the current pose, with the mirrors' reflections (not in depth)."""
        r.update_scene(self.data, camera=camera, scene_option=None if depth else self._rgb_option)
        if self._mirrors and not depth:
            reflect_in_view(r.scene, self._mirrors, r.width / r.height, (self.model, self.data, self._body_id),
                            keep=camera == drone.FRONT_CAMERA)  # the chase view: no reflection pass

    def front_depth(self, width: int, height: int) -> np.ndarray:
        """The front camera's z-depth image (HxW float32, metres) at the current pose (`DepthSensing`)."""
        return self.render(drone.FRONT_CAMERA, width, height, depth=True)

    def segmentation(self, camera: str = drone.FRONT_CAMERA) -> np.ndarray:
        """Per-pixel geom ids (-1 for background) of a low-resolution render, for visibility queries."""
        cfg = self.config
        if self._seg_renderer is None:
            self._seg_renderer = self._new_renderer(cfg.visibility_width, cfg.visibility_height)
            self._seg_renderer.enable_segmentation_rendering()
        self._sync()
        self._seg_renderer.update_scene(self.data, camera=camera)
        seg = self._seg_renderer.render()
        ids = seg[..., 0].astype(np.int32)
        ids[seg[..., 1] != int(mujoco.mjtObj.mjOBJ_GEOM)] = -1
        return ids

    def target_pixel_fraction(self, target_id: str) -> float:
        if target_id not in self.target_geoms:
            raise UnknownNameError("target", target_id, self.target_geoms)
        ids = self.segmentation()
        return float(np.isin(ids, list(self.target_geoms[target_id])).mean())

    def sign_text_px(self, name: str) -> float:
        """Issue 24: how large the sign `name`'s text is in the front image now: the projected height of a capital
        letter in px of a 640x480 frame (`sim.events.sign_view`), when the sign has appeared, its whole text block
        is in the frame before its face, and at least SIGN_VISIBLE_SHARE of it is unoccluded (segmentation render);
        else 0.0. Legible from `sim.events.SIGN_LEGIBLE_PX`."""
        if self.events is None or name not in self.events.specs or self.events.specs[name].kind != "sign":
            raise UnknownNameError("sign", name, [n for n, e in (self.events.specs if self.events else {}).items()
                                                  if e.kind == "sign"])
        if name not in self.events.fired:
            return 0.0
        view = sign_view(self.events.specs[name], self.scene, self._pose)
        if not view.in_frame or view.text_px <= 0:
            return 0.0
        ids = self.segmentation()
        h, w = ids.shape
        sx, sy = w / LEGIBILITY_FRAME[0], h / LEGIBILITY_FRAME[1]
        quad = np.array([(u * sx, v * sy) for u, v in view.corners])
        vs, us = np.mgrid[0:h, 0:w] + 0.5
        inside = np.ones((h, w), bool)  # the pixels of the text block's (convex) quad
        (ax, ay), (bx, by) = quad[1] - quad[0], quad[2] - quad[1]
        turn = 1.0 if ax * by - ay * bx >= 0 else -1.0
        for (x0, y0), (x1, y1) in zip(quad, np.roll(quad, -1, axis=0), strict=True):
            inside &= turn * ((x1 - x0) * (vs - y0) - (y1 - y0) * (us - x0)) >= 0
        if not inside.any():  # smaller than a pixel of the segmentation: its centre
            c = quad.mean(axis=0)
            inside[min(int(c[1]), h - 1), min(int(c[0]), w - 1)] = True
        face = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, f"sign:{name}:face")
        return view.text_px if (ids[inside] == face).mean() >= SIGN_VISIBLE_SHARE else 0.0

    def legible_signs(self) -> tuple[str, ...]:
        """The signs whose text is legible in the front image now (`sign_text_px` >= SIGN_LEGIBLE_PX)."""
        names = [n for n, e in self.events.specs.items() if e.kind == "sign"] if self.events is not None else []
        return tuple(n for n in names if self.sign_text_px(n) >= SIGN_LEGIBLE_PX)

    def ranges(self) -> tuple[RangeReading, ...]:
        """The range sensors' readings at the current pose (`RangeSensing`); () without any."""
        if self.range_sensor is None:
            return ()
        self._sync()
        return read_ranges(self.model, self.data, self._pose, self.range_sensor, self._body_id,
                           self._range_rng if self.config.range_noise else None)

    def target_footprint(self, target_id: str) -> Footprint:
        """Each of the target's geoms as the floor outline of its bounding box (world x, y, convex, CCW)."""
        if target_id not in self.target_geoms:
            raise UnknownNameError("target", target_id, self.target_geoms)
        if target_id not in self._footprints:
            mujoco.mj_kinematics(self.model, self.data)  # the world geoms' poses (static; the drone's is not read)
            self._footprints[target_id] = tuple(_geom_outline(self.model, self.data, g)
                                                for g in sorted(self.target_geoms[target_id]))
        return self._footprints[target_id]

    def ground_truth(self) -> GroundTruth:  # a SimGroundTruth, imported lazily to keep the module graph simple
        from vlnpilot.sim.ground_truth import SimGroundTruth

        return SimGroundTruth(self)

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        if self._seg_renderer is not None:
            self._seg_renderer.close()
        self._renderers.clear()
        self._seg_renderer = None

    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
