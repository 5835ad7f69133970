"""Pause, emergency stop, take-over and hand back, shared by the web server's threads and the episode loop.

The loop calls `before_step` once per step before it asks the pilot, and `abort_reason` before it executes the
answer, so that an emergency stop pressed while a model thinks stops its command too (episode.LoopControl);
while a person flies, the KeyboardPilot calls `wait_for_command`. Nothing is queued: a person's command is taken
only while the loop waits for that very step, so a message from a page that lost its connection is never replayed.
"""

from __future__ import annotations

import threading
from typing import Any

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.fsm import state_spec
from vlnpilot.episode.config import Gate
from vlnpilot.pilots.base import Pilot, PilotError
from vlnpilot.pilots.keyboard import KeyboardPilot, human_decision

ACTIONS = ("pause", "resume", "stop", "take_over", "hand_back", "command")
STOP_REASON = "emergency stop from the live station"
_TICK_S = 0.5  # waits wake up this often, so that Ctrl-C reaches a loop that is held


class Refused(VLNPilotError):
    """A control message that cannot act now (the episode is over, or a command for a step nobody waits for)."""


class LiveControl:
    """The control state of one episode; every method is thread-safe."""

    def __init__(self, pilot: Pilot):
        self._cond = threading.Condition()
        self.keyboard = KeyboardPilot(self, pilot)
        self._paused = self._stopped = self._human = self._finished = False
        self._holding = False  # the loop is held by a pause, before asking the pilot
        self._step = 0  # the step the loop is at
        self._waiting: dict[str, Any] | None = None  # the step a person's command is awaited for
        self._command: Decision | None = None
        self.version = 0  # bumped on every change, so that a feed sends the status only when it changed

    def status(self) -> dict[str, Any]:
        with self._cond:
            return {"paused": self._paused, "holding": self._holding, "stopped": self._stopped,
                    "human": self._human, "finished": self._finished, "step": self._step,
                    "waiting": self._waiting, "version": self.version}

    def _changed(self) -> None:
        self.version += 1
        self._cond.notify_all()

    # -- the episode loop's side -------------------------------------------------------------------------
    def before_step(self, step: int) -> Gate:
        with self._cond:
            self._step = step
            self._changed()
            while self._paused and not (self._stopped or self._human):
                if not self._holding:
                    self._holding = True
                    self._changed()
                self._cond.wait(_TICK_S)
            if self._holding:
                self._holding = False
                self._changed()
            if self._stopped:
                return Gate(abort=STOP_REASON)
            return Gate(pilot=self.keyboard if self._human else None)

    def wait_for_command(self, pin: PilotInput) -> Decision | None:
        spec = state_spec(pin.state, pin.profile)
        with self._cond:
            self._waiting = {"step": pin.step, "state": pin.state.value, "moves": list(spec.answer_moves),
                             "next_states": [s.value for s in spec.next_states], "feedback": list(pin.feedback)}
            self._command = None
            self._changed()
            try:
                while self._command is None and self._human and not self._stopped:
                    self._cond.wait(_TICK_S)
                if self._stopped:  # the loop then ends the episode without executing anything
                    raise PilotError(STOP_REASON, fatal=True, reason="emergency_stop")
                return self._command  # None: handed back while waiting, the model flies this step
            finally:
                self._waiting, self._command = None, None
                self._changed()

    def abort_reason(self) -> str | None:
        with self._cond:
            return STOP_REASON if self._stopped else None

    def finish(self) -> None:
        """The episode is over: every later control message is refused."""
        with self._cond:
            self._finished = True
            self._changed()

    # -- the page's side ---------------------------------------------------------------------------------
    def act(self, action: str, *, step: int | None = None, movement: str | None = None,
            state: str | None = None) -> dict[str, Any]:
        """Apply one control message; returns the new status or raises Refused."""
        with self._cond:
            if self._finished:
                raise Refused("the episode is over")
            if action == "command":
                self._take_command(step, movement, state)
            elif action in ("pause", "resume"):
                self._paused = action == "pause"
            elif action == "stop":
                self._stopped = True
            elif action in ("take_over", "hand_back"):
                self._human = action == "take_over"
                self._paused = False  # a person who takes over flies at once; one who hands back lets it fly
            else:
                raise Refused(f"unknown action {action!r}; valid actions: {', '.join(ACTIONS)}")
            self._changed()
        return self.status()

    def _take_command(self, step: int | None, movement: str | None, state: str | None) -> None:
        waiting = self._waiting
        if waiting is None or not self._human:
            raise Refused("no step is waiting for a command (take over first, and wait for the page to ask)")
        if step != waiting["step"]:
            raise Refused(f"the command is for step {step}, but step {waiting['step']} is waiting")
        if self._command is not None:
            raise Refused(f"step {step} already has its command")
        if not movement or not state or len(movement) > 8 or len(state) > 40:
            raise Refused("a command needs a movement code (A1...E) and a next state")
        self._command = human_decision(movement, state)
