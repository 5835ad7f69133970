"""Add a recorded real-VLM episode to a set of trials under trials/, and rewrite the set's suite.yaml.

    python scripts/import_trial.py RUN_DIR trials/after-plus living-bathroom-1 \
        --flown-by "..." --interface stdin --pilot-memory conversation [--scene cabin-v1] [--account report.md]

`--pilot-memory` says what the pilot remembered: `conversation` (one pilot saw the whole episode), `none` (a fresh
pilot per step, e.g. through the files pilot: docs/pilot-memory.md) or `history=N` (a model pilot's `history` option;
a run's summary.json records it, and it is the default then).

Copies the run's summary.json and episode.jsonl (not the frames: the simulator is deterministic, and a replay
regenerates them), writes trial.json (who flew it, when, through which interface, the scene and prompt versions)
and the pilot's own account of the episode, then lists every trial of the set as a row of its suite.yaml, so that
`vln-pilot bench --suite SET/suite.yaml --pilots replay:SET` replays the whole set.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

import yaml

from vlnpilot.core.rundir import load_run
from vlnpilot.pilots.replay import camera_flown_with
from vlnpilot.scene.events import scene_with_recorded
from vlnpilot.tasks.mission import Mission

PILOT_MEMORY = re.compile(r"conversation|none|history=[1-9]\d*(,images=\d+)?")


def pilot_memory(given: str | None, summary: dict) -> str:
    """The trial's pilot memory: as given, else as the run recorded it; one line and exit 2 when neither is valid."""
    memory = given if given is not None else summary.get("pilot_memory")
    if memory is None or not PILOT_MEMORY.fullmatch(memory):
        problem = "the run does not record it" if memory is None else f"got {memory!r}"
        print(f"--pilot-memory is needed ({problem}): conversation, none or history=N", file=sys.stderr)
        raise SystemExit(2)
    return memory


def range_sensor_of(summary: dict) -> str:
    """The range sensor the run's drone carried (`none` for runs recorded before sensors existed)."""
    return (summary.get("capabilities") or {}).get("range_sensor") or "none"


def import_trial(run_dir: Path, set_dir: Path, row: str, *, flown_by: str, interface: str, scene: str | None,
                 account: Path | None, memory: str | None = None) -> Path:
    summary, _ = load_run(run_dir)
    memory = pilot_memory(memory, summary)
    dest = set_dir / row
    dest.mkdir(parents=True, exist_ok=False)
    for name in ("summary.json", "episode.jsonl"):
        shutil.copy2(run_dir / name, dest / name)
    scene_name = scene or summary["scene"]  # a baseline flown before a scene was renamed names it here
    trial = {
        "flown_by": flown_by,
        "interface": interface,
        "pilot_memory": memory,
        "started_at": summary["provenance"]["started_at"],
        "scene": scene_name,
        "scene_fingerprint": scene_with_recorded(scene_name, summary.get("scenario")).fingerprint(),
        "prompt_hash": summary["provenance"]["prompt_hash"],
        "git_sha": summary["provenance"]["git_sha"],
        "context": (summary["config"].get("context") or {}).get("preset", "paper"),
        "shield": summary["config"]["shield"],
        "profile": summary["config"]["profile"],
        "sensors": range_sensor_of(summary),
        **({"camera": camera} if (camera := summary["config"].get("camera")) else {}),  # docs/camera.md
        **({"detail": detail} if (detail := summary["config"].get("detail")) else {}),  # docs/scenes.md
        **({"scenario": scenario["name"], "events": [e["kind"] for e in scenario["events"]]}
           if (scenario := summary.get("scenario")) else {}),  # docs/events.md
        "outcome": summary["result"]["outcome"],
        "steps": summary["result"]["steps"],
    }
    (dest / "trial.json").write_text(json.dumps(trial, indent=2) + "\n")
    if account is not None:
        shutil.copy2(account, dest / "account.md")
    write_suite(set_dir)
    return dest


def write_suite(set_dir: Path) -> Path:
    """One suite row per trial of the set (one repetition each), with the set's common settings."""
    trials = sorted(p for p in set_dir.iterdir() if (p / "trial.json").is_file())
    rows, limits, profiles, pins, cameras = [], set(), set(), set(), set()
    for path in trials:
        summary, _ = load_run(path)
        trial = json.loads((path / "trial.json").read_text())
        task = summary["task"]
        goal = {"room": task["goal_room"], **({"target": task["goal_target"]} if task["goal_target"] else {})}
        # a mission's row carries the plan it flew (its goal alone reads as a one-goal query), and who planned it: a
        # pilot's plan is flown as written, not planned again by the parser, which may read the instruction otherwise
        what = Mission.from_dict(summary["mission"]).suite_row() if summary.get("mission") else {"goal": goal}
        rows.append({"id": path.name, "spawn": summary["spawn"], "query": task["query"], **what,
                     "scene": trial["scene"]})
        sensors = range_sensor_of(summary)
        if sensors != "none":  # the drone it was flown with: a replay must carry the same sensor
            rows[-1]["sensors"] = sensors
        scenario = summary.get("scenario")
        if scenario:  # the events it met, as recorded (the row's scene is the scenario's)
            rows[-1]["events"] = {k: v for k, v in scenario.items() if k != "scene"}  # its name: the fingerprint
        frames = camera_flown_with(summary["config"])
        if frames.get("randomize") is not None:  # the world it was flown in: its camera height decides what is visible
            rows[-1]["randomize"] = frames["randomize"]
        cameras.add(frames.get("camera", "ideal"))
        limits.add(summary["config"]["max_steps"])
        profiles.add(summary["config"]["profile"])
        pins.add((trial.get("context") or "paper", trial.get("shield") or "off"))
    if len(limits) != 1 or len(profiles) != 1 or len(pins) != 1 or len(cameras) != 1:
        raise SystemExit(f"{set_dir}: a set of trials shares one step limit, profile, context, shield and camera; "
                         f"found {sorted(limits)}, {sorted(profiles)}, {sorted(pins)}, {sorted(cameras)}")
    context, shield = pins.pop()
    scene = rows[0]["scene"]
    for row in rows:  # a row names its scene only where it differs from the set's (houses)
        if row["scene"] == scene:
            del row["scene"]
    suite = {"name": set_dir.name, "description": f"Replays the real-VLM trials of {set_dir.name}, one row each.",
             "scene": scene, "repetitions": 1, "max_steps": limits.pop(), "seed": 0,
             "profile": profiles.pop(), "context": context, "shield": shield,
             **({"camera": camera} if (camera := cameras.pop()) != "ideal" else {}),  # the frames it saw
             "rows": rows}  # pinned: replays as flown
    path = set_dir / "suite.yaml"
    path.write_text(yaml.safe_dump(suite, sort_keys=False, allow_unicode=True))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("set_dir", type=Path)
    parser.add_argument("row")
    parser.add_argument("--flown-by", required=True, help="the model, as it names itself")
    parser.add_argument("--interface", required=True, choices=["stdin", "files"])
    parser.add_argument("--pilot-memory", help="conversation, none or history=N (default: as the run records it)")
    parser.add_argument("--scene", help="the scene's current name, if it was renamed since the trial was flown")
    parser.add_argument("--account", type=Path, help="the pilot's own account of the episode (markdown)")
    args = parser.parse_args()
    dest = import_trial(args.run_dir, args.set_dir, args.row, flown_by=args.flown_by, interface=args.interface,
                        scene=args.scene, account=args.account, memory=args.pilot_memory)
    print(f"wrote {dest}")


if __name__ == "__main__":
    main()
