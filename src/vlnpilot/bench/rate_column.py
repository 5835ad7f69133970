"""The bench progress line's rate: each provider and model's requests in the last minute, its allowed rate and its
limit, read from the budgets the workers share (pilots/ratelimit.py) at most once a second."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.progress import ProgressColumn
from rich.text import Text

from vlnpilot.pilots.ratelimit import RateBudget, budget_files

REFRESH_S = 1.0


def rate_text(snapshot: dict[str, Any]) -> str:
    """'42/min (allowed 60, limit 60 headers)': sent in the last minute, the AIMD rate, the limit and its source."""
    sent = f"{snapshot['sent_per_min']}/min"
    limit = snapshot.get("limit_rpm")
    if not limit and not snapshot.get("rate_rpm"):
        return f"{sent} (no limit known)"
    allowed = f"allowed {snapshot['rate_rpm']:.0f}" if snapshot.get("rate_rpm") else "allowed any"
    limit_text = f"limit {limit:g} {snapshot.get('source') or ''}".rstrip() if limit else "limit unknown"
    throttled = f", {snapshot['throttled']} x 429" if snapshot.get("throttled") else ""
    return f"{sent} ({allowed}, {limit_text}{throttled})"


def rate_line(directory: Path | None, clock: Callable[[], float] = time.time) -> str:
    """One 'provider-model: rate' part per budget in the bench's rate directory ('' when none is used)."""
    if directory is None:
        return ""
    parts = []
    for path in budget_files(directory):
        try:
            snapshot = RateBudget(path, clock=clock).snapshot()
        except (OSError, ValueError, KeyError):  # a budget being written for the first time: next refresh
            continue
        parts.append(f"{path.stem}: {rate_text(snapshot)}")
    return "  ".join(parts)


class RateColumn(ProgressColumn):
    """A Rich progress column with the rate line, re-read at most every REFRESH_S."""

    def __init__(self, directory: Path | None) -> None:
        super().__init__()
        self.directory = directory
        self._text, self._read_at = "", float("-inf")

    def render(self, task: Any) -> Text:
        now = time.monotonic()
        if now - self._read_at >= REFRESH_S:
            self._text, self._read_at = rate_line(self.directory), now
        return Text(self._text)
