"""The Gemini pilot (the paper's Gemini runs): the official `google-genai` SDK, JSON output with a schema.

The answer schema goes as `response_json_schema` (plain JSON Schema) with `response_mime_type` JSON.
Thinking is off by default (`thinking_budget=0`): it adds seconds per step to a decision that is a
single move. Each model family has its valid settings (THINKING): gemini-2.5-pro cannot switch thinking off,
so "off" becomes its minimum budget; Gemini 3 takes a thinking level instead. Whenever the model may think,
its thoughts count against max_output_tokens, so the answer gets its own budget on top.
google-genai's own retry (HttpRetryOptions) does not honour Retry-After or Google's
RetryInfo, so the SDK is told not to retry (attempts=1) and `call_with_retries` does it here.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from google import genai
from google.genai import errors as genai_errors
from google.genai import types
from pydantic import SecretStr

from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots._history import Message, single
from vlnpilot.pilots.base import PilotError, register_pilot
from vlnpilot.pilots.model import ModelPilot, Reply, TokenCounts
from vlnpilot.pilots.options import ModelOptions, secret_value
from vlnpilot.pilots.secrets import resolve_api_key
from vlnpilot.pilots.transport import (
    HTTPX_TIMEOUTS,
    HTTPX_TRANSPORT_ERRORS,
    call_with_retries,
    connection_error,
    error_message_and_code,
    is_retryable_status,
    parse_retry_after,
    status_error,
    timeout_error,
)

log = logging.getLogger(__name__)

_FILTERED = {"SAFETY", "RECITATION", "BLOCKLIST", "PROHIBITED_CONTENT", "SPII", "IMAGE_SAFETY",
             "IMAGE_PROHIBITED_CONTENT", "MODEL_ARMOR", "LANGUAGE"}
_MEDIA_RESOLUTIONS = {"low": "MEDIA_RESOLUTION_LOW", "medium": "MEDIA_RESOLUTION_MEDIUM",
                      "high": "MEDIA_RESOLUTION_HIGH"}


@dataclass(frozen=True)
class Thinking:
    """The thinking budgets a model family accepts, per the Gemini API's "Thinking" guide (as of 2025; not
    re-checked from this offline machine: a provider's 400 still names what it refuses)."""

    can_disable: bool  # thinking_budget=0 is valid
    min_budget: int
    max_budget: int
    uses_level: bool = False  # Gemini 3: thinking_level ("low", "high") rather than a budget


# Longest prefix first. Unknown families are treated like gemini-2.5-flash.
THINKING = {
    "gemini-3": Thinking(can_disable=False, min_budget=0, max_budget=0, uses_level=True),
    "gemini-2.5-flash-lite": Thinking(can_disable=True, min_budget=512, max_budget=24576),
    "gemini-2.5-flash": Thinking(can_disable=True, min_budget=1, max_budget=24576),
    "gemini-2.5-pro": Thinking(can_disable=False, min_budget=128, max_budget=32768),
}
DYNAMIC_THINKING_TOKENS = 8192  # output headroom when the model decides how long to think


def thinking_rules(model: str) -> Thinking:
    for prefix in sorted(THINKING, key=len, reverse=True):
        if model.startswith(prefix):
            return THINKING[prefix]
    return THINKING["gemini-2.5-flash"]


def thinking_settings(model: str, budget: int | None, level: str | None) -> tuple[dict[str, Any] | None, int]:
    """(ThinkingConfig fields or None, output tokens to add for thoughts) for a model, a budget and a level."""
    rules = thinking_rules(model)
    if level is not None or (rules.uses_level and budget == 0):
        return {"thinking_level": (level or "low").upper()}, DYNAMIC_THINKING_TOKENS
    if budget is None or budget == -1:  # the model's default, or dynamic: it may think at length
        return ({"thinking_budget": budget} if budget is not None else None), DYNAMIC_THINKING_TOKENS
    if budget == 0 and not rules.can_disable:
        return {"thinking_budget": rules.min_budget}, rules.min_budget  # as close to "off" as it goes
    if budget != 0 and not rules.min_budget <= budget <= rules.max_budget:
        off = "0 (off), " if rules.can_disable else ""
        raise ConfigError(f"thinking_budget {budget} is invalid for {model}; valid: {off}-1 (dynamic) or "
                          f"{rules.min_budget}..{rules.max_budget}")
    return {"thinking_budget": budget}, budget


