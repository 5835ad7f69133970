"""Chaos: SIGTERM is handled as Ctrl-C everywhere (issue 26): a bench says so, leaks nothing and records its
episodes in flight as `interrupted`; a run stopped during start-up exits 130."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cli_support import PROVIDER_ENV
from polling import wait_for
from vlnpilot.core.exits import INTERRUPTED

pytestmark = pytest.mark.chaos
TESTS = Path(__file__).resolve().parents[1]


def cli(*args: str, env: dict[str, str] | None = None) -> subprocess.Popen:
    base = {k: v for k, v in os.environ.items() if k not in PROVIDER_ENV}
    base["PYTHONPATH"] = os.pathsep.join([str(TESTS), base.get("PYTHONPATH", "")])
    return subprocess.Popen([sys.executable, "-m", "vlnpilot.cli", *args], env={**base, **(env or {})},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_sigterm_stops_a_bench_like_ctrl_c(tmp_path: Path) -> None:
    marks, out = tmp_path / "marks", tmp_path / "bench"
    marks.mkdir()
    proc = cli("bench", "--pilots", "test-hanging", "--plugin", "fakes.hanging", "--workers", "1", "--reps", "1",
               "--no-report", "--out", str(out), env={"HANGING_MARKS": str(marks)})
    try:
        # a failure bound only: a spawned worker imports MuJoCo and renders before its first episode
        assert wait_for(lambda: len(list(marks.iterdir())) == 1, timeout=600), "no episode ever got in flight"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == INTERRUPTED, err
    assert "interrupted" in err and "--resume" in err
    assert "leaked" not in err and "Traceback" not in err, err
    statuses = sorted(__import__("json").loads(p.read_text())["status"] for p in out.rglob("summary.json"))
    assert statuses == ["interrupted"]  # the one in flight: not left `running`


def test_sigterm_during_start_up_exits_130(tmp_path: Path) -> None:
    proc = cli("run", "Go to the bedroom", "--no-video", "-q", "--out", str(tmp_path / "r"))  # names its pilot
    try:
        assert proc.stdout.readline().startswith("pilot: ")  # start-up: the pilot, simulator and run come next
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == INTERRUPTED and "Traceback" not in err, (proc.returncode, err)  # was 143
