"""Chaos: bad values an outside audit found accepted or crashing, each refused in one line before anything is
written (exit code 2, no traceback)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_support import run_main
from vlnpilot.core.exits import BAD_INPUT

pytestmark = pytest.mark.chaos
FLY = ["--spawn", "bedroom", "--pilot", "oracle", "--max-steps", "2", "-q", "--no-video"]
Q = "Go to the bathroom"


def one_line(code: int, err: str) -> None:
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1 and err.startswith("error: "), (code, err)
    assert "Traceback" not in err


def refused(monkeypatch, capsys, *args: str) -> str:
    """The one error line of `vln-pilot ARGS`, asserting that it is one line and exit code 2."""
    code, _, err = run_main(monkeypatch, capsys, *args)
    one_line(code, err)
    return err


# -- seeds --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [["run", Q, *FLY], ["bench", "--suite", "paper", "--reps", "1"]])
def test_a_negative_seed_is_refused_before_a_directory_is_made(monkeypatch, capsys, tmp_path, command) -> None:
    out = tmp_path / "seedneg"
    err = refused(monkeypatch, capsys, *command, "--seed", "-5", "--out", str(out))
    assert "--seed" in err and not out.exists()


def test_a_scenario_with_a_negative_seed_is_refused_before_a_directory_is_made(monkeypatch, capsys,
                                                                               tmp_path) -> None:
    events = tmp_path / "ev.yaml"
    events.write_text("scene: cabin\nseed: -1\nevents: [{kind: lights_out, room: bedroom, trigger: {step: 1}}]\n")
    out = tmp_path / "seedneg"
    err = refused(monkeypatch, capsys, "run", Q, *FLY, "--events", str(events), "--out", str(out))
    assert "seed" in err and not out.exists()
