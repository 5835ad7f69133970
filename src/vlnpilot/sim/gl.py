"""OpenGL for MuJoCo: headless EGL where there is no display, and a clear error when the libraries are missing.

MuJoCo fixes its GL backend when it is first imported, from MUJOCO_GL. `choose_backend` runs right before the
simulator imports MuJoCo (never on `import vlnpilot`), and sets MUJOCO_GL only if it is unset and the machine
has no display: a Linux server without X11 or Wayland gets EGL (Mesa's software rasteriser works there); a
desktop, macOS and Windows keep MuJoCo's own default, and a value the user set is never touched.
"""

from __future__ import annotations

import ctypes.util
import os
import sys
from collections.abc import MutableMapping

from vlnpilot.core.errors import RenderBackendError

INSTALL_HINT = "sudo apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0 (or run `make sysdeps`)"
_LIBS = {"egl": ("EGL", "GL"), "osmesa": ("OSMesa",), "glfw": ("GL",)}
HEADLESS = "egl"

# Whether someone imported MuJoCo before the simulator could choose its backend (the error then says so).
mujoco_imported_first = False


def has_display(environ: MutableMapping[str, str], platform: str) -> bool:
    """macOS and Windows always draw through their own window system; Linux only with X11 or Wayland."""
    if not platform.startswith("linux"):
        return True
    return bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


def choose_backend(environ: MutableMapping[str, str] | None = None, platform: str | None = None) -> str | None:
    """Set MUJOCO_GL to EGL if it is unset and there is no display; returns the backend MuJoCo will use
    (None: MuJoCo's own default). Must run before `import mujoco`."""
    global mujoco_imported_first
    environ = os.environ if environ is None else environ
    if "MUJOCO_GL" in environ:
        return environ["MUJOCO_GL"]
    if has_display(environ, platform or sys.platform):
        return None
    if "mujoco" in sys.modules:  # too late to choose: MuJoCo already took its default
        mujoco_imported_first = True
        return None
    environ["MUJOCO_GL"] = HEADLESS
    return HEADLESS


def missing_libraries(backend: str | None = None) -> list[str]:
    backend = (backend or os.environ.get("MUJOCO_GL", "glfw")).lower()
    return [f"lib{name}" for name in _LIBS.get(backend, ()) if ctypes.util.find_library(name) is None]


def backend_error(exc: BaseException) -> RenderBackendError:
    """Turn whatever the GL stack raised into an error that names the library and the fix."""
    backend = os.environ.get("MUJOCO_GL", "glfw")  # MuJoCo's default when it is unset
    missing = missing_libraries(backend)
    what = f"missing {', '.join(missing)}" if missing else f"{type(exc).__name__}: {exc}"
    if mujoco_imported_first:
        return RenderBackendError(
            f"cannot start headless OpenGL rendering: mujoco was imported before the simulator could select its "
            f"headless backend ({what}). Set MUJOCO_GL=egl in the environment, or create the simulator before "
            "importing mujoco."
        )
    return RenderBackendError(
        f"cannot start headless OpenGL rendering (MUJOCO_GL={backend}): {what}. Install the libraries with: "
        f"{INSTALL_HINT}"
    )
