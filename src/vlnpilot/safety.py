"""Safety beyond the paper: a volumetric shield, a door-crossing assist and an oscillation guard.

The paper's two failures: the model has no sense of the drone's size, so propeller tips clip door frames;
and a model that wants the door perfectly centred oscillates until the step limit. The controller asks a
`SafetyLayer` to filter every validated command before the drone moves, in this order:

1. **Oscillation guard** (`OscillationGuard`). Counts direction reversals of the pilot's *proposed* rotations
   (B after C) and lateral moves (D1 after D2) since the last forward progress. When `threshold` reversals fall
   within the last `window` steps it fires (an event, recorded; one per stretch until the next forward move or
   state change), tells the pilot in the next prompt, and vetoes the next proposal that reverses the last
   executed direction (once per event, so that a pilot that heeds the note can still make a genuine
   correction). How the veto "accepts the current alignment as good enough":
   - in Oriented Towards Door, if the door assist says the drone fits the doorway ahead (centre within
     ±(width/2 - drone half-width - margin) of the centre line, heading within `accept_heading_deg` of the door
     normal, door within `accept_distance_m`), the reversal is replaced by A1 and the FSM advances to Go Through
     Door: the controller commits to the crossing, and the assist keeps the crossing centred;
   - otherwise (not aligned enough, or another state such as Reach Object) the reversal is replaced by E
     (hover) and the pilot is told that its alignment is accepted and it should move on (a cooperative pilot
     then moves forward or changes state).
   With the shield off the guard still detects and records events (for comparison) but never acts or speaks.
2. **Door-crossing assist** (`DoorAssist`, Oriented Towards Door and Go Through Door only). Before a forward
   move it checks, from the scene's door geometry and the drone's pose, whether the drone's outline inflated by
   the margin would enter the door frame's depth band while reaching beyond the opening; if so it replaces the
   forward move by D1 or D2 towards the doorway's centre line. When the shield would turn a forward move in
   those states into a hover (e.g. an open door leaf beside the passage), it steps towards the centre line
   instead if that step is safe, so that a pilot that may only fly A1 (Go Through Door) is not stuck.
3. **Shield** (`GeometryShield` or `DepthShield`). Predicts from the Tello's real outline with propellers
   (`tello_spec`) plus `margin_m` whether the motion would collide; an unsafe move is shortened (A3 -> A2 -> A1,
   B3 -> B2 -> B1, ...) or replaced by hovering (E). Inside the margin already (e.g. after a close approach),
   a motion is unsafe only if it brings the drone closer than it is, so the drone can always back out.

Every change is an `Intervention(step, source, proposed, executed, reason)`: in `episode.jsonl`, the summary,
`EpisodeResult.interventions`, and, as text, in the next prompt's controller feedback.

Knowledge sources (`make_shield(name, env)`):
- `geometry`: the simulator's collision geometry through a narrow query (`clearance_at(pose, max_distance)`
  of the ground truth), evaluated at a superset of the poses at which the simulator checks the motion. Exact:
  a command it lets through never collides in the simulator (property-tested). The upper bound.
- `depth`: only the front depth image, as a drone with a depth sensor would have, plus odometry (the pose).
  Each step's image is back-projected (vertical FOV `FRONT_FOVY`, 4:3) into points within a slab around the
  flight height and kept as a short memory (`memory_steps` steps, within `memory_radius_m`, voxel-thinned) in
  the odometry frame. Motions are checked against that memory with the same outline and margin. It assumes
  unseen space is free and that odometry is good over the memory's span. The camera sees a 69 x 55 degree cone
  in front; for **lateral moves** (and the sides in general) it relies on the memory only: a 10 cm sideways
  move is vetoed only if a remembered point lies in its path, so an obstacle never seen (e.g. approached
  sideways from outside the field of view) is not caught. **Rotations** are checked the same way; an in-place
  rotation sweeps only the bounding circle (6.7 cm radius), and anything that close was normally seen when the
  drone approached it. Door jambs beside a crossing drone are remembered from the approach.

Visual aid (`EpisodeConfig.overlay = "corridor"`): `draw_corridor` draws the propeller tips' paths on the
image the pilot sees; recorded frames stay raw (the run's config records the overlay, so it can be redrawn).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from vlnpilot import tello_spec
from vlnpilot.commands import COMMANDS, HOVER, OPPOSITE, Command, Kind
from vlnpilot.errors import ConfigError, UnknownNameError
from vlnpilot.fsm import State
from vlnpilot.scene.model import Door, Scene
from vlnpilot.types import Motion, Observation, Pose, wrap_deg

SHIELDS = ("off", "geometry", "depth", "assist")  # assist: door assist and oscillation guard, no shield (a Tello)
DEFAULT_SHIELD = "geometry"  # the CLI's default in the simulator; the library default stays "off" (paper behaviour)
OVERLAYS = ("corridor",)

# Prefixes of the feedback lines, so a pilot (or a test) can tell them apart.
SHIELD_NOTE, ASSIST_NOTE, GUARD_NOTE = "Safety shield", "Door assist", "Oscillation guard"

DOOR_STATES = (State.ORIENTED_TOWARDS_DOOR, State.GO_THROUGH_DOOR)
_MIN_CLEARANCE = 0.005  # a motion may never bring the drone closer than this to anything, whatever the margin


# -- configuration --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OscillationConfig:
    window: int = 8  # steps
    threshold: int = 3  # reversals within the window, without forward progress
    accept_heading_deg: float = 20.0  # tolerance band of the heading to the door normal for committing
    accept_distance_m: float = 1.2  # the door must be at most this far ahead

    def __post_init__(self) -> None:
        if self.window < 2 or not 1 <= self.threshold < self.window:
            raise ConfigError(f"oscillation guard needs window >= 2 and 1 <= threshold < window, got "
                              f"window={self.window}, threshold={self.threshold}")


@dataclass(frozen=True)
class DepthConfig:
    width: int = 160  # depth render size (4:3, the front camera's field of view)
    height: int = 120
    max_range_m: float = 3.0
    slab_m: float = 0.12  # keep points within this height of the flight altitude (no vertical moves exist)
    memory_steps: int = 40
    memory_radius_m: float = 2.0
    voxel_m: float = 0.02


@dataclass(frozen=True)
class SafetyConfig:
    margin_m: float = 0.05  # kept around the drone's outline with propellers
    substep_m: float = 0.01  # the shield samples motions at least this finely (and always at the sim's poses)
    substep_deg: float = 2.0
    door_assist: bool = True
    oscillation_guard: bool = True
    door_half_depth_m: float = 0.10  # half the depth of a door frame (wall plus casing), conservative
    door_search_m: float = 0.30  # a forward move with the centre this far beside an opening is still a crossing
    assist_heading_deg: float = 45.0  # the assist acts only when heading within this of the door axis
    oscillation: OscillationConfig = field(default_factory=OscillationConfig)
    depth: DepthConfig = field(default_factory=DepthConfig)

    def __post_init__(self) -> None:
        if not 0 <= self.margin_m <= 0.5:
            raise ConfigError(f"margin_m must be within 0..0.5 m, got {self.margin_m}")
        if self.substep_m <= 0 or self.substep_deg <= 0:
            raise ConfigError("shield sub-step sizes must be positive")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


# -- records --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Intervention:
    step: int
    source: str  # "shield" | "door_assist" | "oscillation_guard"
    proposed: str
    executed: str
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class OscillationEvent:
    step: int
    state: str
    reversals: int
    window: int
    acted: bool  # False when the safety layer is off: detection only
    action: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class SafetyVerdict:
    """What the safety layer made of one proposed command."""

    command: Command
    next_state: State
    interventions: tuple[Intervention, ...] = ()
    oscillation: OscillationEvent | None = None
    feedback: tuple[str, ...] = ()


def obstacle_kind(geom: str) -> str:
    """What a pilot may be told about an obstacle: its kind, never the scene's name for it (names such as
    `wall_living_room_e_3` or `door_bedroom_bathroom_frame_left` would tell the room, which the camera must)."""
    for word, kind in (("leaf", "an open door leaf"), ("frame", "a door frame"), ("window", "a window"),
                       ("wall", "a wall"), ("floor", "the floor"), ("ceiling", "the ceiling")):
        if word in geom:
            return kind
    return "an object"


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


def make_shield(name: str, env: Any, config: SafetyConfig | None = None) -> Shield | None:
    """The shield called `name` ('off', 'geometry', 'depth') for `env`, or None for 'off'.

    `geometry` needs an environment with ground truth offering `clearance_at` (the simulator); `depth` needs
    one that renders a front depth image (`render(camera, width, height, depth=True)`).
    """
    config = config or SafetyConfig()
    key = str(name).strip().lower()
    if key in ("off", "assist"):
        return None
    if key == "geometry":
        gt = env.ground_truth() if hasattr(env, "ground_truth") else None
        if gt is None or not hasattr(gt, "clearance_at"):
            raise ConfigError("the geometry shield needs the simulator's collision geometry, which this environment "
                              "does not provide; use --shield depth or --shield off")
        return GeometryShield(gt.clearance_at, config, getattr(gt, "substeps", None))
    if key == "depth":
        if not hasattr(env, "render"):
            raise ConfigError("the depth shield needs an environment that renders a front depth image; "
                              "use --shield off")
        from vlnpilot.sim import drone  # the camera name and intrinsics; no simulator object is kept

        d = config.depth

        def depth_image() -> np.ndarray:
            return env.render(drone.FRONT_CAMERA, d.width, d.height, depth=True)

        substeps = env.substeps if hasattr(env, "substeps") else None
        return DepthShield(depth_image, config, substeps, fovy_deg=drone.FRONT_FOVY)
    raise UnknownNameError("shield", name, SHIELDS)


# -- door-crossing assist ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DoorAlignment:
    door: Door
    lateral_m: float  # drone centre from the doorway's centre line, + = to the drone's left
    clearance_m: float  # how far the centre may be off the line: width/2 - half-width - margin
    heading_err_deg: float  # door axis relative to the heading, + = to the left
    distance_m: float  # along the door axis from the drone to the door plane (negative once past it)

    @property
    def fits(self) -> bool:
        return abs(self.lateral_m) <= self.clearance_m


class DoorAssist:
    """Keeps a door crossing inside the clearance the doorway leaves (scene map plus the drone's pose)."""

    def __init__(self, scene: Scene, config: SafetyConfig):
        self.doors = scene.open_doors()
        self.config = config

    def clearance(self, door: Door) -> float:
        return door.width / 2 - tello_spec.HALF_WIDTH - self.config.margin_m

    def _axis(self, door: Door, pose: Pose) -> float | None:
        """+1 if the drone faces along the door normal, -1 against it, None if too oblique to be crossing."""
        rel = abs(wrap_deg(pose.yaw_deg - door.normal_deg))
        lim = self.config.assist_heading_deg
        return 1.0 if rel <= lim else -1.0 if rel >= 180 - lim else None

    def alignment(self, pose: Pose, max_distance: float | None = None,
                  behind_m: float | None = None) -> DoorAlignment | None:
        """The doorway the drone faces (ahead, or at most `behind_m` past its plane) and the alignment, or None."""
        best: DoorAlignment | None = None
        behind = self.config.door_half_depth_m if behind_m is None else behind_m
        for door in self.doors:
            sign = self._axis(door, pose)
            if sign is None:
                continue
            depth, lateral = door.frame_of(pose.x, pose.y)
            ahead = -depth * sign  # along the drone's direction of travel, to the door plane
            if abs(lateral) > door.width / 2 + self.config.door_search_m or ahead < -behind:
                continue
            if max_distance is not None and ahead > max_distance:
                continue
            axis_deg = door.normal_deg if sign > 0 else door.normal_deg + 180.0
            a = DoorAlignment(door, lateral * sign, self.clearance(door), wrap_deg(axis_deg - pose.yaw_deg), ahead)
            if best is None or abs(a.distance_m) < abs(best.distance_m):
                best = a
        return best

    def conflict(self, pose: Pose, motion: Motion) -> tuple[Door, float] | None:
        """(door, centre's lateral offset in the door frame) if the motion would bring the outline (grown by the
        margin) into a door frame's depth band beyond the opening, else None."""
        m, hd = self.config.margin_m, self.config.door_half_depth_m
        for door in self.doors:
            if self._axis(door, pose) is None:
                continue
            _, lat0 = door.frame_of(pose.x, pose.y)
            if abs(lat0) > door.width / 2 + self.config.door_search_m:
                continue
            for frac in [0.0, *_fractions(motion, self.config, None)]:
                p = motion.apply(pose, frac)
                corners = outline_corners(p, m)
                nx, ny = door.normal
                dx, dy = corners[:, 0] - door.center[0], corners[:, 1] - door.center[1]
                depth, lateral = dx * nx + dy * ny, -dx * ny + dy * nx
                if depth.max() >= -hd and depth.min() <= hd and np.abs(lateral).max() > door.width / 2:
                    return door, door.frame_of(p.x, p.y)[1]
        return None

    def correction(self, pose: Pose, command: Command) -> tuple[Command, str] | None:
        """D1/D2 towards the centre line (or E if the door is too narrow) instead of a forward move that would
        bring a propeller into the frame; None when the forward move is fine."""
        if command.kind is not Kind.FORWARD:
            return None
        hit = self.conflict(pose, command.motion())
        if hit is None:
            return None
        door, lateral = hit
        sign = self._axis(door, pose) or 1.0
        lat_drone = lateral * sign  # + = the drone is left of the centre line
        clear = self.clearance(door)
        side = "left" if lat_drone > 0 else "right"
        what = (f"the drone is {abs(lat_drone) * 100:.0f} cm {side} of the centre line of the doorway, which "
                f"leaves ±{clear * 100:.0f} cm (opening {door.width * 100:.0f} cm, drone {tello_spec.WIDTH * 100:.1f} "
                f"cm wide, margin {self.config.margin_m * 100:.0f} cm): {command.code} would bring a propeller into "
                f"the door frame")
        if clear < COMMANDS["D1"].amount / 2:
            return HOVER, f"{what}; the opening is too narrow to correct with 10 cm moves, so the drone hovers"
        fix = COMMANDS["D2"] if lat_drone > 0 else COMMANDS["D1"]
        return fix, f"{what}, so the drone moves {'right' if lat_drone > 0 else 'left'} 10 cm first"


    def centring(self, pose: Pose) -> tuple[Command, DoorAlignment] | None:
        """A sideways step towards the centre line of the doorway being approached or crossed (within 1 m of its
        plane on either side), when the drone is at least half a step off it; else None."""
        a = self.alignment(pose, self.config.oscillation.accept_distance_m, behind_m=1.0)
        if a is None or abs(a.lateral_m) < COMMANDS["D1"].amount / 2:
            return None
        return (COMMANDS["D2"] if a.lateral_m > 0 else COMMANDS["D1"]), a


# -- oscillation guard ----------------------------------------------------------------------------------------------
class OscillationGuard:
    """Detects a pilot that reverses rotation or lateral direction again and again without progress."""

    def __init__(self, config: OscillationConfig):
        self.config = config
        self.reset()

    def reset(self) -> None:
        self._window: deque[bool] = deque(maxlen=self.config.window)
        self._last_proposed: dict[str, Kind] = {}
        self._last_executed: dict[str, Kind] = {}
        self.committed = False  # fired in this stretch (until forward progress or a state change)
        self.veto_pending = False  # the next reversal is vetoed (once per event)
        self._state: State | None = None

    @staticmethod
    def _axis(kind: Kind) -> str | None:
        if kind in (Kind.ROTATE_LEFT, Kind.ROTATE_RIGHT):
            return "rotation"
        if kind in (Kind.LATERAL_LEFT, Kind.LATERAL_RIGHT):
            return "lateral"
        return None

    def propose(self, state: State, command: Command) -> int | None:
        """Register a proposal; the number of reversals in the window when the guard fires, else None."""
        if self._state is not None and state is not self._state:
            self.committed = self.veto_pending = False
        self._state = state
        axis = self._axis(command.kind)
        reversal = axis is not None and self._last_proposed.get(axis) is OPPOSITE[command.kind]
        if axis is not None:
            self._last_proposed[axis] = command.kind
        self._window.append(reversal)
        count = sum(self._window)
        if count >= self.config.threshold and not self.committed:
            self._window.clear()
            return count
        return None

    def reverses(self, command: Command) -> bool:
        """Whether `command` reverses the last executed direction on its axis."""
        axis = self._axis(command.kind)
        return axis is not None and self._last_executed.get(axis) is OPPOSITE[command.kind]

    def executed(self, command: Command) -> None:
        axis = self._axis(command.kind)
        if axis is not None:
            self._last_executed[axis] = command.kind
        if command.kind is Kind.FORWARD:  # progress: a new stretch starts
            self._window.clear()
            self._last_proposed.clear()
            self.committed = self.veto_pending = False


# -- the layer the controller uses ---------------------------------------------------------------------------------
class SafetyLayer:
    """Guard, assist and shield in the controller's step. `active=False` (shield off): detection only."""

    def __init__(self, scene: Scene, config: SafetyConfig | None = None, shield: Shield | None = None,
                 active: bool = True):
        self.config = config or SafetyConfig()
        self.shield = shield
        self.active = active
        self.assist = DoorAssist(scene, self.config)
        self.guard = OscillationGuard(self.config.oscillation)
        self.interventions: list[Intervention] = []
        self.events: list[OscillationEvent] = []

    @property
    def name(self) -> str:
        if not self.active:
            return "off"
        return self.shield.name if self.shield is not None else "assist"

    def reset(self, obs: Observation) -> None:
        self.guard.reset()
        self.interventions, self.events = [], []
        if self.active and self.shield is not None:
            self.shield.reset(obs)

    def observe(self, obs: Observation) -> None:
        if self.active and self.shield is not None:
            self.shield.observe(obs)

    def filter(self, step: int, state: State, command: Command, next_state: State, pose: Pose) -> SafetyVerdict:
        """The command to execute (and next state) for a validated proposal, with what changed and why."""
        cfg = self.config
        found: list[Intervention] = []
        notes: list[str] = []
        event: OscillationEvent | None = None
        cmd, nxt = command, next_state
        guard_on = self.active and cfg.oscillation_guard

        fired = self.guard.propose(state, command)
        if fired is not None:
            self.guard.committed = True  # one event per stretch; only an active guard acts on it
            self.guard.veto_pending = guard_on
            action = "detection only (safety layer off)"
            if guard_on:
                action = "veto reversals; accept the current alignment"
                notes.append(f"{GUARD_NOTE}: you reversed rotation or sideways direction {fired} times in the last "
                             f"{cfg.oscillation.window} steps without moving forward. Your alignment is good "
                             f"enough; stop re-centring and commit (move forward, or go through the door).")
            event = OscillationEvent(step, state.value, fired, cfg.oscillation.window, guard_on, action)
            self.events.append(event)

        if guard_on and self.guard.veto_pending and self.guard.reverses(cmd):
            self.guard.veto_pending = False
            before = cmd
            al = self.assist.alignment(pose, cfg.oscillation.accept_distance_m)
            band = cfg.oscillation.accept_heading_deg
            if state is State.ORIENTED_TOWARDS_DOOR and al is not None and al.fits and abs(al.heading_err_deg) <= band:
                cmd, nxt = COMMANDS["A1"], State.GO_THROUGH_DOOR
                why = (f"accepted the alignment with the doorway ({abs(al.lateral_m) * 100:.0f} cm off the centre "
                       f"line, within ±{al.clearance_m * 100:.0f} cm; heading {abs(al.heading_err_deg):.0f}° off, "
                       f"within ±{band:.0f}°) and committed to the crossing: A1, state {nxt.value}")
            else:
                cmd = HOVER
                axis = "rotation" if before.is_rotation else "sideways"
                why = (f"vetoed {before.code}, which reverses the last {axis} direction; the current alignment is "
                       f"accepted as good enough, so the drone hovers: move on")
            found.append(Intervention(step, "oscillation_guard", before.code, cmd.code, why))
            notes.append(f"{GUARD_NOTE}: {why}.")

        if self.active and cfg.door_assist and state in DOOR_STATES:
            fix = self.assist.correction(pose, cmd)
            if fix is not None:
                found.append(Intervention(step, "door_assist", cmd.code, fix[0].code, fix[1]))
                notes.append(f"{ASSIST_NOTE}: {fix[1]} (executed {fix[0].code} instead of {cmd.code}).")
                cmd = fix[0]

        if self.active and self.shield is not None:
            safe, why = self.shield.filter(pose, cmd)
            side = None
            if why is not None and cfg.door_assist and state in DOOR_STATES and cmd.kind is Kind.FORWARD \
                    and safe.kind is Kind.NONE:
                side = self.assist.centring(pose)  # blocked near a doorway: step towards its centre line instead
            if side is not None and self.shield.hazard(pose, side[0].motion()) is None:
                fix, al = side
                text = (f"{cmd.code} is blocked ({why}); the drone is {abs(al.lateral_m) * 100:.0f} cm off the centre "
                        f"line of the doorway, so it moves {'right' if al.lateral_m > 0 else 'left'} 10 cm instead")
                found.append(Intervention(step, "door_assist", cmd.code, fix.code, text))
                notes.append(f"{ASSIST_NOTE}: {text}.")
                cmd = fix
            elif why is not None:
                found.append(Intervention(step, "shield", cmd.code, safe.code, why))
                notes.append(f"{SHIELD_NOTE}: {cmd.code} ({cmd.description}) is unsafe: {why}; executed "
                             f"{safe.code} ({safe.description}) instead.")
                cmd = safe

        self.guard.executed(cmd)
        self.interventions += found
        return SafetyVerdict(cmd, nxt, tuple(found), event, tuple(notes))


def make_safety(shield: str, env: Any, scene: Scene, config: SafetyConfig | None = None) -> SafetyLayer:
    """The controller's safety layer for a shield name; 'off' gives a passive layer (oscillation detection only)."""
    config = config or SafetyConfig()
    s = make_shield(shield, env, config)
    assist = str(shield).strip().lower() == "assist"  # the parts that need only the map and the pose
    return SafetyLayer(scene, config, s, active=s is not None or assist)


# -- visual aid for the model -------------------------------------------------------------------------------------
def corridor_pixels(width: int, height: int, *, half_width: float = tello_spec.HALF_WIDTH,
                    fovy_deg: float | None = None, depths: tuple[float, ...] = (0.3, 0.5, 1.0, 2.0, 4.0),
                    drop_m: float = 0.12) -> list[list[tuple[float, float]]]:
    """Pixel polylines (left, right) of the propeller tips' paths on a forward move, drawn `drop_m` below the
    flight height so that they are visible: at each depth their separation is the drone's width at that depth."""
    fovy = fovy_deg if fovy_deg is not None else tello_spec.vertical_fov_deg()
    f = (height / 2) / math.tan(math.radians(fovy) / 2)
    cx, cy = width / 2, height / 2
    return [[(cx + side * f * half_width / d, cy + f * drop_m / d) for d in depths] for side in (-1, 1)]


def draw_corridor(image: np.ndarray, *, color: tuple[int, int, int] = (255, 0, 255), **kwargs: Any) -> np.ndarray:
    """A copy of the front image with two thin lines where the propeller tips would pass on a forward move
    (see `corridor_pixels`), with a tick at each depth. Placeholder images (render off) are returned unchanged."""
    if image.ndim != 3 or image.shape[0] < 16 or image.shape[1] < 16:
        return image
    from PIL import Image, ImageDraw

    h, w = image.shape[:2]
    out = Image.fromarray(np.ascontiguousarray(image))
    draw = ImageDraw.Draw(out)
    for line in corridor_pixels(w, h, **kwargs):
        draw.line(line, fill=color, width=1)
        for x, y in line:
            draw.line([(x - 3, y), (x + 3, y)], fill=color, width=1)
    return np.asarray(out)
