"""Cost of one simulator step: the motion with its collision sweep plus the front and rear renders.

Runs a fixed command sequence from each spawn of the cabin and prints the median and p90 of a full step,
then the split (sweep only, front render, rear render), and the machine it ran on. The budget is 40 ms a step
with both renders at 640x480.

    .venv/bin/python bench/step_cost.py [--steps 40] [--width 640] [--height 480]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

from machine import cpu_model  # bench/machine.py, beside this script

from vlnpilot.core.commands import get_command
from vlnpilot.sim import SimConfig, Simulator, drone  # selects the headless GL backend before mujoco loads

# A mix of forward moves, turns, lateral moves and a hover; some runs end against walls or furniture,
# which exercises the bisection as well.
SEQUENCE = ("A1", "B1", "A2", "C2", "D1", "A1", "D2", "C1", "A3", "B2", "E", "A1", "C3", "A2", "B1", "A1")
BUDGET_MS = 40.0


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40, help="steps per spawn (default 40)")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    args = parser.parse_args()

    times = measure(args.steps, args.width, args.height)
    import mujoco

    n = len(times["step"])
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, MuJoCo {mujoco.__version__}, "
          f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, Python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.2f} (other processes share the cores)")
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


if __name__ == "__main__":
    main()
