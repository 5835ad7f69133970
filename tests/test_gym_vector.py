"""Gymnasium's async vector environment, whose workers are forked: after the parent rendered (sim/gl_fork.py).

Each case runs in a process of its own, so that the GL state the workers inherit is the case's and not the test
session's (whose shared simulators keep their renderers open).
"""

from __future__ import annotations

import multiprocessing
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no os.fork here")

PARENT_RENDERS = """
import numpy as np, gymnasium as gym, vlnpilot
parent = gym.make("VLNPilot/Cabin-v0", width=32, height=24)
parent.reset(seed=0)
parent.step(11)
{close}
workers = gym.make_vec("VLNPilot/Cabin-v0", num_envs=2, vectorization_mode="async", width=32, height=24,
                       vector_kwargs={{"context": "fork"}})
try:
    obs, _ = workers.reset(seed=3)
    obs, *_ = workers.step(np.array([11, 11]))
    print("workers", obs["front"].shape)
except Exception as exc:
    print("refused", type(exc).__name__, exc)
finally:
    workers.close(terminate=True)
again = gym.make("VLNPilot/Cabin-v0", width=32, height=24)
print("parent", again.reset(seed=0)[0]["front"].shape)
"""


def _run(close: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", PARENT_RENDERS.format(close=close)], capture_output=True, text=True,
                         check=True)
    return out.stdout.strip().splitlines()


def test_async_workers_render_after_the_parent_rendered_and_closed_its_environment() -> None:
    """The workers' first frame waited forever on the EGL display they inherited; the parent now releases it, and
    renders again afterwards."""
    assert _run("parent.close()") == ["workers (2, 24, 32, 3)", "parent (24, 32, 3)"]


def test_async_workers_forked_with_an_environment_open_refuse_in_one_line_naming_the_fix() -> None:
    lines = _run("")
    assert lines[0].startswith("refused RenderBackendError cannot render in a process forked from one with an OpenGL")
    assert "vector_kwargs={'context': 'spawn'}" in lines[0] and lines[1:] == ["parent (24, 32, 3)"]
