"""Wall time of the paper suite flown by the oracle: `vln-pilot bench --suite paper --pilots oracle`.

Default workers (one episode per core), cameras and frame recording on, exactly as the command runs. Checks
that every episode succeeds without a collision and that table.md has the paper's Table 4 layout, then prints
the wall time, the machine and its load (other processes on a shared machine slow it down: the load is part
of the figure).

    .venv/bin/python bench/paper_oracle_walltime.py [--reps N] [--workers N] [--keep DIR] [--smoke]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_model  # bench/machine.py, beside this script

from vlnpilot.bench import bench_command, default_workers

HEADER = "| Starting Room | Query | oracle Ach. | oracle Coll. | oracle Steps |"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=None, help="repetitions (default: the suite's 5)")
    ap.add_argument("--workers", type=int, default=None, help="episodes in flight (default: the cores)")
    ap.add_argument("--keep", type=Path, default=None, help="bench directory to keep (default: temporary)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="10 episodes of 2 steps in this process; "
                    "the table is checked, not the outcomes (for the tests)")
    args = ap.parse_args()
    if args.smoke:
        args.reps, args.no_progress = 1, True

    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep or Path(tmp) / "bench"
        t0 = time.monotonic()
        bench_command(suite="paper", pilots="oracle", reps=args.reps, workers=args.workers, out=out,
                      max_steps=2 if args.smoke else None,
                      progress=not args.no_progress, executor="inline" if args.smoke else "local")
        wall = time.monotonic() - t0
        load_after = os.getloadavg()
        records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
        table = (out / "table.md").read_text()
    outcomes = [r["result"]["outcome"] for r in records]
    steps = sum(r["result"]["steps"] for r in records)
    ok = (args.smoke or outcomes.count("success") == len(records)) and HEADER in table
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}; load average "
          f"(1/5/15 min) before {load_before[0]:.2f}/{load_before[1]:.2f}/{load_before[2]:.2f}, "
          f"after {load_after[0]:.2f}/{load_after[1]:.2f}/{load_after[2]:.2f}")
    print(f"paper suite, oracle: {len(records)} episodes, {outcomes.count('success')} successes, "
          f"{outcomes.count('collision')} collisions, {steps} steps; workers {args.workers or default_workers()}")
    print(f"wall time {wall:.1f} s ({wall / 60:.2f} min; aim < 3 min); table layout "
          f"{'ok' if HEADER in table else 'WRONG'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
