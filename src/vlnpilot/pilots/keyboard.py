"""A person flying from the live ground station (vlnpilot.live): decide() waits for a command typed on the page.

Its decisions go through the same validation, shield and recording as a model's; they carry the model name
`human`, and the episode marks those steps `"human": true` in episode.jsonl.
"""

from __future__ import annotations

from typing import Protocol

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.pilots.base import BasePilot, Pilot

HUMAN = "human"  # the `model` of a decision a person made


class CommandSource(Protocol):
    def wait_for_command(self, pin: PilotInput) -> Decision | None:
        """The person's next decision for this step, or None when they handed control back while it waited."""


class KeyboardPilot(BasePilot):
    """Flies what the person types; hands the step to `pilot` (the model) when control is handed back mid-wait."""

    name = HUMAN
    model = HUMAN

    def __init__(self, commands: CommandSource, pilot: Pilot):
        self._commands = commands
        self._pilot = pilot

    def decide(self, pin: PilotInput) -> Decision:
        decision = self._commands.wait_for_command(pin)
        return decision if decision is not None else self._pilot.decide(pin)


def human_decision(movement: str, state: str, description: str = "flown from the keyboard") -> Decision:
    """A person's command as a Decision (the room is not asked of a person)."""
    return Decision(room="unknown", movement=movement, state=state, description=description, model=HUMAN)
