"""The worker's side of a bench: one episode from its spec (plain, picklable data) to its results record.

Every executor (executors.py) runs `run_guarded(spec, simulators)` wherever it runs episodes, and reports
the outcome as an `Event`; only the parent writes results.jsonl.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import shutil
import socket
import threading
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from vlnpilot.core.errors import ConfigError, VLNPilotError


@dataclass(frozen=True)
class EpisodeSpec:
    """Everything a worker needs to fly and record one episode; plain data, picklable."""

    key: str
    pilot: str  # the SPEC, e.g. 'openai:gpt-4.1'
    row: str
    rep: int
    seed: int
    scene: str
    spawn: str
    query: str
    goal_room: str
    goal_target: str | None
    max_steps: int
    profile: str
    run_dir: str  # absolute: where the worker writes
    run_dir_rel: str  # relative to the bench directory: what results.jsonl records
    pilot_options: dict[str, Any] = field(default_factory=dict)
    episode_options: dict[str, Any] = field(default_factory=dict)  # extra EpisodeConfig fields (e.g. a shield)
    render: bool = True
    save_frames: bool = True
    spawn_jitter_m: float = 0.0
    spawn_jitter_deg: float = 0.0
    sensors: str = "none"  # the range sensors the drone carries (vlnpilot.core.ranging.SENSORS)
    camera: str = "ideal"  # what the front camera delivers (sim.camera_model.CAMERAS)
    randomize: int | None = None  # the domain randomisation seed of the row's world (docs/camera.md)
    mission: dict[str, Any] | None = None  # a mission of several stages (Mission.to_dict); None: the goal above
    events: dict[str, Any] | None = None  # the row's scenario of events (scene.events.Scenario.to_dict), issue 24
    rate_dir: str | None = None  # the bench's shared rate budgets (pilots/ratelimit.py), where every worker reads
    rate_limit: str | None = None  # 'RPM,TPM' of --rate-limit, until a provider's headers say otherwise


@dataclass(frozen=True)
class Event:
    kind: Literal["started", "finished", "failed"]
    key: str
    record: dict[str, Any] | None = None
    error: str | None = None
    worker: str | None = None


class SimulatorCache:
    """One Simulator per (thread, scene, settings), built on first use and reused for every later episode."""

    def __init__(self, per_thread: int = 4) -> None:
        self.per_thread = per_thread  # simulators kept per thread (each holds a model and GL renderers)
        self._local = threading.local()
        self._all: list[Any] = []
        self._lock = threading.Lock()

    def get(self, scene: str, config: Any, events: dict[str, Any] | None = None) -> Any:
        """The simulator of `scene` with `config` (a `SimConfig`) and a row's scenario of `events`."""
        from vlnpilot.scene.events import scene_with_recorded
        from vlnpilot.sim import Simulator

        sims = getattr(self._local, "sims", None)
        if sims is None:
            sims = self._local.sims = {}
        key = (scene, config, json.dumps(events, sort_keys=True) if events else None)
        if key not in sims:
            if len(sims) >= self.per_thread:  # a suite over many houses: keep the most recent few, not all
                self._close(sims.pop(next(iter(sims))))
            sims[key] = Simulator(scene_with_recorded(scene, events, "of the suite row"), key[1])
            with self._lock:
                self._all.append(sims[key])
        sims[key] = sims.pop(key)  # most recently used last
        return sims[key]

    def _close(self, sim: Any) -> None:
        with contextlib.suppress(Exception):
            sim.close()
        with self._lock:
            if sim in self._all:
                self._all.remove(sim)

    def close_thread(self) -> None:
        """Close this thread's simulators (their GL contexts must be released by the thread that owns them)."""
        for sim in (getattr(self._local, "sims", None) or {}).values():
            with contextlib.suppress(Exception):
                sim.close()
            with self._lock:
                if sim in self._all:
                    self._all.remove(sim)
        self._local.sims = {}


