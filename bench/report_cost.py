"""Cost of the reports of one 50-step episode: the HTML page (with its floor plan) and the video (mp4 + gif).

Flies one real 50-step episode in the simulator (640x480 front and rear frames) with a pilot that turns on the
spot until the step limit, then times, over a few repetitions, `write_episode_report`, `write_episode_video`,
and both together in a fresh process (what `vln-pilot report RUN_DIR` costs, imports included). Prints the
median of each and the machine it ran on. The budget is 10 s for the report of a 50-step episode.

    .venv/bin/python bench/report_cost.py [--steps 50] [--reps 3] [--keep DIR] [--smoke]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_model  # bench/machine.py, beside this script

BUDGET_S = 10.0


class Spinner:
    """A pilot that recognises the room forever, turning 15° a step: a full-length episode, no model needed."""

    name = "spinner"
    model = "spinner"

    def decide(self, pilot_input):  # noqa: ANN001, ANN201 - the Pilot protocol
        from vlnpilot.core.decision import Decision, Usage

        return Decision(room="living_room", movement="C1", state="Recognize Room",
                        description=f"Turning to look around the room (step {pilot_input.step}).",
                        door_position="not_visible", raw_text='{"movement": "C1"}',
                        usage=Usage(input_tokens=1500, output_tokens=60, latency_s=2.0, cost_usd=0.003))


def fly(run_dir: Path, steps: int) -> None:
    from vlnpilot.core.rundir import Recorder
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.sim import Simulator
    from vlnpilot.tasks.task import parse_query

    with Simulator("cabin") as sim:
        task = parse_query("Go to the bathroom", sim.scene)
        result = run_episode(sim, Spinner(), task, EpisodeConfig(max_steps=steps), spawn="living_room",
                             recorder=Recorder(run_dir))
    print(f"flew {result.steps} steps ({result.outcome}) into {run_dir}")


def timed(fn, *args) -> float:  # noqa: ANN001
    t0 = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--keep", type=Path, default=None, help="fly into this directory and keep it")
    ap.add_argument("--smoke", action="store_true", help="a 3-step episode, 1 repetition (for the tests)")
    args = ap.parse_args()
    if args.smoke:
        args.steps, args.reps = 3, 1

    with tempfile.TemporaryDirectory() as tmp:
        run_dir = args.keep or Path(tmp) / "run"
        if not (run_dir / "summary.json").is_file():
            fly(run_dir, args.steps)

        from vlnpilot.report.html import write_episode_report
        from vlnpilot.report.video import write_episode_video

        write_episode_report(run_dir)  # warm-up: imports, fonts, the scene cache
        page = [timed(write_episode_report, run_dir) for _ in range(args.reps)]
        video = [timed(write_episode_video, run_dir) for _ in range(args.reps)]
        code = ("import sys; from vlnpilot.report.html import write_episode_report; "
                "from vlnpilot.report.video import write_episode_video; "
                "write_episode_report(sys.argv[1]); write_episode_video(sys.argv[1])")
        cold = []
        for _ in range(args.reps):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", code, str(run_dir)], check=True)
            cold.append(time.perf_counter() - t0)
        sizes = {p.name: p.stat().st_size for p in run_dir.iterdir() if p.is_file()}

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, load {load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f}, "
          f"Python {platform.python_version()}, {platform.system()} {platform.release()}")
    print(f"episode: {args.steps} steps, 640x480 front and rear frames; median of {args.reps} runs")
    print(f"  report.html + floorplan.png  {statistics.median(page):6.2f} s   (all: "
          f"{', '.join(f'{t:.2f}' for t in page)})")
    print(f"  episode.mp4 + episode.gif    {statistics.median(video):6.2f} s   (all: "
          f"{', '.join(f'{t:.2f}' for t in video)})")
    total = statistics.median(cold)
    print(f"  both, fresh process          {total:6.2f} s   (all: {', '.join(f'{t:.2f}' for t in cold)})  "
          f"budget {BUDGET_S:.0f} s: {'OK' if total < BUDGET_S else 'OVER'}")
    print("  sizes: " + ", ".join(f"{k} {v / 1024:.0f} kB" for k, v in sorted(sizes.items())
                                  if k in ("report.html", "floorplan.png", "episode.mp4", "episode.gif")))


if __name__ == "__main__":
    main()
