"""Rate limits as the providers enforce them, for the fakes: requests and tokens per minute over a sliding window.

    fake.limit(rpm=60, tpm=100_000, clock=clock)  # then: fake.throttled, the requests answered 429

`Windows.admit(tokens)` takes a request if both windows have room; `Usage` says how the windows stand, which the
provider fakes turn into their own headers (OpenAI `x-ratelimit-*`, Anthropic `anthropic-ratelimit-*`; Gemini
sends none) and their own 429 bodies.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

WINDOW_S = 60.0


@dataclass(frozen=True)
class Usage:
    """The windows after a request: limits, what is left, seconds until a slot frees, which limit refused."""

    rpm: int | None
    tpm: int | None
    left_requests: int
    left_tokens: int
    reset_requests_s: float
    reset_tokens_s: float
    refused: str | None = None  # "requests" or "tokens": the limit this request hit


class Windows:
    def __init__(self, rpm: int | None, tpm: int | None, clock: Callable[[], float] = time.monotonic):
        self.rpm, self.tpm, self.clock = rpm, tpm, clock
        self._sent: deque[tuple[float, int]] = deque()
        self._lock = threading.Lock()

    def admit(self, tokens: int) -> Usage:
        with self._lock:
            now = self.clock()
            while self._sent and self._sent[0][0] <= now - WINDOW_S:
                self._sent.popleft()
            used_tokens = sum(n for _, n in self._sent)
            refused = None
            if self.rpm is not None and len(self._sent) + 1 > self.rpm:
                refused = "requests"
            elif self.tpm is not None and used_tokens + tokens > self.tpm:
                refused = "tokens"
            else:
                self._sent.append((now, tokens))
                used_tokens += tokens
            reset = (self._sent[0][0] + WINDOW_S - now) if self._sent else 0.0
            return Usage(self.rpm, self.tpm, max(0, (self.rpm or 0) - len(self._sent)),
                         max(0, (self.tpm or 0) - used_tokens), max(0.0, reset), max(0.0, reset), refused)


def go_duration(seconds: float) -> str:
    """OpenAI's reset header format: '1s', '6m0s', '20ms'."""
    if seconds < 1:
        return f"{max(1, round(seconds * 1000))}ms"
    minutes, rest = divmod(seconds, 60)
    return f"{int(minutes)}m{rest:.0f}s" if minutes else f"{rest:.3g}s"
