"""The Environment contract that the simulator and the real Tello both implement, and what each one declares.

An environment says what it senses in `capabilities`; everything beyond the front camera is reached through a
protocol that the capability promises (`GroundTruthSource` for `ground_truth`, `DepthSensing` for `depth`).
Callers read the declaration (`capabilities_of`, `ground_truth_of`, `depth_sensing_of`), never probe methods.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Protocol, cast, runtime_checkable

import numpy as np

from vlnpilot.core.commands import Command
from vlnpilot.core.decision import traits_of
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.movers import MoverSensing, MoverState
from vlnpilot.core.ranging import SENSORS, RangeReading, range_sensor
from vlnpilot.core.records import Footprint, MotionSampling, Observation, Pose

if TYPE_CHECKING:  # the scene sits above the floor; the protocol only names it
    from vlnpilot.scene.model import Scene, Spawn


@runtime_checkable
class GroundTruth(MotionSampling, Protocol):
    """Privileged facts about the world, for monitors and privileged pilots only (never model pilots).

    `clearance_at` and `substeps` are the collision geometry that the geometry shield queries."""

    @property
    def scene(self) -> Scene: ...

    def pose(self) -> Pose: ...

    def room(self) -> str | None:
        """Id of the room the drone is in, or None (inside a wall or doorway)."""

    def target_distance_bearing(self, target_id: str) -> tuple[float, float]:
        """Horizontal distance (m) from the drone to the target, and its bearing (deg, + = left of heading)."""

    def target_footprint(self, target_id: str) -> Footprint:
        """The target's footprint: the outline of each of its parts projected on the floor (world x, y)."""

    def target_visible(self, target_id: str) -> bool:
        """Whether the target occupies enough pixels of the front camera (segmentation render)."""

    def clearance_at(self, pose: Pose, max_distance: float) -> tuple[float, str, str] | None:
        """(distance, scene part, drone part) of the nearest geometry within `max_distance` of the drone at
        `pose` (negative when penetrating), else None."""

    def movers(self) -> tuple[MoverState, ...]:
        """The people and pets in the scene now (issue 24; () where nothing moves)."""


@dataclass(frozen=True)
class Capabilities:
    """What an environment can sense beyond the front camera: it declares each one it has (the simulator all,
    a Tello none). Each `True` is a promise: `ground_truth` that it is a `GroundTruthSource`, `depth` that it
    is a `DepthSensing`."""

    ground_truth: bool = False  # privileged pose, rooms and geometry (oracle pilot, geometry shield, success judge)
    depth: bool = False  # a front depth image (depth shield)
    rear_view: bool = False  # the chase camera behind the drone
    contact_sensing: bool = False  # whether `Observation.collided` is known
    range_sensor: str = "none"  # range sensors it carries (vlnpilot.core.ranging.SENSORS): a `RangeSensing`
    movers: bool = False  # people or pets move in its scene (issue 24): a `core.movers.MoverSensing`

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        if self.range_sensor == "none":  # the records of drones without range sensors read as before
            del out["range_sensor"]
        if not self.movers:  # nor do those of scenes where nothing moves
            del out["movers"]
        return out


# An environment that declares nothing is taken to sense nothing beyond the front camera and its pose: what is
# not promised is never used, so a privileged pilot or a shield is refused before take-off with one clear line
# instead of failing in flight, and no report claims a rear view or a contact sensor it never had.
UNDECLARED = Capabilities()


@runtime_checkable
class Environment(Protocol):
    """A drone in a scene that executes the command table and observes; `capabilities` says what else it offers."""

    scene: Scene
    capabilities: Capabilities

    def reset(self, spawn: str | Spawn | Pose | None = None, seed: int | None = None) -> Observation:
        """Start an episode at a spawn point (the drone is airborne at flight altitude afterwards)."""

    def step(self, command: Command | str) -> Observation:
        """Execute one command of the table and observe."""


@runtime_checkable
class GroundTruthSource(Protocol):
    """An environment with `capabilities.ground_truth`: privileged facts, for monitors and privileged pilots."""

    def ground_truth(self) -> GroundTruth: ...


