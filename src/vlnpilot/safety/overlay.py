"""The visual aid for the model: the propeller tips' corridor drawn on the image the pilot sees."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vlnpilot.core import tello_spec


# -- visual aid for the model -------------------------------------------------------------------------------------
def corridor_pixels(width: int, height: int, *, half_width: float = tello_spec.HALF_WIDTH,
                    fovy_deg: float | None = None, depths: tuple[float, ...] = (0.3, 0.5, 1.0, 2.0, 4.0),
                    drop_m: float = 0.12) -> list[list[tuple[float, float]]]:
    """Pixel polylines (left, right) of the propeller tips' paths on a forward move, drawn `drop_m` below the
    flight height so that they are visible: at each depth their separation is the drone's width at that depth."""
    fovy = fovy_deg if fovy_deg is not None else tello_spec.vertical_fov_deg()
    f = (height / 2) / math.tan(math.radians(fovy) / 2)
    cx, cy = width / 2, height / 2
    return [[(cx + side * f * half_width / d, cy + f * drop_m / d) for d in depths] for side in (-1, 1)]


def draw_corridor(image: np.ndarray, *, color: tuple[int, int, int] = (255, 0, 255), **kwargs: Any) -> np.ndarray:
    """A copy of the front image with two thin lines where the propeller tips would pass on a forward move
    (see `corridor_pixels`), with a tick at each depth. Placeholder images (render off) are returned unchanged."""
    if image.ndim != 3 or image.shape[0] < 16 or image.shape[1] < 16:
        return image
    from PIL import Image, ImageDraw

    h, w = image.shape[:2]
    out = Image.fromarray(np.ascontiguousarray(image))
    draw = ImageDraw.Draw(out)
    for line in corridor_pixels(w, h, **kwargs):
        draw.line(line, fill=color, width=1)
        for x, y in line:
            draw.line([(x - 3, y), (x + 3, y)], fill=color, width=1)
    return np.asarray(out)
