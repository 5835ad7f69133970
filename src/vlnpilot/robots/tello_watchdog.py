"""The Tello's watchdog: a link that goes silent, or a limit that passes, lands the drone from a helper thread.

A Tello sends a state packet ten times a second and a video stream without pause, and answers every command
but `rc`. The watchdog samples those channels every `POLL_S` on its clock. The drone is flown on both of them:
without state packets its height, heading and battery are unknown, without frames the pilot flies blind. So
when the state packets have been silent for `link_silence_s` (1 s by default: ten in a row missing), or the
video for `video_silence_s` (2 s: 30-60 frames), the link is declared lost. It also lands the drone when a
limit passes while nobody steps (`limits`: the battery floor, the flight time; the pilot or the operator may
take their time, the battery does not wait). Then nothing more is sent but `land`, resent every second until
the drone is down (an "ok", or a state packet showing it on the ground; an "error" is no landing), and
`emergency` (motors off) if it is not within `land_confirm_s`. The episode's thread sees `lost` and ends the
episode (`cause` says whether the link or a limit ended it). Should every packet of ours be lost too, the Tello
lands by itself 15 s after the last command it received, and after the loss we send it nothing else.

A wake-up that comes late (this process was starved of the CPU) does not count the time it was not looking as
silence: only silence observed on schedule declares a loss, so a busy machine does not land a healthy drone.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
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

    def on_ground(self) -> bool:
        """Whether the newest state packet shows the drone on the ground."""


class LinkWatchdog:
    """Watches `port` on `clock` from a helper thread; `lost_at` / `reason` say when and why it gave up."""

    def __init__(self, port: LinkPort, clock: Clock, *, silence_s: float, land_confirm_s: float,
                 video_silence_s: float | None = None, report: Any = None,
                 limits: Callable[[], tuple[str, str] | None] | None = None):
        self.port, self.clock = port, clock
        self.silence_s, self.land_confirm_s = silence_s, land_confirm_s
        self.video_silence_s = 2 * silence_s if video_silence_s is None else video_silence_s
        self.report = report or (lambda kind, **facts: None)  # the backend's event log
        self.limits = limits or (lambda: None)  # (event kind, reason) of a limit passed, or None
        self.lost_at: float | None = None
        self.silent_since: float | None = None  # the last sign of life before the loss
        self.reason = ""
        self.cause = ""  # what ended the flight: "link", a limit's kind (battery_low, ...) or "operator_interrupt"
        self.landed: bool | None = None  # after the landing sequence: down (True) or emergency sent (False)
        self.sent: list[tuple[float, str]] = []  # (clock time, command) of the landing sequence
        self.done = threading.Event()  # the landing sequence is over (or there was none)
        self._wake = threading.Event()
        self._closing = False
        self._declared: tuple[str, str] | None = None
        self._thread: threading.Thread | None = None

    @property
    def lost(self) -> bool:
        return self.port.lost.is_set()

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="tello-link-watchdog", daemon=True)
            self._thread.start()

    def declare_lost(self, reason: str, cause: str = "link") -> None:
        """The backend saw the link die itself (no reply and no state packet after a command), or wants the drone
        down and nothing else sent (`cause`: a Ctrl-C, a landing the drone did not confirm): land now."""
        if not self.lost and self._declared is None:
            self._declared, self.reason, self.cause = (reason, cause), reason, cause  # the backend quotes them
            self.port.lost.set()  # at once: no command sent meanwhile (a `streamoff`) may take the land's reply
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
                reason, cause = self._declared
                return self._give_up(reason, cause, max(seen), announce=cause == "link")
            previous, now = now, self.clock.now()
            if now - previous > 2 * POLL_S:  # this thread was not running: what it did not watch is no silence
                seen = [t + (now - previous - POLL_S) for t in seen]
            current = self.port.evidence()
            seen = [now if c != p else t for c, p, t in zip(current, last, seen, strict=True)]
            last = current
            silent = self._silence(now, seen)
            if silent is not None:
                return self._give_up(silent[0], "link", silent[1])
            passed = self.limits()
            if passed is not None:
                return self._give_up(passed[1], passed[0], max(seen))
        return False

    def _silence(self, now: float, seen: list[float]) -> tuple[str, float] | None:
        """Why the link counts as lost (a channel the drone is flown on silent too long) and its last sign of life
        (`seen`: when the state packets, frames and replies last came), or None."""
        state, video = now - seen[0], now - seen[1]
        if state >= self.silence_s and video >= self.silence_s:
            return (f"no state packet or video frame for {min(state, video):.1f} s (limit {self.silence_s:g} s)",
                    max(seen[:2]))
        if state >= self.silence_s:
            return (f"no state packet for {state:.1f} s (limit {self.silence_s:g} s): the drone's height, heading "
                    "and battery are unknown", seen[0])
        if video >= self.video_silence_s:
            return (f"no video frame for {video:.1f} s (limit {self.video_silence_s:g} s): the pilot would fly "
                    "blind", seen[1])
        return None

    def _give_up(self, reason: str, cause: str, silent_since: float, announce: bool = True) -> bool:
        """Why and since when, then `lost` before anything else is sent (no command of the episode's may take
        the land's reply for its own); `announce`: report it (a cause the backend declared, it reported)."""
        self.lost_at, self.silent_since, self.reason, self.cause = self.clock.now(), silent_since, reason, cause
        self.port.lost.set()
        if announce:
            self.report("link_lost" if cause == "link" else cause, reason=reason, action="land")
        return True

    def _land(self) -> None:
        """`land` every LAND_RESEND_S until the drone is down ("ok", or a state packet on the ground), then
        `emergency` if it is not within land_confirm_s."""
        start = self.clock.now()
        self._wake.clear()
        while self.port.poll_reply() is not None:  # late answers to earlier commands are no answer to `land`
            pass
        refused: list[str] = []
        while self.clock.now() - start < self.land_confirm_s and not self._closing:
            self._send("land")
            resend = min(self.clock.now() + LAND_RESEND_S, start + self.land_confirm_s)
            while self.clock.now() < resend and not self._closing:
                reply = self.port.poll_reply()
                if reply == "ok" or self.port.on_ground():
                    self.landed = True
                    self.report("land", reply=reply, action="down: no emergency")
                    return
                if reply is not None:
                    refused.append(reply)  # an "error" to `land` is no landing: asked again
                self.clock.wait_until(min(resend, self.clock.now() + POLL_S), self._wake)
        if self._closing:
            return
        self._send("emergency")
        self.landed = False
        self.report("emergency", reason=f"not down within {self.land_confirm_s:g} s of 'land'"
                    + (f" (it answered {', '.join(sorted(set(refused)))})" if refused else " (no reply)"),
                    action="emergency: motors off")

    def _send(self, command: str) -> None:
        self.sent.append((self.clock.now(), command))
        self.port.emergency_send(command)
