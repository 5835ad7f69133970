"""The Ray executor: the bench's episodes as Ray actor calls (pip install 'vln-pilot[ray]'). The bench's rate budgets
live in one more actor on the driver's node (pilots/ratelimit_ray.py), so the workers need no shared filesystem."""

from __future__ import annotations

import contextlib
import os
import socket
from collections.abc import Iterator, Sequence
from dataclasses import replace
from typing import Any

from vlnpilot.bench.episode_job import EpisodeSpec, Event, SimulatorCache, import_plugins, run_guarded
from vlnpilot.bench.executors import BenchError, Executor, ExecutorOptions, register_executor, split_workers


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
        keeper = None
        if specs[0].rate_dir:  # the rate budgets in one actor on this node: the workers need no shared filesystem
            from vlnpilot.pilots.ratelimit_ray import start_keeper

            address, keeper = start_keeper(specs[0].rate_dir, specs[0].rate_limit)
            specs = [replace(spec, rate_dir=address) for spec in specs]
        try:
            yield from self._run(specs)
        finally:
            if keeper is not None:
                with contextlib.suppress(Exception):
                    self._ray.kill(keeper)

    def _run(self, specs: Sequence[EpisodeSpec]) -> Iterator[Event]:
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
        record, error = run_guarded(spec, self.sims)
        return record, error, self.name


@register_executor("ray")
def _ray(options: ExecutorOptions) -> Executor:
    return RayExecutor(options.workers, options.ray_address, options.plugins)
