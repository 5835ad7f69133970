"""The gallery of procedural houses (docs/houses.md): per house its floor plan beside one drone view, in one image.

    .venv/bin/python scripts/house_gallery.py [--seeds 0,1,5,9,16,36] [--out docs/img/houses-gallery.jpg]

The view is the front camera at the spawn whose image shows the most detail (highest pixel spread), so
that no tile is a blank wall.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from vlnpilot.report.floorplan import save_floorplan
from vlnpilot.sim import SimConfig, Simulator

TILE_H, TILE_W = 300, 860


def tile(scene_name: str) -> Image.Image:
    with Simulator(scene_name, SimConfig(width=400, height=300, rear_width=16, rear_height=16)) as sim:
        views = [(float(np.std(obs.front_rgb)), spawn.id, obs.front_rgb)
                 for spawn in sim.scene.spawns for obs in [sim.reset(spawn.id)]]
        _, spawn_id, best = max(views, key=lambda v: v[0])
        with tempfile.TemporaryDirectory() as tmp:
            plan = Image.open(save_floorplan(sim.scene, Path(tmp) / "plan.png", dpi=60)).convert("RGB")
        description = sim.scene.description.split(";")[0]
    plan = plan.resize((round(plan.width * TILE_H / plan.height), TILE_H))
    view = Image.fromarray(best)
    out = Image.new("RGB", (plan.width + view.width + 10, TILE_H + 24), "white")
    out.paste(plan, (0, 24))
    out.paste(view, (plan.width + 10, 24))
    ImageDraw.Draw(out).text((4, 4), f"{scene_name}: {description.removeprefix('A procedural house of ')}; "
                                     f"view from the {spawn_id} spawn", fill="black")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,5,9,16,36")
    ap.add_argument("--out", type=Path, default=Path("docs/img/houses-gallery.jpg"))
    args = ap.parse_args()
    tiles = [tile(f"house:{s.strip()}") for s in args.seeds.split(",")]
    tiles = [t.resize((TILE_W, round(t.height * TILE_W / t.width))) for t in tiles]  # one width: two even columns
    h = max(t.height for t in tiles)
    rows = [tiles[i : i + 2] for i in range(0, len(tiles), 2)]
    sheet = Image.new("RGB", (2 * TILE_W + 10, len(rows) * (h + 10)), "white")
    for r, pair in enumerate(rows):
        for c, t in enumerate(pair):
            sheet.paste(t, (c * (TILE_W + 10), r * (h + 10) + (h - t.height) // 2))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.out, quality=85)
    print(f"wrote {args.out} ({sheet.width}x{sheet.height})")


if __name__ == "__main__":
    main()
