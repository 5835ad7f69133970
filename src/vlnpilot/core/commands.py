"""The movement command table of the paper's Table 2: the one source of truth for A1...E.

Prompts, JSON schemas, validation, the simulator and the docs all read this table.
(The paper's appendix swaps the B and C rotation directions; we follow Table 2.)
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from vlnpilot.core.errors import UnknownNameError
from vlnpilot.core.records import Motion


class Kind(StrEnum):
    FORWARD = "forward"
    ROTATE_RIGHT = "rotate_right"
    ROTATE_LEFT = "rotate_left"
    LATERAL_LEFT = "lateral_left"
    LATERAL_RIGHT = "lateral_right"
    NONE = "none"


@dataclass(frozen=True)
class Command:
    code: str
    kind: Kind
    amount: float  # metres for translations, degrees for rotations, 0 for E

    def motion(self) -> Motion:
        k, a = self.kind, self.amount
        if k is Kind.FORWARD:
            return Motion(forward_m=a)
        if k is Kind.ROTATE_RIGHT:
            return Motion(yaw_deg=-a)
        if k is Kind.ROTATE_LEFT:
            return Motion(yaw_deg=a)
        if k is Kind.LATERAL_LEFT:
            return Motion(lateral_m=a)
        if k is Kind.LATERAL_RIGHT:
            return Motion(lateral_m=-a)
        return Motion()

    @property
    def description(self) -> str:
        """Human/model-readable text, e.g. 'move forward 10 cm', 'rotate right 15°'."""
        k, a = self.kind, self.amount
        if k is Kind.FORWARD:
            return f"move forward {a * 100:.0f} cm"
        if k in (Kind.ROTATE_RIGHT, Kind.ROTATE_LEFT):
            return f"rotate {'right' if k is Kind.ROTATE_RIGHT else 'left'} {a:.0f}°"
        if k in (Kind.LATERAL_LEFT, Kind.LATERAL_RIGHT):
            return f"move {'left' if k is Kind.LATERAL_LEFT else 'right'} {a * 100:.0f} cm (sideways, no rotation)"
        return "no movement (hover in place)"

    @property
    def is_rotation(self) -> bool:
        return self.kind in (Kind.ROTATE_LEFT, Kind.ROTATE_RIGHT)

    @property
    def is_lateral(self) -> bool:
        return self.kind in (Kind.LATERAL_LEFT, Kind.LATERAL_RIGHT)


COMMANDS: dict[str, Command] = {
    c.code: c
    for c in (
        Command("A1", Kind.FORWARD, 0.10),
        Command("A2", Kind.FORWARD, 0.25),
        Command("A3", Kind.FORWARD, 0.50),
        Command("B1", Kind.ROTATE_RIGHT, 15.0),
        Command("B2", Kind.ROTATE_RIGHT, 45.0),
        Command("B3", Kind.ROTATE_RIGHT, 90.0),
        Command("C1", Kind.ROTATE_LEFT, 15.0),
        Command("C2", Kind.ROTATE_LEFT, 45.0),
        Command("C3", Kind.ROTATE_LEFT, 90.0),
        Command("D1", Kind.LATERAL_LEFT, 0.10),
        Command("D2", Kind.LATERAL_RIGHT, 0.10),
        Command("E", Kind.NONE, 0.0),
    )
}

HOVER = COMMANDS["E"]
# The reverse of each rotation and sideways direction: a move followed by its opposite is an oscillation.
OPPOSITE: dict[Kind, Kind] = {Kind.ROTATE_LEFT: Kind.ROTATE_RIGHT, Kind.ROTATE_RIGHT: Kind.ROTATE_LEFT,
                              Kind.LATERAL_LEFT: Kind.LATERAL_RIGHT, Kind.LATERAL_RIGHT: Kind.LATERAL_LEFT}


def get_command(code: str) -> Command:
    """Look a command up by code (case and surrounding spaces ignored)."""
    key = str(code).strip().upper()
    try:
        return COMMANDS[key]
    except KeyError:
        raise UnknownNameError("command", code, COMMANDS) from None


def command_table_markdown() -> str:
    """The command table for the docs (docs/simulator.md holds it verbatim; a test keeps them equal)."""
    rows = ["| command | what it does |", "|---|---|"]
    rows += [f"| `{c.code}` | {c.description} |" for c in COMMANDS.values()]
    return "\n".join(rows)
