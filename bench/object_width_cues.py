"""Does Reach Object's stop rule agree with the success monitor for every kind of object, not only the cabin's?

    .venv/bin/python bench/object_width_cues.py [--houses 40] [--out bench/results/object_width_cues.md]

The prompt says an object is within the success distance when it spans at least OBJECT_CLOSE_WIDTH_FRACTION of
the image width (`tests/test_calibration.py` checks that for the cabin's fridge, mirror and sink). Here every
target of the cabin, `cabin-v1` and houses 0..N-1 is rendered on its facing axis at 0.7x, 1.0x and 1.1x the
success distance (where the drone can hover there), and the table says, per kind of object, how wide it looks
and how often the rule is right: "close at 0.7x" (a pilot that obeys it can stop) and "false close at 1.1x" (a
pilot that obeys it declares too early: a false success).
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.sim import Simulator
from vlnpilot.sim.target_views import facing_view, free_standpoint, target_kind, width_fraction
from vlnpilot.success import OBJECT_CLOSE_WIDTH_FRACTION, SuccessConfig

FACTORS = (0.7, 1.0, 1.1)
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


def table(widths: Widths, houses: int) -> str:
    rule = OBJECT_CLOSE_WIDTH_FRACTION
    lines = [f"Reach Object's rule (close when the object spans >= {rule:.0%} of the image width) against the monitor "
             f"(within {SuccessConfig().object_distance_m} m), cabin, cabin-v1 and houses 0..{houses - 1}; "
             f"{describe()}", "",
             "| object | targets | width at 0.7x | width at 1.0x | width at 1.1x | close at 0.7x "
             "| false close at 1.1x |",
             "|---|---|---|---|---|---|---|"]
    for kind in sorted(widths):
        w = widths[kind]
        span = [f"{min(w[k]):.0%}–{max(w[k]):.0%}" if w[k] else "–" for k in FACTORS]
        near, far = w[0.7], w[1.1]
        ok = f"{sum(x >= rule for x in near)}/{len(near)}" if near else "–"
        bad = f"{sum(x >= rule for x in far)}/{len(far)}" if far else "–"
        lines.append(f"| {kind} | {max(len(v) for v in w.values())} | {' | '.join(span)} | {ok} | {bad} |")
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
