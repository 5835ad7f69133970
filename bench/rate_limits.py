"""Adaptive concurrency against a rate-limited fake (issue 27): steps per second and 429s, with the shared budget.

Against FakeOpenAI (tests/fakes, the real wire protocol, its x-ratelimit-* headers and 429 bodies) answering after
1.5 s, 64 lightweight simulated episodes run in flight as threads, each with its own OpenAI pilot (the official
SDK) and the bench's shared, file-locked budget (pilots/ratelimit.py). A simulated episode is the asking part of a
real one: `episode.ask.ask_once` per step, a 429 asked again within the step as `PilotAsker.ask` does, no
simulator (the 2-core machine cannot render 64 real episodes in flight; the limiter is what is measured).

Scenarios: a limit of 300 rpm (fake and --rate-limit 300): steps/s against the ideal 300/60; 60 rpm: a bench of
64 episodes of 2 steps flown to the end, its failed episodes and the share of calls answered 429; no limit:
steps/s against 64/1.5. Each reports the median of the
steps per second over 5 s windows after a warm-up window, and over the whole run.

    PYTHONPATH=src python bench/rate_limits.py            # 3 scenarios, 60 s each
    PYTHONPATH=src python bench/rate_limits.py --smoke    # a few calls each: does it still run?
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from machine import describe  # bench/machine.py, beside this script

from fakes import FakeOpenAI  # noqa: E402
from vlnpilot.core.decision import PilotInput  # noqa: E402
from vlnpilot.core.fsm import State  # noqa: E402
from vlnpilot.episode.ask import RATE_LIMITED, ask_once  # noqa: E402
from vlnpilot.pilots.base import make_pilot  # noqa: E402
from vlnpilot.pilots.ratelimit import RateBudget, budget_file, parse_rate_limit, share_budgets  # noqa: E402

LATENCY_S = 1.5
IN_FLIGHT = 64
STEPS_PER_EPISODE = 10
WINDOW_S = 5.0
FINISHING_STEPS = 2  # the 60 rpm bench flies every episode to its end: 64 x 2 calls take at least 128 s


def run_scenario(rpm: int | None, seconds: float, in_flight: int, episodes_total: int | None = None,
                 steps: int = STEPS_PER_EPISODE, option: bool = True) -> dict:
    """Episodes back to back in `in_flight` threads for `seconds` (or, given `episodes_total`, until that many
    have flown: a bench that finishes); the steps' finish times, failures, 429s."""
    finished: list[float] = []
    failed_episodes, episodes = [0], [0]
    lock = threading.Lock()
    with tempfile.TemporaryDirectory() as rate_dir, FakeOpenAI(delay=LATENCY_S) as fake:
        if rpm:
            fake.limit(rpm=rpm, tpm=None)
        share_budgets(rate_dir, parse_rate_limit(str(rpm)) if rpm and option else None)
        t0 = time.monotonic()
        stop = t0 + seconds if episodes_total is None else float("inf")
        left = [episodes_total if episodes_total is not None else -1]

        def worker() -> None:
            pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-bench", max_retries=2)
            pin = PilotInput(image=np.zeros((8, 8, 3), np.uint8), query="Go to the bedroom", topological_map={},
                             state=State.RECOGNIZE_ROOM, previous_movement=None)
            while time.monotonic() < stop:
                with lock:
                    if left[0] == 0:
                        break
                    left[0] -= 1
                ok = fly_episode(pilot, pin, finished, lock, stop, steps)
                if ok is None:  # cut by the end of the scenario: neither finished nor failed
                    break
                with lock:
                    episodes[0] += 1
                    failed_episodes[0] += not ok
            pilot.close()

        threads = [threading.Thread(target=worker) for _ in range(in_flight)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.monotonic() - t0
        budget = RateBudget(budget_file(Path(rate_dir), "OpenAI", "gpt-4.1")).snapshot()
        share_budgets(None)
        calls, throttled = len(fake.requests), fake.throttled
    return {"steps": [t - t0 for t in finished], "seconds": seconds if episodes_total is None else wall,
            "wall": wall, "episodes": episodes[0],
            "failed": failed_episodes[0], "calls": calls, "throttled": throttled, "budget": budget}


def fly_episode(pilot, pin: PilotInput, finished: list[float], lock: threading.Lock, stop: float,
                steps: int) -> bool | None:
    """STEPS_PER_EPISODE steps; a 429 is asked again within its step (as PilotAsker.ask does). False: failed;
    None: the scenario ended first."""
    for _ in range(steps):
        if time.monotonic() >= stop:
            return None
        for _attempt in range(50):
            answer = ask_once(pilot, pin, State.RECOGNIZE_ROOM, "paper")
            if answer.kind != RATE_LIMITED:
                break
        if answer.error is not None:
            return False
        with lock:
            finished.append(time.monotonic())
    return True


def rates(result: dict) -> tuple[float, float]:
    """(median steps/s over WINDOW_S windows after the first, steps/s over the whole run after the first window)."""
    times, seconds = result["steps"], result["seconds"]
    windows = int(seconds // WINDOW_S)
    counts = [sum(1 for t in times if k * WINDOW_S <= t < (k + 1) * WINDOW_S) / WINDOW_S for k in range(1, windows)]
    whole = sum(1 for t in times if WINDOW_S <= t < seconds) / max(seconds - WINDOW_S, 1e-9)
    return (statistics.median(counts) if counts else whole), whole


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of each scenario")
    parser.add_argument("--in-flight", type=int, default=IN_FLIGHT)
    parser.add_argument("--smoke", action="store_true", help="a few seconds and 4 in flight: does it run?")
    parser.add_argument("--only", choices=("300", "60", "none"), help="one scenario")
    parser.add_argument("--headers-only", action="store_true",
                        help="no --rate-limit: the budgets learn the limit from the first responses' headers")
    args = parser.parse_args()
    seconds, in_flight = (2 * WINDOW_S + 1, 4) if args.smoke else (args.seconds, args.in_flight)
    print(f"machine: {describe()}")
    print(f"fake latency {LATENCY_S} s per call, {in_flight} episodes in flight, {seconds:g} s per timed scenario; "
          f"at 60 rpm a bench of {in_flight} episodes of {FINISHING_STEPS} steps flown to the end")
    for rpm in (300, 60, None):
        if args.only and args.only != str(rpm or "none"):
            continue
        option = not args.headers_only
        result = (run_scenario(rpm, seconds, in_flight, in_flight, FINISHING_STEPS, option) if rpm == 60
                  else run_scenario(rpm, seconds, in_flight, option=option))
        median, whole = rates(result)
        ideal = min(in_flight / LATENCY_S, rpm / 60) if rpm else in_flight / LATENCY_S
        share = result["throttled"] / max(1, result["calls"])
        print(f"limit {rpm or 'none'} rpm: median {median:.2f} steps/s over {WINDOW_S:g} s windows (whole run "
              f"{whole:.2f}), {100 * median / ideal:.0f} % of the ideal {ideal:.2f}; {result['episodes']} episodes, "
              f"{result['failed']} failed, in {result['wall']:.0f} s; {result['calls']} calls, "
              f"{result['throttled']} answered 429 "
              f"({100 * share:.1f} %); budget at the end: allowed {result['budget']['rate_rpm']} rpm, limit "
              f"{result['budget']['limit_rpm']} ({result['budget']['source']})")


if __name__ == "__main__":
    main()
