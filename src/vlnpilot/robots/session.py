"""Choosing the robot for `vln-pilot run --robot NAME` (`ROBOT_REGISTRY`: sim, tello, or a registered one) and
serving the emulator; the CLI's thin wiring."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

from vlnpilot.core.environment import Capabilities
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.registry import Registry
from vlnpilot.scene import Scene


class Robot:
    """What the command line needs of a robot flown with `--robot NAME`: what it carries for `--sensors`, and
    opening it as a context manager. A third party subclasses it and registers an instance (or the class) with
    `ROBOT_REGISTRY.register("NAME")` or through the `vlnpilot.robots` entry-point group."""

    extra: str | None = None  # the pip extra it needs (`core.extras`), checked before anything else
    takes_tello_host = False  # whether `--tello-host` applies to it

    def carried(self, sensors: str, tello_host: str | None) -> tuple[Capabilities, str]:
        """What it senses flown with `--sensors`, and how a refusal names it ('the NAME does not have ...')."""
        raise NotImplementedError

    def open(self, scene: Scene, *, tello_host: str | None, event_log: Path | None, operator: Any,
             sensors: str) -> AbstractContextManager[Any]:
        """The environment, released when the block ends, whatever happened. A robot whose frames are simulated
        also takes `camera`, `camera_lag_ms`, `randomize` and `detail` (docs/camera.md, docs/scenes.md)."""
        raise NotImplementedError


class SimRobot(Robot):
    """The embedded simulator: it simulates any range sensor asked for."""

    def carried(self, sensors: str, tello_host: str | None) -> tuple[Capabilities, str]:
        from vlnpilot.core.ranging import range_sensor
        from vlnpilot.sim.simulator import Simulator

        wanted = range_sensor(sensors)
        return replace(Simulator.capabilities, range_sensor=wanted.name if wanted else "none"), "sim"

    def open(self, scene: Scene, *, tello_host: str | None, event_log: Path | None, operator: Any,
             sensors: str, camera: str | None = None, camera_lag_ms: float | None = None,
             randomize: int | None = None, detail: str = "plain") -> AbstractContextManager[Any]:
        from vlnpilot.sim import SimConfig, Simulator

        return Simulator(scene, SimConfig(sensors=sensors, camera=camera or "ideal", camera_lag_ms=camera_lag_ms,
                                          randomize=randomize, detail=detail))


class TelloRobot(Robot):
    """A real DJI Tello (or the emulator) over djitellopy: its modules are imported only when it is asked for."""

    extra = "tello"
    takes_tello_host = True

    def carried(self, sensors: str, tello_host: str | None) -> tuple[Capabilities, str]:
        from vlnpilot.robots.tello import tello_capabilities
        from vlnpilot.robots.tello_config import load_tello_config

        carried = tello_capabilities(load_tello_config(**({"host": tello_host} if tello_host else {})))
        return carried, "Tello" if carried.range_sensor == "tof" else "plain Tello (tello.yaml: ext_tof false)"

    @contextmanager
    def open(self, scene: Scene, *, tello_host: str | None, event_log: Path | None, operator: Any,
             sensors: str, detail: str = "plain") -> Iterator[Any]:
        from vlnpilot.robots.tello import TelloEnv
        from vlnpilot.robots.tello_config import load_tello_config

        config = load_tello_config(**({"host": tello_host} if tello_host else {}))
        tello = TelloEnv(scene, config, event_log=event_log, operator=operator, sensors=sensors)
        try:
            yield tello
        finally:
            tello.close()  # landed and released, whatever happened


# Robots by name (`core.registry`); `--robot` accepts every name in it.
ROBOT_REGISTRY: Registry[Robot | type[Robot]] = Registry("robot", group="vlnpilot.robots")
ROBOT_REGISTRY.add("sim", SimRobot())
ROBOT_REGISTRY.add("tello", TelloRobot())


def get_robot(robot: str) -> Robot:
    """The registered robot called `robot` (a registered class is instantiated); a bad name lists the valid."""
    key = str(robot).strip().lower()
    if key not in ROBOT_REGISTRY:
        raise UnknownNameError("robot", robot, ROBOT_REGISTRY.names())
    entry = ROBOT_REGISTRY.get(key)
    return entry() if isinstance(entry, type) else entry


def check_robot(robot: str, tello_host: str | None) -> str:
    """The robot's registered name, once its extra is installed and `--tello-host` fits it (one line if not)."""
    key, found = str(robot).strip().lower(), get_robot(robot)
    if found.extra is not None:
        from vlnpilot.core.extras import require

        require(found.extra, what=f"--robot {key}")
    if tello_host is not None and not found.takes_tello_host:
        raise ConfigError(f"--tello-host applies to --robot {_host_robots()} only")
    if tello_host is not None:
        from vlnpilot.robots.tello_config import check_tello_host

        check_tello_host(tello_host, '--tello-host')
    return key


