"""Domain randomisation (`--randomize SEED`): the same scene under other lights, paints, texture scales, camera
height and exposure, varied on the compiled model at reset, deterministic per seed (Tobin et al. 2017).

The ranges (docs/camera.md) stay within what a real house and a real Tello show, so that nothing a task names
changes: a paint gets lighter or darker and shifts its hue slightly (a white fridge stays white), texture scale
stays within +-15 %.
Geometry is never changed (collisions, the monitor and the oracle see the same world).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

RANGES = {  # name: (low, high); one source for the code and docs/camera.md
    "light_intensity": (0.7, 1.3),  # scales every light's diffuse and the headlight
    # warm white bulb .. daylight, as an RGB tint of the lights: what a camera's auto white balance leaves of
    # 2700-6500 K light (the renders have no white balance, so the whole range would paint a white fridge yellow)
    "light_temperature_k": (4000.0, 6500.0),
    "material_brightness": (0.85, 1.15),  # per material, on its rgba: lighter and darker paints
    "material_tint": (0.95, 1.05),  # per material and channel: a slight shift that keeps each colour's hue
    "texture_scale": (0.85, 1.15),  # per material, on its texrepeat
    "camera_height_m": (-0.05, 0.05),  # the front camera's mounting height, relative to the drone body
    "exposure_ev": (-0.5, 0.5),  # the camera's exposure bias, in stops
}


def temperature_rgb(kelvin: float) -> np.ndarray:
    """The RGB tint of a black body at `kelvin`, normalised to its largest channel (Tanner Helland's fit of
    Mitchell Charity's table, to within a few per cent over 1000-40000 K)."""
    t = kelvin / 100
    r = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
    g = 99.4708025861 * np.log(t) - 161.1195681661 if t <= 66 else 288.1221695283 * (t - 60) ** -0.0755148492
    b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.5177312231 * np.log(t - 10) - 305.0447927307)
    rgb = np.clip(np.array([r, g, b], float), 0, 255)
    return rgb / rgb.max()


@dataclass(frozen=True)
class Randomization:
    """One seed's draw (recorded with the run)."""

    seed: int
    light_intensity: float
    light_temperature_k: float
    camera_height_m: float
    exposure_ev: float

    @property
    def exposure_gain(self) -> float:
        return float(2.0 ** self.exposure_ev)

    def to_dict(self) -> dict[str, float | int]:
        return {"seed": self.seed, "light_intensity": round(self.light_intensity, 4),
                "light_temperature_k": round(self.light_temperature_k, 1),
                "camera_height_m": round(self.camera_height_m, 4), "exposure_ev": round(self.exposure_ev, 4)}


class Randomizer:
    """Applies a seed's draw to a compiled model, always from the model's own values (repeatable at each reset)."""

    def __init__(self, model: mujoco.MjModel, camera_id: int, skip_materials: frozenset[int] = frozenset()):
        self.model, self.camera_id = model, camera_id
        self.skip_materials = skip_materials  # the drone's own materials: not part of the world
        self._base = {"light_diffuse": model.light_diffuse.copy(), "headlight": model.vis.headlight.diffuse.copy(),
                      "ambient": model.vis.headlight.ambient.copy(), "mat_rgba": model.mat_rgba.copy(),
                      "mat_texrepeat": model.mat_texrepeat.copy(), "cam_pos": model.cam_pos[camera_id].copy()}

    def restore(self) -> None:
        m, b = self.model, self._base
        m.light_diffuse[:] = b["light_diffuse"]
        m.vis.headlight.diffuse[:] = b["headlight"]
        m.vis.headlight.ambient[:] = b["ambient"]
        m.mat_rgba[:] = b["mat_rgba"]
        m.mat_texrepeat[:] = b["mat_texrepeat"]
        m.cam_pos[self.camera_id] = b["cam_pos"]

    def apply(self, seed: int) -> Randomization:
        """Set the model to `seed`'s world (from the base values) and return the draw."""
        self.restore()
        m, b = self.model, self._base
        rng = np.random.default_rng([int(seed), 2017])

        def draw(name: str, size: int | tuple[int, ...] | None = None) -> np.ndarray | float:
            lo, hi = RANGES[name]
            return rng.uniform(lo, hi, size) if size is not None else float(rng.uniform(lo, hi))

        r = Randomization(seed=int(seed), light_intensity=float(draw("light_intensity")),
                          light_temperature_k=float(draw("light_temperature_k")),
                          camera_height_m=float(draw("camera_height_m")), exposure_ev=float(draw("exposure_ev")))
        light = r.light_intensity * temperature_rgb(r.light_temperature_k)
        m.light_diffuse[:] = np.clip(b["light_diffuse"] * light, 0, 1)
        m.vis.headlight.diffuse[:] = np.clip(b["headlight"] * light, 0, 1)
        m.vis.headlight.ambient[:] = np.clip(b["ambient"] * light, 0, 1)
        tint = np.asarray(draw("material_brightness", (m.nmat, 1))) * np.asarray(draw("material_tint", (m.nmat, 3)))
        scale = np.asarray(draw("texture_scale", (m.nmat, 1)))
        keep = np.array([i in self.skip_materials for i in range(m.nmat)], bool)
        tint[keep], scale[keep] = 1.0, 1.0
        m.mat_rgba[:, :3] = np.clip(b["mat_rgba"][:, :3] * tint, 0, 1)
        m.mat_texrepeat[:] = b["mat_texrepeat"] * scale
        m.cam_pos[self.camera_id] = b["cam_pos"] + np.array([0.0, 0.0, r.camera_height_m])
        return r
