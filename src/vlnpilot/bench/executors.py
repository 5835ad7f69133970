"""Where episodes run: in this thread (`inline`), in local worker processes (`local`), or on Ray (`ray`).

Every executor runs the same function, `execute_spec(spec, simulators)`, and reports the same events
(started / finished / failed) to the parent, which alone writes `results.jsonl`.

Local executor: `workers` is the number of episodes in flight. It starts min(workers, cores) processes
(spawn context: no MuJoCo or OpenGL state is ever inherited through fork) and splits the episodes in flight
among them as threads. Each thread builds its own Simulator once and reuses it for every episode it runs
(a rendering context is bound to one thread). With the default (one episode per core) a CPU-bound pilot such
as the oracle uses every core; with `--workers 16` on 2 cores, 16 model-pilot episodes wait on the network
at once while rendering and recording share the cores. Workers die with the parent (PR_SET_PDEATHSIG and a
parent watchdog), so a killed bench leaves no orphan writing into its run directories.
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing as mp
import os
import queue
import shutil
import signal
import socket
import sys
import threading
import time
import traceback
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from vlnpilot.errors import ConfigError, VLNPilotError

EXECUTORS = ("local", "ray", "inline")


class BenchError(VLNPilotError):
    """A bench that cannot start or complete; the message says what to do (often: --resume)."""


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


@dataclass(frozen=True)
class Event:
    kind: Literal["started", "finished", "failed"]
    key: str
    record: dict[str, Any] | None = None
    error: str | None = None
    worker: str | None = None


# ---------------------------------------------------------------------------------------------- worker side
class SimulatorCache:
    """One Simulator per (thread, scene, settings), built on first use and reused for every later episode."""

    def __init__(self, per_thread: int = 4) -> None:
        self.per_thread = per_thread  # simulators kept per thread (each holds a model and GL renderers)
        self._local = threading.local()
        self._all: list[Any] = []
        self._lock = threading.Lock()

    def get(self, scene: str, render: bool, jitter_m: float, jitter_deg: float) -> Any:
        from vlnpilot.sim import SimConfig, Simulator

        sims = getattr(self._local, "sims", None)
        if sims is None:
            sims = self._local.sims = {}
        key = (scene, SimConfig(render=render, spawn_jitter_m=jitter_m, spawn_jitter_deg=jitter_deg))
        if key not in sims:
            if len(sims) >= self.per_thread:  # a suite over many houses: keep the most recent few, not all
                self._close(sims.pop(next(iter(sims))))
            sims[key] = Simulator(scene, key[1])
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
    """Import modules that register extra pilots (`@register_pilot`), in a worker or in the parent."""
    for module in plugins:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ConfigError(f"cannot import pilot plugin module {module!r}: {exc}") from None


def _pilot_options(spec: EpisodeSpec) -> dict[str, Any]:
    """The spec's pilot options, plus the row id for pilots that fly one recording per row (replay of trials)."""
    from vlnpilot.pilots.base import parse_spec, pilot_factory

    wants_row = getattr(pilot_factory(parse_spec(spec.pilot)[0]), "wants_row", False)
    return {**spec.pilot_options, "row": spec.row} if wants_row else dict(spec.pilot_options)


def execute_spec(spec: EpisodeSpec, simulators: SimulatorCache) -> dict[str, Any]:
    """Fly and record one episode; the results.jsonl record (without the parent's fields)."""
    from vlnpilot.episode import EpisodeConfig, run_episode
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.prompting import prompt_hash
    from vlnpilot.record import Recorder, git_sha
    from vlnpilot.tasks import Task

    sim = simulators.get(spec.scene, spec.render, spec.spawn_jitter_m, spec.spawn_jitter_deg)
    pilot = TimedPilot(make_pilot(spec.pilot, **_pilot_options(spec)))
    run_dir = Path(spec.run_dir)
    if run_dir.exists():  # a leftover of an interrupted attempt: the rerun starts clean
        shutil.rmtree(run_dir)
    recorder = Recorder(run_dir, save_frames=spec.save_frames and spec.render)
    config = EpisodeConfig(max_steps=spec.max_steps, profile=spec.profile, seed=spec.seed, **spec.episode_options)
    task = Task(query=spec.query, goal_room=spec.goal_room, goal_target=spec.goal_target)
    try:
        result = run_episode(sim, pilot, task, config, spawn=spec.spawn, recorder=recorder, pilot_spec=spec.pilot)
    finally:
        recorder.close()
        close = getattr(pilot._pilot, "close", None)
        if callable(close):
            with contextlib.suppress(Exception):
                close()
    return {
        "key": spec.key, "pilot": spec.pilot, "model": pilot.model, "row": spec.row, "rep": spec.rep,
        "seed": spec.seed, "spawn": spec.spawn, "query": spec.query, "goal_room": spec.goal_room,
        "goal_target": spec.goal_target, "result": result.to_dict(), "call_latencies_s": pilot.latencies,
        "run_dir": spec.run_dir_rel,
        "provenance": {"prompt_hash": prompt_hash(spec.profile), "git_sha": git_sha(),
                       "worker": f"{socket.gethostname()}:{os.getpid()}"},
    }


