"""Why an executed command lies outside its state's allowed moves: the controller's documented overrides.

The FSM table says which moves each state allows, and a model's answer is held to it. Three parts of the
controller may still execute another command, because safety outranks the table: the hover fallback (E after
the re-asks failed), the shield, the door-crossing assist and the oscillation guard. Every step record
carries `override`: None when the executed command is allowed, else which of them put it there. Since hover is
allowed in every asked state (issue 24), the fallback's hover is an override only in recordings made before.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from vlnpilot.core.commands import Command
from vlnpilot.core.fsm import State, state_spec

OVERRIDE_REASONS = ("fallback", "shield", "assist", "guard")
_BY_SOURCE = {"shield": "shield", "door_assist": "assist", "oscillation_guard": "guard"}


def override_reason(state: State, profile: str, executed: Command | None, fallback: bool,
                    interventions: Sequence[Any] = (), next_state: State | None = None) -> str | None:
    """None if `executed` is allowed in `state` (E with a final next state included), else the override that
    chose it (the last one to act)."""
    if executed is None or state_spec(state, profile).allows(executed.code, next_state or state):
        return None
    if interventions:
        return _BY_SOURCE.get(interventions[-1].source, interventions[-1].source)
    return "fallback" if fallback else "unexplained"  # "unexplained" would be a controller bug: tests look for it
