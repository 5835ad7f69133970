"""Clocks for the robot layer: the wall clock in use, a manual clock in tests.

The Tello backend and its emulator take every time they need (keep-alive intervals, rc pulse lengths, the
emulator's auto-land and battery drain) from a clock object, so that tests can run a 12-second pilot or a
15-second silence without waiting and without timing assertions.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Seconds on a monotonic scale."""

    def sleep(self, seconds: float) -> None:
        """Let `seconds` pass for the caller (a foreground wait: a motion pulse, a slow pilot)."""

    def wait_until(self, deadline: float, stop: threading.Event) -> bool:
        """Background wait until `deadline` or until `stop` is set (then True); for helper threads."""

    def wake(self) -> None:
        """Wake background waiters so that they see their `stop` event."""

    def done(self) -> None:
        """A helper thread that ends says so."""


class WallClock:
    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def wait_until(self, deadline: float, stop: threading.Event) -> bool:
        return stop.wait(max(0.0, deadline - self.now()))

    def wake(self) -> None:
        """Background waits end on their stop event by themselves."""

    def done(self) -> None:
        """Nothing to release on the wall clock."""


class ManualClock:
    """Time moves only when a caller sleeps; helper threads that wait on it run to completion at each tick.

    `sleep(d)` advances time in ticks of `tick` seconds; after each tick it blocks until every helper thread
    whose deadline has passed has woken, done its work and waited again (or ended). So a keep-alive thread
    sends its query at the simulated moment it is due, before time moves on.
    """

    def __init__(self, start: float = 1000.0, tick: float = 0.05):
        self._t = start
        self.tick = tick
        self._cond = threading.Condition()
        self._deadlines: dict[int, float] = {}  # waiting helper thread -> its deadline
        self._running: set[int] = set()  # helpers woken by a tick that have not waited again yet

    def now(self) -> float:
        with self._cond:
            return self._t

    def sleep(self, seconds: float) -> None:
        end = self.now() + max(0.0, seconds)
        while self.now() < end - 1e-9:
            with self._cond:
                self._t = min(end, self._t + self.tick)
                self._cond.notify_all()
                self._cond.wait_for(self._settled)

    def _settled(self) -> bool:
        return not self._running and all(d > self._t for d in self._deadlines.values())

    def wait_until(self, deadline: float, stop: threading.Event) -> bool:
        me = threading.get_ident()
        with self._cond:
            self._running.discard(me)
            self._deadlines[me] = deadline
            self._cond.notify_all()
            self._cond.wait_for(lambda: stop.is_set() or self._t >= deadline)
            del self._deadlines[me]
            if not stop.is_set():
                self._running.add(me)  # busy until it waits again or calls done()
            self._cond.notify_all()
            return stop.is_set()

    def done(self) -> None:
        """A helper thread that ends says so (it no longer holds time back)."""
        with self._cond:
            self._running.discard(threading.get_ident())
            self._cond.notify_all()

    def wake(self) -> None:
        with self._cond:
            self._cond.notify_all()
