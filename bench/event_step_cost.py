"""Cost of a simulator step with two movers (a person and a pet walking) against a static step (issue 24).

Two simulators of the cabin, one still and one with a scenario of two movers that walk back and forth the whole
time, fly the same command sequence step by step (interleaved, so that both see the same load), each step with
its collision sweep and the front render at 640x480 (what a bench step does). Prints the medians and their ratio
with the machine it ran on, and keeps the table in bench/results/event_step_cost.txt. Acceptance: the step with
two movers costs at most 1.2x the static step. `--smoke`: a few steps (for the tests).

    .venv/bin/python bench/event_step_cost.py [--steps 120] [--smoke]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.scene import load_scene
from vlnpilot.scene.events import scenario_from_dict, with_scenario
from vlnpilot.sim import SimConfig, Simulator  # selects the headless GL backend before mujoco loads

SEQUENCE = ("A1", "B1", "A2", "C2", "E", "A1", "C1", "E", "B2", "A1", "D1", "D2")
TARGET = 1.2
TWO_MOVERS = {"name": "two-movers", "scene": "cabin", "seed": 1, "events": [
    {"kind": "person", "path": [[1.0, 1.2], [2.6, 2.4]], "repeat": True},
    {"kind": "pet", "path": [[0.8, 2.2], [2.8, 1.0]], "repeat": True},
]}


def measure(steps: int, width: int, height: int) -> tuple[list[float], list[float]]:
    cfg = SimConfig(width=width, height=height, rear_camera=False)
    still = Simulator(load_scene("cabin"), cfg)
    moving = Simulator(with_scenario(load_scene("cabin"), scenario_from_dict(TWO_MOVERS)), cfg)
    times: tuple[list[float], list[float]] = ([], [])
    for sim in (still, moving):  # warm-up: renderers and GL contexts exist before anything is timed
        sim.reset("living_room")
        sim.step("E")
    for sim in (still, moving):
        sim.reset("living_room", seed=1)
    for i in range(steps):
        for sim, out in ((still, times[0]), (moving, times[1])):
            t0 = time.perf_counter()
            obs = sim.step(SEQUENCE[i % len(SEQUENCE)])
            out.append(time.perf_counter() - t0)
            if obs.collided:  # start again where nothing is in the way
                sim.reset("living_room", seed=i)
    assert len(moving.movers()) == 2, "both movers must be in the scene while it is timed"
    still.close()
    moving.close()
    return times


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=120)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--smoke", action="store_true", help="a few steps, for the tests")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "event_step_cost.txt")
    args = ap.parse_args()
    steps = 6 if args.smoke else args.steps
    still, moving = measure(steps, args.width, args.height)
    a, b = statistics.median(still) * 1000, statistics.median(moving) * 1000
    ratio = b / a
    text = (f"event_step_cost: {steps} steps each, front render {args.width}x{args.height}, interleaved\n"
            f"machine: {describe()}\n"
            f"static step   median {a:7.2f} ms\n"
            f"two movers    median {b:7.2f} ms\n"
            f"ratio {ratio:.2f}x (target <= {TARGET}x): {'ok' if ratio <= TARGET else 'OVER'}\n")
    publish(text, args.out, smoke=args.smoke)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
