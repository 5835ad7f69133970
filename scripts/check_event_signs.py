"""Check that every sign row of a bench was legible to its pilot (issue 24 follow-up): for each episode of a row
with a sign, the largest text the pilot saw (`Simulator.sign_text_px`, px of a 640x480 frame, whole and
unoccluded) at each observation it was given, and the first step at which it was legible (>= SIGN_LEGIBLE_PX).

    vln-pilot bench --suite events-houses --pilots oracle --no-report --out /tmp/b
    python scripts/check_event_signs.py /tmp/b [/tmp/b2 ...]

Exit code 1 when a sign row was never legible. Signs that fire at take-off only (the suites' signs): a pose is
re-flown with `reset(pose)`, which fires the take-off events.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vlnpilot.core.records import Pose
from vlnpilot.scene import load_scene
from vlnpilot.scene.events import scenario_from_dict, with_scenario
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.sim.events import SIGN_LEGIBLE_PX


def check_bench(bench: Path) -> list[tuple[str, str, int | None, float, int]]:
    """(row, outcome, first step legible or None, largest text px, steps) of each sign episode of the bench."""
    out = []
    for line in (bench / "results.jsonl").read_text().splitlines():
        rec = json.loads(line)
        events = rec.get("events") or {}  # the row's scenario as flown (`Scenario.to_dict`)
        if not any(e["kind"] == "sign" for e in events.get("events", [])):
            continue
        scene = load_scene(events["scene"])
        scenario = scenario_from_dict(events)
        names = [str(e.name) for e in scenario.events if e.kind == "sign"]
        steps = [json.loads(s) for s in (bench / rec["run_dir"] / "episode.jsonl").read_text().splitlines()]
        poses = [s["pose_before"] for s in steps if "pose_before" in s]
        seen, best = None, 0.0
        with Simulator(with_scenario(scene, scenario), SimConfig(render=False, rear_camera=False)) as sim:
            for k, p in enumerate(poses, start=1):
                sim.reset(Pose(p["x"], p["y"], p["z"], p["yaw_deg"]))
                px = max(sim.sign_text_px(n) for n in names)
                best = max(best, px)
                if seen is None and px >= SIGN_LEGIBLE_PX:
                    seen = k
        out.append((rec["row"], rec["result"]["outcome"], seen, best, len(poses)))
    return out


def main(dirs: list[str]) -> int:
    never = 0
    for d in dirs:
        for row, outcome, seen, best, steps in check_bench(Path(d)):
            never += seen is None
            print(f"{row:32s} {outcome:12s} steps {steps:3d}  legible first at step "
                  f"{'never' if seen is None else seen!s:>5s}  largest text {best:5.1f} px")
    print(f"sign episodes never legible: {never}")
    return 1 if never else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
