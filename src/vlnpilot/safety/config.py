"""The safety layer's settings, names and records: what the shields, the assist and the guard share."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from vlnpilot.core.commands import Command
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State
from vlnpilot.core.movers import MOVER_CLEARANCES

DEFAULT_SHIELD = "geometry"  # the CLI's default in the simulator; the library default stays "off" (paper behaviour)


def default_shield(ground_truth: bool) -> str:
    """The command line's shield for an environment: the exact one where there is ground truth (the simulator),
    else the door assist and oscillation guard alone (a real Tello has neither ground truth nor depth)."""
    return DEFAULT_SHIELD if ground_truth else "assist"
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
    # how the mover shield reads a mover's height (core.movers.MOVER_CLEARANCES): new runs record "3d"; a recording
    # without it replays under "column", the rule it was flown with (pilots/replay.py)
    mover_clearance: str = "3d"

    def __post_init__(self) -> None:
        if self.mover_clearance not in MOVER_CLEARANCES:
            raise ConfigError(f"mover_clearance {self.mover_clearance!r} is not one of {', '.join(MOVER_CLEARANCES)}")
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
