"""Shared parts of the Tello tests: the loopback guard, free ports, and an emulator wired to a TelloEnv.

djitellopy binds its reply and state sockets once per process, so the whole test session uses one pair of
local ports (picked free at import); each emulator gets its own command and video ports.
"""

from __future__ import annotations

import io
import ipaddress
import socket
from contextlib import contextmanager
from typing import Any

import pytest

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.robots.clock import Clock, ManualClock
from vlnpilot.robots.emulator import EmulatorConfig, TelloEmulator
from vlnpilot.robots.operator import ConsoleOperator
from vlnpilot.robots.tello import TelloEnv
from vlnpilot.robots.tello_config import TelloConfig, load_tello_config

LOOPBACK = "127.0.0.1"


def free_udp_port(host: str = LOOPBACK) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


LOCAL_PORT, STATE_PORT = free_udp_port(""), free_udp_port("")  # djitellopy's, for the whole session


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@pytest.fixture(autouse=True)
def loopback_only(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int]]:
    """Fail the test if any Python socket sends to, or connects to, an address other than loopback."""
    targets: list[tuple[str, int]] = []
    real_sendto, real_connect = socket.socket.sendto, socket.socket.connect

    def check(address: Any) -> None:
        if isinstance(address, tuple) and address:
            targets.append(address[:2])
            if not _is_loopback(str(address[0])):
                raise AssertionError(f"a socket targets {address[0]}, which is not loopback")

    def sendto(self: socket.socket, data: bytes, *args: Any) -> int:
        check(args[-1])
        return real_sendto(self, data, *args)

    def connect(self: socket.socket, address: Any) -> None:
        check(address)
        return real_connect(self, address)

    monkeypatch.setattr(socket.socket, "sendto", sendto)
    monkeypatch.setattr(socket.socket, "connect", connect)
    return targets


def tello_config(emulator: TelloEmulator, **overrides: Any) -> TelloConfig:
    """Backend settings that reach `emulator` quickly (short settles; rc pulses as calibrated by default)."""
    host, port = emulator.address
    settings: dict[str, Any] = {"host": host, "command_port": port, "local_port": LOCAL_PORT,
                                "state_port": STATE_PORT, "video_port": emulator.config.video_port,
                                "connect_timeout_s": 2.0, "reply_timeout_s": 2.0, "video_latency_s": 0.2,
                                "calibration": {"move_settle_s": 0.0}}
    settings.update(overrides)
    return load_tello_config(**settings)


def emulator_config(**overrides: Any) -> EmulatorConfig:
    settings: dict[str, Any] = {"host": LOOPBACK, "port": free_udp_port(), "state_port": STATE_PORT,
                                "video_port": free_udp_port()}
    settings.update(overrides)
    return EmulatorConfig(**settings)


@contextmanager
def rig(*, spawn: str = "living_room", clock: Clock | None = None, emulator: dict[str, Any] | None = None,
        backend: dict[str, Any] | None = None, **env_options: Any):
    """An emulator and a TelloEnv talking to it; both closed afterwards. The operator presses Enter when asked."""
    env_options.setdefault("operator", ConsoleOperator(io.StringIO("\n" * 8), io.StringIO()))
    with TelloEmulator("cabin", emulator_config(**(emulator or {})), spawn=spawn, clock=clock) as emu:
        env_options.setdefault("handle_sigint", False)
        env = TelloEnv("cabin", tello_config(emu, **(backend or {})), clock=clock, **env_options)
        try:
            yield emu, env
        finally:
            env.close()


class ThinkingPilot:
    """Thinks `seconds` on the test clock before each answer, then rotates right 15° in Recognize Room (a slow model
    whose answers are always safe to fly: the tests measure time and the robot's limits, not the route)."""

    name, model = "thinking", "thinking-1"

    def __init__(self, clock: ManualClock, seconds: float):
        self.clock, self.seconds = clock, seconds

    def decide(self, pilot_input: PilotInput) -> Decision:
        self.clock.sleep(self.seconds)
        return Decision(room="living_room", movement="B1", state="Recognize Room", description="thinking")
