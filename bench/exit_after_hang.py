"""How long a process lives on after its episode ended while a provider call still hangs (issue 16).

Each repetition starts a child process that flies a 1-step episode with the `openai` pilot against the fake
OpenAI server (tests/fakes, 127.0.0.1), whose answer hangs for 600 s; the step deadline (0.2 s) abandons the
call. The child prints when the episode has ended; this script times from that line to the child's exit.
Before the fix the abandoned call sat in a non-daemon worker thread, so the exit waited for the SDK's time-out
and retries (the report: 65 s late).

    .venv/bin/python bench/exit_after_hang.py [--reps 5] [--smoke]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

from machine import describe

CHILD = """
import sys
sys.path.insert(0, sys.argv[1])
from fakes import FakeOpenAI
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

fake = FakeOpenAI().start()
fake.push("hang", times=20, seconds=600.0)
pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-not-a-real-key-bench", timeout=300)
with Simulator("cabin", SimConfig(render=False)) as sim:
    run_episode(sim, pilot, parse_query("Go to the bedroom", sim.scene),
                EpisodeConfig(max_steps=1, step_deadline_s=0.2), spawn="living_room")
print("episode ended", flush=True)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--smoke", action="store_true", help="1 repetition (for the tests)")
    args = parser.parse_args()
    if args.smoke:
        args.reps = 1
    tests = str(Path(__file__).resolve().parents[1] / "tests")
    print(describe())
    delays = []
    for rep in range(args.reps):
        child = subprocess.Popen([sys.executable, "-c", CHILD, tests], stdout=subprocess.PIPE, text=True)
        child.stdout.readline()
        t0 = time.perf_counter()
        child.wait(timeout=900)
        delays.append(time.perf_counter() - t0)
        print(f"rep {rep}: exit {delays[-1]:.3f} s after the episode ended")
    print(f"median over {args.reps}: {statistics.median(delays):.3f} s")


if __name__ == "__main__":
    main()
