"""The simulated front camera's models, by name (docs/camera.md): one table for the simulator, the suites and the
command line, importable without the simulator (a suite that pins its camera is read before MuJoCo loads)."""

from __future__ import annotations

from vlnpilot.core.errors import UnknownNameError

CAMERAS = ("ideal", "tello")  # --camera: ideal (the render), tello (the Tello's stream)
DEFAULT_CAMERA = "ideal"


def check_camera(name: str) -> str:
    """The camera model's name, or one line naming the valid ones."""
    key = str(name).strip().lower()
    if key not in CAMERAS:
        raise UnknownNameError("camera", name, CAMERAS)
    return key
