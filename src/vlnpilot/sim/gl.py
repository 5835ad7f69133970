"""Headless OpenGL for MuJoCo: EGL with Mesa by default, and a clear error when the libraries are missing."""

from __future__ import annotations

import ctypes.util
import os

import vlnpilot
from vlnpilot.core.errors import RenderBackendError

INSTALL_HINT = "sudo apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0 (or run `make sysdeps`)"
_LIBS = {"egl": ("EGL", "GL"), "osmesa": ("OSMesa",), "glfw": ("GL",)}


def select_backend() -> str:
    """Default MUJOCO_GL to EGL (headless, works with Mesa's software rasteriser); must run before `import mujoco`."""
    return os.environ.setdefault("MUJOCO_GL", "egl")


def missing_libraries(backend: str | None = None) -> list[str]:
    backend = (backend or os.environ.get("MUJOCO_GL", "egl")).lower()
    return [f"lib{name}" for name in _LIBS.get(backend, ()) if ctypes.util.find_library(name) is None]


def backend_error(exc: BaseException) -> RenderBackendError:
    """Turn whatever the GL stack raised into an error that names the library and the fix."""
    backend = os.environ.get("MUJOCO_GL", "egl")
    missing = missing_libraries(backend)
    what = f"missing {', '.join(missing)}" if missing else f"{type(exc).__name__}: {exc}"
    if vlnpilot._MUJOCO_IMPORTED_FIRST:
        return RenderBackendError(
            f"cannot start headless OpenGL rendering: mujoco was imported before vlnpilot could select its headless "
            f"backend ({what}). Set MUJOCO_GL=egl in the environment, or import vlnpilot before mujoco."
        )
    return RenderBackendError(
        f"cannot start headless OpenGL rendering (MUJOCO_GL={backend}): {what}. Install the libraries with: "
        f"{INSTALL_HINT}"
    )


select_backend()
