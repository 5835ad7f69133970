"""The effect of the safety layer: the paper suite flown by `noisy-oracle` with the shield off and on.

    .venv/bin/python bench/shield_effect.py [--reps 50] [--workers 2] [--shields off,geometry,depth]
                                            [--out bench/results/shield_effect.md] [--seed 0] [--smoke]

Every condition flies the same episodes (paper suite rows x reps, episode seed = seed + 100 * rep + row), so
the pilot draws the same failures in each; only the safety layer differs. No frames are rendered (the depth
shield renders its own small depth image). Writes a markdown table to stdout and to --out.
Standalone on purpose: it does not use `vlnpilot.bench`.
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

from vlnpilot.bench.suite import load_suite

# Table 4 of the paper, (spawn, query) in its order, read from the built-in suite (one source of truth).
PAPER_SUITE: tuple[tuple[str, str], ...] = tuple((row.spawn, row.query) for row in load_suite("paper").rows)
OUTCOMES = ("success", "collision", "max_steps", "false_success", "pilot_error")

_SIM = None


def _init_worker() -> None:
    global _SIM
    from vlnpilot.sim import SimConfig, Simulator

    _SIM = Simulator("cabin", SimConfig(render=False))


def run_one(job: tuple[str, int, int, int, str]) -> dict:
    """One episode in a worker: (shield, row index, rep, seed, pilot spec) -> a flat result row."""
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.tasks.task import parse_query

    shield, row, rep, seed, pilot_spec = job
    spawn, query = PAPER_SUITE[row]
    sources: collections.Counter[str] = collections.Counter()

    def on_step(rec: dict) -> None:
        sources.update(i["source"] for i in rec["interventions"])

    result = run_episode(_SIM, make_pilot(pilot_spec), parse_query(query, _SIM.scene),
                         EpisodeConfig(seed=seed, shield=shield), spawn=spawn, on_step=on_step, pilot_spec=pilot_spec)
    return {"shield": shield, "row": row, "rep": rep, "seed": seed, **result.to_dict(), "by_source": dict(sources)}


def _pct(n: int, total: int) -> str:
    return f"{n} ({100 * n / total:.1f}%)" if total else "0"


def summarise(rows: list[dict], shields: list[str]) -> str:
    by = {s: [r for r in rows if r["shield"] == s] for s in shields}
    head = ("| shield | episodes | successes | collisions | steps exceeded | false successes | oscillation events "
            "(episodes) | interventions (guard / assist / shield) |")
    lines = [head, "|" + "---|" * 8]
    for s in shields:
        rs = by[s]
        n = len(rs)
        c = collections.Counter(r["outcome"] for r in rs)
        src: collections.Counter[str] = collections.Counter()
        for r in rs:
            src.update(r["by_source"])
        osc = sum(r["oscillation_events"] for r in rs)
        osc_eps = sum(1 for r in rs if r["oscillation_events"])
        iv = sum(r["interventions"] for r in rs)
        lines.append(f"| {s} | {n} | {_pct(c['success'], n)} | {_pct(c['collision'], n)} | {_pct(c['max_steps'], n)} "
                     f"| {_pct(c['false_success'], n)} | {osc} ({osc_eps}) | {iv} ({src['oscillation_guard']} / "
                     f"{src['door_assist']} / {src['shield']}) |")
    lines += ["", "Per row (successes / collisions / steps exceeded), as in the paper's Table 4:", "",
              "| start | query | " + " | ".join(shields) + " |", "|---|---|" + "---|" * len(shields)]
    for i, (spawn, query) in enumerate(PAPER_SUITE):
        cells = []
        for s in shields:
            rs = [r for r in by[s] if r["row"] == i]
            c = collections.Counter(r["outcome"] for r in rs)
            cells.append(f"{c['success']}/{len(rs)} · {c['collision']} · {c['max_steps']}")
        lines.append(f"| {spawn} | {query} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=50, help="repetitions of each of the ten rows (50 -> 500 episodes)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--shields", default="off,geometry,depth")
    ap.add_argument("--pilot", default="noisy-oracle")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "shield_effect.md")
    ap.add_argument("--smoke", action="store_true", help="2 rows, 1 rep, 1 worker, nothing written (for the tests)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.reps, args.workers = 1, 1
    shields = [s.strip() for s in args.shields.split(",") if s.strip()]
    rows = range(2 if args.smoke else len(PAPER_SUITE))
    jobs = [(s, row, rep, args.seed + 100 * rep + row, args.pilot)
            for s in shields for rep in range(args.reps) for row in rows]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=mp.get_context("spawn"),
                             initializer=_init_worker) as pool:
        rows = list(pool.map(run_one, jobs, chunksize=10))
    wall = time.perf_counter() - t0
    per_condition = len(rows) // max(len(shields), 1)
    text = "\n".join([
        f"## Safety layer effect: `{args.pilot}` on the paper suite",
        "",
        f"{per_condition} episodes per condition ({args.reps} x {len(PAPER_SUITE)} rows, same seeds in every "
        f"condition), 50-step limit, margin 5 cm. Wall time {wall:.0f} s for {len(rows)} episodes on "
        f"{args.workers} worker processes, {cpu_model()} ({os.cpu_count()} cores visible), Python "
        f"{platform.python_version()}.",
        "",
        summarise(rows, shields),
        "",
    ])
    publish(text, args.out, smoke=args.smoke)
    return 0


if __name__ == "__main__":
    sys.exit(main())
