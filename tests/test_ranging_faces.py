"""`--sensors` on every face: run, bench (and suite rows), the Gymnasium environments, the Tello backend against
the emulator (a RoboMaster TT answers `EXT tof?`; a plain Tello is refused in one line)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_support import run_main
from tello_support import loopback_only, rig  # noqa: F401  (loopback_only: the autouse guard)
from vlnpilot.bench.command import bench_command
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.ranging import TT_TOF_BEYOND_MM
from vlnpilot.core.records import Pose
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.sim.gym_env import CabinEnv
from vlnpilot.sim.house_env import HouseEnv


@pytest.mark.parametrize("command", [["run", "Go to the bedroom", "--pilot", "oracle"], ["bench", "--reps", "1"]])
def test_a_bad_sensor_name_is_one_line_and_exit_2(monkeypatch, capsys, tmp_path: Path, command: list[str]) -> None:
    code, out, err = run_main(monkeypatch, capsys, *command, "--sensors", "lidar", "--out", str(tmp_path / "x"))
    assert code == 2 and "unknown --sensors 'lidar'; valid: none, tof, multiranger" in err
    assert "Traceback" not in err + out and len(err.strip().splitlines()) == 1


def test_a_plain_tello_with_tof_is_refused_before_take_off(monkeypatch, capsys, tmp_path: Path) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--robot", "tello", "--pilot", "stdin",
                            "--sensors", "tof", "--out", str(tmp_path / "x"))
    assert code == 2 and "--sensors tof needs one forward time-of-flight beam" in err and "Tello" in err
    assert len(err.strip().splitlines()) == 1


def test_run_records_the_readings(monkeypatch, capsys, tmp_path: Path) -> None:
    out = tmp_path / "run"
    code, _, _ = run_main(monkeypatch, capsys, "run", "Find the refrigerator", "--pilot", "oracle", "--sensors",
                          "multiranger", "--context", "plus", "--out", str(out), "--no-video", "--quiet")
    first = json.loads((out / "episode.jsonl").read_text().splitlines()[0])
    assert code == 0 and set(first["ranges"]) == {"front", "left", "right", "back", "up"}
    assert json.loads((out / "summary.json").read_text())["capabilities"]["range_sensor"] == "multiranger"


def test_bench_flies_a_suite_row_with_its_own_sensors(tmp_path: Path) -> None:
    suite = tmp_path / "suite.yaml"
    suite.write_text("scene: cabin\nrepetitions: 1\nrows:\n"
                     "  - {id: fridge-tof, spawn: living_room, query: Find the refrigerator, sensors: tof}\n"
                     "  - {id: fridge, spawn: living_room, query: Find the refrigerator}\n")
    out = bench_command(suite=str(suite), pilots="oracle", out=tmp_path / "bench", workers=1, progress=False,
                        episode_options={"context": "plus"}, render=False)
    steps = {row: json.loads((out / "runs" / "oracle" / row / "1" / "episode.jsonl").read_text().splitlines()[0])
             for row in ("fridge-tof", "fridge")}
    assert set(steps["fridge-tof"]["ranges"]) == {"front"} and "ranges" not in steps["fridge"]
    with pytest.raises(ConfigError, match="unknown sensors 'sonar'"):
        suite.write_text("scene: cabin\nrows:\n  - {spawn: living_room, query: Go to the bedroom, sensors: sonar}\n")
        bench_command(suite=str(suite), pilots="oracle", out=tmp_path / "bad", workers=1, progress=False)


def test_the_gymnasium_environments_observe_the_ranges() -> None:
    env = CabinEnv(width=32, height=24, sensors="multiranger")
    try:
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs) and obs["ranges"].shape == (5,)
    finally:
        env.close()
    house = HouseEnv(0, width=32, height=24, sensors="tof")
    try:
        obs, _ = house.reset(seed=0)
        assert house.observation_space.contains(obs) and obs["ranges"].dtype == np.float32
    finally:
        house.close()
    with pytest.raises(ConfigError, match="--sensors"):
        CabinEnv(width=32, height=24, sensors="radar")


def test_a_tt_reads_ext_tof_from_the_emulator() -> None:
    """The emulator answers `EXT tof?` from the simulator (mm; 8192 beyond range); the backend reads it back."""
    with rig(emulator={"ext_tof": True}, backend={"ext_tof": True}, sensors="tof") as (emu, env):
        env.reset("living_room")
        with emu._sim_lock:
            emu.sim.reset(Pose(3.0, 3.0, 1.0, 90.0))  # 0.55 m before the living room's north wall
        (near,) = env.ranges()
        with emu._sim_lock:
            emu.sim.reset(Pose(2.0, 1.0, 1.0, 90.0))
        (far,) = env.ranges()
    assert "EXT tof?" in env.link.sent and env.capabilities.range_sensor == "tof"
    with Simulator("cabin", SimConfig(render=False, sensors="tof", range_noise=False)) as sim:
        sim.reset(Pose(3.0, 3.0, 1.0, 90.0))
        exact = sim.ranges()[0].metres
    assert near.metres == pytest.approx(exact, abs=0.1)  # the emulated TT's reading carries its modelled noise
    assert far.metres is None and far.text() == "beyond 1.2 m"
    assert f"tof {TT_TOF_BEYOND_MM}" == emu._ext_tof() or far.metres is None


def test_a_plain_tello_backend_refuses_tof() -> None:
    from vlnpilot.robots.tello import TelloEnv

    with pytest.raises(ConfigError, match="--sensors tof needs one forward time-of-flight beam.*Tello"):
        TelloEnv("cabin", sensors="tof")
