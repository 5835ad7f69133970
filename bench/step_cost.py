"""Cost of one simulator step: the motion with its collision sweep plus the front and rear renders, and what
rendering the front camera only saves, step and paper-suite bench alike (issue 27).

Runs a fixed command sequence from each spawn of the cabin and prints, with the machine it ran on:
- the median and p90 of a full step, then the split (sweep only, kinematics, front render, rear render);
- a step with both cameras against a step with the front camera only (`SimConfig(rear_camera=False)`), two
  simulators flying the same commands step by step, so that both see the same load (target: front only at most
  55 % of both); and what building a renderer costs (once per simulator: a bench worker keeps its simulators, and
  so their GL contexts, across episodes);
- the paper suite flown by the oracle on 2 workers (`bench_command`), with frames and the chase view (what
  `vln-pilot bench` records for its report) and without (`--no-report`): wall time and the table (target: at
  most 10 s; the table must stay 50/50, SPL 0.885, 13.1 mean steps).
The exit code is 1 if the oracle's table changed (a correctness check, not a timing one). The budget is 40 ms a
step with both renders at 640x480. `--smoke`: 2 steps per spawn and a 10-episode, 2-step bench in this process
(for the tests).

    .venv/bin/python bench/step_cost.py [--steps 40] [--width 640] [--height 480] [--workers 2] [--smoke]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_model, load_average, time_alternately  # bench/machine.py, beside this script

from vlnpilot.core.commands import get_command
from vlnpilot.sim import SimConfig, Simulator, drone  # selects the headless GL backend before mujoco loads

# A mix of forward moves, turns, lateral moves and a hover; some runs end against walls or furniture,
# which exercises the bisection as well.
SEQUENCE = ("A1", "B1", "A2", "C2", "D1", "A1", "D2", "C1", "A3", "B2", "E", "A1", "C3", "A2", "B1", "A1")
BUDGET_MS = 40.0
FRONT_ONLY_TARGET = 0.55  # a step without the rear camera, as a share of a step with both (issue 27)
BENCH_TARGET_S = 10.0
ORACLE_TABLE = (50, 50, 0.885, 13.1)  # the paper suite's oracle row: episodes, successes, SPL, mean steps


def percentile(values: list[float], q: float) -> float:
    s = sorted(values)
    k = (len(s) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (k - lo)


def ms(seconds: float) -> float:
    return seconds * 1000.0


def measure(steps: int, width: int, height: int, scene: str = "cabin") -> dict[str, list[float]]:
    import mujoco  # after vlnpilot.sim, which picks the headless GL backend

    sim = Simulator(scene, SimConfig(width=width, height=height, rear_width=width, rear_height=height))
    times: dict[str, list[float]] = {"step": [], "sweep": [], "front": [], "rear": [], "forward": []}
    try:
        for spawn in sim.scene.spawns:
            sim.reset(spawn)
            sim.step("E")  # warm-up: renderers and GL contexts exist before we time anything
            sim.reset(spawn)
            for i in range(steps):
                cmd = get_command(SEQUENCE[i % len(SEQUENCE)])
                start = sim.pose
                t0 = time.perf_counter()
                obs = sim.step(cmd)  # the whole step, as the controller sees it
                t1 = time.perf_counter()
                times["step"].append(t1 - t0)
                # the parts, replayed from the same start pose (pure: the sweep does not change the sim's pose)
                t0 = time.perf_counter()
                sim.sweep(start, cmd.motion())
                t1 = time.perf_counter()
                sim.contact_at(obs.pose)
                mujoco.mj_forward(sim.model, sim.data)
                t2 = time.perf_counter()
                sim.render(drone.FRONT_CAMERA)
                t3 = time.perf_counter()
                sim.render(drone.REAR_CAMERA)
                t4 = time.perf_counter()
                times["sweep"].append(t1 - t0)
                times["forward"].append(t2 - t1)
                times["front"].append(t3 - t2)
                times["rear"].append(t4 - t3)
                if obs.collided:  # start over from the spawn rather than grind against the obstacle
                    sim.reset(spawn)
    finally:
        sim.close()
    return times


def measure_front_only(steps: int, width: int, height: int, scene: str = "cabin") -> dict[str, list[float]]:
    """The whole step of two simulators flying the same commands, one with both cameras and one with the front
    only, alternately step by step (the same poses, the same load on the machine)."""
    return time_alternately(
        {"both": Simulator(scene, SimConfig(width=width, height=height, rear_width=width, rear_height=height)),
         "front": Simulator(scene, SimConfig(width=width, height=height, rear_camera=False))}, steps, SEQUENCE)


def renderer_build_ms(width: int, height: int, reps: int = 3) -> float:
    """The median time to build one `mujoco.Renderer` (its GL context and buffers) for the cabin."""
    import mujoco

    sim = Simulator("cabin")
    try:
        built = []
        for _ in range(reps):
            t0 = time.perf_counter()
            renderer = mujoco.Renderer(sim.model, height, width)
            built.append(time.perf_counter() - t0)
            renderer.close()
    finally:
        sim.close()
    return ms(statistics.median(built))


def oracle_bench(frames: bool, workers: int, reps: int | None = None, max_steps: int | None = None,
                 executor: str = "local") -> tuple[float, tuple]:
    """Wall time of the paper suite flown by the oracle, and its table row (episodes, successes, SPL, mean steps)."""
    from rich.console import Console

    from vlnpilot.bench import bench_command
    from vlnpilot.bench.results import summarize

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench"
        t0 = time.monotonic()
        bench_command(suite="paper", pilots="oracle", reps=reps, max_steps=max_steps, workers=workers, out=out,
                      executor=executor, progress=False, frames=frames, console=Console(file=io.StringIO()))
        wall = time.monotonic() - t0
        records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    s = summarize("oracle", records)
    return wall, (s.episodes, s.successes, round(s.spl, 3), round(s.mean_steps, 1))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40, help="steps per spawn (default 40)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--workers", type=int, default=2, help="episodes in flight in the oracle bench (default 2)")
    parser.add_argument("--smoke", action="store_true", help="2 steps per spawn, a 10-episode 2-step bench in-process")
    args = parser.parse_args()
    if args.smoke:
        args.steps = 2
    import mujoco

    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, MuJoCo {mujoco.__version__}, "
          f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, Python {platform.python_version()}, "
          f"load average {load_average()} (1/5/15 min; other processes share the cores)")
    times = measure(args.steps, args.width, args.height)
    n = len(times["step"])
    print(f"steps: {n} ({args.steps} per spawn x 3 spawns), both cameras {args.width}x{args.height}")
    print(f"{'part':<28}{'median ms':>10}{'p90 ms':>10}")
    rows = (("step (sweep + both renders)", "step"), ("  sweep only", "sweep"),
            ("  kinematics (mj_forward)", "forward"), ("  front render", "front"), ("  rear render", "rear"))
    for label, key in rows:
        v = [ms(t) for t in times[key]]
        print(f"{label:<28}{statistics.median(v):>10.1f}{percentile(v, 0.9):>10.1f}")
    med = ms(statistics.median(times["step"]))
    verdict = "within" if med <= BUDGET_MS else f"over by {med - BUDGET_MS:.1f} ms ({med / BUDGET_MS:.2f}x)"
    print(f"budget {BUDGET_MS:.0f} ms per step: median {med:.1f} ms, {verdict}")

    pair = measure_front_only(args.steps, args.width, args.height)
    both, front = (ms(statistics.median(pair[k])) for k in ("both", "front"))
    share = front / both
    print(f"a whole step, alternately, {len(pair['both'])} each: both cameras {both:.1f} ms, front only "
          f"{front:.1f} ms = {100 * share:.0f} % (target <= {100 * FRONT_ONLY_TARGET:.0f} %: "
          f"{'met' if share <= FRONT_ONLY_TARGET else 'MISSED'})")
    print(f"building a {args.width}x{args.height} renderer: {renderer_build_ms(args.width, args.height):.0f} ms "
          "(once per simulator; a bench worker keeps its simulators across episodes)")

    reps, max_steps, executor = (1, 2, "inline") if args.smoke else (None, None, "local")
    changed = False
    for frames, what in ((True, "frames and chase view (vln-pilot bench)"), (False, "no frames (--no-report)")):
        wall, row = oracle_bench(frames, args.workers, reps, max_steps, executor)
        ok = args.smoke or row == ORACLE_TABLE
        changed |= not ok
        print(f"paper suite, oracle, {args.workers} workers, {what}: {wall:.1f} s (target <= {BENCH_TARGET_S:.0f} s: "
              f"{'met' if wall <= BENCH_TARGET_S else 'missed'}); {row[1]}/{row[0]} successes, SPL {row[2]:.3f}, "
              f"{row[3]:.1f} mean steps{'' if ok else ' -- the TABLE CHANGED'}")
    print(f"load average after: {load_average()}")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
