"""Cancelling abandoned provider calls, so that nothing calls a provider after its step (or episode) gave up.

The controller runs a network-bound pilot call in a helper thread and stops waiting at the step deadline
(`episode_ask.Deadline`). The SDK inside that thread would go on retrying for up to timeout x retries. A CallGate
stops it: each call notes the gate's generation in its own thread; `cancel()` moves the generation on, and every
HTTP request of an older call (an SDK retry included) is refused before it leaves the machine.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any


class CallCancelled(RuntimeError):
    """An HTTP request of a call that the controller has abandoned; it is never sent."""


class CallGate:
    """Generation counter shared by a pilot and the httpx hooks of its SDK client."""

    def __init__(self) -> None:
        self._generation = 0
        self._local = threading.local()

    def enter(self) -> None:
        """Mark the calling thread's current call as belonging to this generation."""
        self._local.generation = self._generation

    def cancel(self) -> None:
        """Abandon every call entered so far (calls entered later are not affected)."""
        self._generation += 1

    def check(self) -> None:
        if getattr(self._local, "generation", self._generation) != self._generation:
            raise CallCancelled("the controller abandoned this call (step deadline or end of episode)")

    def on_request(self, request: Any) -> None:
        """httpx `event_hooks["request"]` entry: runs in the calling thread before each request is sent."""
        self.check()


def call_in_daemon_thread(fn: Callable[[], Any], timeout_s: float) -> tuple[bool, Any]:
    """Run `fn` in a daemon thread for at most `timeout_s`: (True, its result) or (False, None) if it overran.

    A daemon thread, unlike a ThreadPoolExecutor worker, never holds up the process's exit. Exceptions of `fn`
    are raised here.
    """
    box: dict[str, Any] = {}
    done = threading.Event()

    def target() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            box["error"] = exc
        finally:
            done.set()

    threading.Thread(target=target, name="pilot-call", daemon=True).start()
    if not done.wait(timeout_s):
        return False, None
    if "error" in box:
        raise box["error"]
    return True, box["value"]
