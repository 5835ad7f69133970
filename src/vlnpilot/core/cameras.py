"""The simulated front camera's models, by name (docs/camera.md): one table for the simulator, the suites and the
command line, importable without the simulator (a suite that pins its camera is read before MuJoCo loads)."""

from __future__ import annotations

from vlnpilot.core.errors import ConfigError, UnknownNameError

CAMERAS = ("ideal", "tello")  # --camera: ideal (the render), tello (the Tello's stream)
DEFAULT_CAMERA = "ideal"


def check_camera(name: str) -> str:
    """The camera model's name, or one line naming the valid ones."""
    key = str(name).strip().lower()
    if key not in CAMERAS:
        raise UnknownNameError("camera", name, CAMERAS)
    return key


def check_camera_lag(camera: str | None, lag_ms: float | None) -> None:
    """A frame lag is the tello camera's (`--camera-lag-ms`): one line where it is asked of another camera."""
    if lag_ms is not None and check_camera(camera or DEFAULT_CAMERA) != "tello":
        raise ConfigError("a camera lag applies to --camera tello only")
