"""What every bench script prints about the machine it measured on, and how the step-cost scripts time
simulators side by side (imported by the scripts beside it)."""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (or what platform knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def load_average() -> str:
    one, five, fifteen = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return f"{one:.2f}/{five:.2f}/{fifteen:.2f}"


def describe() -> str:
    """One line: CPU model, cores, Python, and the load average (other processes share the cores)."""
    return (f"{cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"load average {load_average()}")


def publish(text: str, out: Path, *, smoke: bool = False) -> None:
    """Print a result table and keep it in `out` (bench/results/ by default), saying where; a `--smoke` run only
    prints it (its few steps are no result to keep)."""
    print(text)
    if smoke:
        return
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out}", file=sys.stderr)


def median_ms(fn: Callable[[], object], reps: int) -> float:
    """The median of `reps` timed calls of `fn`, in milliseconds, after one untimed call (tables, caches)."""
    fn()
    took = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        took.append(time.perf_counter() - t0)
    return statistics.median(took) * 1000


def time_alternately(sims: dict[str, Any], steps: int, sequence: Sequence[str],
                     seed: int | None = None) -> dict[str, list[float]]:
    """The whole step of each simulator, flying the same commands from each spawn alternately step by step (the
    same poses, the same load on the machine): seconds per step, per key. Starts over from the spawn when one
    collides rather than grind against the obstacle; closes the simulators."""
    times: dict[str, list[float]] = {key: [] for key in sims}
    try:
        for spawn in next(iter(sims.values())).scene.spawns:
            for sim in sims.values():
                sim.reset(spawn.id, seed=seed)
                sim.step("E")  # warm-up: renderers, GL contexts and lens tables exist before anything is timed
                sim.reset(spawn.id, seed=seed)
            for i in range(steps):
                code = sequence[i % len(sequence)]
                collided = False
                for key, sim in sims.items():
                    t0 = time.perf_counter()
                    obs = sim.step(code)
                    times[key].append(time.perf_counter() - t0)
                    collided = collided or obs.collided
                if collided:
                    for sim in sims.values():
                        sim.reset(spawn.id, seed=seed)
    finally:
        for sim in sims.values():
            sim.close()
    return times
