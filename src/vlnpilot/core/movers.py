"""People and pets that move through the scene (issue 24): their state as pure data, and the sensing protocol.

An environment with movers declares `Capabilities.movers` and implements `MoverSensing.movers()` (ground truth:
the shields predict with it, the oracle waits for it); the Tello declares none.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

MOVER_KINDS = ("person", "pet")
# Footprint radius and height (m) of each kind: the sizes the simulator builds and the shields predict with.
MOVER_RADIUS = {"person": 0.25, "pet": 0.2}
MOVER_HEIGHT = {"person": 1.75, "pet": 0.35}
# Movers yield like people do: one whose next YIELD_LOOKAHEAD_S would bring it within YIELD_DISTANCE_M of the
# drone (footprint edge to the drone's centre) stops and waits.
YIELD_LOOKAHEAD_S = 0.5
YIELD_DISTANCE_M = 0.3
CONTACT_PREFIX = "mover:"  # Observation.contact of a touch with a mover: "mover:person-1"


@dataclass(frozen=True)
class MoverState:
    """A mover now: world position of its footprint's centre, velocity, and size."""

    name: str  # "person-1", "pet-1"
    kind: str  # "person" | "pet"
    x: float
    y: float
    vx: float  # m/s now
    vy: float
    radius: float  # footprint radius (m)
    height: float  # top above the floor (m)

    def at(self, seconds: float) -> MoverState:
        """Where it will be after `seconds` at its present velocity (constant-velocity extrapolation)."""
        return replace(self, x=self.x + self.vx * seconds, y=self.y + self.vy * seconds)

    @property
    def contact_name(self) -> str:
        return CONTACT_PREFIX + self.name

    def as_dict(self) -> dict[str, float | str]:
        return {"name": self.name, "kind": self.kind, "x": round(self.x, 4), "y": round(self.y, 4),
                "vx": round(self.vx, 4), "vy": round(self.vy, 4), "radius": self.radius, "height": self.height}


def is_mover_contact(contact: str | None) -> bool:
    """Whether an observation's contact names a mover (not a wall or furniture)."""
    return bool(contact) and str(contact).startswith(CONTACT_PREFIX)


@runtime_checkable
class MoverSensing(Protocol):
    """An environment with `capabilities.movers`: the movers' current states (ground truth) and its clock."""

    def movers(self) -> tuple[MoverState, ...]: ...

    @property
    def seconds(self) -> float:
        """Seconds elapsed in the episode (the sum of the executed commands' durations)."""


@dataclass(frozen=True)
class FiredEvent:
    """An event of the scenario that fired: when (step, seconds on the episode's clock) and with what parameters.
    The observation of the step it fired in carries it (`Observation.events`); the step record writes it."""

    name: str  # "person-1", "door-closes-1"
    kind: str  # scene.events.EVENT_KINDS
    step: int
    time_s: float
    trigger: str  # how it fired: "step 3", "5 s", "entering bedroom"
    params: dict[str, object]

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "kind": self.kind, "step": self.step, "time_s": round(self.time_s, 3),
                "trigger": self.trigger, "params": self.params}


# The mover shield (safety/movers.py) keeps the drone's bounding circle this far (m, horizontally) from the
# footprint of each kind of mover, at its predicted position over every command; the prompts state the same numbers.
SHIELD_MARGIN_M = {"person": 0.5, "pet": 0.4}
# How the shield reads a mover's height (a recorded safety setting, `SafetyConfig.mover_clearance`):
# "column": every mover is a column from floor to ceiling (the rule the events trials were flown under);
# "3d" (EVFIX item 1): a pet conflicts only if the drone's bottom could come within JUMP_MARGIN_M of its top (a dog
# jumps); a person always conflicts. A recording without the setting was flown under "column".
MOVER_CLEARANCES = ("column", "3d")
JUMP_MARGIN_M = 0.3
ALWAYS_CONFLICTS = frozenset({"person"})


def reaches_height(mover: MoverState, bottom_z: float, clearance: str) -> bool:
    """Whether `mover` could come within the vertical margin of a drone whose bottom is at `bottom_z` (m)."""
    return clearance == "column" or mover.kind in ALWAYS_CONFLICTS or bottom_z < mover.height + JUMP_MARGIN_M
