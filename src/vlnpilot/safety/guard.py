"""The oscillation guard: detects reversals without progress and vetoes one, accepting the alignment."""

from __future__ import annotations

from collections import deque

from vlnpilot.core.commands import OPPOSITE, Command, Kind
from vlnpilot.core.fsm import State
from vlnpilot.safety.config import OscillationConfig


# -- oscillation guard ----------------------------------------------------------------------------------------------
class OscillationGuard:
    """Detects a pilot that reverses rotation or lateral direction again and again without progress."""

    def __init__(self, config: OscillationConfig):
        self.config = config
        self.reset()

    def reset(self) -> None:
        self._window: deque[bool] = deque(maxlen=self.config.window)
        self._last_proposed: dict[str, Kind] = {}
        self._last_executed: dict[str, Kind] = {}
        self.committed = False  # fired in this stretch (until forward progress or a state change)
        self.veto_pending = False  # the next reversal is vetoed (once per event)
        self._state: State | None = None

    @staticmethod
    def _axis(kind: Kind) -> str | None:
        if kind in (Kind.ROTATE_LEFT, Kind.ROTATE_RIGHT):
            return "rotation"
        if kind in (Kind.LATERAL_LEFT, Kind.LATERAL_RIGHT):
            return "lateral"
        return None

    def propose(self, state: State, command: Command) -> int | None:
        """Register a proposal; the number of reversals in the window when the guard fires, else None."""
        if self._state is not None and state is not self._state:
            self.committed = self.veto_pending = False
        self._state = state
        if command.kind is Kind.NONE:  # a hover (waiting, looking again) is no step of an oscillation: not counted
            return None
        axis = self._axis(command.kind)
        reversal = axis is not None and self._last_proposed.get(axis) is OPPOSITE[command.kind]
        if axis is not None:
            self._last_proposed[axis] = command.kind
        self._window.append(reversal)
        count = sum(self._window)
        if count >= self.config.threshold and not self.committed:
            self._window.clear()
            return count
        return None

    def reverses(self, command: Command) -> bool:
        """Whether `command` reverses the last executed direction on its axis."""
        axis = self._axis(command.kind)
        return axis is not None and self._last_executed.get(axis) is OPPOSITE[command.kind]

    def executed(self, command: Command) -> None:
        axis = self._axis(command.kind)
        if axis is not None:
            self._last_executed[axis] = command.kind
        if command.kind is Kind.FORWARD:  # progress: a new stretch starts
            self._window.clear()
            self._last_proposed.clear()
            self.committed = self.veto_pending = False
