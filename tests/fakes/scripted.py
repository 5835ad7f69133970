"""A scripted in-process pilot for server and remote-pilot tests, registered as `test-scripted`."""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

from vlnpilot.core.decision import Decision, PilotInput, Usage
from vlnpilot.pilots.base import register_pilot

DEFAULT_DECISION = Decision(room="hall", movement="A1", state="Search Object", description="scripted",
                            door_position="left", usage=Usage(input_tokens=10, output_tokens=5, cost_usd=0.001))


class ScriptedPilot:
    """Answers with the queued outcomes (a Decision, or an exception to raise), then with `default`."""

    name = "test-scripted"

    def __init__(self, model: str | None = None, default: Decision = DEFAULT_DECISION, **options: Any):
        self.model = model or "scripted-1"
        self.default = default
        self.options = options
        self.inputs: list[PilotInput] = []
        self.script: deque[Decision | BaseException] = deque()
        self._lock = threading.Lock()

    def push(self, *outcomes: Decision | BaseException) -> ScriptedPilot:
        with self._lock:
            self.script.extend(outcomes)
        return self

    def decide(self, pilot_input: PilotInput) -> Decision:
        with self._lock:
            self.inputs.append(pilot_input)
            outcome = self.script.popleft() if self.script else self.default
        if isinstance(outcome, BaseException):
            raise outcome
        return outcome.model_copy(update={"model": outcome.model or self.model})


INSTANCES: list[ScriptedPilot] = []


@register_pilot("test-scripted")
def make_scripted(**options: Any) -> ScriptedPilot:
    pilot = ScriptedPilot(**options)
    INSTANCES.append(pilot)
    return pilot
