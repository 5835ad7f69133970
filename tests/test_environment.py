"""What an environment declares is all that is used: capabilities, ground truth and the front depth image.

A real drone implements `Environment` without ground truth. These fakes stand in for one with a depth camera
and one with neither, so the refusals (geometry shield, oracle) and the depth shield are tested without the
simulator.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from vlnpilot.core import tello_spec
from vlnpilot.core.commands import COMMANDS, HOVER, Command, get_command
from vlnpilot.core.environment import (
    UNDECLARED,
    Capabilities,
    DepthSensing,
    Environment,
    GroundTruth,
    GroundTruthSource,
    capabilities_of,
    check_capabilities,
    depth_sensing_of,
    ground_truth_of,
)
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Motion, Observation, Pose
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.safety import make_safety, make_shield
from vlnpilot.scene import Scene
from vlnpilot.tasks.task import parse_query

WALL_X = 3.0  # the fakes' world: one flat wall across the flight slab at x = 3 m, seen head-on
CAMERA_OFFSET = tello_spec.LENGTH / 2 + 0.002  # the front camera sits at the nose
NO_IMAGE = np.zeros((1, 1, 3), np.uint8)


class BlindDrone:
    """A real drone's contract: one RGB camera and odometry, no ground truth, no depth (like the Tello)."""

    capabilities = Capabilities()

    def __init__(self, scene: Scene):
        self.scene, self.pose = scene, Pose(0.0, 2.0, 1.0, 0.0)

    def reset(self, spawn: Any = None, seed: int | None = None) -> Observation:
        self.pose = spawn if isinstance(spawn, Pose) else Pose(0.0, 2.0, 1.0, 0.0)
        return self._observe()

    def step(self, command: Command | str) -> Observation:
        cmd = command if isinstance(command, Command) else get_command(command)
        self.pose = cmd.motion().apply(self.pose)
        return self._observe()

    def _observe(self) -> Observation:
        return Observation(front_rgb=NO_IMAGE, rear_rgb=NO_IMAGE, pose=self.pose, collided=None)


class DepthDrone(BlindDrone):
    """A drone with a front depth camera and still no ground truth; it sees the wall at `WALL_X` when facing +x."""

    capabilities = Capabilities(depth=True)
    front_fovy_deg = tello_spec.vertical_fov_deg()

    def substeps(self, motion: Motion) -> int:
        return 1  # it moves continuously: no sampled poses to align with

    def front_depth(self, width: int, height: int) -> np.ndarray:
        assert self.pose.yaw_deg == 0.0, "the fake renders the wall head-on only"
        return np.full((height, width), WALL_X - self.pose.x - CAMERA_OFFSET, np.float32)


class Undeclared:
    """Methods that once made an environment look privileged, but no declaration: none of them is used."""

    def __init__(self, scene: Scene):
        self.scene = scene

    def ground_truth(self) -> GroundTruth:
        raise AssertionError("an undeclared ground truth must never be queried")

    def render(self, *args: Any, **kwargs: Any) -> np.ndarray:
        raise AssertionError("an undeclared depth camera must never be rendered")

    def substeps(self, motion: Motion) -> int:
        raise AssertionError("never asked")


def _oracle_task(scene: Scene):
    return parse_query("Go to the bathroom", scene)


# -- what is declared ---------------------------------------------------------------------------------------------
def test_an_environment_that_declares_nothing_senses_nothing(scene: Scene) -> None:
    env = Undeclared(scene)
    assert capabilities_of(env) == UNDECLARED == Capabilities(False, False, False, False)
    assert ground_truth_of(env) is None and depth_sensing_of(env) is None
    for name in ("geometry", "depth"):
        with pytest.raises(ConfigError, match=f"the {name} shield needs .*valid shields here: off, assist$"):
            make_shield(name, env)


def test_the_simulator_and_the_tello_keep_their_promises(geo_sim) -> None:
    from vlnpilot.robots.tello import TelloEnv

    assert isinstance(geo_sim, Environment)
    assert capabilities_of(geo_sim) == Capabilities(True, True, True, True)
    assert isinstance(geo_sim, GroundTruthSource) and isinstance(geo_sim, DepthSensing)
    assert isinstance(ground_truth_of(geo_sim), GroundTruth)
    assert depth_sensing_of(geo_sim) is geo_sim
    assert TelloEnv.capabilities == UNDECLARED  # a real drone: no ground truth, no depth, no rear view, no contact


def test_the_simulators_depth_image_is_its_front_cameras(geo_sim) -> None:
    geo_sim.reset(Pose(3.0, 2.0, 1.0, 0.0))
    assert np.array_equal(geo_sim.front_depth(160, 120), geo_sim.render("front", 160, 120, depth=True))


# -- a drone with depth and no ground truth -----------------------------------------------------------------------
def test_the_depth_shield_works_without_ground_truth(scene: Scene) -> None:
    """The wall 45 cm ahead: A3 is shortened to A2; once 8 cm from it every forward move hovers."""
    env = DepthDrone(scene)
    layer = make_safety("depth", env, scene)
    pose = Pose(WALL_X - 0.45, 2.0, 1.0, 0.0)
    layer.reset(env.reset(pose))
    verdict = layer.filter(1, State.REACH_OBJECT, COMMANDS["A3"], State.REACH_OBJECT, pose)
    assert layer.name == "depth" and verdict.command.code == "A2"
    assert "depth image shows a surface" in verdict.interventions[0].reason
    seen = layer.shield.points_from_depth(env.front_depth(160, 120), pose)  # through the declared field of view
    half_width = (WALL_X - pose.x - CAMERA_OFFSET) * np.tan(np.radians(tello_spec.horizontal_fov_deg()) / 2)
    assert np.abs(seen[:, 1] - pose.y).max() == pytest.approx(half_width, rel=0.02)
    close = Pose(WALL_X - tello_spec.LENGTH / 2 - 0.08, 2.0, 1.0, 0.0)
    layer.observe(env.reset(close))
    for code in ("A1", "A2", "A3"):
        assert layer.shield.filter(close, COMMANDS[code])[0] is HOVER
    assert layer.shield.filter(close, COMMANDS["D1"]) == (COMMANDS["D1"], None)


def test_a_drone_with_depth_refuses_the_geometry_shield_and_the_oracle(scene: Scene) -> None:
    env = DepthDrone(scene)
    with pytest.raises(ConfigError, match="geometry shield needs ground truth.*here: off, assist, depth$"):
        make_shield("geometry", env)
    with pytest.raises(ConfigError, match="pilot 'oracle' needs ground truth"):
        run_episode(env, OraclePilot(), _oracle_task(scene), EpisodeConfig(shield="depth"))


# -- a drone with neither ------------------------------------------------------------------------------------------
def test_a_drone_with_neither_flies_only_off_or_assist(scene: Scene) -> None:
    env = BlindDrone(scene)
    for name in ("geometry", "depth"):
        with pytest.raises(ConfigError, match="valid shields here: off, assist$"):
            make_shield(name, env)
        with pytest.raises(ConfigError, match="valid shields here: off, assist$"):
            check_capabilities(capabilities_of(env), "drone", shield=name, pilot=None)
    assert make_shield("assist", env) is None and make_safety("assist", env, scene).name == "assist"
    with pytest.raises(ConfigError, match="pilot 'oracle' needs ground truth"):
        run_episode(env, OraclePilot(), _oracle_task(scene))
