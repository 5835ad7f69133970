"""The providers' prompt caches as the fakes run them: a request's prefix that the fake has seen in the last minutes
is served from the cache and reported as cached tokens, the way each API reports them (issue 27).

A request is a list of segments in the order the provider reads them (`Segment`: a digest of its content, its
tokens, whether it ends a cache breakpoint). A prefix is known by the digest of its segments:
- OpenAI: any prefix of at least 1,024 tokens, reported in steps of 128 beyond the first 1,024;
- Gemini (implicit caching): any prefix of at least 1,024 tokens;
- Anthropic: only the prefixes that end at a `cache_control` breakpoint (of at least 1,024 tokens); the tokens up to
  the last breakpoint that were not read are written (`cache_creation_input_tokens`).
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

TTL_S = 300.0  # five minutes: OpenAI's and Anthropic's default lifetime of an unused prefix


@dataclass(frozen=True)
class Segment:
    content: str
    tokens: int
    breakpoint: bool = False


def text_tokens(text: str) -> int:
    """The fakes' token count of a text (as `FakeServer._usage_counts` counts the input)."""
    return len(text) // 4


class PromptCache:
    def __init__(self, *, minimum: int = 1024, step: int = 1, breakpoints_only: bool = False,
                 ttl_s: float = TTL_S, clock: Callable[[], float] = time.monotonic):
        self.minimum, self.step, self.breakpoints_only, self.ttl_s, self.clock = (
            minimum, step, breakpoints_only, ttl_s, clock)
        self._seen: dict[str, float] = {}  # prefix digest -> when last used
        self._lock = threading.Lock()

    def serve(self, segments: Sequence[Segment]) -> tuple[int, int]:
        """(tokens read from the cache, tokens written to it) for a request; its prefixes are remembered."""
        boundaries: list[tuple[str, int]] = []
        digest, total = hashlib.sha256(), 0
        for segment in segments:
            digest.update(segment.content.encode("utf-8", "replace") + b"\0")
            total += segment.tokens
            if segment.breakpoint or not self.breakpoints_only:
                boundaries.append((digest.hexdigest(), total))
        with self._lock:
            now = self.clock()
            self._seen = {d: t for d, t in self._seen.items() if now - t <= self.ttl_s}
            read = max((n for d, n in boundaries if d in self._seen and n >= self.minimum), default=0)
            if read and self.step > 1:
                read = self.minimum + (read - self.minimum) // self.step * self.step
            written = 0
            if self.breakpoints_only and boundaries and boundaries[-1][1] >= self.minimum:
                written = max(0, boundaries[-1][1] - read)
            for d, n in boundaries:
                if n >= self.minimum:
                    self._seen[d] = now
        return read, written
