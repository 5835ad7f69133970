"""Mirrors that reflect (`--detail rich`, docs/scenes.md): MuJoCo draws the reflection of one reflective geom per
frame (the first in its scene list; the others render as plain glass). With several mirrors in a house, this keeps
the reflection on the one that matters to the camera: the nearest mirror whose face turns towards it.
"""

from __future__ import annotations

import mujoco
import numpy as np


def mirror_geoms(model: mujoco.MjModel) -> frozenset[int]:
    """The geoms that reflect (a material with reflectance > 0)."""
    return frozenset(int(g) for g in np.flatnonzero(model.geom_matid >= 0)
                     if model.mat_reflectance[model.geom_matid[g]] > 0)


def reflect_nearest(scene: mujoco.MjvScene, mirrors: frozenset[int]) -> None:
    """Leave the reflection on the nearest mirror facing the camera of `scene` (updated for this frame); none on the
    others, so that MuJoCo's one reflection goes there."""
    eye = (np.asarray(scene.camera[0].pos) + np.asarray(scene.camera[1].pos)) / 2
    found: list[tuple[float, mujoco.MjvGeom]] = []
    for i in range(scene.ngeom):
        geom = scene.geoms[i]
        if geom.objtype == mujoco.mjtObj.mjOBJ_GEOM and geom.objid in mirrors:
            to_eye = eye - geom.pos
            facing = float(to_eye @ geom.mat[:, 2]) > 0  # a plane's normal is its local z
            found.append((float(np.linalg.norm(to_eye)) if facing else np.inf, geom))
    if len(found) < 2:
        return
    found.sort(key=lambda item: item[0])
    for _, geom in found[1:]:
        geom.reflectance = 0.0
