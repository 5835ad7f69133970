"""Which recorded trials the current success monitor judges differently from the one they were flown under.

    python scripts/trials_rejudged.py [trials] [--all]     # markdown on stdout; --all lists every object trial

Each object-goal trial is replayed twice, with the monitor recorded in its summary (a trial that names none was
judged by the point monitor: the middle of the object's front) and with today's (`success.DEFAULT_SUCCESS`: the
nearest point of the object's footprint). The recorded outcome is read, never rewritten: trial.json and
summary.json stay as they were flown.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vlnpilot.core.rundir import load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import EpisodeResult
from vlnpilot.pilots.base import make_pilot
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.success import DEFAULT_SUCCESS, SuccessConfig, recorded_success
from vlnpilot.tasks.task import Task


def replay(sim: Simulator, trial_dir: Path, success: SuccessConfig) -> EpisodeResult:
    summary, _ = load_run(trial_dir)
    cfg = summary["config"]
    config = EpisodeConfig(max_steps=cfg["max_steps"], profile=cfg["profile"], seed=cfg["seed"], shield=cfg["shield"],
                           overlay=cfg.get("overlay"), context=(cfg.get("context") or {}).get("preset", "paper"),
                           success=success)
    return run_episode(sim, make_pilot(f"replay:{trial_dir}"), Task(**summary["task"]), config,
                       spawn=summary["spawn"])


def rejudge(root: Path) -> list[dict]:
    """One record per object-goal trial: the recorded outcome and what today's monitor makes of the same flight."""
    out, sims = [], {}
    try:
        for path in sorted(root.glob("*/*/trial.json")):
            trial, summary = json.loads(path.read_text()), json.loads((path.parent / "summary.json").read_text())
            if not summary["task"].get("goal_target"):
                continue
            sim = sims.setdefault(trial["scene"], Simulator(trial["scene"], SimConfig(render=False)))
            then = replay(sim, path.parent, recorded_success(summary["config"].get("success")))
            now = replay(sim, path.parent, DEFAULT_SUCCESS)
            out.append({"set": path.parent.parent.name, "row": path.parent.name, "recorded": trial["outcome"],
                        "replayed": then.outcome, "then": then.reason, "now": now.outcome, "why": now.reason})
    finally:
        for sim in sims.values():
            sim.close()
    return out


def table(records: list[dict], every: bool) -> str:
    lines = ["| trials | row | recorded outcome | footprint monitor | what it measures |", "|---|---|---|---|---|"]
    for r in records:
        if every or r["now"] != r["recorded"]:
            lines.append(f"| {r['set']} | {r['row']} | {r['recorded']} | {r['now']} | {r['why']} |")
    changed = sum(r["now"] != r["recorded"] for r in records)
    return "\n".join(lines) + (f"\n\n{changed} of {len(records)} object trials judged differently by the footprint "
                                "monitor.")


def main() -> None:
    args = [a for a in sys.argv[1:] if a != "--all"]
    records = rejudge(Path(args[0] if args else "trials"))
    bad = [r for r in records if r["replayed"] != r["recorded"]]
    if bad:  # the recording no longer reproduces under its own monitor: say so rather than compare
        print(f"not reproduced under the recorded monitor: {[(r['set'], r['row']) for r in bad]}", file=sys.stderr)
    print(table(records, "--all" in sys.argv[1:]))


if __name__ == "__main__":
    main()