class TimedPilot:
    """Wraps a pilot to time every call (including failed ones); delegates everything else."""

    def __init__(self, pilot: Any):
        self._pilot = pilot
        self.latencies: list[float] = []

    def decide(self, pilot_input: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return self._pilot.decide(pilot_input)
        finally:
            self.latencies.append(round(time.perf_counter() - t0, 4))

    def __getattr__(self, name: str) -> Any:  # name, model, privileged, attach, ...
        return getattr(self._pilot, name)


def import_plugins(plugins: Sequence[str]) -> None:
    """Import modules that register extra pilots, executors or shields (`@register_pilot`, `@register_executor`,
    `@register_shield`), in a worker or in the parent."""
    for module in plugins:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ConfigError(f"cannot import plugin module {module!r}: {exc}") from None


def _pilot_options(spec: EpisodeSpec) -> dict[str, Any]:
    """The spec's pilot options, plus the row id for pilots that fly one recording per row (replay of trials)."""
    from vlnpilot.pilots.base import parse_spec, pilot_options_class

    wants_row = pilot_options_class(parse_spec(spec.pilot)[0]).accepts("row")
    return {**spec.pilot_options, "row": spec.row} if wants_row else dict(spec.pilot_options)


def execute_spec(spec: EpisodeSpec, simulators: SimulatorCache) -> dict[str, Any]:
    """Fly and record one episode; the results.jsonl record (without the parent's fields)."""
    from vlnpilot.core.rundir import git_sha
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.run import run_recorded_episode
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.pilots.ratelimit import parse_rate_limit, share_budgets
    from vlnpilot.prompting.render import prompt_hash
    from vlnpilot.sim import SimConfig
    from vlnpilot.tasks.mission import Mission
    from vlnpilot.tasks.task import Task

    frames = spec.save_frames and spec.render
    # the chase camera is seen only in the recorded frames (the episode pages of the report): without them, not rendered
    config = EpisodeConfig(max_steps=spec.max_steps, profile=spec.profile, seed=spec.seed, **spec.episode_options)
    sim = simulators.get(spec.scene, SimConfig(render=spec.render, spawn_jitter_m=spec.spawn_jitter_m,
                                               spawn_jitter_deg=spec.spawn_jitter_deg, sensors=spec.sensors,
                                               rear_camera=frames, camera=spec.camera, randomize=spec.randomize,
                                               detail=config.detail), spec.events)
    share_budgets(spec.rate_dir, parse_rate_limit(spec.rate_limit))  # before the pilot: it takes its budget
    pilot = TimedPilot(make_pilot(spec.pilot, **_pilot_options(spec)))
    run_dir = Path(spec.run_dir)
    if run_dir.exists():  # a leftover of an interrupted attempt: the rerun starts clean
        shutil.rmtree(run_dir)
    task = (Mission.from_dict(spec.mission) if spec.mission is not None
            else Task(query=spec.query, goal_room=spec.goal_room, goal_target=spec.goal_target))
    result = run_recorded_episode(sim, pilot, task, config, run_dir=run_dir, spawn=spec.spawn,
                                  pilot_spec=spec.pilot, save_frames=frames)
    return {
        "key": spec.key, "pilot": spec.pilot, "model": pilot.model, "row": spec.row, "rep": spec.rep,
        "seed": spec.seed, "spawn": spec.spawn, "query": spec.query, "goal_room": spec.goal_room,
        "goal_target": spec.goal_target, **({"events": spec.events} if spec.events else {}),
        "result": result.to_dict(), "call_latencies_s": pilot.latencies,
        "run_dir": spec.run_dir_rel,
        "provenance": {"prompt_hash": prompt_hash(spec.profile), "git_sha": git_sha(),
                       "worker": f"{socket.gethostname()}:{os.getpid()}"},
    }


def run_guarded(spec: EpisodeSpec, simulators: SimulatorCache) -> tuple[dict[str, Any] | None, str | None]:
    try:
        return execute_spec(spec, simulators), None
    except VLNPilotError as exc:
        return None, f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which keeps the key for --resume
        tb = traceback.format_exception(type(exc), exc, exc.__traceback__)
        return None, f"{type(exc).__name__}: {exc}\n" + "".join(tb[-6:])
