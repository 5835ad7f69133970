"""Cost of procedural houses: generation plus MJCF compile per house, and a simulator step in a six-room
house against the cabin.

    .venv/bin/python bench/house_cost.py [--houses 40] [--steps 20] [--width 640] [--height 480] [--smoke]

Generation is timed uncached (each seed built from scratch, its validation and refused sub-seeds included),
then `scene_to_mjcf` and `mujoco.MjModel.from_xml_string` on the result. The step cost uses
`step_cost.measure` (sweep plus both renders) from every spawn of each scene. Budgets from issue 13: 1 s
median per house, and a six-room house's step within 1.3x the cabin's.
"""

from __future__ import annotations

import argparse
import statistics
import time

from machine import describe  # bench/machine.py, beside this script
from step_cost import measure, ms, percentile

from vlnpilot.scene import load_scene
from vlnpilot.scene.houses import generate_house
from vlnpilot.scene.mjcf import scene_to_mjcf
from vlnpilot.sim import drone  # selects the headless GL backend before mujoco loads

GENERATE_BUDGET_S, STEP_RATIO_BUDGET = 1.0, 1.3


def generation_times(houses: int) -> tuple[list[float], list[float]]:
    """(generate, generate + MJCF + compile) seconds per house, seeds 0..houses-1, nothing cached."""
    import mujoco

    gen, total = [], []
    for seed in range(houses):
        generate_house.cache_clear()
        t0 = time.perf_counter()
        scene = generate_house(seed)
        t1 = time.perf_counter()
        xml, assets = scene_to_mjcf(scene, bodies=drone.drone_body_xml(), assets_xml=drone.drone_assets_xml())
        mujoco.MjModel.from_xml_string(xml, assets)
        t2 = time.perf_counter()
        gen.append(t1 - t0)
        total.append(t2 - t0)
    return gen, total


def six_room_house(start: int = 0) -> str:
    seed = start
    while len(load_scene(f"house:{seed}").rooms) < 6:
        seed += 1
    return f"house:{seed}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--houses", type=int, default=40)
    ap.add_argument("--steps", type=int, default=20, help="steps per spawn for the step cost")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--smoke", action="store_true", help="2 houses, 1 step per spawn (for the tests)")
    args = ap.parse_args()
    if args.smoke:
        args.houses, args.steps = 2, 1
    print(f"machine: {describe()}")
    gen, total = generation_times(args.houses)
    med = statistics.median(total)
    print(f"houses 0..{args.houses - 1}: generate median {ms(statistics.median(gen)):.0f} ms; generate + MJCF + "
          f"compile median {ms(med):.0f} ms, p90 {ms(percentile(total, 0.9)):.0f} ms, max {ms(max(total)):.0f} ms "
          f"(budget {GENERATE_BUDGET_S:.0f} s: {'within' if med <= GENERATE_BUDGET_S else 'OVER'})")
    house = six_room_house()
    medians = {}
    for scene in ("cabin", house):
        steps = measure(args.steps, args.width, args.height, scene)["step"]
        medians[scene] = statistics.median(steps)
        print(f"step {scene:<12} median {ms(medians[scene]):.1f} ms, p90 {ms(percentile(steps, 0.9)):.1f} ms "
              f"({len(steps)} steps, both cameras {args.width}x{args.height})")
    ratio = medians[house] / medians["cabin"]
    print(f"six-room house / cabin step cost: {ratio:.2f}x (budget {STEP_RATIO_BUDGET}x: "
          f"{'within' if ratio <= STEP_RATIO_BUDGET else 'OVER'})")


if __name__ == "__main__":
    main()
