"""Serve the live app: in a background thread beside a flying episode (`run --live`), or until Ctrl-C (`watch`).

The socket is bound here, before uvicorn starts, so that a port in use or a bad address is one clear error.
A station that controls a run always has a token (env VLN_LIVE_TOKEN, else a fresh one per run), shown in the
address it prints; off loopback even a read-only station needs one. See live/guard.py for what is checked.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import socket
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import uvicorn

from vlnpilot.core.errors import ConfigError, VLNPilotError
from vlnpilot.core.rundir import load_run
from vlnpilot.live.app import create_live_app
from vlnpilot.live.control import LiveControl
from vlnpilot.pilots.base import Pilot
from vlnpilot.scene import load_scene
from vlnpilot.server.app import is_loopback
from vlnpilot.server.net import bind_socket

TOKEN_ENV = "VLN_LIVE_TOKEN"
DEFAULT_PORT = 8765


def _exposed(control: LiveControl | None) -> str:
    """What a station without a token would give away: the controls of a flight, or (read-only) a run's record."""
    return "fly the drone" if control is not None else "see the run (its camera frames, path and the pilot's text)"


class LiveStation:
    """The live app on `host:port` (port 0: any free port), served from a daemon thread until `close()`."""

    def __init__(self, run_dir: Path, *, control: LiveControl | None = None, scene: Any | None = None,
                 host: str = "127.0.0.1", port: int = DEFAULT_PORT, token: str | None = None):
        token = token if token is not None else (os.environ.get(TOKEN_ENV) or None)
        if token is None and not is_loopback(host):  # a choice to expose the station: the operator's own token
            raise ConfigError(f"the live station on {host} without a token would let anyone who reaches it "
                              f"{_exposed(control)}; set one, e.g. export {TOKEN_ENV}=$(openssl rand -hex 16), or "
                              "bind 127.0.0.1")
        if token is None and control is not None:  # even on loopback: any local process could fly otherwise
            token = secrets.token_urlsafe(16)
        self.token = token
        self._socket = _bind(host, port)
        self.port = self._socket.getsockname()[1]
        self.host = host
        app = create_live_app(run_dir, control=control, token=token, scene=scene, host=host)
        config = uvicorn.Config(app, log_level="warning", lifespan="off", timeout_graceful_shutdown=2)
        self._server = uvicorn.Server(config)
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="live-station", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    @property
    def page_url(self) -> str:
        """The page's address with the token after '#' (the page reads it there; a fragment is never sent)."""
        return self.url + (f"#token={self.token}" if self.token else "")

    @property
    def native_id(self) -> int | None:
        """The serving thread's id for the OS (bench/live_cost.py reads its CPU time)."""
        return self._thread.native_id

    def _serve(self) -> None:
        self._server.run(sockets=[self._socket])

    def wait(self) -> None:
        """Serve until Ctrl-C (the thread is a daemon: it never holds up the process's exit)."""
        while self._thread.is_alive():
            self._thread.join(0.5)

    def close(self) -> None:
        self._server.should_exit = True
        self._thread.join(5)
        self._socket.close()

    def __enter__(self) -> LiveStation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _bind(host: str, port: int) -> socket.socket:
    sock = bind_socket(host, port, "the live station")
    sock.set_inheritable(True)
    return sock


@contextlib.contextmanager
def live_control(run_dir: Path, pilot: Pilot, scene: Any, *, host: str, port: int,
                 say: Callable[[str], None] = print) -> Iterator[LiveControl]:
    """`run --live`: the station beside the episode; yields the control to give run_episode."""
    control = LiveControl(pilot)
    with LiveStation(run_dir, control=control, scene=scene, host=host, port=port) as station:
        say(f"live station: {station.page_url}  (the address holds this run's token: share it only with who may fly)")
        try:
            yield control
        finally:
            control.finish()


def watch_run(run_dir: Path, *, host: str, port: int, say: Callable[[str], None] = print) -> None:
    """`watch`: serve a finished or running run read-only from its files until Ctrl-C."""
    summary, _ = load_run(run_dir)  # a ConfigError when it is not a run directory
    try:
        scene = load_scene(summary.get("scene") or "")
    except VLNPilotError:  # a scene this machine does not know (a real room): the page shows no plan
        scene = None
    with LiveStation(run_dir, scene=scene, host=host, port=port) as station:
        say(f"watching {run_dir}: {station.url}  (read-only; Ctrl-C to stop)")
        with contextlib.suppress(KeyboardInterrupt):
            station.wait()