def _run_guarded(spec: EpisodeSpec, simulators: SimulatorCache) -> tuple[dict[str, Any] | None, str | None]:
    try:
        return execute_spec(spec, simulators), None
    except VLNPilotError as exc:
        return None, f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which keeps the key for --resume
        tb = traceback.format_exception(type(exc), exc, exc.__traceback__)
        return None, f"{type(exc).__name__}: {exc}\n" + "".join(tb[-6:])


# ------------------------------------------------------------------------------------------------- executors
class InlineExecutor:
    """Runs the episodes one after another in the calling thread (debugging, tests, a single episode)."""

    name = "inline"

    def __init__(self, plugins: Sequence[str] = ()):
        import_plugins(plugins)
        self.describe = "inline (1 episode at a time in this process)"

    def run(self, specs: Sequence[EpisodeSpec]) -> Iterator[Event]:
        sims = SimulatorCache()
        try:
            for spec in specs:
                yield Event("started", spec.key, worker="inline")
                record, error = _run_guarded(spec, sims)
                yield Event("finished" if error is None else "failed", spec.key, record, error, "inline")
        finally:
            sims.close_thread()


def default_workers() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def split_workers(workers: int, cores: int) -> list[int]:
    """Threads per process: min(workers, cores) processes sharing `workers` episodes in flight evenly."""
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    procs = max(1, min(workers, cores))
    base, extra = divmod(workers, procs)
    return [base + (1 if i < extra else 0) for i in range(procs)]


