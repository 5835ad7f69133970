"""The safety layer's effect on procedural houses: `noisy-oracle` with the shield off and on, over a houses suite.

    .venv/bin/python bench/house_shield_effect.py [--suite houses] [--reps 1] [--workers 2] [--smoke]
                                                  [--shields off,geometry] [--out bench/results/house_shield_effect.md]

Every condition flies the same episodes (suite rows x reps, same episode seeds), so the pilot draws the same
failures in each; only the shield differs. No frames are rendered. Writes a markdown table to stdout and --out.
The acceptance check of issue 13: 0 collisions with the geometry shield.
"""

from __future__ import annotations

import argparse
import collections
import multiprocessing as mp
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from machine import cpu_model, publish  # bench/machine.py, beside this script

from vlnpilot.bench.suite import episode_seed, load_suite

_SIMS: dict = {}


def run_one(job: tuple[str, str, str, str, str, int, str, int]) -> dict:
    """One episode in a worker: (shield, row id, scene, spawn, query, seed, pilot, max steps) -> a result row."""
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.sim import SimConfig, Simulator
    from vlnpilot.tasks.task import parse_query

    shield, row, scene, spawn, query, seed, pilot_spec, max_steps = job
    if scene not in _SIMS:
        for sim in _SIMS.values():  # one house at a time per worker (jobs come sorted by house)
            sim.close()
        _SIMS.clear()
        _SIMS[scene] = Simulator(scene, SimConfig(render=False))
    sim = _SIMS[scene]
    result = run_episode(sim, make_pilot(pilot_spec), parse_query(query, sim.scene),
                         EpisodeConfig(seed=seed, shield=shield, max_steps=max_steps), spawn=spawn,
                         pilot_spec=pilot_spec)
    return {"shield": shield, "row": row, "scene": scene, **result.to_dict()}


def summarise(rows: list[dict], shields: list[str]) -> str:
    lines = ["| shield | episodes | successes | collisions | steps exceeded | false successes | interventions |",
             "|" + "---|" * 7]
    for s in shields:
        rs = [r for r in rows if r["shield"] == s]
        c, n = collections.Counter(r["outcome"] for r in rs), len(rs)
        cells = [f"{c[k]} ({100 * c[k] / n:.1f}%)" if n else "0"
                 for k in ("success", "collision", "max_steps", "false_success")]
        lines.append(f"| {s} | {n} | " + " | ".join(cells) + f" | {sum(r['interventions'] for r in rs)} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="houses")
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--shields", default="off,geometry")
    ap.add_argument("--pilot", default="noisy-oracle")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "house_shield_effect.md")
    ap.add_argument("--smoke", action="store_true", help="2 rows, 3 steps, 1 worker, nothing written (for the tests)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.workers = 1
    suite = load_suite(args.suite)
    shields = [s.strip() for s in args.shields.split(",") if s.strip()]
    jobs = [(s, r.id, r.scene or suite.scene, r.spawn, r.query, episode_seed(suite.seed, r.id, rep), args.pilot,
             suite.max_steps) for s in shields for r in suite.rows for rep in range(1, args.reps + 1)]
    if args.smoke:  # the first two rows of one house, a few steps each
        jobs = [(*j[:-1], 3) for j in jobs if j[1] in {r.id for r in suite.rows[:2]}]
    jobs.sort(key=lambda j: (j[2], j[0]))  # by house, so that a worker builds each house's simulator once
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=mp.get_context("spawn")) as pool:
        rows = list(pool.map(run_one, jobs, chunksize=5))
    wall = time.perf_counter() - t0
    text = "\n".join([
        f"## Safety layer effect on houses: `{args.pilot}` on `{args.suite}`", "",
        f"{len(rows) // max(len(shields), 1)} episodes per condition ({len(suite.rows)} rows x {args.reps}, same "
        f"seeds in every condition), {suite.max_steps}-step limit, margin 5 cm. Wall time {wall:.0f} s on "
        f"{args.workers} worker processes, {cpu_model()} ({os.cpu_count()} cores visible), Python "
        f"{platform.python_version()}.", "", summarise(rows, shields), ""])
    publish(text, args.out, smoke=args.smoke)
    return 0


if __name__ == "__main__":
    sys.exit(main())
