"""Render the documentation's pictures (docs/img, shown by docs/simulator.md): the front view from every spawn
and in front of every target, a chase view, and the floor plan.
Run: .venv/bin/python scripts/readme_images.py [--out docs/img]"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from PIL import Image

from vlnpilot.core.records import Pose
from vlnpilot.report.floorplan import save_floorplan
from vlnpilot.sim import Simulator


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="docs/img")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with Simulator() as sim:
        for spawn in sim.scene.spawns:
            obs = sim.reset(spawn.id)
            Image.fromarray(obs.front_rgb).save(out / f"spawn-{spawn.id}-front.jpg", quality=88)
            Image.fromarray(obs.rear_rgb).save(out / f"spawn-{spawn.id}-rear.jpg", quality=88)
        for t in sim.scene.targets:
            a = math.radians(t.facing_deg)
            pose = Pose(t.position[0] + 0.8 * math.cos(a), t.position[1] + 0.8 * math.sin(a), 1.0, t.facing_deg + 180)
            Image.fromarray(sim.reset(pose).front_rgb).save(out / f"target-{t.id}.jpg", quality=88)
        save_floorplan(sim.scene, out / "map.png")
    print(f"wrote pictures to {out}")


if __name__ == "__main__":
    main()