def _die_with_parent(parent_pid: int) -> None:
    """Make this worker die when the parent does: PR_SET_PDEATHSIG on Linux, and a watchdog thread anyway."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(Exception):
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _worker_main(tasks: Any, events: Any, threads: int, parent_pid: int, plugins: Sequence[str]) -> None:
    """Entry point of a local worker process: `threads` threads take specs from the shared queue."""
    _die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business; it terminates us
    name = f"{socket.gethostname()}:{os.getpid()}"
    try:
        import_plugins(plugins)
    except VLNPilotError as exc:
        events.put(("fatal", None, None, str(exc), name))
        return
    sims = SimulatorCache()

    def loop() -> None:
        try:
            while True:
                spec = tasks.get()
                if spec is None:
                    return
                events.put(("started", spec.key, None, None, name))
                record, error = _run_guarded(spec, sims)
                events.put(("finished" if error is None else "failed", spec.key, record, error, name))
        finally:
            sims.close_thread()

    pool = [threading.Thread(target=loop, name=f"episode-{i}") for i in range(threads)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    events.close()
    events.join_thread()


class LocalExecutor:
    """Worker processes on this machine, each with a few episode threads (see the module docstring)."""

    name = "local"

    def __init__(self, workers: int | None = None, plugins: Sequence[str] = (), start_method: str = "spawn"):
        self.workers = workers or default_workers()
        self.plan = split_workers(self.workers, default_workers())
        self.plugins = tuple(plugins)
        self.start_method = start_method
        threads = sorted(set(self.plan))
        per = f"{threads[0]}" if len(threads) == 1 else f"{threads[0]}-{threads[-1]}"
        self.describe = f"local: {self.workers} in flight = {len(self.plan)} process(es) x {per} thread(s)"

    def run(self, specs: Sequence[EpisodeSpec]) -> Iterator[Event]:
        if not specs:
            return
        ctx = mp.get_context(self.start_method)
        plan = split_workers(min(self.workers, len(specs)), default_workers())
        tasks, events = ctx.Queue(), ctx.Queue()
        for spec in specs:
            tasks.put(spec)
        for _ in range(sum(plan)):
            tasks.put(None)
        procs = [ctx.Process(target=_worker_main, args=(tasks, events, n, os.getpid(), self.plugins),
                             name=f"vln-bench-{i}", daemon=True) for i, n in enumerate(plan)]
        for p in procs:
            p.start()
        pending = {s.key for s in specs}
        running: dict[str, set[str]] = {}  # worker name -> keys it started and has not reported yet
        reaped: set[int] = set()
        try:
            while pending:
                try:
                    kind, key, record, error, worker = events.get(timeout=0.5)
                except queue.Empty:
                    dead = [p for p in procs if p.exitcode is not None and p.pid not in reaped]
                    for p in dead:  # episodes that a dead worker had started fail (and --resume reruns them)
                        reaped.add(p.pid)
                        name = f"{socket.gethostname()}:{p.pid}"
                        for key in sorted(running.pop(name, set())):
                            pending.discard(key)
                            yield Event("failed", key, error=f"worker process {p.pid} died (exit code {p.exitcode})",
                                        worker=name)
                    if len(reaped) == len(procs):
                        for key in sorted(pending):
                            yield Event("failed", key, error="not run: every worker process exited")
                        pending.clear()
                    continue
                if kind == "fatal":
                    raise BenchError(f"worker {worker} could not start: {error}")
                if kind == "started":
                    running.setdefault(worker, set()).add(key)
                    yield Event("started", key, worker=worker)
                    continue
                running.get(worker, set()).discard(key)
                pending.discard(key)
                yield Event(kind, key, record, error, worker)
        finally:
            for p in procs:
                if p.is_alive():
                    p.terminate()
            for p in procs:
                p.join(timeout=5)
                if p.is_alive():
                    p.kill()
                    p.join(timeout=5)
            for q in (tasks, events):
                q.cancel_join_thread()
                q.close()


class RayExecutor:
    """The same episodes as Ray actor calls: min(workers, cluster CPUs) actors, each with a few threads."""

    name = "ray"

    def __init__(self, workers: int | None = None, address: str | None = None, plugins: Sequence[str] = ()):
        try:
            import ray
        except ImportError:
            raise BenchError("the ray executor needs Ray: pip install 'vln-pilot[ray]' (or pip install ray)") from None
        self._ray = ray
        self._owns = not ray.is_initialized()
        if self._owns:
            try:
                ray.init(address=address, include_dashboard=False, ignore_reinit_error=True, log_to_driver=False)
            except Exception as exc:  # noqa: BLE001 - connection errors come in many types
                raise BenchError(f"cannot start or reach Ray (address={address or 'local'}): {exc}") from None
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self.workers = workers or cpus
        self.plan = split_workers(self.workers, cpus)
        self.plugins = tuple(plugins)
        self.describe = (f"ray ({address or 'local'}): {self.workers} in flight = {len(self.plan)} actor(s) "
                         f"on {cpus} CPU(s)")

    def run(self, specs: Sequence[EpisodeSpec]) -> Iterator[Event]:
        if not specs:
            return
        ray = self._ray
        plan = split_workers(min(self.workers, len(specs)), len(self.plan))
        actor_cls = ray.remote(num_cpus=1)(_RayWorker)
        actors = [actor_cls.options(max_concurrency=n).remote(list(self.plugins)) for n in plan]
        free = [n for n in plan]
        todo = list(reversed(specs))
        inflight: dict[Any, tuple[int, str]] = {}
        try:
            while todo or inflight:
                for i, actor in enumerate(actors):
                    while free[i] > 0 and todo:
                        spec = todo.pop()
                        inflight[actor.run.remote(spec)] = (i, spec.key)
                        free[i] -= 1
                        yield Event("started", spec.key, worker=f"ray-actor-{i}")
                done, _ = ray.wait(list(inflight), num_returns=1)
                for ref in done:
                    i, key = inflight.pop(ref)
                    free[i] += 1
                    try:
                        record, error, worker = ray.get(ref)
                    except Exception as exc:  # noqa: BLE001 - actor died, node lost, ...
                        record, error, worker = None, f"ray: {type(exc).__name__}: {exc}", f"ray-actor-{i}"
                    yield Event("finished" if error is None else "failed", key, record, error, worker)
        finally:
            for ref in inflight:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
            for actor in actors:
                with contextlib.suppress(Exception):
                    ray.kill(actor)

    def close(self) -> None:
        if self._owns:
            with contextlib.suppress(Exception):
                self._ray.shutdown()


class _RayWorker:
    """A Ray actor: per-thread simulators (threaded actor, `max_concurrency` threads), reused across calls."""

    def __init__(self, plugins: list[str]):
        import_plugins(plugins)
        self.sims = SimulatorCache()
        self.name = f"{socket.gethostname()}:{os.getpid()}"

    def run(self, spec: EpisodeSpec) -> tuple[dict[str, Any] | None, str | None, str]:
        record, error = _run_guarded(spec, self.sims)
        return record, error, self.name


def make_executor(name: str, *, workers: int | None = None, ray_address: str | None = None,
                  plugins: Sequence[str] = ()) -> Any:
    """An executor by name: local, ray or inline; a bad name lists the known ones."""
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
    if name == "local":
        return LocalExecutor(workers, plugins)
    if name == "ray":
        return RayExecutor(workers, ray_address, plugins)
    if name == "inline":
        return InlineExecutor(plugins)
    raise ConfigError(f"unknown executor {name!r}; valid executors: {', '.join(EXECUTORS)}")

