"""Every HTTP attempt of a pilot call (the SDK's retries included), recorded through httpx event hooks.

The SDKs retry a 429, a 5xx or a time-out on their own, out of our sight; the hooks on their httpx client see each
attempt. An attempt is `{"status": 200}` (or `{"error": kind}` when no response came: a transport error or a
time-out, whose kind only the call's final exception can name), its `latency_s` (request sent to response
headers) and its `wait_s` (since the previous attempt ended, or the call began: the SDK's back-off). An attempt
without a response has no known end: its `latency_s` is None and the next attempt's `wait_s` counts from its start.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

Attempt = dict[str, Any]


class AttemptLog:
    """The attempts of the call running in each thread (the hooks run in the calling thread, as CallGate's)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock  # a test injects its own
        self._local = threading.local()

    def begin(self) -> None:
        """A new call starts in this thread: forget the attempts of the previous one."""
        self._local.attempts, self._local.sent, self._local.ended = [], None, self.clock()
        self._latest = self._local.attempts  # for `abandoned`, read from the controller's thread

    def on_request(self, request: Any) -> None:
        """httpx `event_hooks["request"]`: an attempt leaves (an unanswered earlier one failed in transport)."""
        if not hasattr(self._local, "attempts"):
            self.begin()
        now = self.clock()
        self._close_unanswered("transport_error")
        self._local.attempts.append({"wait_s": _round(now - self._local.ended), "latency_s": None})
        self._local.sent = now

    def on_response(self, response: Any) -> None:
        """httpx `event_hooks["response"]`: the attempt's status and latency (to the response headers)."""
        if getattr(self._local, "sent", None) is None:
            return
        now = self.clock()
        self._local.attempts[-1].update(status=int(response.status_code), latency_s=_round(now - self._local.sent))
        self._local.sent, self._local.ended = None, now

    def end(self, error_kind: str | None = None) -> tuple[Attempt, ...]:
        """The call is over: its attempts in order; an unanswered last one gets `error_kind` (timeout, ...)."""
        if not hasattr(self._local, "attempts"):
            return ()
        self._close_unanswered(error_kind or "transport_error")
        attempts = tuple(self._local.attempts)
        del self._local.attempts
        return attempts

    def abandoned(self) -> tuple[Attempt, ...]:
        """The attempts so far of the call begun last, from any thread: the controller stopped waiting for it
        (step deadline); one still unanswered is marked `abandoned`."""
        return tuple(a if "status" in a or "error" in a else {**a, "error": "abandoned"}
                     for a in list(getattr(self, "_latest", ())))

    def _close_unanswered(self, kind: str) -> None:
        if getattr(self._local, "sent", None) is not None:
            self._local.attempts[-1]["error"] = kind
            self._local.ended, self._local.sent = self._local.sent, None


def event_hooks(on_request: Callable[[Any], None], log: AttemptLog) -> dict[str, list[Callable[[Any], None]]]:
    """The httpx `event_hooks` of a pilot's SDK client: the call gate's check first (a cancelled call sends
    nothing, and so records nothing), then the attempt log."""
    return {"request": [on_request, log.on_request], "response": [log.on_response]}


def _round(seconds: float) -> float:
    return round(max(0.0, seconds), 4)
