"""Counting OpenAI tokens offline (o200k): what a request costs before it is sent, and how much of it a prefix cache
can serve (issue 27: `bench/prompt_prefix.py`, `vln-pilot bench --estimate`).

tiktoken downloads its BPE ranks on first use, which a machine that reaches only the package registries cannot do;
`bpe-openai` (the `tokens` extra) ships the o200k ranks inside its wheel and counts the same tokens.

A request is read as its segments in the order they are sent (`openai_segments`): the structured-output schema
(OpenAI serves it as a prefix of the system message), then each message's texts and images. Two requests share the
segments they begin with, and within the first segment that differs, the tokens it begins with (`shared_prefix`).
"""

from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from vlnpilot.core.extras import needs

ENCODING = "o200k_base"  # the GPT-4o, 4.1 and 5 families
LOW_DETAIL_IMAGE_TOKENS = 85  # an image sent with detail="low" (the OpenAI pilot's default)


@cache
def encoding() -> Any:
    """The o200k encoding (from the wheel: no download)."""
    # bpe-openai 0.1.4 reads its ranks (on import, and on first use) with importlib.resources.open_binary
    with needs("tokens", what="counting tokens offline"), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import bpe_openai

        found = bpe_openai.get_encoding(ENCODING)
        found.encode("ranks")  # they load on first use
    return found


def encode(text: str) -> list[int]:
    return list(encoding().encode(text))


@dataclass(frozen=True)
class Segment:
    """One part of a request, in send order: a text (its tokens) or an image (a digest of its bytes, a flat count)."""

    tokens: tuple[int, ...] = ()
    image: str | None = None
    image_tokens: int = 0

    @property
    def count(self) -> int:
        return self.image_tokens if self.image is not None else len(self.tokens)

    @property
    def text_count(self) -> int:
        return 0 if self.image is not None else len(self.tokens)


def text_segment(text: str) -> Segment:
    return Segment(tokens=tuple(encode(text)))


def openai_segments(kwargs: dict[str, Any], *, schema: bool = True) -> list[Segment]:
    """The segments of a Chat Completions request (`chat.completions.create` keywords), in the order they reach the
    model: the response format's schema (when `schema`), then each message's content parts."""
    out: list[Segment] = []
    fmt = kwargs.get("response_format") or {}
    if schema and fmt.get("type") == "json_schema":
        out.append(text_segment(json.dumps(fmt["json_schema"], sort_keys=True)))
    for message in kwargs["messages"]:
        content = message["content"]
        parts: list[dict[str, Any]] = [{"type": "text", "text": content}] if isinstance(content, str) else content
        for part in parts:
            if part["type"] == "text":
                out.append(text_segment(part["text"]))
            else:
                url = part["image_url"]["url"]
                detail = part["image_url"].get("detail", "auto")
                count = LOW_DETAIL_IMAGE_TOKENS if detail == "low" else 765  # high/auto at 640x480: 4 tiles + base
                out.append(Segment(image=hashlib.sha256(url.encode()).hexdigest(), image_tokens=count))
    return out


@dataclass(frozen=True)
class PrefixSplit:
    """One request against the one before it: its input tokens, text tokens, and those of the prefix they share."""

    input_tokens: int
    text_tokens: int
    shared_tokens: int
    shared_text_tokens: int

    @property
    def text_outside(self) -> int:
        return self.text_tokens - self.shared_text_tokens

    @property
    def shared_share(self) -> float:
        return self.shared_tokens / self.input_tokens if self.input_tokens else 0.0


def shared_prefix(current: Sequence[Segment], previous: Sequence[Segment] | None) -> PrefixSplit:
    """How much of `current` begins as `previous` did: whole equal segments, then the equal leading tokens of the
    first text segment that differs (an image that differs ends the prefix)."""
    total = sum(s.count for s in current)
    text = sum(s.text_count for s in current)
    shared = shared_text = 0
    for i, segment in enumerate(current):
        before = previous[i] if previous is not None and i < len(previous) else None
        if before == segment:
            shared += segment.count
            shared_text += segment.text_count
            continue
        if before is not None and segment.image is None and before.image is None:
            common = _common_length(segment.tokens, before.tokens)
            shared += common
            shared_text += common
        break
    return PrefixSplit(total, text, shared, shared_text)


def _common_length(a: Sequence[int], b: Sequence[int]) -> int:
    n = 0
    for x, y in zip(a, b, strict=False):
        if x != y:
            break
        n += 1
    return n
