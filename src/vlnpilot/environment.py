"""The Environment contract that the simulator and the real Tello both implement."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Protocol, runtime_checkable

from vlnpilot.commands import Command
from vlnpilot.errors import ConfigError
from vlnpilot.scene.model import Scene, Spawn
from vlnpilot.types import Observation, Pose


@runtime_checkable
class Environment(Protocol):
    """`capabilities` (a `Capabilities`, below) says what it senses; `capabilities_of` reads it, or infers it."""

    scene: Scene

    def reset(self, spawn: str | Spawn | Pose | None = None, seed: int | None = None) -> Observation:
        """Start an episode at a spawn point (the drone is airborne at flight altitude afterwards)."""

    def step(self, command: Command | str) -> Observation:
        """Execute one command of the table and observe."""


@dataclass(frozen=True)
class Capabilities:
    """What an environment can sense beyond the front camera. The simulator has everything; a Tello none of it."""

    ground_truth: bool = True  # privileged pose, rooms and geometry (oracle pilot, geometry shield, success judge)
    depth: bool = True  # a front depth image (depth shield)
    rear_view: bool = True  # the chase camera behind the drone
    contact_sensing: bool = True  # whether `Observation.collided` is known

    def to_dict(self) -> dict[str, bool]:
        return asdict(self)


def capabilities_of(env: object) -> Capabilities:
    """An environment's declared capabilities (`capabilities` attribute), else what its methods offer."""
    declared = getattr(env, "capabilities", None)
    if isinstance(declared, Capabilities):
        return declared
    return Capabilities(ground_truth=hasattr(env, "ground_truth"), depth=hasattr(env, "render"))


def check_capabilities(caps: Capabilities, robot: str, *, shield: str, pilot: object) -> None:
    """Refuse, before anything flies, a shield or a pilot that needs what the environment cannot sense."""
    usable = "off, assist" if not caps.depth else "off, assist, depth"
    key = str(shield).strip().lower()
    if key == "geometry" and not caps.ground_truth:
        raise ConfigError(f"--shield geometry needs ground truth (the simulator's collision geometry), which the "
                          f"{robot} does not have; valid shields here: {usable}")
    if key == "depth" and not caps.depth:
        raise ConfigError(f"--shield depth needs a front depth image, which the {robot} does not have (one RGB "
                          f"camera); valid shields here: {usable}")
    if getattr(pilot, "privileged", False) and not caps.ground_truth:
        raise ConfigError(f"pilot {getattr(pilot, 'name', pilot)!r} flies on ground truth, which the {robot} does not "
                          "have; use a model pilot (openai, gemini, anthropic, remote, stdin or replay)")
