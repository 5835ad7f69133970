"""A run directory read as it grows: the step records of episode.jsonl and summary.json when it changes.

Each page connection gets its own feed from the start of the file, so a page opened or reopened mid-episode
shows every step so far. Only complete lines are read: a step being written is picked up on the next poll.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from vlnpilot.core.rundir import EPISODE, SUMMARY


class RunFeed:
    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        self._offset = 0
        self._summary_stamp: tuple[int, int] | None = None

    def new_lines(self) -> list[str]:
        """The step records (JSON text, one per step) written since the last call."""
        path = self.run_dir / EPISODE
        try:
            if path.stat().st_size <= self._offset:
                return []
            with open(path, "rb") as f:
                f.seek(self._offset)
                chunk = f.read()
        except FileNotFoundError:
            return []
        complete = chunk[:chunk.rfind(b"\n") + 1]
        self._offset += len(complete)
        return [line for line in complete.decode("utf-8").splitlines() if line.strip()]

    def changed_summary(self) -> dict[str, Any] | None:
        """summary.json if it changed since the last call (it is written atomically), else None."""
        path = self.run_dir / SUMMARY
        try:
            st = path.stat()
            stamp = (st.st_mtime_ns, st.st_size)
            if stamp == self._summary_stamp:
                return None
            summary = json.loads(path.read_text(encoding="utf-8"))
        except (FileNotFoundError, json.JSONDecodeError):
            return None
        self._summary_stamp = stamp
        return summary
