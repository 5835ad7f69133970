"""Reading a run's `episode.jsonl` back, one step a line, and saying which line is damaged.

A run that was killed mid-write leaves a torn last line: it is skipped, since every step before it is whole. A
damaged line anywhere else (not JSON, not a JSON object, a step number that is not a whole number) means the
file was changed after it was written: the caller either refuses the file (a replay must fly every step as
recorded) or is told about each line it skips (a report shows what it could read, and says what it could not).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vlnpilot.core.errors import ConfigError

OnDamage = Callable[[str], None]  # told "FILE line N: PROBLEM; skipped" for each damaged line it accepts to skip


def read_steps(path: Path, on_damage: OnDamage | None = None) -> list[dict[str, Any]]:
    """The steps of `path`; a damaged line other than a torn last one is a ConfigError naming the file and the
    line, or, given `on_damage`, skipped and reported to it."""
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    last = max((n for n, line in enumerate(lines, 1) if line.strip()), default=0)
    steps = []
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        step, problem = _parsed(line)
        if step is not None:
            steps.append(step)
        elif number == last and problem == "not valid JSON":
            continue  # torn by a crash mid-write: the steps before it are whole
        elif on_damage is None:
            raise ConfigError(f"{path} line {number}: {problem}; the steps after it cannot be trusted: restore the "
                              "file or fly the run again")
        else:
            on_damage(f"{path} line {number}: {problem}; skipped")
    return steps


def _parsed(line: str) -> tuple[dict[str, Any] | None, str]:
    """(the step, "") or (None, what is wrong with the line)."""
    try:
        step = json.loads(line)
    except ValueError:
        return None, "not valid JSON"
    if not isinstance(step, dict):
        return None, f"a JSON {type(step).__name__}, not a step (a JSON object)"
    number = step.get("step", 0)
    if isinstance(number, bool) or not isinstance(number, int):
        return None, f"its step is {json.dumps(number)[:40]}, not a whole number"
    return step, ""
