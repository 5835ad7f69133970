"""The shared rate budgets of a bench on a Ray cluster without a shared filesystem: one Ray actor holds them.

The actor (`BudgetKeeper`) runs on the driver's node, uses no CPU, and keeps the budgets as the same files in the
bench's `rate/` directory there (so the progress line reads them as ever); its calls run one at a time, and its clock
is the only one. Every worker's model pilot reaches it by name (`ratelimit.RayBudget`, a `RateBudget`'s methods): one
actor call per HTTP attempt to take a request (the wait, if any, is slept in the worker) and one per response to
adapt the budget. Needs Ray (`pip install 'vln-pilot[ray]'`); imported only where Ray runs the bench.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from vlnpilot.pilots.ratelimit import NAMESPACE, RAY_ACTOR, RateBudget, budget_file, parse_rate_limit


class BudgetKeeper:
    """The budgets of one bench, per provider and model (a Ray actor; plain Python for the tests)."""

    def __init__(self, directory: str, default: str | None = None, clock: Callable[[], float] = time.time):
        self.directory, self.default, self.clock = Path(directory), parse_rate_limit(default), clock
        self.budgets: dict[Path, RateBudget] = {}

    def _budget(self, provider: str, model: str) -> RateBudget:
        path = budget_file(self.directory, provider, model)
        if path not in self.budgets:
            self.budgets[path] = RateBudget(path, self.default, self.clock)
        return self.budgets[path]

    def try_take(self, provider: str, model: str) -> float:
        return self._budget(provider, model).try_take()

    def observe(self, provider: str, model: str, status: int, headers: Mapping[str, str]) -> None:
        self._budget(provider, model).observe(status, headers)

    def charge(self, provider: str, model: str, tokens: int) -> None:
        self._budget(provider, model).charge(tokens)

    def snapshot(self, provider: str, model: str) -> dict[str, Any]:
        return self._budget(provider, model).snapshot()

    def ready(self) -> bool:
        return True


def start_keeper(directory: str | Path, default: str | None = None) -> tuple[str, Any]:
    """Start the keeper on this (the driver's) node: (the budget address `ray-actor:NAME` for the workers, the
    actor handle, to kill when the bench ends)."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    name = f"vlnpilot-rate-{uuid.uuid4().hex[:12]}"
    here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
    keeper: Any = ray.remote(num_cpus=0)(BudgetKeeper)
    actor = keeper.options(name=name, namespace=NAMESPACE, scheduling_strategy=here).remote(str(directory), default)
    ray.get(actor.ready.remote())  # started before the first worker looks for it
    return RAY_ACTOR + name, actor