def _host_robots() -> str:
    return " or ".join(name for name in ROBOT_REGISTRY.names() if get_robot(name).takes_tello_host)


def robot_capabilities(robot: str, sensors: str = "none", tello_host: str | None = None) -> Capabilities:
    """What `robot` senses when flown with `--sensors`; refuses (one line) a sensor it does not carry."""
    from vlnpilot.core.environment import check_sensors
    from vlnpilot.core.ranging import range_sensor

    wanted = range_sensor(sensors)
    carried, shown_as = get_robot(robot).carried(sensors, tello_host)
    check_sensors(carried, shown_as, sensors)
    return replace(carried, range_sensor=wanted.name if wanted else "none")


def check_camera_for(robot: str, camera: str | None, camera_lag_ms: float | None, randomize: int | None) -> None:
    """Refuse (one line) a simulated camera or world for a robot whose frames are real: a Tello's own stream is
    never post-processed (its emulator simulates the Tello's camera itself, its lag as `--video-delay`). In
    simulation a lag without the tello camera is refused by `pilots.replay.check_replay_camera`, after a replay's
    own refusal (a replay's recorded lag with `--camera ideal` is a replay flown with other frames)."""
    from vlnpilot.core.cameras import check_camera

    key = str(robot).strip().lower()
    if camera is not None:
        camera = check_camera(camera)
    if key == "sim":
        return
    if camera == "ideal":
        raise ConfigError(f"--robot {key} sends its own camera's frames: --camera ideal applies to --robot sim only "
                          "(simulate the Tello's camera in its emulator: vln-pilot tello-emulator --camera tello)")
    if randomize is not None:
        raise ConfigError(f"--randomize applies to --robot sim only (the emulator takes it: vln-pilot tello-emulator "
                          f"--randomize {randomize})")
    if camera_lag_ms is not None:
        seconds = f"{camera_lag_ms / 1000:g}"
        raise ConfigError(f"--camera-lag-ms applies to --robot sim only (the emulator's frame lag is its "
                          f"--video-delay, in seconds: vln-pilot tello-emulator --video-delay {seconds})")


@contextmanager
def open_robot(robot: str, scene: Scene, *, tello_host: str | None = None, event_log: Path | None = None,
               operator: Any = None, sensors: str = "none", camera: str | None = None,
               camera_lag_ms: float | None = None, randomize: int | None = None,
               detail: str = "plain") -> Iterator[Any]:
    """The environment for `robot`; a Tello is landed and released when the block ends, whatever happened.
    `camera`, `camera_lag_ms`, `randomize`, `detail`: how a simulator's frames are made (`check_camera_for` first);
    each reaches `open` only when set, so a robot registered before they existed opens as it did."""
    imaging = {key: value for key, value in (("camera", camera), ("camera_lag_ms", camera_lag_ms),
                                             ("randomize", randomize)) if value is not None}
    if detail != "plain":
        imaging["detail"] = detail
    if str(robot).strip().lower() != "sim":
        imaging = {}  # a real camera (check_camera_for and --detail's check refused what does not apply)
    with get_robot(robot).open(scene, tello_host=tello_host, event_log=event_log, operator=operator,
                               sensors=sensors, **imaging) as env:
        yield env


def check_emulator_ports(command: int, state: int, video: int) -> None:
    """Commands, state and video each need their own port (one socket cannot be all three): ConfigError if not."""
    ports = {"--port": command, "--state-port": state, "--video-port": video}
    shared = [name for name, port in ports.items() if list(ports.values()).count(port) > 1]
    if shared:
        raise ConfigError(f"{' and '.join(shared)} are the same port ({ports[shared[0]]}); give commands, state and "
                          "video three different ports, e.g. 8889, 8890 and 11111")


def serve_emulator(scene: str, spawn: str | None, config: Any, say: Any = print,
                   stop: threading.Event | None = None) -> None:
    """Run the Tello emulator until Ctrl-C (or `stop`)."""
    from vlnpilot.robots.emulator import TelloEmulator

    check_emulator_ports(config.port, config.state_port, config.video_port)
    stop = stop or threading.Event()
    emu: TelloEmulator | None = None
    try:  # around the whole block: a Ctrl-C right after the ready line must also stop it cleanly
        with TelloEmulator(scene, config, spawn=spawn) as emu:
            host, port = emu.address
            where = f"spawn {spawn or emu.sim.scene.spawns[0].id} of {emu.sim.scene.name}"
            say(f"Tello emulator (SDK 2.0) on {host}:{port}: state to port {config.state_port}, video "
                f"({emu.video.codec}) to port {config.video_port}; drone at {where}. "
                f"Fly it with: vln-pilot run \"...\" --robot tello --tello-host {host}. Ctrl-C stops it.")
            while not stop.wait(0.5):
                pass
    except KeyboardInterrupt:
        say(f"stopped; it executed {len(emu.log.executed) if emu else 0} moves")
