"""What the mover shield does (issue 24): a reckless pilot that flies at the nearest person or pet, shield on and off.

    .venv/bin/python bench/mover_chase.py [--seeds 5] [--shields off,geometry,assist]
                                          [--out bench/results/mover_chase.md] [--smoke]

The oracle waits for people by itself (it reads them through ground truth), so it shows nothing of the shield; this
pilot is the worst case: every step it turns towards the nearest mover and flies at it (A2), for 60 steps, from the
living room of the cabin, while a person or a pet walks a path back and forth (walks x seeds, the same in every
condition). Counts the episodes that ended touching a mover, and the hovers the shield put in (`mover:` reasons).
No frames are rendered. Standalone on purpose: it does not use `vlnpilot.bench`.
"""

from __future__ import annotations

import argparse
import collections
import math
import sys
import time
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.records import wrap_deg

WALKS = (("person", ("bedroom", "living_room"), 1.2), ("person", ("living_room", "bedroom", "bathroom"), 1.6),
         ("person", ("bathroom", "bedroom"), 0.6), ("pet", ("living_room", "bedroom"), 2.0))


class Chaser:
    """Flies straight at the nearest person or pet (ground truth) for the whole episode."""

    name = model = "chaser"

    def __init__(self, sim) -> None:  # noqa: ANN001
        self.sim = sim

    def decide(self, pilot_input: PilotInput) -> Decision:
        pose, movers = self.sim.ground_truth().pose(), self.sim.movers()
        move = "B2"  # look around until someone appears
        if movers:
            m = min(movers, key=lambda m: math.hypot(m.x - pose.x, m.y - pose.y))
            err = wrap_deg(math.degrees(math.atan2(m.y - pose.y, m.x - pose.x)) - pose.yaw_deg)
            turn = ("C1" if err > 0 else "B1") if abs(err) < 30 else ("C2" if err > 0 else "B2")
            move = "A2" if abs(err) < 10 else turn
        return Decision(room="unknown", movement=move, state="Recognize Room", model=self.model)


def chase(kind: str, path: tuple, speed: float, shield: str, seed: int) -> dict:
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.scene import load_scene
    from vlnpilot.scene.events import scenario_from_dict, with_scenario
    from vlnpilot.sim import SimConfig, Simulator
    from vlnpilot.tasks.task import parse_query

    scenario = scenario_from_dict({"scene": "cabin", "seed": seed, "events": [
        {"kind": kind, "path": list(path), "speed_mps": speed, "repeat": True}]})
    scene = with_scenario(load_scene("cabin"), scenario)
    sim = Simulator(scene, SimConfig(render=False))
    hovers = 0

    def on_step(rec: dict) -> None:
        nonlocal hovers
        hovers += sum(str(i.get("reason", "")).startswith("mover:") for i in rec["interventions"])

    try:
        result = run_episode(sim, Chaser(sim), parse_query("Go to the kitchen", scene),
                             EpisodeConfig(max_steps=60, shield=shield, profile="fast", seed=seed),
                             spawn="living_room", on_step=on_step)
    finally:
        sim.close()
    return {"shield": shield, "kind": kind, **result.to_dict(), "mover_hovers": hovers}


def summarise(rows: list[dict], shields: list[str]) -> str:
    lines = ["| shield | episodes | mover collisions | wall collisions | shield hovers for a mover |",
             "|---|---|---|---|---|"]
    for s in shields:
        rs = [r for r in rows if r["shield"] == s]
        movers = sum(r["mover_collisions"] or 0 for r in rs)
        walls = sum(r["outcome"] == "collision" and not r["mover_collisions"] for r in rs)
        lines.append(f"| {s} | {len(rs)} | {movers} | {walls} | {sum(r['mover_hovers'] for r in rs)} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="seeds per walk (4 walks)")
    ap.add_argument("--shields", default="off,geometry,assist")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "mover_chase.md")
    ap.add_argument("--smoke", action="store_true", help="one walk, one seed, nothing written (for the tests)")
    args = ap.parse_args(argv)
    shields = [s.strip() for s in args.shields.split(",") if s.strip()]
    walks, seeds = (WALKS[:1], 1) if args.smoke else (WALKS, args.seeds)
    t0 = time.perf_counter()
    rows = [chase(kind, path, speed, s, seed) for s in shields for kind, path, speed in walks for seed in range(seeds)]
    counts = collections.Counter(r["kind"] for r in rows if r["shield"] == shields[0])
    text = "\n".join([
        "## The mover shield against a pilot that flies at people and pets",
        "",
        f"{len(rows) // len(shields)} episodes per shield ({dict(counts)}; 60 steps, the cabin), "
        f"{time.perf_counter() - t0:.0f} s in all on {describe()}.",
        "",
        summarise(rows, shields),
        "",
    ])
    publish(text, args.out, smoke=args.smoke)
    return 0


if __name__ == "__main__":
    sys.exit(main())
