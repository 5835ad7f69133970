"""The OpenAI pilot (the paper's GPT runs): the official `openai` SDK, Chat Completions, strict JSON schema.

`base_url` (or env OPENAI_BASE_URL) points it at any OpenAI-compatible server (vLLM, Ollama, LM Studio,
llama.cpp): there the key is optional. Servers that reject `json_schema` structured output get JSON mode
(`json_object`) instead, once, and the reply is validated locally as always.

Image detail defaults to "low": the front camera renders 640x480, "low" sends it as one 512 px image for a
flat 85 tokens, while "high" upsamples it to 1024x768 tiles for ~765 tokens (9x the image cost and more
latency) without adding pixels the camera never had. Rooms, doors and a target object remain readable at
512 px; pass detail="high" or "auto" to compare.
"""

from __future__ import annotations

import base64
import logging
import os
from collections.abc import Sequence
from typing import Any, Literal
from urllib.parse import urlsplit

import openai as openai_sdk
from pydantic import SecretStr

from vlnpilot.pilots._history import Message, Part, single
from vlnpilot.pilots.base import PilotError, register_pilot
from vlnpilot.pilots.model import ModelPilot, Reply, TokenCounts
from vlnpilot.pilots.options import ModelOptions, secret_value
from vlnpilot.pilots.secrets import redact, resolve_api_key
from vlnpilot.pilots.transport import map_stainless_error

log = logging.getLogger(__name__)

ResponseFormat = Literal["auto", "json_schema", "json_object", "none"]
SCHEMA_NAME = "vln_pilot_decision"
# A 400 that means "no structured output here" names response_format / json_schema (OpenAI: param
# "response_format"; vLLM, Ollama, llama.cpp: "json_schema ... not supported"). "Unsupported value: 'temperature'"
# or "Unsupported parameter: 'max_tokens'" do not: they must not switch structured output off.
_FORMAT_PARAMS = ("response_format", "json_schema", "structured output", "structured_output", "guided_json")
OFFICIAL_HOST = "api.openai.com"


class OpenAIOptions(ModelOptions):
    """The options of the OpenAI pilot (the common ones are ModelOptions')."""

    model: str = "gpt-4.1"
    detail: Literal["low", "high", "auto"] = "low"
    response_format: ResponseFormat = "auto"
    max_tokens_param: Literal["max_completion_tokens", "max_tokens"] | None = None  # None: by the server
    extra_body: dict[str, Any] | None = None


