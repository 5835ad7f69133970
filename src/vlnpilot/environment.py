"""The Environment contract that the simulator and the real Tello both implement."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from vlnpilot.commands import Command
from vlnpilot.scene.model import Scene, Spawn
from vlnpilot.types import GroundTruth, Observation, Pose


@runtime_checkable
class Environment(Protocol):
    scene: Scene

    def reset(self, spawn: str | Spawn | Pose | None = None, seed: int | None = None) -> Observation:
        """Start an episode at a spawn point (the drone is airborne at flight altitude afterwards)."""

    def step(self, command: Command | str) -> Observation:
        """Execute one command of the table and observe."""


class HasGroundTruth(Protocol):
    def ground_truth(self) -> GroundTruth: ...
