"""Do Reach Object's stop rules agree with the success monitor for every kind of object, not only the cabin's?

    .venv/bin/python bench/object_width_cues.py [--houses 40] [--out bench/results/object_width_cues.md]

The first prompts said an object is within the success distance when it spans at least 65 % of the image width
(calibrated on the cabin's fridge, mirror and sink); the prompt now names a cue per kind of object
(`success.OBJECT_CLOSE_CUES`). Here every target of the cabin, `cabin-v1` and houses 0..N-1 is rendered on its
facing axis at 0.7x, 1.0x, 1.1x and 1.5x the success distance (where the drone can hover there), and the table
says, per kind of object, how wide it looks and how often each rule is right: "close at 0.7x" (a pilot that obeys
it can stop) and "false close" (a pilot that obeys it declares too early: a false success; for the widest kinds,
whose cue adds half a metre after the object fills the image, "false close" means it fills it from 1.5x).
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.scene.model import target_kind
from vlnpilot.sim import Simulator
from vlnpilot.sim.target_views import facing_view, free_standpoint, width_fraction
from vlnpilot.tasks.success import OBJECT_CLOSE_WIDTH_FRACTION, SuccessConfig, close_cue

FACTORS = (0.7, 1.0, 1.1, 1.5)
Widths = dict[str, dict[float, list[float]]]


def measure(scenes: list[str]) -> Widths:
    """{kind: {factor: [width fraction per target that can be viewed from there]}}."""
    success_m = SuccessConfig().object_distance_m
    out: Widths = collections.defaultdict(lambda: collections.defaultdict(list))
    for name in scenes:
        with Simulator(name) as sim:
            for target in sim.scene.targets:
                ids = sim.target_geoms[target.id]
                for k in FACTORS:
                    if free_standpoint(sim, target.id, k * success_m):
                        seg = facing_view(sim, target.id, k * success_m)
                        out[target_kind(target.id)][k].append(width_fraction(seg, ids))
    return out


def _count(widths: list[float], threshold: float) -> str:
    return f"{sum(x >= threshold for x in widths)}/{len(widths)}" if widths else "–"


def table(widths: Widths, houses: int) -> str:
    one = OBJECT_CLOSE_WIDTH_FRACTION
    lines = [f"Reach Object's stop rules against the monitor (within {SuccessConfig().object_distance_m} m): one "
             f"{one:.0%} rule, and the cue of each kind; cabin, cabin-v1 and houses 0..{houses - 1}; {describe()}", "",
             "| object | targets | width at 0.7x | 1.0x | 1.1x | 1.5x | 65 %: close at 0.7x | 65 %: false close "
             "at 1.1x | its cue | cue: close at 0.7x | cue: false close |", "|---" * 11 + "|"]
    for kind in sorted(widths):
        w, cue = widths[kind], close_cue(kind)
        span = [f"{min(w[k]):.0%}–{max(w[k]):.0%}" if w[k] else "–" for k in FACTORS]
        shown = f"{cue.width_fraction:.0%}" + (f" + {cue.then_m:g} m" if cue.then_m else "")
        reach = "–" if cue.then_m else _count(w[0.7], cue.width_fraction)  # the widest fill it, then fly on
        false_close = _count(w[1.5] if cue.then_m else w[1.1], cue.width_fraction)
        lines.append(f"| {kind} | {max(len(v) for v in w.values())} | {' | '.join(span)} | {_count(w[0.7], one)} | "
                     f"{_count(w[1.1], one)} | {shown} | {reach} | {false_close} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--houses", type=int, default=40)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "object_width_cues.md")
    args = parser.parse_args()
    scenes = ["cabin", "cabin-v1", *(f"house:{seed}" for seed in range(args.houses))]
    publish(table(measure(scenes), args.houses), args.out)


if __name__ == "__main__":
    main()
