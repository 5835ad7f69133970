"""The Tello backend through djitellopy against the emulator: a full episode, keep-alive, lost replies, frames."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from tello_support import (  # noqa: F401  (loopback_only: the autouse guard)
    ThinkingPilot,
    emulator_config,
    loopback_only,
    rig,
    tello_config,
)
from vlnpilot import cli
from vlnpilot.core.commands import get_command
from vlnpilot.core.errors import RobotHalt
from vlnpilot.core.records import Pose, wrap_deg
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.robots.clock import ManualClock
from vlnpilot.robots.emulator import TelloEmulator
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

FAST_PULSES = {"calibration": {side: {"speed": 20, "duration_s": 0.5, "settle_s": 0.0}
                               for side in ("forward_10cm", "left_10cm", "right_10cm")} | {"move_settle_s": 0.0}}
POSITION_TOLERANCE_M = 0.01  # per rc pulse: an rc pulse is timed on the wall clock (loopback jitter of a few ms)


@pytest.fixture(scope="module")
def sim_trial(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sim trial to replay on the Tello: the oracle flies living room -> bedroom (19 steps, 13 rc pulses)."""
    run_dir = tmp_path_factory.mktemp("sim-trial")
    with Simulator("cabin", SimConfig(render=False)) as sim:
        task = parse_query("Go to the bedroom", sim.scene)
        result = run_episode(sim, make_pilot("oracle"), task, EpisodeConfig(shield="assist"), spawn="living_room",
                             recorder=Recorder(run_dir, save_frames=False))
    assert result.outcome == "success"
    return run_dir


def replay_in_sim(codes: list[str], spawn: str = "living_room"):
    with Simulator("cabin", SimConfig(render=False)) as sim:
        sim.reset(spawn)
        for code in codes:
            assert not sim.step(code).collided
        return sim.pose


