"""VLN-Pilot: a large vision-language model pilots an indoor drone (embedded MuJoCo simulator)."""

import os as _os
import sys as _sys

# MuJoCo picks its OpenGL backend when it is first imported: default to headless EGL before that happens,
# and remember when it is too late (the renderer's error then says how to fix it).
_MUJOCO_IMPORTED_FIRST = "mujoco" in _sys.modules and "MUJOCO_GL" not in _os.environ
_os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
