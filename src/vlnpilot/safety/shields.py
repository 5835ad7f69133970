"""The shields: predict from the drone's outline whether a motion collides (geometry or depth knowledge)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from vlnpilot.core import tello_spec
from vlnpilot.core.commands import COMMANDS, HOVER, Command, Kind
from vlnpilot.core.environment import Environment, capabilities_of, depth_sensing_of, ground_truth_of, usable_shields
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.records import Motion, Observation, Pose
from vlnpilot.core.registry import Registry
from vlnpilot.safety.config import _MIN_CLEARANCE, SafetyConfig, obstacle_kind


# -- geometry helpers -------------------------------------------------------------------------------------------
def _fractions(motion: Motion, config: SafetyConfig, substeps: Callable[[Motion], int] | None) -> list[float]:
    """Sample fractions of a motion: at least as fine as the config, and a superset of the simulator's poses."""
    trans = math.hypot(motion.forward_m, motion.lateral_m) + abs(motion.vertical_m)
    n = max(1, math.ceil(trans / config.substep_m), math.ceil(abs(motion.yaw_deg) / config.substep_deg))
    if substeps is not None:
        n_env = max(1, substeps(motion))
        n = n_env * math.ceil(n / n_env)
    return [i / n for i in range(1, n + 1)]


def shorter_commands(command: Command) -> list[Command]:
    """The same kind of command with smaller amounts, longest first (A3 -> A2, A1)."""
    return sorted((c for c in COMMANDS.values() if c.kind is command.kind and c.amount < command.amount),
                  key=lambda c: -c.amount)


def outline_corners(pose: Pose, inflate: float = 0.0) -> np.ndarray:
    """World (x, y) of the corners of the drone's horizontal outline with propellers, grown by `inflate`."""
    hl, hw = tello_spec.LENGTH / 2 + inflate, tello_spec.WIDTH / 2 + inflate
    c, s = pose.heading()
    local = np.array([(hl, hw), (hl, -hw), (-hl, hw), (-hl, -hw)])
    return np.column_stack((pose.x + local[:, 0] * c - local[:, 1] * s, pose.y + local[:, 0] * s + local[:, 1] * c))


# -- shields ------------------------------------------------------------------------------------------------------
class Shield:
    """Base: `hazard(pose, motion)` says what a motion would come too close to; `filter` shortens or hovers."""

    name = "shield"

    def __init__(self, config: SafetyConfig, substeps: Callable[[Motion], int] | None = None):
        self.config = config
        self._substeps = substeps

    def reset(self, obs: Observation) -> None:
        """A new episode starts at `obs`."""

    def observe(self, obs: Observation) -> None:
        """The drone sensed `obs` (after a step)."""

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        raise NotImplementedError

    def fractions(self, motion: Motion) -> list[float]:
        return _fractions(motion, self.config, self._substeps)

    def filter(self, pose: Pose, command: Command) -> tuple[Command, str | None]:
        """(command to execute, reason if it was changed): the longest safe version of `command`, else E."""
        if command.kind is Kind.NONE:
            return command, None
        why = self.hazard(pose, command.motion())
        if why is None:
            return command, None
        for alt in shorter_commands(command):
            if self.hazard(pose, alt.motion()) is None:
                return alt, why
        return HOVER, why


class ClearanceQuery(Protocol):
    def __call__(self, pose: Pose, max_distance: float) -> tuple[float, str, str] | None: ...


class GeometryShield(Shield):
    """Exact: the simulator's collision geometry, queried at every sampled pose of the motion with the margin."""

    name = "geometry"

    def __init__(self, clearance_at: ClearanceQuery, config: SafetyConfig,
                 substeps: Callable[[Motion], int] | None = None):
        super().__init__(config, substeps)
        self._clearance_at = clearance_at

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        margin = self.config.margin_m
        start = self._clearance_at(pose, margin)
        limit = margin if start is None else max(min(margin, start[0]), _MIN_CLEARANCE)
        limit = max(limit, _MIN_CLEARANCE)
        for frac in self.fractions(motion):
            hit = self._clearance_at(motion.apply(pose, frac), limit)
            if hit is not None and hit[0] < limit:
                dist, world, part = hit
                return (f"{part.replace('_', ' ')} would come {max(dist, 0.0) * 100:.0f} cm from "
                        f"{obstacle_kind(world)} (keeps {limit * 100:.0f} cm)")
        return None


