"""Operator safety and bad input with the Tello: Ctrl-C, battery, flight time, geofence, lost replies, time-outs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cli_support import run_main
from polling import wait_for
from tello_support import (  # noqa: F401  (loopback_only: the autouse guard)
    LOCAL_PORT,
    STATE_PORT,
    ThinkingPilot,
    emulator_config,
    free_udp_port,
    loopback_only,
    rig,
)
from vlnpilot.core.errors import RobotHalt
from vlnpilot.core.exits import LINK_FAULT
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.robots.clock import ManualClock
from vlnpilot.robots.emulator import TelloEmulator
from vlnpilot.robots.tello import TelloEnv
from vlnpilot.robots.tello_config import load_tello_config
from vlnpilot.robots.tello_link import RobotError
from vlnpilot.sim import Simulator
from vlnpilot.tasks.task import parse_query


def test_first_ctrl_c_lands_and_the_second_stops_the_motors(tmp_path: Path) -> None:
    log = tmp_path / "events.jsonl"
    with rig(handle_sigint=True, event_log=log) as (emu, env):
        env.reset("living_room")
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        assert wait_for(lambda: "land" in emu.log.events)
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
        assert wait_for(lambda: "emergency" in emu.log.events)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored by close()
    recorded = [json.loads(line) for line in log.read_text().splitlines()]
    assert [e["action"] for e in recorded if e["event"] == "operator_interrupt"] == ["land", "emergency"]


def test_a_battery_below_the_floor_refuses_take_off() -> None:
    with rig(emulator={"battery_pct": 25}) as (emu, env):
        with pytest.raises(RobotError, match=r"battery is at 25 %, below the take-off floor of 30 %"):
            env.reset("living_room")
        assert "takeoff" not in [c for _, c in emu.log.received]
        assert env.events[-1]["event"] == "battery_refused"


def test_crossing_the_geofence_lands_the_drone() -> None:
    with rig(backend={"geofence_m": 0.6}) as (emu, env):
        env.reset("living_room")
        env.step("A3")  # 0.5 m from take-off: inside
        with pytest.raises(RobotHalt, match="past the geofence of 0.6 m") as halt:
            env.step("A3")
        assert halt.value.landed and emu.landed.is_set() and not emu.flying
        assert [e["event"] for e in env.events][-2:] == ["geofence", "land"]


@pytest.mark.parametrize(("emulator", "backend", "event", "words"), [
    ({"battery_pct": 16.0}, {"takeoff_battery_pct": 10}, "battery_low", "below the landing floor of 15 %"),
    ({}, {"max_flight_s": 20.0}, "flight_time", "passed the limit of 20 s"),
])
def test_low_battery_and_flight_time_land_and_end_the_episode(tmp_path: Path, emulator, backend, event,
                                                              words) -> None:
    clock = ManualClock()
    with rig(clock=clock, emulator=emulator, backend=backend) as (emu, env):
        task = parse_query("Go to the bedroom", env.scene)
        result = run_episode(env, ThinkingPilot(clock, 12.0), task, EpisodeConfig(max_steps=10, shield="assist"),
                             spawn="living_room", recorder=Recorder(tmp_path, save_frames=False))
        assert result.outcome == "halted" and words in result.reason
        assert emu.landed.is_set() and not emu.flying
    _, steps = load_run(tmp_path)
    assert event in [e["event"] for e in steps[-1]["robot"]["events"]]  # recorded with the step


def test_a_lost_rotation_reply_is_judged_from_the_yaw_and_a_lost_translation_reply_halts() -> None:
    with rig(emulator={"drop_verbs": ("cw",)}, backend={"reply_timeout_s": 0.5}) as (emu, env):
        start = env.reset("living_room")
        obs = env.step("B3")  # its "ok" is lost: the yaw shows it happened
        assert obs.pose.yaw_deg == pytest.approx(start.pose.yaw_deg - 90, abs=1)
        assert emu.log.executed.count("cw 90") == 1 and env.link.sent.count("cw 90") == 1
        assert obs.info["events"][-1]["action"].endswith("the rotation happened")
        emu.config.drop_verbs = ("forward",)
        with pytest.raises(RobotHalt, match="not sent again") as halt:
            env.step("A2")
        assert not halt.value.landed and emu.flying  # hovering until the operator's word
        assert emu.log.executed.count("forward 25") == 1 and env.link.sent.count("forward 25") == 1
        env.close()  # the operator presses Enter: it lands
        assert emu.landed.is_set()


def test_stale_frames_are_dropped_when_the_video_lags(sim: Simulator) -> None:
    with rig(emulator={"video_delay_s": 0.4}, backend={"video_latency_s": 0.9}) as (emu, env):
        before = env.reset("living_room").pose
        obs = env.step("B3")
        after = emu.pose
    old_view, new_view = sim.reset(before).front_rgb, sim.reset(after).front_rgb
    err_new = np.abs(obs.front_rgb.astype(int) - new_view.astype(int)).mean()
    err_old = np.abs(obs.front_rgb.astype(int) - old_view.astype(int)).mean()
    assert err_new < err_old / 2, (err_new, err_old)  # the frame shows the drone after the rotation
    assert obs.info["frame_fresh"] and obs.info["frames_dropped"] > 0 and obs.info["frame_after_settle_s"] >= 0.9
    assert obs.info["decoded_fps"] > 0  # recorded: a backlog shows as a rate above the stream's


def test_a_tello_that_does_not_answer_gives_a_clear_time_out() -> None:
    silent = free_udp_port()  # nothing listens here
    config = load_tello_config(host="127.0.0.1", command_port=silent, local_port=LOCAL_PORT, state_port=STATE_PORT,
                               connect_timeout_s=0.3)
    env = TelloEnv("cabin", config, handle_sigint=False)
    with pytest.raises(RobotError, match=rf"no reply from a Tello at 127.0.0.1:{silent} within 0.6 s"):
        env.reset()
    env.close()


@pytest.mark.parametrize(("args", "words"), [
    (["--shield", "geometry"], "--shield geometry needs ground truth"),
    (["--shield", "depth"], "--shield depth needs a front depth image"),
    (["--pilot", "oracle"], "pilot 'oracle' flies on ground truth"),
    (["--robot", "drone"], "unknown robot 'drone'; valid robots: sim, tello"),
    (["--judge", "maybe"], "unknown judge 'maybe'; valid judges: ask, none"),
    (["--tello-host", "my-tello"], "--tello-host must be an IP address"),
    (["--tello-host", "8.8.8.8"], "--tello-host 8.8.8.8 is not on a local network"),  # refused before a packet
    (["--tello-host", "0.0.0.0"], "--tello-host 0.0.0.0 is not on a local network"),
    (["--robot", "sim", "--tello-host", "127.0.0.1"], "--tello-host applies to --robot tello only"),
])
def test_bad_tello_options_are_one_line_and_exit_2(monkeypatch, capsys, args, words) -> None:
    base = ["run", "Go to the bedroom", "--robot", "tello", "--pilot", "stdin"]
    code, _, err = run_main(monkeypatch, capsys, *base, *args)
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_the_cli_times_out_on_a_silent_tello_with_one_line_and_the_link_fault_code(tmp_path: Path) -> None:
    silent = free_udp_port()
    settings = tmp_path / "tello.yaml"
    settings.write_text(f"command_port: {silent}\nlocal_port: {free_udp_port('')}\nstate_port: {free_udp_port('')}\n"
                        "connect_timeout_s: 0.3\n")
    env = {**os.environ, "VLN_PILOT_TELLO_CONFIG": str(settings)}
    proc = subprocess.run([sys.executable, "-m", "vlnpilot.cli", "run", "Go to the bedroom", "--robot", "tello",
                           "--tello-host", "127.0.0.1", "--pilot", "stdin", "--out", str(tmp_path / "run")],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL, timeout=120)
    assert proc.returncode == LINK_FAULT, proc.stderr  # a link fault, not bad input (2)
    assert proc.stderr.strip().splitlines() == [
        f"error: no reply from a Tello at 127.0.0.1:{silent} within 0.6 s: is this computer on the Tello's Wi-Fi "
        "(TELLO-XXXXXX) and the drone switched on?"]


def test_ctrl_c_during_a_cli_run_lands_the_tello_and_keeps_the_record(tmp_path: Path) -> None:
    """`vln-pilot run --robot tello` in its own process; Ctrl-C while the (stdin) pilot thinks."""
    state_port = free_udp_port("")
    with TelloEmulator("cabin", emulator_config(state_port=state_port), spawn="living_room") as emu:
        host, port = emu.address
        settings = tmp_path / "tello.yaml"
        settings.write_text(f"command_port: {port}\nlocal_port: {free_udp_port('')}\nstate_port: {state_port}\n"
                            f"video_port: {emu.config.video_port}\nvideo_latency_s: 0.2\n")
        out = tmp_path / "run"
        proc = subprocess.Popen([sys.executable, "-m", "vlnpilot.cli", "run", "Go to the bedroom", "--robot", "tello",
                                 "--tello-host", host, "--pilot", "stdin", "--judge", "none", "--no-video",
                                 "--out", str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True,
                                env={**os.environ, "VLN_PILOT_TELLO_CONFIG": str(settings)})
        try:
            for line in proc.stderr:  # the stdin pilot's prompt: it now waits for an answer
                if line.startswith("answer with ONE line of JSON"):
                    break
            assert emu.flying
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 130, err
        assert "land" in emu.log.events and not emu.flying
    events = [json.loads(line) for line in (out / "robot_events.jsonl").read_text().splitlines()]
    assert [e["action"] for e in events if e["event"] == "operator_interrupt"] == ["land"]
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"
