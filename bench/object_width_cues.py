"""Do Reach Object's stop rules agree with the success monitor for every kind of object, from every side?

    .venv/bin/python bench/object_width_cues.py [--houses 40] [--camera ideal|tello] [--out FILE] [--smoke]

The monitor measures to the nearest point of the object's footprint (`success.py`). The prompt names a width cue
per kind of object (`success.OBJECT_CLOSE_CUES`) and, for a drone with a forward range sensor, a range rule for
the kinds its beam meets (`success.RANGE_STOP_M`, `success.ON_THE_BEAM`). Here every target of the cabin,
`cabin-v1` and houses 0..N-1 is seen from its front, from 45 degrees and from its side (`target_views.VIEW_ANGLES`)
at 0.7x and 1.1x the success distance (where the drone can hover there), and the table says, per kind and view,
how wide it looks, how often its cue is right ("close at 0.7x": a pilot that obeys it can stop; "false close at
1.1x": a pilot that obeys it declares too early, a false success) and what the forward beam reads.
`--camera tello` measures the widths through the Tello camera model's lens (`camera_model.through_lens`: barrel
distortion keeping the diagonal field of view, docs/camera.md); its table goes to object_width_cues_tello.md.
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.core.cameras import CAMERAS
from vlnpilot.scene.model import target_kind
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.sim.camera_model import through_lens
from vlnpilot.sim.ranging import beam
from vlnpilot.sim.target_views import (
    VIEW_ANGLES,
    free_pose,
    view,
    view_pose,
    width_fraction,
)
from vlnpilot.tasks.success import ON_THE_BEAM, RANGE_STOP_M, SuccessConfig, close_cue

FACTORS = (0.7, 1.1)
Seen = dict[tuple[str, str, float], list[tuple[float, float | None]]]  # (kind, view, factor) -> [(width, range)]


def measure(scenes: list[str], camera: str = "ideal") -> Seen:
    success_m = SuccessConfig().object_distance_m
    out: Seen = collections.defaultdict(list)
    for name in scenes:
        with Simulator(name, SimConfig(width=16, height=16, rear_width=16, rear_height=16)) as sim:
            for target in sim.scene.targets:
                for view_name, angle in VIEW_ANGLES.items():
                    for k in FACTORS:
                        pose = next((p for p in (view_pose(sim, target.id, k * success_m, angle, side)
                                                 for side in (1, -1)) if free_pose(sim, target.id, p)), None)
                        if pose is None:
                            continue
                        width = width_fraction(through_lens(view(sim, pose), camera), sim.target_geoms[target.id])
                        front, _ = beam(sim.model, sim.data, pose, "front", sim._body_id, 4.0)
                        out[(target_kind(target.id), view_name, k)].append((width, front))
    return out


def _count(hits: list[bool]) -> str:
    return f"{sum(hits)}/{len(hits)}" if hits else "–"


def _span(values: list[float]) -> str:
    return f"{min(values):.0%}–{max(values):.0%}" if values else "–"


def table(seen: Seen, houses: int, camera: str = "ideal") -> str:
    lines = [f"Reach Object's stop rules against the footprint monitor (within {SuccessConfig().object_distance_m:g} "
             f"m of the nearest point), cabin, cabin-v1 and houses 0..{houses - 1}, seen by the {camera} camera; "
             f"{describe()}", "",
             "| object | view | targets | width at 0.7x | at 1.1x | its cue | cue: close at 0.7x | cue: false close at "
             f"1.1x | front range at 0.7x | at 1.1x | range <= {RANGE_STOP_M:g} m: close at 0.7x | false close at "
             "1.1x |",
             "|---" * 12 + "|"]
    for kind in sorted({k for k, _, _ in seen}):
        cue = close_cue(kind)
        shown = f"{cue.width_fraction:.0%}" + (f" + {cue.then_m:g} m" if cue.then_m else "")
        for view_name in VIEW_ANGLES:
            near, far = seen.get((kind, view_name, 0.7), []), seen.get((kind, view_name, 1.1), [])
            if not near and not far:
                continue
            ranges = [[r for _, r in near], [r for _, r in far]]
            shown_ranges = [" ".join(sorted({"beyond" if r is None else f"{r:.2f}" for r in rs})[:3]) or "–"
                            for rs in ranges]
            on_beam = kind in ON_THE_BEAM
            lines.append(
                f"| {kind} | {view_name} | {max(len(near), len(far))} | {_span([w for w, _ in near])} | "
                f"{_span([w for w, _ in far])} | {shown} | "
                f"{'–' if cue.then_m else _count([w >= cue.width_fraction for w, _ in near])} | "
                f"{_count([w >= cue.width_fraction for w, _ in far])} | {shown_ranges[0]} | {shown_ranges[1]} | "
                f"{_count([r is not None and r <= RANGE_STOP_M for r in ranges[0]]) if on_beam else 'no rule'} | "
                f"{_count([r is not None and r <= RANGE_STOP_M for r in ranges[1]]) if on_beam else 'no rule'} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--houses", type=int, default=40)
    parser.add_argument("--camera", choices=CAMERAS, default="ideal", help="whose lens the widths are seen through")
    parser.add_argument("--out", type=Path, default=None, help="default: bench/results/object_width_cues[_tello].md")
    parser.add_argument("--smoke", action="store_true", help="the cabin only, nothing written (for the tests)")
    args = parser.parse_args()
    if args.smoke:
        print(table(measure(["cabin"], args.camera), 0, args.camera))
        print(table(measure(["cabin"], "tello"), 0, "tello"))
        return
    out = args.out or Path(__file__).parent / "results" / ("object_width_cues.md" if args.camera == "ideal"
                                                           else f"object_width_cues_{args.camera}.md")
    scenes = ["cabin", "cabin-v1", *(f"house:{seed}" for seed in range(args.houses))]
    publish(table(measure(scenes, args.camera), args.houses, args.camera), out)


if __name__ == "__main__":
    main()
