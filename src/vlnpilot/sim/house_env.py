"""Gymnasium environment `VLNPilot/House-v0`: the cabin environment's rules in procedural houses.

`reset(seed=S)` flies house `house:S` (the simulator is rebuilt only when the house changes); a Gymnasium seed
beyond the houses' range (0..999999999) flies `house:S mod 10**9`; without a seed the current house is kept.
Each episode starts at a random spawn of the house with a random goal room (both drawn from the reset seed)
unless `options` gives `spawn` / `goal_room`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.ranging import range_sensor
from vlnpilot.scene.houses import SEEDS, HouseSpec
from vlnpilot.sim.gym_env import CLOSED, CabinEnv, front_shape, ranges_space
from vlnpilot.sim.simulator import SimConfig

MAX_EXTENT_M = 40.0  # bound of the pose observation: larger than any generated house


class HouseEnv(gym.Env):
    metadata = CabinEnv.metadata

    def __init__(self, house: int = 0, rooms: int | None = None, *, max_steps: int = 150, width: int = 640,
                 height: int = 480, render_mode: str | None = None, sensors: str = "none", camera: str = "ideal",
                 randomize: int | None = None, detail: str = "plain"):
        self._spec = HouseSpec(int(house), rooms)
        self._kwargs: dict[str, Any] = {"max_steps": max_steps, "width": width, "height": height,
                                        "render_mode": render_mode, "sensors": sensors, "camera": camera,
                                        "randomize": randomize, "detail": detail}
        self.render_mode = render_mode
        self._env: CabinEnv | None = None
        self._closed = False
        self.action_space = spaces.Discrete(len(COMMANDS))
        low = np.array([-1.0, -1.0, 0.0, -180.0], np.float32)
        high = np.array([MAX_EXTENT_M, MAX_EXTENT_M, 3.0, 180.0], np.float32)
        shape = front_shape(SimConfig(width=width, height=height, camera=camera, randomize=randomize))
        self.observation_space = spaces.Dict({"front": spaces.Box(0, 255, shape, np.uint8),
                                              "pose": spaces.Box(low, high, (4,), np.float32),
                                              "collided": spaces.Discrete(2),
                                              **ranges_space(range_sensor(sensors))})

    @property
    def house(self) -> str:
        """The scene name of the current house, e.g. 'house:7'."""
        return self._spec.name

    @property
    def env(self) -> CabinEnv:
        self._check_open()
        if self._env is None or self._env.scene.name != self._spec.name:
            if self._env is not None:
                self._env.close()
            self._env = CabinEnv(self._spec.name, **self._kwargs)
        return self._env

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._check_open()
        super().reset(seed=seed)
        if seed is not None:
            self._spec = HouseSpec(int(seed) % SEEDS, self._spec.rooms)  # any Gymnasium seed names a house
        env, options = self.env, dict(options or {})
        scene = env.scene
        if options.get("spawn") is None:
            options["spawn"] = scene.spawns[int(self.np_random.integers(len(scene.spawns)))].id
        if "goal_room" not in options:
            start = scene.spawn(options["spawn"]).room if isinstance(options["spawn"], str) else None
            rooms = [r.id for r in scene.rooms if r.id != start]
            options["goal_room"] = rooms[int(self.np_random.integers(len(rooms)))]
        obs, info = env.reset(seed=int(self.np_random.integers(2**31 - 1)), options=options)
        return obs, {**info, "house": self.house}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "house": self.house}

    def render(self):
        return self.env.render()

    def close(self) -> None:
        """Free the house's simulator; the environment is then closed for good (a second close() does nothing)."""
        if self._env is not None:
            self._env.close()
            self._env = None
        self._closed = True

    def _check_open(self) -> None:
        if self._closed:  # rather than a new house's simulator, whose step would ask for a reset
            raise gym.error.ClosedEnvironmentError(CLOSED)
