"""Upper bounds of the numbers a command line or a suite sets, shared so that both refuse alike."""

from __future__ import annotations

MAX_STEPS = 100_000  # a bound that no flight reaches (a Tello battery lasts about 400 steps), far below overflow
MAX_REPS = 10_000  # repetitions of a suite's rows: a bench's episodes are planned (and listed) before any flies
