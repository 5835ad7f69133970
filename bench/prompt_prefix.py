"""How much of each call a prefix cache can serve: o200k tokens of the OpenAI requests of a recorded run (issue 27).

Replays a set of recorded trials (default `trials/after-plus`: the paper suite's ten rows in the cabin, flown by a
real model, Claude of the Opus 4 family, with the `plus` context, 22 episodes), catches every step's `PilotInput`,
builds the Chat Completions request exactly as the OpenAI pilot sends it (`OpenAIPilot._kwargs`, defaults: detail
low, json_schema, no history) and, against the previous call of the same episode (the first call of an episode has
none and is left out), prints the median and max of
- (a) text tokens outside the prefix the two calls share,
- (b) the shared prefix's share of the call's input (images at 85 tokens, detail low),
over the messages (the acceptance, on the medians as the issue measures: (a) <= 1,200 and (b) >= 60 %; the max
of (a) is printed against 1,200 too: a step that enters a state sends that state's prompt anew), and again with the
structured-output schema in front, where OpenAI serves it (the schema is per state: a step that changes state
shares nothing there).
Exit code 1 if the acceptance is not met. `--smoke`: two episodes.

    .venv/bin/python bench/prompt_prefix.py [--trials trials/after-plus] [--smoke]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
from pathlib import Path
from typing import Any

from machine import cpu_model  # bench/machine.py, beside this script

from vlnpilot.core.rundir import load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots._history import messages
from vlnpilot.pilots.base import make_pilot
from vlnpilot.pilots.openai import OpenAIPilot
from vlnpilot.pilots.tokens import openai_segments, shared_prefix
from vlnpilot.prompting.render import prompt_hash
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.mission import Mission
from vlnpilot.tasks.success import recorded_success
from vlnpilot.tasks.task import Task

ROOT = Path(__file__).resolve().parents[1]
MAX_OUTSIDE = 1200
MIN_SHARE = 0.60


class Catching:
    """A pilot that passes every call on to `inner` and keeps what it was asked."""

    def __init__(self, inner: Any):
        self.inner, self.asked = inner, []

    def decide(self, pilot_input: Any) -> Any:
        self.asked.append(pilot_input)
        return self.inner.decide(pilot_input)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def inputs_of(trial_dir: Path, sims: dict[str, Simulator]) -> list[Any]:
    """Every PilotInput of the trial's episode, replayed as tests/test_trials.py replays it."""
    summary, _ = load_run(trial_dir)
    cfg = summary["config"]
    config = EpisodeConfig(max_steps=cfg["max_steps"], profile=cfg["profile"], seed=cfg["seed"], shield=cfg["shield"],
                           overlay=cfg.get("overlay"), context=(cfg.get("context") or {}).get("preset", "paper"),
                           success=recorded_success(cfg.get("success")))
    scene = json.loads((trial_dir / "trial.json").read_text())["scene"]
    sim = sims.setdefault(scene, Simulator(scene, SimConfig(rear_camera=False)))
    task = Mission.from_dict(summary["mission"]) if "mission" in summary else Task(**summary["task"])
    pilot = Catching(make_pilot(f"replay:{trial_dir}"))
    run_episode(sim, pilot, task, config, spawn=summary["spawn"])
    return pilot.asked


def splits(asked: list[Any], pilot: OpenAIPilot, *, schema: bool) -> list[Any]:
    out, previous = [], None
    for pilot_input in asked:
        prompt, chat = messages(pilot_input, (), jpeg_quality=pilot.jpeg_quality, max_side=pilot.max_side)
        segments = openai_segments(pilot._kwargs(prompt, "json_schema", chat), schema=schema)
        if previous is not None:
            out.append(shared_prefix(segments, previous))
        previous = segments
    return out


def report(label: str, rows: list[Any]) -> bool:
    outside = [r.text_outside for r in rows]
    share = [r.shared_share for r in rows]
    text = [r.text_tokens for r in rows]
    print(f"{label}: {len(rows)} calls; text tokens a call {statistics.median(text):.0f} median; "
          f"outside the shared prefix: median {statistics.median(outside):.0f}, max {max(outside)}; "
          f"shared share of the input: median {statistics.median(share):.1%}, min {min(share):.1%}, "
          f"over all calls {sum(r.shared_tokens for r in rows) / sum(r.input_tokens for r in rows):.1%}")
    return statistics.median(outside) <= MAX_OUTSIDE and statistics.median(share) >= MIN_SHARE


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=Path, default=ROOT / "trials" / "after-plus")
    ap.add_argument("--smoke", action="store_true", help="two episodes")
    args = ap.parse_args()
    dirs = sorted(p.parent for p in args.trials.glob("*/trial.json"))
    if not dirs:
        print(f"no trials under {args.trials} (a directory of trial directories, each with a trial.json)")
        return 2
    dirs = dirs[:2] if args.smoke else dirs
    pilot = OpenAIPilot(api_key="offline", base_url="http://127.0.0.1:9/v1")  # never called: it only builds requests
    sims: dict[str, Simulator] = {}
    asked = [inputs_of(d, sims) for d in dirs]
    print(f"{args.trials} ({len(dirs)} episodes), prompt hash {prompt_hash()}, o200k (bpe-openai); "
          f"{platform.python_version()}, {cpu_model()}")
    message_rows = [r for a in asked for r in splits(a, pilot, schema=False)]
    schema_rows = [r for a in asked for r in splits(a, pilot, schema=True)]
    met = report("messages (acceptance)", message_rows)
    report("schema + messages", schema_rows)
    changes = sum(a[i].state != a[i - 1].state for a in asked for i in range(1, len(a)))
    over = sum(r.text_outside > MAX_OUTSIDE for r in message_rows)
    print(f"calls whose state differs from the previous call's: {changes} of {len(message_rows)}; "
          f"calls with more than {MAX_OUTSIDE} text tokens outside the shared prefix: {over}")
    print(f"acceptance (medians: (a) <= {MAX_OUTSIDE}, (b) >= {MIN_SHARE:.0%}): {'met' if met else 'NOT met'}")
    for sim in sims.values():
        sim.close()
    return 0 if met or args.smoke else 1


if __name__ == "__main__":
    sys.exit(main())
