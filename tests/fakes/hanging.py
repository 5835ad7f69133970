"""A pilot that never answers (`test-hanging`), for interrupting a bench while its episodes are in flight.

Imported by a bench with `--plugin fakes.hanging`: each call touches `asked-<pid>-<thread>` in $HANGING_MARKS, so
that a test knows an episode is in flight, then waits until the process is stopped.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.pilots.base import register_pilot


@register_pilot("test-hanging")
class HangingPilot:
    name = "test-hanging"

    def __init__(self, model: str | None = None, **options: object):
        self.model = model or "hanging-1"

    def decide(self, pilot_input: PilotInput) -> Decision:
        marks = Path(os.environ["HANGING_MARKS"])
        (marks / f"asked-{os.getpid()}-{threading.get_ident()}").touch()
        threading.Event().wait()  # until the process is stopped
        raise AssertionError("unreachable")