class GeminiOptions(ModelOptions):
    """The options of the Gemini pilot (the common ones are ModelOptions')."""

    model: str = "gemini-2.5-flash"
    thinking_budget: int | None = 0  # 0: off; None: the model's default; -1: dynamic
    thinking_level: str | None = None  # Gemini 3 style, e.g. "low"; replaces thinking_budget when given
    media_resolution: Literal["low", "medium", "high"] | None = None
    retry_base_delay: float = 0.5  # seconds, the first backoff step


@register_pilot("gemini", options=GeminiOptions)
class GeminiPilot(ModelPilot):
    """Gemini as the pilot.

    Options (`GeminiOptions`): model (default gemini-2.5-flash), api_key (default env GEMINI_API_KEY, then
    GOOGLE_API_KEY), base_url (default env GOOGLE_GEMINI_BASE_URL; the Gemini API otherwise), thinking_budget
    (default 0: off; None leaves the model's default, -1 is dynamic), thinking_level (Gemini 3 style, e.g. "low";
    replaces thinking_budget when given), media_resolution ("low" | "medium" | "high"), retry_base_delay
    (seconds, first backoff step), and the common options of ModelPilot (timeout, max_retries,
    max_output_tokens, temperature, jpeg_quality, max_side, validate, prices).
    """

    name = "gemini"
    provider = "Gemini"
    key_envs = ("GEMINI_API_KEY", "GOOGLE_API_KEY")

    def __init__(self, model: str | None = None, **options: Any):
        o = GeminiOptions.build(self.name, model=model, **options)
        super().__init__(o)
        self._thinking, self._thinking_tokens = thinking_settings(self.model, o.thinking_budget, o.thinking_level)
        key = resolve_api_key(secret_value(o.api_key), self.key_envs, "Gemini")
        self.base_url = o.base_url or os.environ.get("GOOGLE_GEMINI_BASE_URL") or None
        self.thinking_budget = o.thinking_budget
        self.thinking_level = o.thinking_level
        self.media_resolution = o.media_resolution
        self.retry_base_delay = o.retry_base_delay
        http_options = types.HttpOptions(
            base_url=self.base_url,
            timeout=max(1, round(self.timeout * 1000)),  # milliseconds
            retry_options=types.HttpRetryOptions(attempts=1),  # we retry, honouring Retry-After / RetryInfo
            client_args={"event_hooks": self._event_hooks()},  # abandoned calls send nothing
        )
        self._secret = SecretStr(key or "")
        self._client = genai.Client(api_key=key, vertexai=False, http_options=http_options)

    def __repr__(self) -> str:
        return f"GeminiPilot(model={self.model!r}, base_url={self.base_url!r}, thinking_budget={self.thinking_budget})"

    # ------------------------------------------------------------ request
    def _config(self, prompt: Any) -> types.GenerateContentConfig:
        thinking = types.ThinkingConfig(**self._thinking) if self._thinking is not None else None
        config: dict[str, Any] = {
            "system_instruction": prompt.system,
            "response_mime_type": "application/json",
            "response_json_schema": prompt.schema,
            # Gemini counts thinking tokens against max_output_tokens: leave the answer its own budget.
            "max_output_tokens": self.max_output_tokens + self._thinking_tokens,
            "thinking_config": thinking,
        }
        if self.temperature is not None:
            config["temperature"] = self.temperature
        if self.media_resolution is not None:
            config["media_resolution"] = _MEDIA_RESOLUTIONS[self.media_resolution]
        return types.GenerateContentConfig(**config)

    def _contents(self, prompt: Any, chat: Sequence[Message] | None = None) -> list[types.Content]:
        # Stable parts first (implicit caching keys on the prefix): earlier turns, then the step text, the image last.
        return [types.Content(role="model" if m.role == "assistant" else "user", parts=[
            types.Part.from_text(text=p.text or "") if p.jpeg is None else
            types.Part.from_bytes(data=p.jpeg, mime_type="image/jpeg") for p in m.parts])
            for m in (single(prompt) if chat is None else chat)]

    def _classify(self, exc: BaseException) -> tuple[bool, float | None]:
        if isinstance(exc, genai_errors.APIError):
            if not is_retryable_status(exc.code or 0):
                return False, None
            headers = getattr(getattr(exc, "response", None), "headers", None)
            retry_after = parse_retry_after(headers)
            return True, retry_after if retry_after is not None else _retry_info(exc.details)
        return isinstance(exc, HTTPX_TIMEOUTS + HTTPX_TRANSPORT_ERRORS), None

    def _error(self, exc: BaseException) -> PilotError:
        if isinstance(exc, genai_errors.APIError):
            message, code = error_message_and_code(exc.details, exc.message or str(exc))
            reasons = " ".join(str(d.get("reason", "")) for d in _details(exc.details))
            return status_error(self.provider, exc.code or 0, message, key_env=" or ".join(self.key_envs),
                                model=self.model, code=f"{code or ''} {reasons}")
        if isinstance(exc, HTTPX_TIMEOUTS):
            return timeout_error(self.provider, self.timeout)
        if isinstance(exc, HTTPX_TRANSPORT_ERRORS):
            return connection_error(self.provider, self.base_url, exc)
        return self._unexpected(exc)

    def _call(self, prompt: Any, chat: Sequence[Message] | None = None) -> Reply:
        config, contents = self._config(prompt), self._contents(prompt, chat)
        try:
            response = call_with_retries(
                lambda: self._client.models.generate_content(model=self.model, contents=contents, config=config),
                classify=self._classify, max_retries=self.max_retries, base_delay=self.retry_base_delay,
                what=f"{self.provider} generate_content",
            )
        except Exception as exc:
            raise self._error(exc) from None
        return _reply(response)


