"""`vln-pilot tello-emulator`'s wiring (robots/session.py): its ports and the line that says how to fly it."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import pytest

from cli_support import run_main
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.exits import BAD_INPUT
from vlnpilot.robots.session import check_emulator_ports, serve_emulator


@pytest.mark.parametrize(("ports", "named"), [((9000, 9000, 11111), "--port and --state-port"),
                                              ((8889, 8890, 8890), "--state-port and --video-port"),
                                              ((7000, 7000, 7000), "--port and --state-port and --video-port")])
def test_two_channels_on_one_port_are_refused(ports, named) -> None:
    with pytest.raises(ConfigError, match=f"{named} are the same port"):
        check_emulator_ports(*ports)


def test_the_command_line_refuses_equal_ports_in_one_line(monkeypatch, capsys) -> None:
    code, _, err = run_main(monkeypatch, capsys, "tello-emulator", "--port", "9000", "--state-port", "9000")
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1 and "same port" in err


class _FakeEmulator:
    """Stands in for the emulator (no socket): it 'listens' where it was told."""

    def __init__(self, scene, config, spawn=None):
        self.address = (config.host, config.port)
        self.sim = SimpleNamespace(scene=SimpleNamespace(name="cabin", spawns=[SimpleNamespace(id="living_room")]))
        self.video = SimpleNamespace(codec="h264")
        self.log = SimpleNamespace(executed=[])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_the_ready_line_names_the_host_it_listens_on(monkeypatch) -> None:
    monkeypatch.setattr("vlnpilot.robots.emulator.TelloEmulator", _FakeEmulator)
    config = SimpleNamespace(host="127.0.0.2", port=8889, state_port=8890, video_port=11111)
    said: list[str] = []
    stop = threading.Event()
    stop.set()
    serve_emulator("cabin", None, config, say=said.append, stop=stop)
    assert "--tello-host 127.0.0.2" in said[0] and "127.0.0.1" not in said[0]
