"""The figure of docs/camera.md: one view through the ideal and the Tello camera, and across three randomised worlds.

Top row: the cabin's living-room spawn through `--camera ideal`, `--camera tello`, and `--camera tello` right after
a 45° turn (the frame lags the turn and streaks along it). Bottom row: the Tello camera in the worlds of
`--randomize 1`, `2` and `3`. Written as a 256-colour PNG (under 400 kB).

    .venv/bin/python scripts/camera_figure.py [--out docs/img/camera-views.png] [--scene cabin] [--spawn living_room]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from vlnpilot.sim import SimConfig, Simulator

TILE = (400, 300)
LABEL_H = 24


def frame(scene: str, spawn: str, camera: str, randomize: int | None = None, turn: str | None = None) -> np.ndarray:
    with Simulator(scene, SimConfig(rear_camera=False, camera=camera, randomize=randomize)) as sim:
        obs = sim.reset(spawn, seed=1)
        if turn:
            sim.step({"B2": "C2", "C2": "B2"}[turn])  # turn away, then back: the drone ends where it began
            obs = sim.step(turn)
        return obs.front_rgb


def tile(image: np.ndarray, label: str) -> Image.Image:
    out = Image.new("RGB", (TILE[0], TILE[1] + LABEL_H), "white")
    out.paste(Image.fromarray(image).resize(TILE, Image.Resampling.LANCZOS), (0, LABEL_H))
    ImageDraw.Draw(out).text((6, 5), label, fill="black")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img/camera-views.png"))
    parser.add_argument("--scene", default="cabin")
    parser.add_argument("--spawn", default="living_room")
    args = parser.parse_args()
    s, p = args.scene, args.spawn
    tiles = [tile(frame(s, p, "ideal"), "--camera ideal (the render, 640x480)"),
             tile(frame(s, p, "tello"), "--camera tello (960x720: lens, noise, JPEG)"),
             tile(frame(s, p, "tello", turn="B2"), "--camera tello, after a 45° turn (300 ms lag, streak)"),
             *(tile(frame(s, p, "tello", randomize=seed), f"--camera tello --randomize {seed}") for seed in (1, 2, 3))]
    w, h = tiles[0].size
    sheet = Image.new("RGB", (3 * w + 8, 2 * h + 4), "white")
    for i, t in enumerate(tiles):
        sheet.paste(t, ((i % 3) * (w + 4), (i // 3) * (h + 4)))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    sheet.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(args.out,
                                                                                                optimize=True)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1000:.0f} kB)")


if __name__ == "__main__":
    main()