def _details(body: Any) -> list[dict]:
    err = body.get("error", body) if isinstance(body, dict) else None
    details = err.get("details") if isinstance(err, dict) else None
    return [d for d in details if isinstance(d, dict)] if isinstance(details, list) else []


def _retry_info(body: Any) -> float | None:
    """Seconds from a google.rpc.RetryInfo detail ('retryDelay': '1.5s'), if any."""
    for detail in _details(body):
        if str(detail.get("@type", "")).endswith("google.rpc.RetryInfo"):
            m = re.fullmatch(r"\s*([0-9.]+)s\s*", str(detail.get("retryDelay", "")))
            if m:
                return float(m.group(1))
    return None


def _name(value: Any) -> str:
    return str(getattr(value, "name", value) or "")


def _reply(response: Any) -> Reply:
    um = getattr(response, "usage_metadata", None)
    counts: TokenCounts = {
        "input_tokens": getattr(um, "prompt_token_count", 0) or 0,
        "cached_tokens": getattr(um, "cached_content_token_count", 0) or 0,
        # thinking tokens are billed as output
        "output_tokens": (getattr(um, "candidates_token_count", 0) or 0)
        + (getattr(um, "thoughts_token_count", 0) or 0),
    }
    feedback = getattr(response, "prompt_feedback", None)
    block = _name(getattr(feedback, "block_reason", None))
    candidates = getattr(response, "candidates", None) or []
    if not candidates:
        if block:
            return Reply(stop="refusal", stop_detail=f"the prompt was blocked: {block}", **counts)
        return Reply(stop_detail="no candidates in the response", **counts)
    candidate = candidates[0]
    finish = _name(getattr(candidate, "finish_reason", None))
    parts = getattr(getattr(candidate, "content", None), "parts", None) or []
    text = "".join(p.text for p in parts if getattr(p, "text", None) and not getattr(p, "thought", False)) or None
    if finish == "MAX_TOKENS":
        return Reply(text=text, stop="truncated", stop_detail="finish_reason=MAX_TOKENS", **counts)
    if finish in _FILTERED:
        return Reply(text=text, stop="content_filter", stop_detail=f"finish_reason={finish}", **counts)
    return Reply(text=text, stop_detail=f"finish_reason={finish}", **counts)
