"""The Tello's link watchdog: a dead link (state packets, video frames and replies all silent) lands the drone.

A Tello sends a state packet ten times a second and a video stream without pause, and answers every command
but `rc`. The watchdog samples those three channels every `POLL_S` on its clock. When none of them has shown
a sign of life for `link_silence_s` (1 s by default: ten state packets in a row missing, about 15-30 frames), the
link is declared lost: nothing more is sent but `land`, resent every second (a repeated `land` is harmless)
until a reply comes, and `emergency` (motors off) if none came within `land_confirm_s`. The episode's thread
sees `lost` and ends the episode `link_lost`. Should every packet of ours be lost too, the Tello lands by
itself 15 s after the last command it received, and after the loss we send it nothing else.

A wake-up that comes late (this process was starved of the CPU) does not count the time it was not looking as
silence: only silence observed on schedule declares a loss, so a busy machine does not land a healthy drone.
"""

from __future__ import annotations

import threading
from typing import Any, Protocol

from vlnpilot.robots.clock import Clock

POLL_S = 0.1  # one state packet period
LAND_RESEND_S = 1.0


class LinkPort(Protocol):
    """What the watchdog needs of a link (TelloLink; a fake in tests)."""

    lost: threading.Event  # set by the watchdog: the link sends nothing more but `land` / `emergency`

    def evidence(self) -> tuple[int, int, int]:
        """Counters of what arrived: state packets, decoded video frames, command replies."""

    def emergency_send(self, command: str) -> None:
        """Send `land` or `emergency` now, whatever else holds the link."""

    def poll_reply(self) -> str | None:
        """A reply that arrived and nobody took yet, or None."""


class LinkWatchdog:
    """Watches `port` on `clock` from a helper thread; `lost_at` / `reason` say when and why it gave up."""

    def __init__(self, port: LinkPort, clock: Clock, *, silence_s: float, land_confirm_s: float,
                 report: Any = None):
        self.port, self.clock = port, clock
        self.silence_s, self.land_confirm_s = silence_s, land_confirm_s
        self.report = report or (lambda kind, **facts: None)  # the backend's event log
        self.lost_at: float | None = None
        self.silent_since: float | None = None  # the last sign of life before the loss
        self.reason = ""
        self.sent: list[tuple[float, str]] = []  # (clock time, command) of the landing sequence
        self.done = threading.Event()  # the landing sequence is over (or there was none)
        self._wake = threading.Event()
        self._closing = False
        self._declared: str | None = None
        self._thread: threading.Thread | None = None

    @property
    def lost(self) -> bool:
        return self.port.lost.is_set()

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="tello-link-watchdog", daemon=True)
            self._thread.start()

    def declare_lost(self, reason: str) -> None:
        """The backend saw the link die itself (no reply and no state packet after a command): land now."""
        if not self.lost and self._declared is None:
            self._declared = reason
            self._wake.set()
            self.clock.wake()

    def close(self, timeout: float = 15.0) -> None:
        """Let a landing sequence under way finish (bounded, in real seconds), then stop the thread."""
        if self._thread is None:
            return
        if self.lost or self._declared is not None:
            self.done.wait(timeout)
        self._closing = True
        self._wake.set()
        self.clock.wake()
        self._thread.join(timeout=10)

    # -- the helper thread --------------------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            if self._watch():
                self._land()
        finally:
            self.done.set()
            self.clock.done()

    def _watch(self) -> bool:
        """Sample until the link is lost (True) or the watchdog closes (False)."""
        now = self.clock.now()
        last = self.port.evidence()
        seen = [now, now, now]  # when each channel last changed
        while not self._closing:
            if self.clock.wait_until(now + POLL_S, self._wake):
                self._wake.clear()
            if self._closing:
                return False
            if self._declared is not None:
                return self._give_up(self._declared, max(seen))
            previous, now = now, self.clock.now()
            if now - previous > 2 * POLL_S:  # this thread was not running: what it did not watch is no silence
                seen = [t + (now - previous - POLL_S) for t in seen]
            current = self.port.evidence()
            seen = [now if c != p else t for c, p, t in zip(current, last, seen, strict=True)]
            last = current
            if now - max(seen) >= self.silence_s:
                return self._give_up(f"no state packet, video frame or reply for {now - max(seen):.1f} s "
                                     f"(limit {self.silence_s:g} s)", max(seen))
        return False

    def _give_up(self, reason: str, silent_since: float) -> bool:
        self.port.lost.set()  # first: no command of the episode's may take the land's reply for its own
        self.lost_at, self.silent_since, self.reason = self.clock.now(), silent_since, reason
        self.report("link_lost", reason=reason, action="land")
        return True

    def _land(self) -> None:
        """`land` every LAND_RESEND_S until a reply, then `emergency` if none came within land_confirm_s."""
        start = self.clock.now()
        self._wake.clear()
        while self.port.poll_reply() is not None:  # late answers to earlier commands are no answer to `land`
            pass
        while self.clock.now() - start < self.land_confirm_s and not self._closing:
            self._send("land")
            resend = min(self.clock.now() + LAND_RESEND_S, start + self.land_confirm_s)
            while self.clock.now() < resend and not self._closing:
                reply = self.port.poll_reply()
                if reply is not None:
                    self.report("land", reply=reply, action="a reply after `land`: no emergency")
                    return
                self.clock.wait_until(min(resend, self.clock.now() + POLL_S), self._wake)
        self._send("emergency")
        self.report("emergency", reason=f"no reply to 'land' within {self.land_confirm_s:g} s",
                    action="emergency: motors off")

    def _send(self, command: str) -> None:
        self.sent.append((self.clock.now(), command))
        self.port.emergency_send(command)
