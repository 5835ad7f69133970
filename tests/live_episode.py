"""A live simulator episode for the live-station tests: the oracle flies, but only as fast as the test lets it.

`GatedOracle.release(n)` lets the pilot answer n more times; the loop otherwise waits inside `decide`, so a test
knows exactly where the loop is without sleeping. `LiveEpisode` runs the episode in a thread beside a station.
"""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path
from typing import Any

from vlnpilot.core.rundir import Recorder
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import EpisodeResult
from vlnpilot.live.control import LiveControl, Refused
from vlnpilot.live.station import LiveStation
from vlnpilot.pilots.base import PilotError
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.scene import load_scene
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

GATE_TIMEOUT_S = 60.0  # a test that forgets to release its pilot fails instead of hanging


class GatedOracle(OraclePilot):
    def __init__(self) -> None:
        super().__init__()
        self._permits = threading.Semaphore(0)
        self.calls = 0

    def release(self, n: int = 1) -> None:
        for _ in range(n):
            self._permits.release()

    def decide(self, pin: Any):  # noqa: ANN201
        if not self._permits.acquire(timeout=GATE_TIMEOUT_S):
            raise PilotError("the test never released the gated pilot", fatal=True)
        self.calls += 1
        return super().decide(pin)


class LiveEpisode:
    """"Go to the bathroom" from the living room, flown in a thread with a live station on a free port."""

    def __init__(self, run_dir: Path, *, max_steps: int = 40, token: str | None = None):
        scene = load_scene("cabin")
        self.run_dir = run_dir
        self.pilot = GatedOracle()
        self.control = LiveControl(self.pilot)
        self.station = LiveStation(run_dir, control=self.control, scene=scene, port=0, token=token)
        self.records: list[dict[str, Any]] = []
        self._stepped = threading.Condition()
        self.result: EpisodeResult | None = None
        task = parse_query("Go to the bathroom", scene)
        config = EpisodeConfig(max_steps=max_steps)

        def fly() -> None:  # its own simulator: a GL context belongs to the thread that renders with it
            recorder = Recorder(run_dir)
            sim = Simulator(scene, SimConfig(width=320, height=240, rear_width=160, rear_height=120))
            try:
                self.result = run_episode(sim, self.pilot, task, config, spawn="living_room", recorder=recorder,
                                          on_step=self._on_step, pilot_spec="gated-oracle", control=self.control)
            finally:
                recorder.close("failed")
                self.control.finish()
                sim.close()

        self.thread = threading.Thread(target=fly, name="live-episode", daemon=True)
        self.thread.start()

    def _on_step(self, record: dict[str, Any]) -> None:
        with self._stepped:
            self.records.append(record)
            self._stepped.notify_all()

    def wait_steps(self, n: int, timeout: float = 30.0) -> None:
        with self._stepped:
            assert self._stepped.wait_for(lambda: len(self.records) >= n, timeout), f"{len(self.records)} steps < {n}"

    def wait_status(self, predicate: Any, timeout: float = 30.0) -> dict[str, Any]:
        """The control status once `predicate(status)` holds (the control notifies on every change)."""
        deadline = time.monotonic() + timeout
        with self.control._cond:
            while not predicate(self.control.status()):
                assert time.monotonic() < deadline, f"status never matched: {self.control.status()}"
                self.control._cond.wait(0.5)
            return self.control.status()

    def close(self) -> EpisodeResult | None:
        if self.thread.is_alive():
            with contextlib.suppress(Refused):  # the episode may have ended meanwhile
                self.control.act("stop")
            self.pilot.release(3)
            self.thread.join(30)
        self.station.close()
        return self.result
