"""MuJoCo's GL backend (sim/gl.py, issue 21): chosen only when the simulator first needs MuJoCo, only if
MUJOCO_GL is unset, and only where there is no display; `import vlnpilot` changes nothing in the process."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from vlnpilot.sim import gl

SRC = Path(__file__).resolve().parents[1] / "src"
DISPLAY_VARS = ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY")


@pytest.fixture
def no_mujoco_yet(monkeypatch: pytest.MonkeyPatch) -> None:
    """As if MuJoCo had not been imported yet (this test process imported it long ago)."""
    monkeypatch.delitem(sys.modules, "mujoco", raising=False)
    monkeypatch.setattr(gl, "mujoco_imported_first", False)


@pytest.mark.parametrize(("environ", "platform", "chosen"), [
    ({}, "linux", "egl"),  # a headless Linux server: EGL
    ({"DISPLAY": ":0"}, "linux", None),  # X11: MuJoCo's own default
    ({"WAYLAND_DISPLAY": "wayland-0"}, "linux", None),
    ({}, "darwin", None),  # macOS has no EGL: MuJoCo's default (CGL through GLFW)
    ({}, "win32", None),
    ({"MUJOCO_GL": "osmesa"}, "linux", "osmesa"),  # the user's choice is never touched
    ({"MUJOCO_GL": "glfw"}, "linux", "glfw"),
])
def test_the_backend_is_egl_only_where_unset_and_headless(no_mujoco_yet: None, environ: dict[str, str],
                                                         platform: str, chosen: str | None) -> None:
    env = dict(environ)
    assert gl.choose_backend(env, platform) == chosen
    assert env.get("MUJOCO_GL") == (chosen or environ.get("MUJOCO_GL"))
    assert not gl.mujoco_imported_first


def test_mujoco_imported_before_the_simulator_is_remembered_for_the_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "mujoco", sys.modules.get("mujoco") or object())
    monkeypatch.setattr(gl, "mujoco_imported_first", False)
    env: dict[str, str] = {}
    assert gl.choose_backend(env, "linux") is None and env == {}  # too late to choose: nothing set
    assert gl.mujoco_imported_first
    assert "mujoco was imported before the simulator" in str(gl.backend_error(RuntimeError("no context")))


def _child(code: str, **extra_env: str) -> str:
    env = {k: v for k, v in os.environ.items() if k not in DISPLAY_VARS}
    env.update(extra_env, PYTHONPATH=str(SRC))
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                          timeout=120).stdout.strip()


IMPORT_THEN_SIM = """
import os, sys
import vlnpilot, vlnpilot.scene, vlnpilot.cli
print("mujoco" in sys.modules, os.environ.get("MUJOCO_GL"))
import vlnpilot.sim
print(os.environ.get("MUJOCO_GL"))
"""


def test_import_vlnpilot_leaves_mujoco_gl_alone_until_the_simulator_is_imported() -> None:
    assert _child(IMPORT_THEN_SIM).splitlines() == ["False None", "egl"]


def test_with_a_display_mujoco_gl_stays_unset() -> None:
    assert _child(IMPORT_THEN_SIM, DISPLAY=":99").splitlines() == ["False None", "None"]
