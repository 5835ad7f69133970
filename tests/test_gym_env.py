"""The Gymnasium environment VLNPilot/Cabin-v0: the env checker, determinism, termination and reward."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import vlnpilot.sim.gym_env as gym_env
from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.records import Pose

W, H = 64, 48
ACTION = {code: i for i, code in enumerate(COMMANDS)}


@pytest.fixture(scope="module")
def env():
    e = gym.make(gym_env.ENV_ID, width=W, height=H, render_mode="rgb_array")
    yield e
    e.close()


def test_registered_and_spaces(env):
    assert gym_env.ENV_ID in gym.registry
    gym_env.register()  # idempotent
    base = env.unwrapped
    assert isinstance(base, gym_env.CabinEnv)
    assert base.action_space == gym.spaces.Discrete(len(COMMANDS))
    assert [c.code for c in base.commands] == list(COMMANDS)
    assert base.action_meaning(ACTION["B1"]).startswith("B1: rotate right")
    space = base.observation_space
    assert set(space.spaces) == {"front", "pose", "collided"}
    assert space["front"].shape == (H, W, 3) and space["front"].dtype == np.uint8
    assert space["pose"].shape == (4,) and space["pose"].dtype == np.float32
    assert base.max_steps == 50 and base.spawn == base.scene.spawns[0]


def test_check_env_passes(env):
    check_env(env.unwrapped, skip_render_check=False)


def test_same_seed_same_trajectory(env):
    def rollout(seed):
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for code in ("A2", "C2", "A1", "D2", "B1"):
            obs, *_ = env.step(ACTION[code])
            out.append(obs)
        return out, env.render()

    (a, ra), (b, rb) = rollout(11), rollout(11)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x["pose"], y["pose"]) and x["collided"] == y["collided"]
        assert np.array_equal(x["front"], y["front"])
    assert ra.shape == (H, W, 3) and np.array_equal(ra, rb)


def test_seed_drives_the_spawn_jitter():
    with gym_env.CabinEnv(width=W, height=H, spawn_jitter_m=0.1, spawn_jitter_deg=10.0) as e:
        p1 = e.reset(seed=1)[0]["pose"]
        p1b = e.reset(seed=1)[0]["pose"]
        p2 = e.reset(seed=2)[0]["pose"]
    assert np.array_equal(p1, p1b) and not np.array_equal(p1, p2)


def test_collision_terminates_with_penalty(env):
    obs, info = env.reset(seed=0, options={"spawn": Pose(7.25, 0.6, 1.0, -90.0)})  # bathroom, wall ahead
    assert obs["collided"] == 0 and info["room"] == "bathroom"
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(ACTION["A3"])
        if terminated:
            break
    assert terminated and not truncated
    assert reward == -1.0 and obs["collided"] == 1
    assert info["contact"].startswith("wall_bathroom_south") and not info["is_success"]


def test_truncated_at_max_steps_not_terminated():
    with gym_env.CabinEnv(width=W, height=H, max_steps=3, goal_room="bathroom") as e:
        e.reset(seed=0)
        results = [e.step(ACTION["E"]) for _ in range(3)]
    for _, reward, terminated, truncated, _ in results[:-1]:
        assert reward == pytest.approx(-0.01) and not terminated and not truncated
    _, reward, terminated, truncated, info = results[-1]
    assert truncated and not terminated and reward == pytest.approx(-0.01) and info["step"] == 3


def test_reaching_the_goal_room_rewards_and_terminates(env):
    door = env.unwrapped.scene.door("door_living_bedroom")
    start = Pose(door.center[0] - 0.25, door.center[1], 1.0, door.normal_deg)
    obs, info = env.reset(seed=0, options={"spawn": start, "goal_room": "bedroom"})
    assert info["room"] == "living_room" and info["goal_room"] == "bedroom"
    rewards = []
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(ACTION["A1"])
        rewards.append(reward)
        if terminated:
            break
    assert terminated and not truncated and info["is_success"] and info["room"] == "bedroom"
    assert rewards[-1] == 1.0 and all(r == pytest.approx(-0.01) for r in rewards[:-1])
    # no goal room: the same flight is just step penalties
    env.reset(seed=0, options={"spawn": start, "goal_room": None})
    assert all(env.step(ACTION["A1"])[1:3] == (pytest.approx(-0.01), False) for _ in range(5))


def test_bad_options_are_refused():
    with pytest.raises(UnknownNameError, match="living_room"):
        gym_env.CabinEnv(width=W, height=H, spawn="attic")
    with pytest.raises(UnknownNameError, match="bathroom"):
        gym_env.CabinEnv(width=W, height=H, goal_room="garage")
    with pytest.raises(ConfigError):
        gym_env.CabinEnv(width=W, height=H, render_mode="human")


@pytest.mark.parametrize("options", [{}, {"camera": "tello"}, {"randomize": 3}], ids=["ideal", "tello", "randomised"])
def test_the_front_frame_is_the_callers_to_write_into(options: dict[str, object]) -> None:
    """The Tello camera's frames (and a randomised world's) were read-only; MuJoCo's render is the caller's."""
    with gym_env.CabinEnv(width=W, height=H, **options) as e:
        frames = [e.reset(seed=1)[0]["front"], e.step(ACTION["A1"])[0]["front"]]
        assert e._last is not None and np.array_equal(frames[-1], e._last.front_rgb)  # the very frame, bit for bit
    assert all(frame.flags.writeable for frame in frames)


@pytest.mark.parametrize("env_id", [gym_env.ENV_ID, gym_env.HOUSE_ENV_ID])
def test_a_closed_environment_refuses_to_step_reset_or_render(env_id: str) -> None:
    """The cabin quietly opened new renderers and flew on; the house built a new simulator and asked for a reset."""
    env = gym.make(env_id, width=32, height=24, render_mode="rgb_array")
    env.reset(seed=1)
    env.close()
    env.close()  # a second close is fine
    for call in (lambda: env.step(0), lambda: env.reset(seed=1), env.render):
        with pytest.raises(gym.error.ClosedEnvironmentError, match="the environment is closed"):
            call()


def test_gymnasium_finds_the_ids_from_the_module_named_in_the_id() -> None:
    """`gym.make("vlnpilot.sim.gym_env:VLNPilot/Cabin-v0")` works in a fresh process, nothing imported first."""
    import subprocess
    import sys

    code = ("import gymnasium as gym; e = gym.make('vlnpilot.sim.gym_env:VLNPilot/House-v0', width=32, height=24); "
            "print(e.spec.id); e.close()")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.strip() == "VLNPilot/House-v0"


@pytest.mark.parametrize("imports", ["import vlnpilot; import gymnasium as gym",
                                     "import gymnasium as gym; import vlnpilot"], ids=["vlnpilot-first", "gym-first"])
def test_import_vlnpilot_registers_the_ids_in_either_order(imports: str) -> None:
    """Gymnasium 1.x reads no entry points: `import vlnpilot` registers the ids, importing neither MuJoCo nor (when
    it is not loaded yet) Gymnasium; `gym.make` then loads the environment."""
    import subprocess
    import sys

    code = (f"import sys; {imports}; loaded = sorted({{'gymnasium', 'mujoco'}} & set(sys.modules)); "
            "e = gym.make('VLNPilot/Cabin-v0', width=32, height=24); e.reset(seed=0); e.close(); "
            "print(loaded, sorted(i for i in gym.registry if i.startswith('VLNPilot/')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['gymnasium'] ['VLNPilot/Cabin-v0', 'VLNPilot/House-v0']"


def test_import_vlnpilot_alone_loads_no_gymnasium() -> None:
    import subprocess
    import sys

    code = "import sys, vlnpilot; print(sorted({'gymnasium', 'mujoco', 'numpy'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
