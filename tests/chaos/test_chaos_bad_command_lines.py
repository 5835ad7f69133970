"""Chaos: the smoke mode of bench/bad_command_lines.py (issue 26): bad lines exit 2 with one line, no traceback."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.chaos
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import bad_command_lines  # noqa: E402


def test_the_smoke_lines_are_each_refused_in_one_line() -> None:
    passed, total, failures = bad_command_lines.check(smoke=True)
    assert total >= 15 and not failures, "\n".join(failures)


def test_there_are_at_least_127_lines_and_every_command_has_some(tmp_path: Path) -> None:
    lines = bad_command_lines.command_lines(tmp_path)
    assert len(lines) >= 127
    commands = {"scene", "run", "watch", "report", "bench", "tello-emulator", "serve"}
    assert commands <= {line[0] for line in lines if line}


def test_the_verdict_counts_a_second_line_or_a_traceback_as_a_failure() -> None:
    assert bad_command_lines.verdict(2, "error: one\n") is None
    assert bad_command_lines.verdict(2, "error: one\nerror: two\n")
    assert bad_command_lines.verdict(1, "Traceback (most recent call last):\n")
    assert bad_command_lines.verdict(0, "")
