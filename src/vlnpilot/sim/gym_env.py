"""Gymnasium environment `VLNPilot/Cabin-v0`: the embedded simulator for reinforcement-learning users.

`import vlnpilot` registers the ids (`vlnpilot.GYM_ENVS`), so `gymnasium.make("VLNPilot/Cabin-v0")` works afterwards.
Actions index the command table (`commands.COMMANDS`, in its order); observations are a dict of the front
image, the pose and the collision flag. Episodes end with `terminated` on reaching the goal room (+1) or on a
collision (-1), and with `truncated` (never both) when `max_steps` steps have been taken.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from vlnpilot import register_gym_envs
from vlnpilot.core.commands import COMMANDS, Command
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.ranging import RangeSensor
from vlnpilot.core.records import Observation, Pose
from vlnpilot.scene import Scene, Spawn, load_scene
from vlnpilot.sim.simulator import SimConfig, Simulator

ENV_ID = "VLNPilot/Cabin-v0"
HOUSE_ENV_ID = "VLNPilot/House-v0"
GOAL_REWARD, COLLISION_REWARD, STEP_REWARD = 1.0, -1.0, -0.01
CLOSED = "the environment is closed: make a new one (close() ends it for good)"


def front_shape(config: SimConfig) -> tuple[int, int, int]:
    """The front image's shape: the render's, or the Tello stream's with `camera="tello"` (docs/camera.md)."""
    if config.camera == "tello":
        from vlnpilot.sim.camera_model import TelloCameraParams

        return TelloCameraParams().height, TelloCameraParams().width, 3
    return config.height, config.width, 3


