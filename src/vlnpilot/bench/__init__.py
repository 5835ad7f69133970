"""The benchmark harness: suites x pilots x repetitions, in parallel, resumable, tabulated as the paper's Table 4.

    from vlnpilot.bench import bench_command
    bench_command(suite="paper", pilots="oracle", out="runs/bench-paper")   # -> the bench directory

See runner.py for the directory layout and the resume rules, manifest.py for bench.json, executors.py for where
episodes run (and how to register another executor), episode_job.py for what a worker does with one episode.
"""

from vlnpilot.bench.command import bench_command
from vlnpilot.bench.episode_job import EpisodeSpec
from vlnpilot.bench.executors import (
    EXECUTORS,
    BenchError,
    Executor,
    default_workers,
    make_executor,
    register_executor,
)
from vlnpilot.bench.results import ResultsLog, percentile, summarize, wilson_interval
from vlnpilot.bench.runner import BenchReport, BenchSettings, run_bench, write_tables
from vlnpilot.bench.suite import Suite, SuiteError, SuiteRow, builtin_suites, episode_seed, load_suite
from vlnpilot.bench.tables import render_tables

__all__ = [
    "EXECUTORS", "BenchError", "BenchReport", "BenchSettings", "EpisodeSpec", "Executor", "ResultsLog", "Suite",
    "SuiteError", "SuiteRow", "bench_command", "builtin_suites", "default_workers", "episode_seed", "load_suite",
    "make_executor", "percentile", "register_executor", "render_tables", "run_bench", "summarize", "wilson_interval",
    "write_tables",
]
