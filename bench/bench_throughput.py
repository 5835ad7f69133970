"""Bench throughput with a model pilot: the paper suite against a fake OpenAI server that answers after 1.5 s.

With W episodes in flight and a model that takes D seconds, the ideal is W / D steps per second (16 / 1.5 =
10.7). Everything else in a step (physics, two 640x480 renders, the JPEG for the model, recording, HTTP,
JSON) must fit in the cores while the episodes wait. The fake (tests/fakes, the real OpenAI wire protocol
through the official SDK) always answers a rotation and the current state, so every episode flies exactly
--max-steps steps; --reps 8 makes 80 episodes, five full waves of 16.

    .venv/bin/python bench/bench_throughput.py [--workers 16] [--delay 1.5] [--reps 8] [--max-steps 20] [--smoke]

Prints the flight-window rate (first request to last answer), the end-to-end rate (including worker start),
the fraction of the ideal, the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from machine import cpu_model  # bench/machine.py, beside this script

from fakes import FakeOpenAI  # noqa: E402
from vlnpilot.bench.runner import BenchSettings, run_bench  # noqa: E402

FINAL = {"Stay on Room", "Describe Object", "Final"}


def rotate_in_place(request) -> dict:
    """A valid decision for any state: a rotation (else the first allowed move), staying in the current state."""
    moves = request.allowed_movements or ["B1"]
    move = next((m for m in moves if m[0] in "BC"), moves[0])
    states = request.allowed_states or []
    current = request.current_state
    state = current if current in states else next((s for s in states if s not in FINAL), states[0] if states else
                                                    "Recognize Room")
    rooms = [r for r in (request.enum("room") or []) if r != "unknown"]
    return {"room": rooms[0] if rooms else "unknown", "movement": move, "state": state,
            "description": "a throughput test: turning in place", "door_position": "not_visible"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=16, help="episodes in flight")
    ap.add_argument("--delay", type=float, default=1.5, help="seconds the fake model takes per answer")
    ap.add_argument("--reps", type=int, default=8)
    ap.add_argument("--max-steps", type=int, default=20)
    ap.add_argument("--suite", default="paper")
    ap.add_argument("--out", type=Path, default=None, help="bench directory (default: a temporary one)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="1 in flight, 0.01 s answers, 2 steps each (tests)")
    args = ap.parse_args()
    if args.smoke:
        args.workers, args.delay, args.reps, args.max_steps, args.no_progress = 1, 0.01, 1, 2, True

    from rich.console import Console

    console = Console(stderr=True)
    load_before = os.getloadavg()
    answered: list[float] = []  # when each answer left: the fake sleeps `delay`, then asks the oracle

    def timed_rotation(request) -> dict:
        answered.append(time.monotonic())
        return rotate_in_place(request)

    with FakeOpenAI(oracle=timed_rotation, delay=args.delay) as fake, tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "bench"
        settings = BenchSettings(suite=args.suite, pilots=("openai:fake-gpt",), out=out, reps=args.reps,
                                 max_steps=args.max_steps, base_url=fake.base_url, workers=args.workers,
                                 progress=not args.no_progress)
        t0 = time.monotonic()
        report = run_bench(settings, console=console)
        wall = time.monotonic() - t0
        times = sorted(answered)
    load_after = os.getloadavg()
    calls = sum(s.pilot_calls for s in report.summaries)
    steps = sum(round(s.mean_steps * s.episodes) for s in report.summaries)
    window = (times[-1] - (times[0] - args.delay)) if times else float("nan")  # first request to last answer
    ideal = args.workers / args.delay
    rate = steps / window
    s = report.summaries[0]
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (1 min)")
    print(f"bench: {report.episodes} episodes x {args.max_steps} steps, {args.workers} in flight "
          f"({report.executor}), fake model delay {args.delay:.2f} s; failed {len(report.failed)}")
    print(f"steps {steps}, pilot calls {calls}; pilot-call latency p50 {s.latency_p50_s:.3f} s, "
          f"p95 {s.latency_p95_s:.3f} s")
    print(f"flight window {window:.1f} s: {rate:.2f} steps/s = {100 * rate / ideal:.1f}% of the ideal "
          f"{args.workers}/{args.delay:g} = {ideal:.2f} steps/s")
    print(f"end to end {wall:.1f} s (incl. worker start and tables): {steps / wall:.2f} steps/s = "
          f"{100 * steps / wall / ideal:.1f}% of the ideal")


if __name__ == "__main__":
    main()
