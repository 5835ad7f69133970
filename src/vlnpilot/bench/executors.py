"""Where episodes run: the `Executor` protocol, its registry, and the built-in executors.

`inline` runs episodes in this thread, `local` in worker processes on this machine, `ray` on a Ray cluster
(ray_executor.py). Every executor runs the same function, `episode_job.run_guarded(spec, simulators)`, and
reports the same events (started / finished / failed) to the parent, which alone writes `results.jsonl`.
A new executor is a class with `describe`, `run(specs)` and `close()`, and a factory registered with
`@register_executor("NAME")`.

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
import multiprocessing as mp
import os
import queue
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, cast

if TYPE_CHECKING:
    from multiprocessing.context import ForkContext, ForkServerContext, SpawnContext

from vlnpilot.bench.episode_job import EpisodeSpec, Event, SimulatorCache, import_plugins, run_guarded
from vlnpilot.core.errors import ConfigError, UnknownNameError, VLNPilotError
from vlnpilot.core.exits import INTERRUPTED
from vlnpilot.core.registry import Registry


class BenchError(VLNPilotError):
    """A bench that cannot start or complete; the message says what to do (often: --resume)."""


class Executor(Protocol):
    """Runs episodes somewhere and reports them as events, in any order; the parent records them."""

    describe: str  # one line for the console: where and how many in flight

    def run(self, specs: Sequence[EpisodeSpec]) -> Iterator[Event]:
        """Yield `started` and then `finished` or `failed` for every spec (a generator the parent may close)."""

    def close(self) -> None:
        """Release what the executor holds (a Ray runtime it started); called once, after `run`."""


@dataclass(frozen=True)
class ExecutorOptions:
    workers: int | None = None  # episodes in flight; None: the executor's default (the cores it has)
    ray_address: str | None = None
    plugins: tuple[str, ...] = ()  # modules every worker imports (custom pilots registered by name)


ExecutorFactory = Callable[[ExecutorOptions], Executor]
# Built-in executors register below; `ray` registers itself when its module is imported (only when asked for);
# third parties register with `@register_executor` in a --plugin module or through the `vlnpilot.executors`
# entry-point group.
EXECUTOR_REGISTRY: Registry[ExecutorFactory] = Registry(
    "executor", group="vlnpilot.executors", builtins={"ray": "vlnpilot.bench.ray_executor"})


def register_executor(name: str) -> Callable[[ExecutorFactory], ExecutorFactory]:
    """Register an executor factory (ExecutorOptions -> Executor) under a name."""
    return EXECUTOR_REGISTRY.register(name)


def executor_names() -> tuple[str, ...]:
    return tuple(EXECUTOR_REGISTRY.names())


def executor_factory(name: str) -> ExecutorFactory:
    """The registered factory of an executor name; a bad name lists the known ones (before anything runs)."""
    try:
        return EXECUTOR_REGISTRY.get(name)
    except UnknownNameError as exc:
        raise ConfigError(exc.args[0]) from None


def make_executor(name: str, *, workers: int | None = None, ray_address: str | None = None,
                  plugins: Sequence[str] = ()) -> Executor:
    """An executor by name (local, ray, inline, or a registered one); a bad name lists the known ones."""
    factory = executor_factory(name)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
    return factory(ExecutorOptions(workers, ray_address, tuple(plugins)))


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
                record, error = run_guarded(spec, sims)
                yield Event("finished" if error is None else "failed", spec.key, record, error, "inline")
        finally:
            sims.close_thread()

    def close(self) -> None:
        """Nothing outlives `run`: its simulators are closed when it ends."""


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


def _interrupted(signum: int, frame: object) -> None:
    """SIGTERM in a worker: its episodes run in threads, which no signal reaches; close their records, then go."""
    from vlnpilot.core.rundir import close_open_records

    close_open_records("interrupted")
    os._exit(INTERRUPTED)


def _worker_main(tasks: Any, events: Any, threads: int, parent_pid: int, plugins: Sequence[str]) -> None:
    """Entry point of a local worker process: `threads` threads take specs from the shared queue."""
    _die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business; it terminates us
    signal.signal(signal.SIGTERM, _interrupted)  # ... and then the episodes in flight are recorded `interrupted`
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
                record, error = run_guarded(spec, sims)
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
        # typeshed gives `Process` only to the concrete contexts, and get_context(str) the base class's type
        ctx = cast("SpawnContext | ForkServerContext | ForkContext", mp.get_context(self.start_method))
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
        reaped: set[int | None] = set()
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

    def close(self) -> None:
        """Nothing outlives `run`: its worker processes are stopped when it ends."""


@register_executor("local")
def _local(options: ExecutorOptions) -> Executor:
    return LocalExecutor(options.workers, options.plugins)


@register_executor("inline")
def _inline(options: ExecutorOptions) -> Executor:
    return InlineExecutor(options.plugins)


EXECUTORS = executor_names()  # the built-in ones, in the order the errors list them
