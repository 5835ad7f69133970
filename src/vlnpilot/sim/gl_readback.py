"""A frame read back from a `mujoco.Renderer` as OpenGL holds it: RGBA, bottom row first (`GLPixels`).

`Renderer.render()` reads RGB, then flips the rows over themselves (numpy copies the array to do it): passes the
Tello camera model need not pay, as its lens table reads rows in any order and its Pillow stages take 4-byte pixels
without a copy (bench/camera_cost.py). This reads with `glReadPixels` from the renderer's offscreen buffer, the
call `mjr_readPixels` makes; it returns None where the renderer keeps no GL context of its own (another MuJoCo
rendering stack), renders multisampled (that buffer must be resolved first, which `mjr_readPixels` does), or
PyOpenGL cannot read it (a GL platform it does not drive): the caller then renders through MuJoCo.
"""

from __future__ import annotations

import mujoco
import numpy as np

from vlnpilot.sim.camera_model import GLPixels


def read_rgba(renderer: mujoco.Renderer, model: mujoco.MjModel) -> GLPixels | None:
    """Render `renderer`'s scene (already updated) and read it back as RGBA, bottom row first; None where that
    cannot be done this way (then `renderer.render()` serves)."""
    gl_context = getattr(renderer, "_gl_context", None)  # mujoco.Renderer keeps these private (MuJoCo 4.0)
    mjr_context = getattr(renderer, "_mjr_context", None)
    rect = getattr(renderer, "_rect", None)
    if gl_context is None or mjr_context is None or rect is None or model.vis.quality.offsamples:
        return None
    try:  # after MuJoCo chose the GL platform (PYOPENGL_PLATFORM), which it sets on first use
        from OpenGL import GL
        from OpenGL import error as gl_error
    except ImportError:
        return None
    gl_context.make_current()
    mujoco.mjr_render(rect, renderer.scene, mjr_context)
    mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, mjr_context)  # read the buffer just drawn
    rgba = np.empty((rect.height, rect.width, 4), np.uint8)
    try:
        GL.glReadPixels(rect.left, rect.bottom, rect.width, rect.height, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE, rgba)
    except gl_error.Error:  # PyOpenGL cannot drive this platform's context: MuJoCo's own read-back serves
        return None
    return GLPixels(rgba)