class CabinEnv(gym.Env):
    """The simulated Tello in a scene, one table command per step.

    Options: `spawn` (name, Spawn or Pose; default the scene's first spawn; `reset(options={"spawn": ...})`
    overrides it for one episode), `goal_room` (room id or alias; optional, also a reset option), `max_steps`,
    `width`/`height` of the front image, `render_mode="rgb_array"` (`render()` returns the rear chase view),
    `spawn_jitter_m`/`spawn_jitter_deg` (seeded spawn variety), `sensors` (none, tof or multiranger: the
    observation gains "ranges", metres per beam of `vlnpilot.core.ranging.SENSORS`, -1 beyond the sensor's range),
    `detail` (plain or rich: the scene detail the cameras render, docs/scenes.md).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, scene: str | Scene = "cabin", *, spawn: str | Spawn | Pose | None = None,
                 goal_room: str | None = None, max_steps: int = 50, width: int = 640, height: int = 480,
                 render_mode: str | None = None, spawn_jitter_m: float = 0.0, spawn_jitter_deg: float = 0.0,
                 sensors: str = "none", camera: str = "ideal", randomize: int | None = None, detail: str = "plain"):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode {render_mode!r} is not one of {self.metadata['render_modes']}")
        if max_steps < 1:
            raise ConfigError(f"max_steps must be at least 1, got {max_steps}")
        self.render_mode = render_mode
        self.max_steps = int(max_steps)
        self.scene = load_scene(scene)
        self.spawn = self._resolve_spawn(spawn)
        self.goal_room = self._resolve_room(goal_room)
        # the rear view is only wanted for render(): without a render mode it is not rendered
        self.sim = Simulator(self.scene, SimConfig(width=width, height=height, rear_width=width, rear_height=height,
                                                   rear_camera=render_mode == "rgb_array",
                                                   spawn_jitter_m=spawn_jitter_m, spawn_jitter_deg=spawn_jitter_deg,
                                                   sensors=sensors, camera=camera, randomize=randomize, detail=detail))
        self.commands: tuple[Command, ...] = tuple(COMMANDS.values())

        (xmin, ymin), (xmax, ymax) = self.scene.bounds
        low = np.array([xmin, ymin, 0.0, -180.0], np.float32)
        high = np.array([xmax, ymax, self.scene.ceiling_height, 180.0], np.float32)
        self.action_space = spaces.Discrete(len(self.commands))
        self.observation_space = spaces.Dict({
            "front": spaces.Box(0, 255, front_shape(self.sim.config), np.uint8),
            "pose": spaces.Box(low, high, (4,), np.float32),
            "collided": spaces.Discrete(2),
            **ranges_space(self.sim.range_sensor),
        })
        self._last: Observation | None = None
        self._steps = 0
        self._episode_goal: str | None = self.goal_room
        self._closed = False

    # -- options --------------------------------------------------------------------------------------
    def _resolve_spawn(self, spawn: str | Spawn | Pose | None) -> Spawn | Pose:
        if spawn is None:
            return self.scene.spawns[0]
        if isinstance(spawn, str):
            return self.scene.spawn(spawn)
        if isinstance(spawn, Spawn | Pose):
            return spawn
        raise ConfigError(f"spawn must be a spawn name, a Spawn or a Pose, got {type(spawn).__name__}")

    def _resolve_room(self, room: str | None) -> str | None:
        if room is None:
            return None
        found = self.scene.find_room(room)
        return found.id if found is not None else self.scene.room(room).id  # .room() raises, listing the ids

    def action_meaning(self, action: int) -> str:
        """'A1: move forward 10 cm', ... for an action index."""
        cmd = self.commands[int(action)]
        return f"{cmd.code}: {cmd.description}"

    # -- Gymnasium API ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._check_open()
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"spawn", "goal_room"}
        if unknown:
            raise ConfigError(f"unknown reset options {sorted(unknown)}; valid: goal_room, spawn")
        spawn = self._resolve_spawn(options["spawn"]) if options.get("spawn") is not None else self.spawn
        self._episode_goal = self._resolve_room(options["goal_room"]) if "goal_room" in options else self.goal_room
        sim_seed = int(self.np_random.integers(2**31 - 1))  # reproducible from the reset seed
        self._last = self.sim.reset(spawn, seed=sim_seed)
        self._steps = 0
        return self._obs(self._last), self._info(self._last)

    def step(self, action):
        self._check_open()
        if self._last is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if not self.action_space.contains(action):
            raise ConfigError(f"action {action!r} is not in {self.action_space}")
        obs = self.sim.step(self.commands[int(action)])
        self._last, self._steps = obs, self._steps + 1
        room = self.scene.room_at(obs.pose.x, obs.pose.y)
        reached = self._episode_goal is not None and room == self._episode_goal
        if obs.collided:
            reward, terminated = COLLISION_REWARD, True
        elif reached:
            reward, terminated = GOAL_REWARD, True
        else:
            reward, terminated = STEP_REWARD, False
        truncated = not terminated and self._steps >= self.max_steps
        return self._obs(obs), reward, terminated, truncated, self._info(obs, room)

    def render(self):
        self._check_open()
        if self.render_mode != "rgb_array":
            return None
        if self._last is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        return self._last.rear_rgb

    def close(self) -> None:
        """Free the renderers; the environment is then closed for good (a second close() does nothing)."""
        self.sim.close()
        self._closed = True

    def _check_open(self) -> None:
        if self._closed:  # the simulator would quietly open new renderers
            raise gym.error.ClosedEnvironmentError(CLOSED)

    # -- helpers ------------------------------------------------------------------------------------------
    def _obs(self, obs: Observation) -> dict[str, Any]:
        p = obs.pose
        ranges = {"ranges": np.array([-1.0 if r.metres is None else r.metres for r in self.sim.ranges()], np.float32)}
        return {
            "front": writable(obs.front_rgb),
            "pose": np.array([p.x, p.y, p.z, p.yaw_deg], np.float32),
            "collided": int(bool(obs.collided)),  # None (no contact sensing) counts as no collision
            **(ranges if self.sim.range_sensor is not None else {}),
        }

    def _info(self, obs: Observation, room: str | None = None) -> dict[str, Any]:
        room = room if room is not None else self.scene.room_at(obs.pose.x, obs.pose.y)
        return {
            "step": obs.step,
            "room": room,
            "goal_room": self._episode_goal,
            "is_success": self._episode_goal is not None and room == self._episode_goal and not obs.collided,
            "contact": obs.contact,
            "contact_part": obs.contact_part,
        }


def writable(frame: np.ndarray) -> np.ndarray:
    """`frame` if its reader may write into it (MuJoCo's renders), else a copy of it: the camera model's frames are
    read-only views of Pillow's bytes. Copied here, for Gymnasium, and not in the simulator, whose step
    (bench/camera_cost.py) has no use for it: ~0.5 ms of a 960x720 frame."""
    return frame if frame.flags.writeable else frame.copy()


def ranges_space(sensor: RangeSensor | None) -> dict[str, spaces.Box]:
    """The "ranges" observation of a drone with range sensors (one value per beam, -1: beyond range), else none."""
    if sensor is None:
        return {}
    n = len(sensor.directions)
    return {"ranges": spaces.Box(np.full(n, -1.0, np.float32), np.full(n, sensor.max_m, np.float32), (n,), np.float32)}


register = register_gym_envs
register()  # `import vlnpilot` did, unless another import hook took Gymnasium's import first (idempotent)
