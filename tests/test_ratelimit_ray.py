"""The rate budgets of a bench on a Ray cluster without a shared filesystem (pilots/ratelimit_ray.py, issue 27): one
actor on the driver's node holds them; the workers reach it by name. The keeper's logic on an injected clock, then
the actor itself in a local Ray (1 CPU), when Ray is installed."""

from __future__ import annotations

import pytest

from vlnpilot.pilots.ratelimit import RAY_ACTOR, RayBudget, budget_file, budget_for, share_budgets
from vlnpilot.pilots.ratelimit_ray import BudgetKeeper


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_the_keeper_holds_one_budget_per_provider_and_model(tmp_path) -> None:
    clock = Clock()
    keeper = BudgetKeeper(str(tmp_path / "rate"), "60", clock)
    assert keeper.try_take("OpenAI", "gpt-4.1") == 0.0
    assert keeper.try_take("OpenAI", "gpt-4.1") == pytest.approx(1.0)  # 60 rpm: the bucket holds one request
    assert keeper.try_take("Anthropic", "claude-sonnet-4-6") == 0.0  # another model: its own budget
    keeper.observe("OpenAI", "gpt-4.1", 429, {"retry-after": "20"})
    assert keeper.try_take("OpenAI", "gpt-4.1") == pytest.approx(20.0)
    keeper.charge("OpenAI", "gpt-4.1", 10)
    assert budget_file(tmp_path / "rate", "OpenAI", "gpt-4.1").is_file()  # where the progress line reads it


def test_a_worker_given_an_actor_address_gets_a_ray_budget() -> None:
    share_budgets(RAY_ACTOR + "vlnpilot-rate-x")
    try:
        budget = budget_for("OpenAI", "gpt-4.1")
        assert isinstance(budget, RayBudget) and (budget.name, budget.model) == ("vlnpilot-rate-x", "gpt-4.1")
        assert budget_for("OpenAI", "gpt-4.1") is budget  # one per provider and model in the process
    finally:
        share_budgets(None)


@pytest.mark.timeout(120)
def test_workers_in_other_processes_share_the_actors_budget(tmp_path) -> None:
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'vln-pilot[ray]')")
    from vlnpilot.pilots.ratelimit_ray import start_keeper

    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        address, keeper = start_keeper(tmp_path / "rate", "60")
        name = address.removeprefix(RAY_ACTOR)

        @ray.remote(num_cpus=1)
        def worker_take(actor_name: str) -> float:  # another process, as a bench worker is
            return RayBudget(actor_name, "OpenAI", "gpt-4.1").try_take()

        assert ray.get(worker_take.remote(name)) == 0.0
        wait = RayBudget(name, "OpenAI", "gpt-4.1").try_take()  # the worker took the bucket's only request
        assert 0.5 < wait <= 1.0
        RayBudget(name, "OpenAI", "gpt-4.1").observe(429, {"Retry-After": "30"})
        assert 29.0 < ray.get(worker_take.remote(name)) <= 30.0  # the pause reaches the other process
        assert budget_file(tmp_path / "rate", "OpenAI", "gpt-4.1").is_file()
        ray.kill(keeper)
    finally:
        ray.shutdown()