@runtime_checkable
class DepthSensing(MotionSampling, Protocol):
    """An environment with `capabilities.depth`: what the depth shield needs, and no camera name.

    `substeps` (from `MotionSampling`) is how the environment checks a motion, so that the shield samples a
    superset of those poses; a drone that moves continuously says 1."""

    front_fovy_deg: float  # vertical field of view of the front camera (the depth image's intrinsics, 4:3)

    def front_depth(self, width: int, height: int) -> np.ndarray:
        """The front camera's z-depth image (H x W, metres along the optical axis) at the current pose."""


@runtime_checkable
class RangeSensing(Protocol):
    """An environment whose `capabilities.range_sensor` is not `none`: its readings at the current pose."""

    def ranges(self) -> tuple[RangeReading, ...]: ...


def capabilities_of(env: object) -> Capabilities:
    """An environment's declared capabilities; `UNDECLARED` (nothing) if it declares none."""
    declared = getattr(env, "capabilities", None)
    return declared if isinstance(declared, Capabilities) else UNDECLARED


def ground_truth_of(env: object) -> GroundTruth | None:
    """The environment's ground truth if it declares one, else None."""
    return cast(GroundTruthSource, env).ground_truth() if capabilities_of(env).ground_truth else None


def depth_sensing_of(env: object) -> DepthSensing | None:
    """The environment as a front depth sensor if it declares one, else None."""
    return cast(DepthSensing, env) if capabilities_of(env).depth else None


@runtime_checkable
class SimulatedCamera(Protocol):
    """An environment whose frames are simulated says how (`camera_settings`: the camera model, its lag, the
    randomised world: docs/camera.md); the run records it, and a replay flies with it. A real camera says nothing."""

    def camera_settings(self) -> dict[str, Any]: ...


def camera_settings_of(env: object) -> dict[str, Any] | None:
    """How the environment's frames are simulated, or None (real frames, or the ideal camera in a world as built:
    what every recording before the camera model flew, so their records stay as they were)."""
    if not isinstance(env, SimulatedCamera):
        return None
    settings = env.camera_settings()
    return None if settings == {"model": "ideal"} else settings


def range_sensing_of(env: object) -> RangeSensing | None:
    """The environment as a range sensor if it declares one, else None."""
    return cast(RangeSensing, env) if capabilities_of(env).range_sensor != "none" else None


def mover_sensing_of(env: object) -> MoverSensing | None:
    """The environment's movers (people, pets) if it declares them, else None."""
    return cast(MoverSensing, env) if capabilities_of(env).movers else None


def check_sensors(caps: Capabilities, robot: str, sensors: str | None) -> None:
    """Refuse `--sensors NAME` when the drone does not carry that sensor (one line naming what is missing)."""
    wanted = range_sensor(sensors)
    if wanted is not None and caps.range_sensor != wanted.name:
        has = caps.range_sensor if caps.range_sensor != "none" else "no range sensor"
        raise ConfigError(f"--sensors {wanted.name} needs {wanted.shown_as}, which the {robot} does not have "
                          f"({has}); valid here: none" + (f", {caps.range_sensor}" if caps.range_sensor in SENSORS
                                                           and caps.range_sensor != "none" else ""))


def usable_shields(caps: Capabilities) -> str:
    """The shields an environment with `caps` can serve, for error messages."""
    needs = {"off": True, "assist": True, "depth": caps.depth, "geometry": caps.ground_truth}
    return ", ".join(name for name, served in needs.items() if served)


def check_capabilities(caps: Capabilities, robot: str, *, shield: str, pilot: object) -> None:
    """Refuse, before anything flies, a shield or a pilot that needs what the environment cannot sense."""
    usable = usable_shields(caps)
    key = str(shield).strip().lower()
    if key == "geometry" and not caps.ground_truth:
        raise ConfigError(f"--shield geometry needs ground truth (the simulator's collision geometry), which the "
                          f"{robot} does not have; valid shields here: {usable}")
    if key == "depth" and not caps.depth:
        raise ConfigError(f"--shield depth needs a front depth image, which the {robot} does not have (one RGB "
                          f"camera); valid shields here: {usable}")
    if traits_of(pilot).privileged and not caps.ground_truth:
        raise ConfigError(f"pilot {getattr(pilot, 'name', pilot)!r} flies on ground truth, which the {robot} does not "
                          "have; use a model pilot (openai, gemini, anthropic, remote, stdin or replay)")
