"""Cost of the rich scene detail (`--detail rich`, scene/detail.py, docs/scenes.md) and of shadows: one simulator
step (the motion's collision sweep plus the front and chase renders at 640x480, what `vln-pilot run` does) in each
configuration, all flying the same commands step by step in one run, so that every configuration sees the same
poses and the same load on the shared machine:

- `plain`: today's scenes (the default);
- `rich`: the detail with its reflective mirrors;
- `rich, mirrors not reflecting`: the same with the mirror material's reflectance set to 0 (the reflection's share);
- `plain + shadows`: every light casting a 1024 px shadow map (MuJoCo's `castshadow`, `<quality shadowsize>`);
- `plain + one shadow`: the first light alone casting a 512 px one (the cheapest shadow there is).

It also measures what the target visibility would lose if it counted the detail (it does not: the segmentation
renders without the detail group): the share of each target's pixels that the detail hides, seen from 0.9 m in
front of it (inside the monitor's 1 m), at the segmentation's 160x120.

Prints the wall-clock medians and p90s, the CPU-time medians (every thread of the process: the renderer's too; less
sensitive than wall time to the other sessions on the machine), each as the median of the paired ratios (each step
against plain's same step, flown just before), the model's build time, and the machine. The budget of the detail is
1.2x plain's step. Timing is not a correctness check:
the exit code is 0 unless a run fails.
`--images DIR` also writes the cabin mirror before and after (`mirror-plain.png`, `mirror-rich.png`, docs/scenes.md).
`--smoke`: 2 steps per spawn of the cabin only, for the tests.

    .venv/bin/python bench/scene_detail_cost.py [--steps 24] [--scenes cabin,house:11?rooms=5] [--images DIR]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from machine import describe, publish  # bench/machine.py, beside this script

from vlnpilot.core.commands import get_command
from vlnpilot.core.records import Pose
from vlnpilot.sim import SimConfig, Simulator  # selects the headless GL backend before mujoco loads

SEQUENCE = ("A1", "B1", "A2", "C2", "D1", "A1", "D2", "C1", "A3", "B2", "E", "A1", "C3", "A2", "B1", "A1")
BUDGET = 1.2  # rich's median step as a multiple of plain's
SHADOW_SIZE = 1024
MIRROR_VIEW = Pose(4.55, 1.9, 1.0, 25.0)  # the cabin's bedroom: the bed, a lamp and the full-length mirror
HIDDEN_SCENES = ("cabin", "house:11?rooms=5", "house:43?rooms=6", "house:7?rooms=4")
OUT = Path(__file__).resolve().parent / "results" / "scene_detail_cost.md"


def _simulators(scene: str) -> dict[str, Simulator]:
    """The configurations; the shadow maps and the reflectance are set on the model before any renderer exists."""
    import mujoco

    sims = {"plain": Simulator(scene), "rich": Simulator(scene, SimConfig(detail="rich")),
            "rich, mirrors not reflecting": Simulator(scene, SimConfig(detail="rich")),
            "plain + shadows": Simulator(scene), "plain + one shadow": Simulator(scene)}
    dull = sims["rich, mirrors not reflecting"].model
    dull.mat_reflectance[mujoco.mj_name2id(dull, mujoco.mjtObj.mjOBJ_MATERIAL, "detail_mirror")] = 0.0
    shadowed = sims["plain + shadows"].model
    shadowed.vis.quality.shadowsize = SHADOW_SIZE
    shadowed.light_castshadow[:] = 1
    one = sims["plain + one shadow"].model
    one.vis.quality.shadowsize = 512
    one.light_castshadow[:] = 0
    one.light_castshadow[0] = 1
    return sims


Times = dict[str, list[float]]


def measure(scene: str, steps: int) -> tuple[Times, Times, dict[str, float]]:
    """Wall and CPU times (s; CPU: every thread of this process, the renderer's included) of each step per
    configuration, interleaved step by step, and the model's build time (s)."""
    build: dict[str, float] = {}
    Simulator(scene).close()  # the textures, generated once per process, are not a build's cost
    for detail in ("plain", "rich"):
        t0 = time.perf_counter()
        Simulator(scene, SimConfig(detail=detail)).close()
        build[detail] = time.perf_counter() - t0
    sims = _simulators(scene)
    wall: Times = {key: [] for key in sims}
    cpu: Times = {key: [] for key in sims}
    try:
        for spawn in sims["plain"].scene.spawns:
            for sim in sims.values():
                sim.reset(spawn)
                sim.step("E")  # warm-up: renderers and GL contexts exist before anything is timed
                sim.reset(spawn)
            for i in range(steps):
                cmd = get_command(SEQUENCE[i % len(SEQUENCE)])
                collided = False
                for key, sim in sims.items():
                    t0, c0 = time.perf_counter(), time.process_time()
                    obs = sim.step(cmd)
                    wall[key].append(time.perf_counter() - t0)
                    cpu[key].append(time.process_time() - c0)
                    collided = obs.collided  # the same geometry everywhere: all collide alike
                if collided:
                    for sim in sims.values():
                        sim.reset(spawn)
    finally:
        for sim in sims.values():
            sim.close()
    return wall, cpu, build


def hidden_by_detail(scene: str) -> list[tuple[str, float]]:
    """(target, share of its segmentation pixels the detail hides) from 0.9 m in front of each target (a mirror's
    reflective face counts as the mirror)."""
    import math

    import mujoco
    import numpy as np

    from vlnpilot.scene.detail import DETAIL_GROUP, PREFIX
    from vlnpilot.sim import drone

    out = []
    with Simulator(scene, SimConfig(detail="rich", render=False)) as sim:
        renderer = mujoco.Renderer(sim.model, 120, 160)
        renderer.enable_segmentation_rendering()
        option = mujoco.MjvOption()
        option.geomgroup[DETAIL_GROUP] = 1
        try:
            for target in sim.scene.targets:
                a = math.radians(target.facing_deg)
                pose = Pose(target.position[0] + 0.9 * math.cos(a), target.position[1] + 0.9 * math.sin(a),
                            sim.scene.flight_altitude, target.facing_deg + 180.0)
                if sim.contact_at(pose) is not None:
                    continue
                sim.reset(pose)
                own = {f"{PREFIX}mirror_{s.name}" for s in sim.scene.solids if s.target == target.id}
                ids = [*sim.target_geoms[target.id], *(g for g in range(sim.model.ngeom) if sim.geom_name(g) in own)]
                seen = []
                for opt in (None, option):
                    renderer.update_scene(sim.data, camera=drone.FRONT_CAMERA, scene_option=opt)
                    seg = renderer.render()
                    seen.append(int(np.isin(seg[..., 0], ids).sum()))
                if seen[0]:
                    out.append((target.id, 1.0 - seen[1] / seen[0]))
        finally:
            renderer.close()
    return out


def paired(values: list[float], plain: list[float]) -> float:
    """The median over steps of this configuration's step time / plain's at the same step (flown back to back, so
    that a change in the machine's load between steps cancels out)."""
    return statistics.median(v / p for v, p in zip(values, plain, strict=True))


def p90(values: list[float]) -> float:
    return statistics.quantiles(values, n=10)[-1] if len(values) > 1 else values[0]


def table(scene: str, wall: Times, cpu: Times, build: dict[str, float]) -> str:
    lines = [f"### {scene}", "", f"{len(wall['plain'])} steps per configuration; model build: plain "
             f"{build['plain'] * 1000:.0f} ms, rich {build['rich'] * 1000:.0f} ms", "",
             "| configuration | median wall (ms) | p90 wall (ms) | paired x plain | median CPU (ms) | paired CPU "
             "x plain |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for key in wall:
        lines.append(f"| {key} | {statistics.median(wall[key]) * 1000:.1f} | {p90(wall[key]) * 1000:.1f} | "
                     f"{paired(wall[key], wall['plain']):.2f} | {statistics.median(cpu[key]) * 1000:.1f} | "
                     f"{paired(cpu[key], cpu['plain']):.2f} |")
    ratios = paired(wall["rich"], wall["plain"]), paired(cpu["rich"], cpu["plain"])
    verdict = "within" if max(ratios) <= BUDGET else "OVER"
    lines += ["", f"rich / plain, paired: wall {ratios[0]:.2f}, CPU {ratios[1]:.2f} ({verdict} the {BUDGET}x budget)",
              ""]
    return "\n".join(lines)


def write_images(out: Path) -> None:
    """The cabin's mirror seen from the bedroom, plain and rich (docs/scenes.md)."""
    from PIL import Image

    out.mkdir(parents=True, exist_ok=True)
    for detail in ("plain", "rich"):
        with Simulator("cabin", SimConfig(detail=detail)) as sim:
            Image.fromarray(sim.reset(MIRROR_VIEW).front_rgb).save(out / f"mirror-{detail}.png", optimize=True)
        print(f"wrote {out / f'mirror-{detail}.png'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=24, help="steps per spawn")
    parser.add_argument("--scenes", default="cabin,house:11?rooms=5")
    parser.add_argument("--images", type=Path, default=None, help="write the mirror before/after PNGs here")
    parser.add_argument("--smoke", action="store_true")
    args = parser.parse_args()
    steps, scenes = (2, ["cabin"]) if args.smoke else (args.steps, args.scenes.split(","))
    parts = ["# Scene detail and shadows: the cost of a step (bench/scene_detail_cost.py)", "",
             f"Machine: {describe()}", "",
             "A step: the collision sweep and the front and chase renders at 640x480.", ""]
    for scene in scenes:
        parts.append(table(scene, *measure(scene, steps)))
    hidden = [(scene, *row) for scene in (["cabin"] if args.smoke else HIDDEN_SCENES)
              for row in hidden_by_detail(scene)]
    parts += ["### Target pixels the detail would hide (from 0.9 m in front; the monitor does not count it)", "",
              "| scene | target | hidden |", "| --- | --- | ---: |",
              *(f"| {scene} | {target} | {share:.1%} |" for scene, target, share in hidden), ""]
    text = "\n".join(parts)
    publish(text, OUT, smoke=args.smoke)
    if args.images:
        write_images(args.images)


if __name__ == "__main__":
    main()
