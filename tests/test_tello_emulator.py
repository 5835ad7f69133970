"""The Tello emulator through djitellopy: the SDK's rules, its state packets, and H.264 that djitellopy decodes."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys

import numpy as np
import pytest

from polling import wait_for
from tello_support import emulator_config, free_udp_port, loopback_only, rig  # noqa: F401  (loopback_only: autouse guard)
from vlnpilot.core.errors import ConfigError
from vlnpilot.robots.clock import ManualClock
from vlnpilot.robots.emulator import OUT_OF_RANGE, EmulatorConfig, TelloEmulator


def test_the_loopback_guard_stops_a_packet_to_another_address() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s, pytest.raises(AssertionError, match="not loopback"):
        s.sendto(b"command", ("192.0.2.1", 8889))  # TEST-NET-1: the guard raises before anything is sent


def test_the_emulator_listens_on_loopback_only() -> None:
    with pytest.raises(ConfigError, match="loopback only"):
        EmulatorConfig(host="0.0.0.0")
    assert (EmulatorConfig().port, EmulatorConfig().state_port, EmulatorConfig().video_port) == (8889, 8890, 11111)


def test_sdk_rules_moves_below_20_cm_are_out_of_range_and_rc_gets_no_reply() -> None:
    clock = ManualClock()
    with TelloEmulator("cabin", emulator_config(), spawn="living_room", clock=clock) as emu:
        assert emu.handle("forward 50") is None  # not in SDK mode yet: ignored, like the Tello
        assert emu.handle("command") == "ok"
        assert emu.handle("forward 50") == "error Motor stop"  # on the ground
        assert emu.handle("takeoff") == "ok"
        start = emu.pose
        assert emu.handle("forward 10") == OUT_OF_RANGE
        assert emu.handle("cw 0") == OUT_OF_RANGE
        assert emu.pose == start  # refused moves do not move the drone
        assert emu.handle("forward 20") == "ok"
        assert emu.pose.distance_xy(start) == pytest.approx(0.20, abs=1e-6)
        assert emu.handle("cw 90") == "ok"
        assert emu.pose.yaw_deg == pytest.approx(start.yaw_deg - 90)
        assert emu.handle("rc 0 20 0 0") is None
        assert emu.handle("keepalive").startswith("unknown command")  # SDK 2.0 firmware
        assert emu.handle("battery?") == "100"
        assert emu.log.executed == ["forward 20", "cw 90"]


def test_auto_land_after_15_s_without_a_command_and_the_battery_drains() -> None:
    clock = ManualClock()
    with TelloEmulator("cabin", emulator_config(), spawn="living_room", clock=clock) as emu:
        emu.handle("command")
        emu.handle("takeoff")
        clock.sleep(14.0)
        emu.handle("battery?")  # a command inside 15 s: still flying
        assert emu.flying and not emu.auto_landed.is_set()
        assert emu.battery == pytest.approx(100 - 14.0 * emu.config.battery_drain_pct_per_s)
        clock.sleep(15.5)
        assert emu.auto_landed.wait(timeout=10)  # the state thread notices the silence
        assert not emu.flying and "auto_land" in emu.log.events


def test_djitellopy_decodes_the_h264_video_and_reads_the_state_packets() -> None:
    with rig() as (emu, env):
        obs = env.reset("living_room")
        assert obs.front_rgb.shape == (480, 640, 3)
        expected = _render(emu)
        diff = np.abs(obs.front_rgb.astype(int) - expected.astype(int)).mean()
        assert diff < 12, diff  # H.264 at the emulator's quality: a few grey levels of error
        assert obs.info["battery_pct"] >= 99 and obs.info["tof_cm"] == 100  # from the state packets
        assert obs.info["frame_fresh"]


def _render(emu: TelloEmulator) -> np.ndarray:
    from vlnpilot.sim import Simulator

    with Simulator("cabin") as sim:
        return sim.reset(emu.pose).front_rgb


def test_a_fraction_of_replies_is_dropped_when_asked() -> None:
    with TelloEmulator("cabin", emulator_config(drop_replies=0.3, seed=3), spawn="living_room") as emu:
        host, port = emu.address
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((host, 0))
            for _ in range(100):
                s.sendto(b"command", (host, port))
            assert wait_for(lambda: len(emu.log.received) == 100)
            s.settimeout(1.0)  # every reply that was sent is already on its way over loopback
            answered = 0
            try:
                while True:
                    answered += s.recvfrom(64)[0] == b"ok"
            except TimeoutError:
                pass
        assert len(emu.log.dropped) == 100 - answered
        assert 15 <= len(emu.log.dropped) <= 45  # 30 % of 100, seeded


def test_the_tello_emulator_command_answers_on_loopback_and_stops_on_ctrl_c() -> None:
    port = free_udp_port()
    proc = subprocess.Popen([sys.executable, "-m", "vlnpilot.cli", "tello-emulator", "--port", str(port),
                             "--state-port", str(free_udp_port()), "--video-port", str(free_udp_port())],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert f"on 127.0.0.1:{port}" in proc.stdout.readline()  # printed once it listens
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(10)
            s.sendto(b"command", ("127.0.0.1", port))
            assert s.recvfrom(64)[0] == b"ok"
            s.sendto(b"takeoff", ("127.0.0.1", port))
            assert s.recvfrom(64)[0] == b"ok"
            s.sendto(b"forward 10", ("127.0.0.1", port))
            assert s.recvfrom(64)[0] == OUT_OF_RANGE.encode()
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "stopped" in out


def test_the_tello_emulator_command_refuses_an_unknown_spawn_in_one_line() -> None:
    proc = subprocess.run([sys.executable, "-m", "vlnpilot.cli", "tello-emulator", "--spawn", "garage"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "unknown spawn 'garage'" in proc.stderr


def test_the_video_falls_back_to_mpeg4_when_pyav_has_no_h264_encoder(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fallback stream is still one that djitellopy's reader decodes (format probed from the UDP bytes)."""
    from vlnpilot.robots import emulator_video

    monkeypatch.setattr(emulator_video, "CODECS", ("no-such-h264-encoder", "mpeg4"))
    with rig() as (emu, env):
        assert emu.video.codec == "mpeg4"
        obs = env.reset("living_room")
        diff = np.abs(obs.front_rgb.astype(int) - _render(emu).astype(int)).mean()
        assert obs.info["frame_fresh"] and diff < 15, diff
