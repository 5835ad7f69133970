"""Suites over procedural houses, the oracle flying a house through ground truth alone, and House-v0."""

from __future__ import annotations

import io
import sys
from collections import Counter
from pathlib import Path

import gymnasium as gym
import pytest
from rich.console import Console

from vlnpilot import cli
from vlnpilot.bench import ResultsLog, bench_command
from vlnpilot.bench.suite import load_suite, suite_from_dict
from vlnpilot.core.errors import ConfigError
from vlnpilot.scene import load_scene


def test_the_default_houses_suite_is_20_houses_by_5_mixed_queries() -> None:
    suite = load_suite("houses")
    assert len(suite.rows) == 100 and suite.repetitions == 1
    per_house = Counter(r.scene for r in suite.rows)
    assert per_house == {f"house:{s}": 5 for s in range(20)}
    kinds, doors = Counter(), Counter()
    for row in suite.rows:
        scene = load_scene(row.scene)
        kinds["object" if row.goal_target else "room"] += 1
        crossings = len(scene.room_path(scene.spawn(row.spawn).room, row.goal_room)) - 1
        doors["one" if crossings == 1 else "more"] += 1
        assert crossings >= 1  # every query leaves its starting room
    assert min(kinds.values()) >= 25 and min(doors.values()) >= 25, (kinds, doors)
    assert load_suite("houses").canonical() == suite.canonical()  # reproducible


def test_a_seed_range_suite_records_each_rows_house_and_survives_the_manifest_round_trip() -> None:
    suite = load_suite("houses:3,5-6")
    assert [r.scene for r in suite.rows[::5]] == ["house:3", "house:5", "house:6"]
    again = suite_from_dict(suite.to_dict())
    assert again.rows == suite.rows and again.canonical() == suite.canonical()
    assert all(r["scene"].startswith("house:") for r in suite.canonical()["rows"])


@pytest.mark.parametrize("name", ["houses:abc", "houses:9-1", "houses:1,x"])
def test_bad_seed_ranges_are_refused(name: str) -> None:
    with pytest.raises(ConfigError, match="bad house seeds"):
        load_suite(name)


def test_bad_seed_range_on_the_command_line_is_one_line_and_exit_2(monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str],
                                                                    tmp_path: Path) -> None:
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "bench", "--suite", "houses:9-1", "--out", str(tmp_path / "b")])
    with pytest.raises(SystemExit) as info:
        cli.main()
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1 and "houses:0-19" in err


def test_the_oracle_flies_a_house_suite_without_collisions(tmp_path: Path) -> None:
    out = bench_command(suite="houses:2", pilots="oracle", out=tmp_path / "b", executor="inline", progress=False,
                        shield="geometry", render=False, console=Console(file=io.StringIO()))
    records = ResultsLog(out / "results.jsonl").read()
    assert len(records) == 5
    assert [r["result"]["outcome"] for r in records] == ["success"] * 5
    assert sum(r["result"]["collisions"] for r in records) == 0
    summary_scenes = {(out / r["run_dir"] / "summary.json").read_text().count('"house:2"') for r in records}
    assert summary_scenes == {1}  # each run records the house it flew in


def test_house_env_builds_the_house_of_the_reset_seed() -> None:
    import vlnpilot.sim.gym_env  # noqa: F401  (registers the ids)

    env = gym.make("VLNPilot/House-v0", width=64, height=48, max_steps=5)
    try:
        obs, info = env.reset(seed=7)
        assert info["house"] == "house:7" and info["goal_room"] != info["room"]
        assert env.observation_space.contains(obs)
        first = obs["pose"].tolist()
        obs, info = env.reset(seed=7)
        assert obs["pose"].tolist() == first  # same seed, same start
        _, info = env.reset(seed=8)
        assert info["house"] == "house:8"
        _, reward, terminated, truncated, info = env.step(0)
        assert info["house"] == "house:8" and isinstance(reward, float)
        from gymnasium.utils.env_checker import check_env

        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


def test_the_simulator_cache_keeps_only_the_most_recent_houses_per_thread() -> None:
    from vlnpilot.bench.episode_job import SimulatorCache
    from vlnpilot.sim import SimConfig

    cache, still = SimulatorCache(per_thread=2), SimConfig(render=False)
    try:
        first = cache.get("house:0", still)
        cache.get("house:1", still)
        assert cache.get("house:0", still) is first  # a hit refreshes it
        cache.get("house:2", still)  # evicts house:1, the least recently used
        assert len(cache._all) == 2 and cache.get("house:0", still) is first
        assert {s.scene.name for s in cache._all} == {"house:0", "house:2"}
    finally:
        cache.close_thread()


@pytest.mark.chaos
@pytest.mark.parametrize(("seed", "house"), [(2**31 - 1, "house:147483647"), (2**64 - 1, "house:709551615")])
def test_house_env_takes_any_gymnasium_seed(seed: int, house: str) -> None:
    """A Gymnasium seed beyond the houses' nine digits names a house (it raised HouseSpecError)."""
    import vlnpilot.sim.gym_env  # noqa: F401  (registers the ids)

    env = gym.make("VLNPilot/House-v0", width=32, height=24, max_steps=2)
    try:
        _, info = env.reset(seed=seed)
        assert info["house"] == house
    finally:
        env.close()
