"""Choosing the robot for `vln-pilot run --robot sim|tello` and serving the emulator; the CLI's thin wiring."""

from __future__ import annotations

import ipaddress
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

from vlnpilot.core.environment import Capabilities
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.scene import Scene

ROBOTS = ("sim", "tello")


def check_robot(robot: str, tello_host: str | None) -> str:
    key = str(robot).strip().lower()
    if key not in ROBOTS:
        raise UnknownNameError("robot", robot, ROBOTS)
    if key == "tello":
        from vlnpilot.core.extras import require

        require("tello", what="--robot tello")
    if tello_host is not None and key != "tello":
        raise ConfigError("--tello-host applies to --robot tello only")
    if tello_host is not None:
        try:
            ipaddress.ip_address(tello_host)  # djitellopy matches replies by the sender's address, not a name
        except ValueError:
            raise ConfigError(f"--tello-host must be an IP address (a Tello on its own Wi-Fi is 192.168.10.1), "
                              f"got {tello_host!r}") from None
    return key


def robot_capabilities(robot: str, sensors: str = "none", tello_host: str | None = None) -> Capabilities:
    """What `robot` senses when flown with `--sensors`; refuses (one line) a sensor it does not carry."""
    from vlnpilot.core.environment import check_sensors
    from vlnpilot.core.ranging import range_sensor

    wanted = range_sensor(sensors)
    if robot == "tello":
        from vlnpilot.robots.tello import tello_capabilities
        from vlnpilot.robots.tello_config import load_tello_config

        carried = tello_capabilities(load_tello_config(**({"host": tello_host} if tello_host else {})))
        robot = "Tello" if carried.range_sensor == "tof" else "plain Tello (tello.yaml: ext_tof false)"
    else:
        from vlnpilot.sim.simulator import Simulator

        carried = replace(Simulator.capabilities, range_sensor=wanted.name if wanted else "none")  # any, simulated
    check_sensors(carried, robot, sensors)
    return replace(carried, range_sensor=wanted.name if wanted else "none")


@contextmanager
def open_robot(robot: str, scene: Scene, *, tello_host: str | None = None, event_log: Path | None = None,
               operator: Any = None, sensors: str = "none") -> Iterator[Any]:
    """The environment for `robot`; a Tello is landed and released when the block ends, whatever happened."""
    if robot == "sim":
        from vlnpilot.sim import SimConfig, Simulator

        with Simulator(scene, SimConfig(sensors=sensors)) as env:
            yield env
        return
    from vlnpilot.robots.tello import TelloEnv
    from vlnpilot.robots.tello_config import load_tello_config

    config = load_tello_config(**({"host": tello_host} if tello_host else {}))
    tello = TelloEnv(scene, config, event_log=event_log, operator=operator, sensors=sensors)
    try:
        yield tello
    finally:
        tello.close()


def serve_emulator(scene: str, spawn: str | None, config: Any, say: Any = print,
                   stop: threading.Event | None = None) -> None:
    """Run the Tello emulator until Ctrl-C (or `stop`)."""
    from vlnpilot.robots.emulator import TelloEmulator

    stop = stop or threading.Event()
    emu: TelloEmulator | None = None
    try:  # around the whole block: a Ctrl-C right after the ready line must also stop it cleanly
        with TelloEmulator(scene, config, spawn=spawn) as emu:
            host, port = emu.address
            where = f"spawn {spawn or emu.sim.scene.spawns[0].id} of {emu.sim.scene.name}"
            say(f"Tello emulator (SDK 2.0) on {host}:{port}: state to port {config.state_port}, video "
                f"({emu.video.codec}) to port {config.video_port}; drone at {where}. "
                "Fly it with: vln-pilot run \"...\" --robot tello --tello-host 127.0.0.1. Ctrl-C stops it.")
            while not stop.wait(0.5):
                pass
    except KeyboardInterrupt:
        say(f"stopped; it executed {len(emu.log.executed) if emu else 0} moves")
