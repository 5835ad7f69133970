"""The Ray executor flies the same episodes to the same results as the local one (a local Ray, 1 CPU)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from vlnpilot.bench import BenchSettings, ResultsLog, run_bench

ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'vln-pilot[ray]')")

SUITE = """\
name: small
repetitions: 2
max_steps: 30
rows:
  - {id: to-bedroom, spawn: living_room, query: Go to the bedroom}
  - {id: sink, spawn: bathroom, query: Find the sink in the bathroom}
"""
VOLATILE = {"wall_time_s", "latency_s_total"}


def _by_key(out: Path) -> dict[str, dict]:
    return {r["key"]: r for r in ResultsLog(out / "results.jsonl").read()}


@pytest.mark.timeout(180)
def test_ray_executor_gives_the_same_results_as_the_local_one(tmp_path: Path):
    (tmp_path / "small.yaml").write_text(SUITE)
    common = dict(suite=str(tmp_path / "small.yaml"), render=False, progress=False, workers=2)
    local = run_bench(BenchSettings(**common, out=tmp_path / "local"))
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        remote = run_bench(BenchSettings(**common, out=tmp_path / "ray", executor="ray"))
    finally:
        ray.shutdown()
    assert local.failed == remote.failed == {} and local.finished == remote.finished == 4
    assert local.config_hash == remote.config_hash  # the executor is not part of the config
    a, b = _by_key(tmp_path / "local"), _by_key(tmp_path / "ray")
    assert sorted(a) == sorted(b)
    for key in a:
        assert {k: v for k, v in a[key]["result"].items() if k not in VOLATILE} == \
               {k: v for k, v in b[key]["result"].items() if k not in VOLATILE}
        for field in ("seed", "model", "run_dir", "pilot", "row", "rep"):
            assert a[key][field] == b[key][field]
    assert all(r["result"]["outcome"] == "success" for r in b.values())
    assert _without_latency(tmp_path / "ray" / "table.md") == _without_latency(tmp_path / "local" / "table.md")


def _without_latency(table: Path) -> str:
    """The table with the two latency cells (p50, p95) of each summary row blanked: wall-clock, never equal."""
    return re.sub(r"\| [0-9.]+ \| [0-9.]+ \|$", "| p50 | p95 |", table.read_text(), flags=re.M)