class DepthShield(Shield):
    """Only the front depth image (plus odometry): a short memory of back-projected points (see module doc)."""

    name = "depth"

    def __init__(self, depth_image: Callable[[], np.ndarray], config: SafetyConfig,
                 substeps: Callable[[Motion], int] | None = None, fovy_deg: float | None = None,
                 camera_offset_m: float | None = None):
        super().__init__(config, substeps)
        self._depth_image = depth_image
        self.fovy_deg = fovy_deg if fovy_deg is not None else tello_spec.vertical_fov_deg()
        self.camera_offset_m = camera_offset_m if camera_offset_m is not None else tello_spec.LENGTH / 2 + 0.002
        self._points = np.zeros((0, 3))
        self._stamp = np.zeros(0, dtype=int)
        self._tick = 0
        self._rays: tuple[np.ndarray, np.ndarray] | None = None

    def reset(self, obs: Observation) -> None:
        self._points, self._stamp, self._tick = np.zeros((0, 3)), np.zeros(0, dtype=int), 0
        self.observe(obs)

    def _ray_factors(self, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
        if self._rays is None or self._rays[0].shape != (h, w):
            f = (h / 2) / math.tan(math.radians(self.fovy_deg) / 2)
            u = (np.arange(w) + 0.5 - w / 2) / f  # image right per metre of depth
            v = (np.arange(h) + 0.5 - h / 2) / f  # image down per metre of depth
            self._rays = (np.broadcast_to(u, (h, w)).copy(), np.broadcast_to(v[:, None], (h, w)).copy())
        return self._rays

    def points_from_depth(self, depth: np.ndarray, pose: Pose) -> np.ndarray:
        """World points (N x 3) of a front depth image (z-depth in metres) within the flight slab."""
        cfg = self.config.depth
        h, w = depth.shape
        ku, kv = self._ray_factors(h, w)
        ok = (depth > 1e-3) & (depth < cfg.max_range_m)
        z = depth[ok].astype(float)
        bx = self.camera_offset_m + z  # body frame: x forward, y left, z up
        by = -ku[ok] * z
        bz = -kv[ok] * z
        keep = np.abs(bz) <= cfg.slab_m
        bx, by, bz = bx[keep], by[keep], bz[keep]
        c, s = pose.heading()
        return np.column_stack((pose.x + bx * c - by * s, pose.y + bx * s + by * c, pose.z + bz))

    def observe(self, obs: Observation) -> None:
        cfg = self.config.depth
        self._tick += 1
        new = self.points_from_depth(np.asarray(self._depth_image()), obs.pose)
        pts = np.vstack((new, self._points))  # newest first: the voxel thinning keeps the first point
        stamp = np.concatenate((np.full(len(new), self._tick), self._stamp))
        near = (np.hypot(pts[:, 0] - obs.pose.x, pts[:, 1] - obs.pose.y) <= cfg.memory_radius_m) & \
               (stamp > self._tick - cfg.memory_steps)
        pts, stamp = pts[near], stamp[near]
        if len(pts):  # voxel-thin: one point per voxel (keys packed into one int64 for a fast 1-D unique)
            ijk = np.floor(pts / cfg.voxel_m).astype(np.int64) + (1 << 20)
            keys = (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]
            _, first = np.unique(keys, return_index=True)
            pts, stamp = pts[first], stamp[first]
        self._points, self._stamp = pts, stamp

    @property
    def memory_size(self) -> int:
        return len(self._points)

    def _nearest(self, pose: Pose, pts: np.ndarray) -> float:
        """Distance from the drone's box at `pose` to the nearest point (0 inside)."""
        if not len(pts):
            return math.inf
        c, s = pose.heading()
        dx, dy, dz = pts[:, 0] - pose.x, pts[:, 1] - pose.y, pts[:, 2] - pose.z
        local = np.column_stack((dx * c + dy * s, -dx * s + dy * c, dz))
        half = np.array([tello_spec.LENGTH / 2, tello_spec.WIDTH / 2, tello_spec.HEIGHT / 2])
        out = np.maximum(np.abs(local) - half, 0.0)
        return float(np.sqrt((out * out).sum(axis=1)).min())

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        margin = self.config.margin_m
        reach = math.hypot(motion.forward_m, motion.lateral_m) + tello_spec.BOUNDING_RADIUS + margin + 0.01
        pts = self._points
        if len(pts):
            pts = pts[np.hypot(pts[:, 0] - pose.x, pts[:, 1] - pose.y) <= reach]
        if not len(pts):
            return None
        start = self._nearest(pose, pts)
        limit = max(min(margin, start), _MIN_CLEARANCE)
        for frac in self.fractions(motion):
            d = self._nearest(motion.apply(pose, frac), pts)
            if d < limit:
                return (f"the depth image shows a surface {d * 100:.0f} cm from the drone's outline on this "
                        f"motion (keeps {limit * 100:.0f} cm)")
        return None


# Shields by name: a factory `(env, config) -> Shield | None` each (None: no shield, as 'off' and 'assist' have).
# A third party registers with `@SHIELD_REGISTRY.register("NAME")` in a module it imports (a `--plugin`) or
# through the `vlnpilot.shields` entry-point group; `--shield`, `EpisodeConfig` and the suites' pins then accept it.
ShieldFactory = Callable[[Environment, SafetyConfig], Shield | None]
SHIELD_REGISTRY: Registry[ShieldFactory] = Registry("shield", group="vlnpilot.shields")


def register_shield(name: str) -> Callable[[ShieldFactory], ShieldFactory]:
    """Register a shield factory `(env, config) -> Shield | None` under a (lower-case) name."""
    return SHIELD_REGISTRY.register(name)


def make_shield(name: str, env: Environment, config: SafetyConfig | None = None) -> Shield | None:
    """The shield called `name` (`SHIELD_REGISTRY`) for `env`, or None for 'off' and 'assist'.

    The built-ins read what `env` declares (`environment.Capabilities`): `geometry` needs ground truth, whose
    `clearance_at` and `substeps` are the simulator's collision geometry; `depth` needs a front depth image
    (`environment.DepthSensing`), and works on a drone without ground truth.
    """
    key = str(name).strip().lower()
    if key not in SHIELD_REGISTRY:
        raise UnknownNameError("shield", name, SHIELD_REGISTRY.names())
    return SHIELD_REGISTRY.get(key)(env, config or SafetyConfig())


@register_shield("off")
def _no_shield(env: Environment, config: SafetyConfig) -> Shield | None:
    return None


@register_shield("geometry")
def _geometry_shield(env: Environment, config: SafetyConfig) -> Shield | None:
    gt = ground_truth_of(env)
    if gt is None:
        raise ConfigError("the geometry shield needs ground truth (the simulator's collision geometry), which "
                          f"this environment does not declare; valid shields here: {_usable(env)}")
    return GeometryShield(gt.clearance_at, config, gt.substeps)


@register_shield("depth")
def _depth_shield(env: Environment, config: SafetyConfig) -> Shield | None:
    sensor = depth_sensing_of(env)
    if sensor is None:
        raise ConfigError("the depth shield needs a front depth image, which this environment does not "
                          f"declare; valid shields here: {_usable(env)}")
    d = config.depth

    def depth_image() -> np.ndarray:
        return sensor.front_depth(d.width, d.height)

    return DepthShield(depth_image, config, sensor.substeps, fovy_deg=sensor.front_fovy_deg)


SHIELD_REGISTRY.add("assist", _no_shield)  # the door assist and oscillation guard alone (`make_safety`), a Tello's


def _usable(env: object) -> str:
    return usable_shields(capabilities_of(env))