@register_pilot("openai", options=OpenAIOptions)
class OpenAIPilot(ModelPilot):
    """GPT (or any OpenAI-compatible model) as the pilot.

    Options (`OpenAIOptions`): model (default gpt-4.1), api_key (default env OPENAI_API_KEY), base_url (default
    env OPENAI_BASE_URL), detail ("low" | "high" | "auto"), response_format ("auto": json_schema with a
    fallback to json_object; or "json_schema", "json_object", "none"), max_tokens_param
    ("max_completion_tokens" for api.openai.com, "max_tokens" for other servers by default),
    extra_body (dict merged into the request, e.g. vLLM sampling options), and the common options of
    ModelPilot (timeout, max_retries, max_output_tokens, temperature, jpeg_quality, max_side, validate, prices).
    """

    name = "openai"
    provider = "OpenAI"
    key_envs = ("OPENAI_API_KEY",)

    def __init__(self, model: str | None = None, **options: Any):
        o = OpenAIOptions.build(self.name, model=model, **options)
        super().__init__(o)
        self.base_url = o.base_url or os.environ.get("OPENAI_BASE_URL") or None
        self.official = official = is_official(self.base_url)
        if not official:
            self.provider = "OpenAI-compatible"
        # A local server needs no key; the official API does (a missing key is fatal and names the env var).
        key = resolve_api_key(secret_value(o.api_key), self.key_envs, "OpenAI", optional=not official) or "EMPTY"
        self.detail = o.detail
        self.response_format = o.response_format
        self._format = "json_schema" if o.response_format == "auto" else o.response_format
        self.max_tokens_param = o.max_tokens_param or ("max_completion_tokens" if official else "max_tokens")
        self.extra_body = dict(o.extra_body or {})
        self._secret = SecretStr(key or "")
        self._client = openai_sdk.OpenAI(api_key=key, base_url=self.base_url, timeout=self.timeout,
                                         max_retries=self.max_retries, http_client=openai_sdk.DefaultHttpxClient(
                                             event_hooks=self._event_hooks()))

    def __repr__(self) -> str:
        return f"OpenAIPilot(model={self.model!r}, base_url={self.base_url!r}, detail={self.detail!r})"

    # ------------------------------------------------------------ request
    def _messages(self, prompt: Any, chat: Sequence[Message] | None = None) -> list[dict[str, Any]]:
        # Stable parts first: OpenAI and vLLM prefix caches hit on system + context + state prompt (+ earlier turns);
        # the step text, then the image last (pilots/_history.py).
        out: list[dict[str, Any]] = [{"role": "system", "content": prompt.system}]
        for message in single(prompt) if chat is None else chat:
            if message.role == "assistant":
                out.append({"role": "assistant", "content": "".join(p.text or "" for p in message.parts)})
            else:
                out.append({"role": "user", "content": [self._part(p) for p in message.parts]})
        return out

    def _part(self, part: Part) -> dict[str, Any]:
        if part.jpeg is None:
            return {"type": "text", "text": part.text}
        url = "data:image/jpeg;base64," + base64.b64encode(part.jpeg).decode("ascii")
        return {"type": "image_url", "image_url": {"url": url, "detail": self.detail}}

    def _kwargs(self, prompt: Any, fmt: str, chat: Sequence[Message] | None = None) -> dict[str, Any]:
        kwargs: dict[str, Any] = {"model": self.model, "messages": self._messages(prompt, chat),
                                  self.max_tokens_param: self.max_output_tokens}
        if self.temperature is not None:
            kwargs["temperature"] = self.temperature
        if fmt == "json_schema":
            kwargs["response_format"] = {"type": "json_schema", "json_schema": {
                "name": SCHEMA_NAME, "strict": True, "schema": prompt.schema}}
        elif fmt == "json_object":
            kwargs["response_format"] = {"type": "json_object"}
        if self.official:  # routes an episode's calls to the same cache (a server of another kind may refuse it)
            kwargs["prompt_cache_key"] = cache_key(prompt)
        if self.extra_body:
            kwargs["extra_body"] = self.extra_body
        return kwargs

    def _error(self, exc: BaseException) -> PilotError:
        return map_stainless_error(exc, openai_sdk, provider=self.provider, key_env="OPENAI_API_KEY",
                                   model=self.model, base_url=self.base_url, timeout_s=self.timeout)

    def _call(self, prompt: Any, chat: Sequence[Message] | None = None) -> Reply:
        fmt = self._format
        try:
            try:
                response = self._client.chat.completions.create(**self._kwargs(prompt, fmt, chat))
            except (openai_sdk.BadRequestError, openai_sdk.UnprocessableEntityError) as exc:
                if not (self.response_format == "auto" and fmt == "json_schema" and _rejects_format(exc)):
                    raise
                log.warning("%s rejected json_schema structured output (%s); using JSON mode from now on",
                            self.provider, redact(getattr(exc, "message", exc))[:200])
                self._format = fmt = "json_object"
                response = self._client.chat.completions.create(**self._kwargs(prompt, fmt, chat))
        except openai_sdk.OpenAIError as exc:
            raise self._error(exc) from None
        return _reply(response)


def _rejects_format(exc: BaseException) -> bool:
    body = getattr(exc, "body", None)
    err = body.get("error", body) if isinstance(body, dict) else None
    param = str(err.get("param") or "") if isinstance(err, dict) else ""
    if param:  # the API names the parameter it rejects
        return param.startswith("response_format")
    text = f"{getattr(exc, 'message', '')} {body or ''}".lower()
    return any(hint in text for hint in _FORMAT_PARAMS)


def cache_key(prompt: Any) -> str:
    """OpenAI's `prompt_cache_key` of a call: one per episode (its system prompt and context: query and map)."""
    import hashlib

    return "vlnpilot-" + hashlib.sha256(f"{prompt.system}\0{prompt.context}".encode()).hexdigest()[:16]


def is_official(base_url: str | None) -> bool:
    """No address, or the official API's own address (then the official rules apply: a key, max_completion_tokens)."""
    return base_url is None or urlsplit(base_url).hostname == OFFICIAL_HOST


def _reply(response: Any) -> Reply:
    usage = getattr(response, "usage", None)
    details = getattr(usage, "prompt_tokens_details", None)
    counts: TokenCounts = {
        "input_tokens": getattr(usage, "prompt_tokens", 0) or 0,
        "cached_tokens": getattr(details, "cached_tokens", 0) or 0,
        "output_tokens": getattr(usage, "completion_tokens", 0) or 0,
    }
    choices = getattr(response, "choices", None) or []
    if not choices:
        return Reply(text=None, stop_detail="no choices in the response", **counts)
    choice = choices[0]
    message = choice.message
    finish = choice.finish_reason or ""
    refusal = getattr(message, "refusal", None)
    text = message.content if isinstance(message.content, str) else None
    if refusal:
        return Reply(text=text, stop="refusal", stop_detail=str(refusal), **counts)
    if finish == "length":
        return Reply(text=text, stop="truncated", stop_detail="finish_reason=length", **counts)
    if finish == "content_filter":
        return Reply(text=text, stop="content_filter", stop_detail="finish_reason=content_filter", **counts)
    return Reply(text=text, stop_detail=f"finish_reason={finish}", **counts)
