"""Would longer forward moves, licensed by the forward range, cut the steps of an approach to an object?

    .venv/bin/python bench/longer_moves.py [--houses 20] [--start 3.0] [--out bench/results/longer_moves.md] [--smoke]

The paper's Reach Object flies `A1` (10 cm) only. A scripted approach flies straight at every target of the cabins
and houses 0..N-1 from `--start` metres in front of it (on its facing axis, where the drone can hover) until the
monitor's distance less 0.1 m (the oracle's stop), under three policies:
- `A1`: the paper's moves;
- `tof`: `A2` (25 cm) while the RoboMaster TT's forward range reads beyond its 1.2 m, else `A1`;
- `multiranger`: `A3` (50 cm) while the front range shows room for it plus the stop distance and the shield's margin
  (0.05 m), else `A2` likewise, else `A1`.
It counts steps and collisions and reports the medians (the simulator's exact geometry; no pilot, no noise).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.footprint import footprint_distance
from vlnpilot.core.ranging import SENSORS
from vlnpilot.safety.config import SafetyConfig
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.sim.ranging import beam_distance
from vlnpilot.sim.target_views import free_pose, view_pose
from vlnpilot.tasks.success import SuccessConfig

STOP_M = SuccessConfig().object_distance_m - 0.1  # where the oracle stops
MARGIN_M = SafetyConfig().margin_m
POLICIES = ("A1", "tof", "multiranger")


def next_move(policy: str, front: float | None) -> str:
    """The longest forward move the policy allows with `front` metres of room ahead (None: beyond the sensor)."""
    if policy == "A1":
        return "A1"
    sensor = SENSORS[policy]
    room = sensor.max_m if front is None else front  # "beyond N m" licenses N m, no more
    for code in ("A3", "A2"):
        if (code == "A2" or policy == "multiranger") and room >= STOP_M + COMMANDS[code].amount + MARGIN_M:
            return code
    return "A1"


def approach(sim: Simulator, target_id: str, start: float, policy: str) -> tuple[int, bool]:
    """(steps, collided) flying straight at the target until within STOP_M of its footprint."""
    footprint = sim.target_footprint(target_id)
    pose = view_pose(sim, target_id, start, 0.0)
    sim.reset(pose)
    for steps in range(1, 200):
        max_m = SENSORS["multiranger"].max_m if policy != "tof" else SENSORS["tof"].max_m
        front = beam_distance(sim.model, sim.data, sim.pose, "front", sim._body_id, max_m)
        obs = sim.step(next_move(policy, front))
        if obs.collided:
            return steps, True
        if footprint_distance(obs.pose, footprint) <= STOP_M:
            return steps, False
    return 200, False


def measure(scenes: list[str], start: float) -> dict[str, list[tuple[int, bool]]]:
    out: dict[str, list[tuple[int, bool]]] = {p: [] for p in POLICIES}
    for name in scenes:
        with Simulator(name, SimConfig(render=False)) as sim:
            for target in sim.scene.targets:
                if not free_pose(sim, target.id, view_pose(sim, target.id, start, 0.0)):
                    continue
                for policy in POLICIES:
                    out[policy].append(approach(sim, target.id, start, policy))
    return out


def table(runs: dict[str, list[tuple[int, bool]]], houses: int, start: float) -> str:
    base = statistics.median(s for s, _ in runs["A1"])
    lines = [f"A scripted approach from {start:g} m in front of every target it can start from (cabin, cabin-v1, "
             f"houses 0..{houses - 1}) to {STOP_M:g} m; {describe()}", "",
             "| policy | approaches | median steps | mean steps | vs A1 (median) | collisions |",
             "|---|---|---|---|---|---|"]
    for policy in POLICIES:
        steps = [s for s, _ in runs[policy]]
        lines.append(f"| {policy} | {len(steps)} | {statistics.median(steps):g} | {statistics.mean(steps):.1f} | "
                     f"{statistics.median(steps) / base:.0%} | {sum(c for _, c in runs[policy])} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--houses", type=int, default=20)
    parser.add_argument("--start", type=float, default=3.0)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "longer_moves.md")
    parser.add_argument("--smoke", action="store_true", help="house 0 only, nothing written (for the tests)")
    args = parser.parse_args()
    if args.smoke:
        print(table(measure(["house:0"], args.start), 1, args.start))  # the cabins have no room for 3 m
        return
    scenes = ["cabin", "cabin-v1", *(f"house:{seed}" for seed in range(args.houses))]
    publish(table(measure(scenes, args.start), args.houses, args.start), args.out)


if __name__ == "__main__":
    main()
