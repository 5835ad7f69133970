"""The Anthropic pilot: the official `anthropic` SDK, Messages API, structured output by a forced tool.

The state's answer schema is the `input_schema` of a single tool, `submit_decision`, and tool_choice
forces it, so the reply is the tool's JSON input. Prompt caching: cache_control marks the end of the
system prompt, of the episode context and of the state prompt; the step text and then the image come last. With the
`history` option it also marks the end of the earlier turns (the model's last answer): four breakpoints at most.
(Anthropic's cache prefix starts with the tools, and the tool schema is per state, so the cache hits
across the consecutive steps spent in one state, which is most of an episode.)
"""

from __future__ import annotations

import base64
import logging
from collections.abc import Sequence
from typing import Any

import anthropic as anthropic_sdk
from pydantic import SecretStr

from vlnpilot.pilots._history import Message, Part, single
from vlnpilot.pilots.base import PilotError, register_pilot
from vlnpilot.pilots.model import ModelPilot, Reply, TokenCounts
from vlnpilot.pilots.options import ModelOptions, secret_value
from vlnpilot.pilots.secrets import resolve_api_key
from vlnpilot.pilots.transport import map_stainless_error

log = logging.getLogger(__name__)

TOOL_NAME = "submit_decision"
_CACHE = {"type": "ephemeral"}


class AnthropicOptions(ModelOptions):
    """The options of the Anthropic pilot (the common ones are ModelOptions')."""

    model: str = "claude-sonnet-4-6"
    cache: bool = True  # prompt-cache breakpoints
    strict_tool: bool = False  # send the tool with strict=True (models that support strict tool use)


@register_pilot("anthropic", options=AnthropicOptions)
class AnthropicPilot(ModelPilot):
    """Claude as the pilot.

    Options (`AnthropicOptions`): model (default claude-sonnet-4-6), api_key (default env ANTHROPIC_API_KEY),
    base_url (default env ANTHROPIC_BASE_URL, else the Anthropic API), cache (prompt-cache breakpoints, default
    True), strict_tool (send the tool with strict=True, for models that support strict tool use;
    default False), and the common options of ModelPilot (timeout, max_retries, max_output_tokens,
    temperature, jpeg_quality, max_side, validate, prices).
    """

    name = "anthropic"
    provider = "Anthropic"
    key_envs = ("ANTHROPIC_API_KEY",)

    def __init__(self, model: str | None = None, **options: Any):
        o = AnthropicOptions.build(self.name, model=model, **options)
        super().__init__(o)
        key = resolve_api_key(secret_value(o.api_key), self.key_envs, "Anthropic")
        self.cache = o.cache
        self.strict_tool = o.strict_tool
        self._secret = SecretStr(key or "")
        http_client = anthropic_sdk.DefaultHttpxClient(event_hooks=self._event_hooks())
        self._client = anthropic_sdk.Anthropic(api_key=key, base_url=o.base_url, timeout=self.timeout,
                                               max_retries=self.max_retries, http_client=http_client)
        self.base_url = str(self._client.base_url)

    def __repr__(self) -> str:
        return f"AnthropicPilot(model={self.model!r}, base_url={self.base_url!r})"

    def _text(self, text: str, cache: bool = False) -> dict[str, Any]:
        block: dict[str, Any] = {"type": "text", "text": text}
        if cache and self.cache:
            block["cache_control"] = _CACHE
        return block

    def _block(self, part: Part) -> dict[str, Any]:
        if part.jpeg is None:
            return self._text(part.text or "", cache=part.cache)
        return {"type": "image", "source": {"type": "base64", "media_type": "image/jpeg",
                                            "data": base64.b64encode(part.jpeg).decode("ascii")}}

    def _kwargs(self, prompt: Any, chat: Sequence[Message] | None = None) -> dict[str, Any]:
        tool: dict[str, Any] = {
            "name": TOOL_NAME,
            "description": "Submit the drone's next decision in the required output format.",
            "input_schema": prompt.schema,
        }
        if self.strict_tool:
            tool["strict"] = True
        kwargs: dict[str, Any] = {
            "model": self.model,
            "max_tokens": self.max_output_tokens,
            "system": [self._text(prompt.system, cache=True)],
            "messages": [{"role": m.role, "content": [self._block(p) for p in m.parts]}
                         for m in (single(prompt) if chat is None else chat)],
            "tools": [tool],
            "tool_choice": {"type": "tool", "name": TOOL_NAME},
        }
        if self.temperature is not None:
            kwargs["temperature"] = self.temperature
        return kwargs

    def _error(self, exc: BaseException) -> PilotError:
        return map_stainless_error(exc, anthropic_sdk, provider=self.provider, key_env="ANTHROPIC_API_KEY",
                                   model=self.model, base_url=self.base_url, timeout_s=self.timeout)

    def _call(self, prompt: Any, chat: Sequence[Message] | None = None) -> Reply:
        try:
            message = self._client.messages.create(**self._kwargs(prompt, chat))
        except anthropic_sdk.AnthropicError as exc:
            raise self._error(exc) from None
        return _reply(message)


def _reply(message: Any) -> Reply:
    usage = getattr(message, "usage", None)
    fresh = getattr(usage, "input_tokens", 0) or 0
    read = getattr(usage, "cache_read_input_tokens", 0) or 0
    written = getattr(usage, "cache_creation_input_tokens", 0) or 0
    counts: TokenCounts = {"input_tokens": fresh + read + written, "cached_tokens": read, "cache_write_tokens": written,
              "output_tokens": getattr(usage, "output_tokens", 0) or 0}
    blocks = getattr(message, "content", None) or []
    tool = next((b for b in blocks if getattr(b, "type", None) == "tool_use"), None)
    text = "".join(getattr(b, "text", "") for b in blocks if getattr(b, "type", None) == "text") or None
    stop = getattr(message, "stop_reason", None) or ""
    if stop == "refusal":
        return Reply(text=text, stop="refusal", stop_detail=text or "stop_reason=refusal", **counts)
    data = tool.input if tool is not None and isinstance(tool.input, dict) else None
    if stop == "max_tokens":
        return Reply(text=text, data=data, stop="truncated", stop_detail="stop_reason=max_tokens", **counts)
    if data is not None:
        return Reply(data=data, stop_detail=f"stop_reason={stop}", **counts)
    return Reply(text=text, stop_detail=f"stop_reason={stop} (no tool call)", **counts)
