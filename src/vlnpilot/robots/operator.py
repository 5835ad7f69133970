"""The operator at the keyboard: confirms a Tello episode's outcome and gives the word to land."""

from __future__ import annotations

import select
import sys
import threading
from collections.abc import Callable
from typing import IO

from vlnpilot.core.errors import ConfigError

JUDGES = ("ask", "none")


class ConsoleOperator:
    """Questions on `out`, answers read from `answers` (stdin by default; an empty line or end of input is 'no')."""

    def __init__(self, answers: IO[str] | None = None, out: IO[str] | None = None):
        self.answers, self.out = answers or sys.stdin, out or sys.stderr

    def ask(self, question: str) -> bool:
        self.out.write(f"{question} [y/N] ")
        self.out.flush()
        return self.answers.readline().strip().lower() in ("y", "yes")

    def wait(self, message: str, until: threading.Event | None = None) -> None:
        """Until the operator presses Enter, or `until` is set (what the wait was for happened without them)."""
        self.out.write(f"{message} ")
        self.out.flush()
        if until is None or not _selectable(self.answers):
            self.answers.readline()
            return
        while not until.is_set():
            if select.select([self.answers], [], [], 0.2)[0]:
                self.answers.readline()
                return
        self.out.write("(no longer waiting)\n")
        self.out.flush()


def _selectable(stream: IO[str]) -> bool:
    """Whether `stream` is a file that select() can watch (a terminal or pipe; not a StringIO)."""
    try:
        stream.fileno()
    except (OSError, ValueError, AttributeError):
        return False
    return sys.platform != "win32"


def make_judge(mode: str, operator: ConsoleOperator) -> Callable[[object, object], tuple[bool, str]] | None:
    """`ask`: the operator confirms a declared final state; `none`: the declaration stands, unconfirmed."""
    key = str(mode).strip().lower()
    if key not in JUDGES:
        raise ConfigError(f"unknown judge {mode!r}; valid judges: {', '.join(JUDGES)}")
    if key == "none":
        return None

    def judge(task: object, state: object) -> tuple[bool, str]:
        query = getattr(task, "query", task)
        said = getattr(state, "value", state)
        if operator.ask(f"The pilot declared '{said}' for \"{query}\". Did the drone reach the goal?"):
            return True, f"'{said}' declared and confirmed by the operator"
        return False, f"'{said}' declared; the operator did not confirm it"

    return judge
