"""Shared fixtures: the built-in scene and one simulator per test session (building one takes ~0.5 s).

The `sim` fixture is shared by every test that asks for it: call `sim.reset(...)` before using it and do not
rely on the state another test left behind.
"""

from __future__ import annotations

import threading
import time

import pytest

from vlnpilot.scene import Scene, load_scene
from vlnpilot.sim import gl

# Some test modules import mujoco themselves, before the simulator: choose its GL backend first, as the
# simulator does (headless EGL only if MUJOCO_GL is unset and there is no display).
gl.choose_backend()


@pytest.fixture(scope="session")
def scene() -> Scene:
    """The built-in cabin scene (immutable)."""
    return load_scene("cabin")


@pytest.fixture(scope="session")
def sim():
    """A default `Simulator` on the cabin (640x480 cameras), shared by the session; reset it before use."""
    from vlnpilot.sim import Simulator

    simulator = Simulator("cabin")
    yield simulator
    simulator.close()


@pytest.fixture(scope="session")
def geo_sim():
    """A render-free simulator (1x1 black images) for fast geometry and collision tests; reset it before use."""
    from vlnpilot.sim import SimConfig, Simulator

    simulator = Simulator("cabin", SimConfig(render=False))
    yield simulator
    simulator.close()


@pytest.fixture(scope="module")
def browser():
    """Debian's Chromium under Playwright (the browser tests skip where it is not installed)."""
    from playwright.sync_api import sync_playwright

    from chromium import ARGS, CHROMIUM

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        yield b
        b.close()


@pytest.fixture
def retry_waits(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The seconds a pilot waits between retries in the test's thread, recorded instead of slept.

    The SDKs (openai, anthropic) and our `call_with_retries` all wait through `time.sleep`; the fake servers'
    threads keep the real one.
    """
    waits: list[float] = []
    real_sleep, test_thread = time.sleep, threading.get_ident()

    def sleep(seconds: float) -> None:
        if threading.get_ident() == test_thread:
            waits.append(seconds)
        else:
            real_sleep(seconds)

    monkeypatch.setattr(time, "sleep", sleep)
    return waits
