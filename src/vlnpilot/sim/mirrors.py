"""Mirrors that reflect (`--detail rich`, docs/scenes.md). MuJoCo draws a reflective geom's reflection with a second
pass over the whole scene, whether or not the mirror is in view, and for one reflective geom per frame only (the
first in its scene list; others render as plain glass). So that a frame pays for a reflection only when it shows
one, and shows the one that matters, each frame keeps the reflection on the nearest mirror that is in the camera's
view, faces it and is in its sight (no wall between), and clears it on every other. Only the front camera (what
the pilot sees) reflects: the chase view, for people, shows the glass and saves the pass.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np


def mirror_geoms(model: mujoco.MjModel) -> frozenset[int]:
    """The geoms that reflect (a material with reflectance > 0)."""
    return frozenset(int(g) for g in np.flatnonzero(model.geom_matid >= 0)
                     if model.mat_reflectance[model.geom_matid[g]] > 0)


def _in_view(camera: mujoco.MjvGLCamera, eye: np.ndarray, geom: mujoco.MjvGeom, aspect: float) -> float:
    """Distance from the eye to a plane geom that faces it and may be in the camera's frustum, else infinity.
    Conservative: the mirror is a sphere of its half-diagonal around its centre."""
    to_geom = geom.pos - eye
    if float(-to_geom @ geom.mat[:, 2]) <= 0:  # the eye is behind the mirror (a plane's normal is its local z)
        return math.inf
    forward, up = np.asarray(camera.forward), np.asarray(camera.up)
    right = np.cross(forward, up)
    radius = math.hypot(geom.size[0], geom.size[1])
    ahead, across, high = float(to_geom @ forward), float(to_geom @ right), float(to_geom @ up)
    near = camera.frustum_near
    half_h = max(abs(camera.frustum_bottom), abs(camera.frustum_top)) / near
    half_w = half_h * aspect  # the frustum's width is set at render time, from the viewport
    if ahead < -radius or abs(across) > ahead * half_w + radius * math.hypot(1, half_w) \
            or abs(high) > ahead * half_h + radius * math.hypot(1, half_h):
        return math.inf
    return float(np.linalg.norm(to_geom))


_SOLID_GROUPS = np.array([1, 1, 0, 0, 0, 0], np.uint8)  # the scene's own geoms: not the drone (2), not the detail (3)
_CORNERS = ((0.0, 0.0), (0.9, 0.9), (-0.9, 0.9), (0.9, -0.9), (-0.9, -0.9))


def _seen(model: mujoco.MjModel, data: mujoco.MjData, eye: np.ndarray, geom: mujoco.MjvGeom, drone_body: int) -> bool:
    """Whether a line from the eye reaches the mirror's face (2 cm before it) at its centre or near a corner."""
    normal, across, up = geom.mat[:, 2], geom.mat[:, 0], geom.mat[:, 1]
    hit_geom = np.zeros(1, np.int32)
    for a, b in _CORNERS:
        to_point = geom.pos + 0.02 * normal + a * geom.size[0] * across + b * geom.size[1] * up - eye
        length = float(np.linalg.norm(to_point))
        hit = mujoco.mj_ray(model, data, eye, to_point / length, _SOLID_GROUPS, 1, drone_body, hit_geom)
        if hit < 0 or hit >= length:
            return True
    return False


def reflect_in_view(scene: mujoco.MjvScene, mirrors: frozenset[int], aspect: float, sight: tuple[Any, Any, int], *,
                    keep: bool = True) -> None:
    """Keep the reflection of `scene` (updated for this frame; `aspect` its image's width / height) on the nearest
    mirror in view and in sight (`sight`: the model, its data at this pose and the drone's body, which the lines of
    sight pass through), none on the others; with `keep=False`, on none (a view that needs no reflection)."""
    if not keep:
        for i in range(scene.ngeom):
            if (geom := scene.geoms[i]).objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in mirrors:
                geom.reflectance = 0.0
        return
    camera = scene.camera[0]
    eye = (np.asarray(scene.camera[0].pos) + np.asarray(scene.camera[1].pos)) / 2
    found = [(_in_view(camera, eye, geom, aspect), geom) for i in range(scene.ngeom)
             if (geom := scene.geoms[i]).objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in mirrors]
    found = [(d if math.isinf(d) or _seen(*sight[:2], eye, geom, sight[2]) else math.inf, geom) for d, geom in found]
    nearest = min(found, key=lambda item: item[0], default=(math.inf, None))
    for distance, geom in found:
        if geom is not nearest[1] or math.isinf(distance):
            geom.reflectance = 0.0