def test_a_replayed_sim_trial_ends_where_the_simulator_ends(sim_trial: Path, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """`vln-pilot run --robot tello` end to end: djitellopy, UDP, H.264, the emulator, the recording and report."""
    with TelloEmulator("cabin", emulator_config(), spawn="living_room") as emu:
        settings = tmp_path / "tello.yaml"
        settings.write_text(yaml.safe_dump(tello_config(emu, **FAST_PULSES).model_dump(exclude={"host"})))
        monkeypatch.setenv("VLN_PILOT_TELLO_CONFIG", str(settings))
        out = tmp_path / "tello"
        result = CliRunner().invoke(cli.app, ["run", "Go to the bedroom", "--robot", "tello", "--tello-host",
                                              "127.0.0.1", "--pilot", f"replay:{sim_trial}", "--out", str(out),
                                              "--no-video", "--quiet"], input="y\n")
        tello_pose = emu.pose
    assert result.exit_code == 0, result.output
    summary, steps = load_run(out)
    assert summary["result"]["outcome"] == "success" and summary["result"]["judged_by"] == "operator"  # "y"
    assert "this robot has no rear camera" in (out / "report.html").read_text()  # the report shows what there is
    executed = [s["executed"] for s in steps]
    _, sim_steps = load_run(sim_trial)
    assert executed == [s["executed"] for s in sim_steps]  # the same commands (assist acted on the same poses)
    sim_pose = replay_in_sim(executed)
    pulses = sum(get_command(c).amount == 0.10 for c in executed)
    tolerance = POSITION_TOLERANCE_M * pulses + 0.005
    assert tello_pose.distance_xy(sim_pose) <= tolerance, (tello_pose, sim_pose)  # the emulated drone
    assert abs(wrap_deg(tello_pose.yaw_deg - sim_pose.yaw_deg)) <= 1.0
    assert abs(tello_pose.z - sim_pose.z) <= 0.01
    dead_reckoned = Pose(**summary["end_pose"])
    assert dead_reckoned.distance_xy(sim_pose) <= 1e-3  # dead reckoning is exact in commanded displacements
    assert summary["capabilities"] == {"ground_truth": False, "depth": False, "rear_view": False,
                                       "contact_sensing": False}
    assert all(s["collided"] is None for s in steps)  # unknown, not False
    assert all(s["robot"]["frame_fresh"] and s["robot"]["frame_after_settle_s"] >= 0.2 for s in steps)
    assert "rear" not in summary["start_frames"]  # no rear camera, no rear frames
    events = [json.loads(line)["event"] for line in (out / "robot_events.jsonl").read_text().splitlines()]
    assert events == ["takeoff", "land"]


def test_keepalive_while_a_pilot_takes_12_s_per_answer(tmp_path: Path) -> None:
    clock = ManualClock()
    with rig(clock=clock) as (emu, env):
        task = parse_query("Go to the bedroom", env.scene)
        result = run_episode(env, ThinkingPilot(clock, 12.0), task, EpisodeConfig(max_steps=3, shield="assist"),
                             spawn="living_room")
        takeoff_t = next(t for t, c in emu.log.received if c == "takeoff")
        gaps = emu.log.gaps(since=takeoff_t)
        assert result.outcome == "max_steps" and result.steps == 3  # 36 s of thinking, still flying
        assert emu.flying and not emu.auto_landed.is_set()
        assert max(gaps) <= 5.5, max(gaps)
        assert env.link.keepalives >= 6 and "battery?" in env.link.sent


def test_thirty_percent_of_replies_lost_never_repeats_a_move(tmp_path: Path) -> None:
    codes = ["B2", "C2", "B1", "C1", "B3", "C3", "A2", "B2", "A3", "C2"] * 2
    with rig(emulator={"seed": 5}, backend={"reply_timeout_s": 0.5}) as (emu, env):
        env.reset("living_room")
        emu.config.drop_replies = 0.3  # from take-off on
        setup = len(emu.log.executed)  # "up 20" to the flight height
        intended: list[str] = []
        halted = None

        for code in codes:
            cmd = get_command(code)
            sdk = ("cw" if code.startswith("B") else "ccw") if cmd.is_rotation else "forward"
            intended.append(f"{sdk} {round(cmd.amount if cmd.is_rotation else cmd.amount * 100)}")
            try:
                env.step(code)
            except RobotHalt as exc:
                halted = exc
                break
        executed = emu.log.executed[setup:]
        env.close()  # lands on the operator's word when a lost translation reply left it hovering
        assert emu.landed.is_set() and emu.log.events[-1] == "land"
    motion_sent = [c for c in env.link.sent if c.split()[0] in ("forward", "cw", "ccw")]
    assert motion_sent == intended  # each motion sent exactly once, in order
    assert executed == intended  # and executed exactly once: nothing repeated
    assert emu.log.dropped  # replies were lost
    assert halted is None or "not sent again" in str(halted)  # a lost translation reply halts, hovering
    lost = [e for e in env.events if e["event"] == "lost_reply"]
    assert lost and all(e["command"] in intended for e in lost)


def test_the_assist_shield_keeps_the_guard_acting_without_ground_truth(scene) -> None:
    """The Tello's default 'assist': the oscillation guard acts on the map and the pose, with no shield."""
    from vlnpilot.core.commands import COMMANDS
    from vlnpilot.core.fsm import State
    from vlnpilot.robots.tello import TelloEnv
    from vlnpilot.safety import make_safety

    env = TelloEnv(scene, handle_sigint=False)  # never reset: nothing is sent
    pose = Pose(2.0, 2.0, 1.0, 0.0)
    codes = ("B1", "C1", "B1", "C1", "B1")
    executed = {}
    for name in ("assist", "off"):
        layer = make_safety(name, env, scene)
        executed[name] = [layer.filter(i, State.REACH_OBJECT, COMMANDS[c], State.REACH_OBJECT, pose).command.code
                          for i, c in enumerate(codes, start=1)]
        assert layer.name == name and layer.shield is None
    assert executed["off"] == list(codes)
    assert executed["assist"] != list(codes) and "E" in executed["assist"]  # a reversal vetoed: hover
