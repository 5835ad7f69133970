"""A fake OpenAI Chat Completions server: `POST /v1/chat/completions`.

    with FakeOpenAI(oracle=my_oracle, delay=1.5) as fake:
        pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-test")

`supports_json_schema=False` makes it behave like a local server that only knows JSON mode.
"""

from __future__ import annotations

import json
import time
import uuid
from typing import Any

from ._server import FakeServer, RecordedRequest
from .limits import Usage, go_duration
from .prompt_cache import PromptCache, Segment, text_tokens


class FakeOpenAI(FakeServer):
    provider = "openai"

    def __init__(self, *, supports_json_schema: bool = True, **kwargs: Any):
        super().__init__(**kwargs)
        self.supports_json_schema = supports_json_schema

    @property
    def base_url(self) -> str:
        return self.url + "/v1"

    def _route(self, method: str, path: str) -> str | None:
        return "" if method == "POST" and path.rstrip("/") == "/v1/chat/completions" else None

    def _parse(self, req: RecordedRequest) -> None:
        body = req.json
        req.model = body.get("model")
        for message in body.get("messages") or []:
            content = message.get("content")
            parts = [{"type": "text", "text": content}] if isinstance(content, str) else (content or [])
            if message.get("role") in ("system", "developer"):
                req.system += "".join(p.get("text", "") for p in parts if isinstance(p, dict))
                continue
            for part in parts:
                if part.get("type") == "text":
                    req.texts.append(part.get("text", ""))
                    req.parts.append("text")
                elif part.get("type") == "image_url":
                    url = (part.get("image_url") or {}).get("url", "")
                    head, _, data = url.partition(",")
                    req.image_media_types.append(head.removeprefix("data:").split(";")[0])
                    req.images.append(self._b64(data))
                    req.parts.append("image")
        fmt = body.get("response_format") or {}
        if fmt.get("type") == "json_schema":
            req.schema = (fmt.get("json_schema") or {}).get("schema")

    def _answer(self, req: RecordedRequest, action: Any) -> tuple[int, Any, dict]:
        fmt = (req.json or {}).get("response_format") or {}
        if not self.supports_json_schema and fmt.get("type") == "json_schema":
            return self._special(req, "reject_schema", {}) + ({},)
        return super()._answer(req, action)

    def _completion(self, req: RecordedRequest, content: str | None, *, finish: str = "stop",
                    refusal: str | None = None, usage_text: str = "") -> dict:
        inp, cached, out = self._usage_counts(req, usage_text or content or refusal or "")
        return {
            "id": f"chatcmpl-{uuid.uuid4().hex[:24]}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": req.model or "gpt-4.1",
            "system_fingerprint": "fp_fake",
            "choices": [{
                "index": 0,
                "message": {"role": "assistant", "content": content, "refusal": refusal, "annotations": []},
                "logprobs": None,
                "finish_reason": finish,
            }],
            "usage": {
                "prompt_tokens": inp,
                "completion_tokens": out,
                "total_tokens": inp + out,
                "prompt_tokens_details": {"cached_tokens": cached, "audio_tokens": 0},
                "completion_tokens_details": {"reasoning_tokens": 0, "audio_tokens": 0,
                                              "accepted_prediction_tokens": 0, "rejected_prediction_tokens": 0},
            },
        }

    def _success(self, req: RecordedRequest, text: str, *, data: dict | None = None) -> dict:
        return self._completion(req, text)

    def _prompt_cache(self) -> PromptCache:
        return PromptCache(step=128)  # cached_tokens come in steps of 128 beyond the first 1,024

    def _cache_segments(self, req: RecordedRequest) -> list[Segment]:
        """The structured-output schema first (OpenAI serves it as a prefix of the system message), then each
        message's parts."""
        body = req.json or {}
        fmt = json.dumps(body.get("response_format") or {}, sort_keys=True)
        out = [Segment(fmt, 0)]  # keys the prefix; the fakes bill only the messages
        for message in body.get("messages") or []:
            content = message.get("content")
            for part in [{"type": "text", "text": content}] if isinstance(content, str) else content or []:
                if part.get("type") == "text":
                    out.append(Segment(part.get("text", ""), text_tokens(part.get("text", ""))))
                else:
                    out.append(Segment(json.dumps(part, sort_keys=True), 85))
        return out

    def _limit_headers(self, usage: Usage) -> dict[str, str]:
        return {"x-ratelimit-limit-requests": str(usage.rpm or 0), "x-ratelimit-limit-tokens": str(usage.tpm or 0),
                "x-ratelimit-remaining-requests": str(usage.left_requests),
                "x-ratelimit-remaining-tokens": str(usage.left_tokens),
                "x-ratelimit-reset-requests": go_duration(usage.reset_requests_s),
                "x-ratelimit-reset-tokens": go_duration(usage.reset_tokens_s)}

    def _limit_error(self, usage: Usage) -> tuple[str, str]:
        what, limit = (("requests per min (RPM)", usage.rpm) if usage.refused == "requests"
                       else ("tokens per min (TPM)", usage.tpm))
        return (f"Rate limit reached for gpt-4.1 in organization org-fake on {what}: Limit {limit}, Used {limit}, "
                f"Requested 1. Please try again in {go_duration(usage.reset_requests_s)}. Visit "
                "https://platform.openai.com/account/rate-limits to learn more.", "rate_limit_exceeded")

    def _error_body(self, status: int, message: str, code: str) -> dict:
        kind = {401: "invalid_request_error", 429: "requests", 400: "invalid_request_error"}.get(
            status, "server_error" if status >= 500 else "invalid_request_error")
        return {"error": {"message": message, "type": kind, "param": None, "code": code}}

    def _special(self, req: RecordedRequest, kind: str, params: dict) -> tuple[int, dict]:
        if kind == "refusal":
            return 200, self._completion(req, None, refusal=params.get("message", "I'm sorry, I can't help with that."))
        if kind == "truncated":
            text = '{"room": "kitchen", "movement": "A1", "state": "Search Obj'
            return 200, self._completion(req, text, finish="length")
        if kind == "content_filter":
            return 200, self._completion(req, None, finish="content_filter")
        if kind == "bad_key":
            key = req.headers.get("authorization", "").removeprefix("Bearer ")
            # The real API masks the key; this fake echoes it whole to prove that the pilot redacts it.
            message = (f"Incorrect API key provided: {key}. You can find your API key at "
                       "https://platform.openai.com/account/api-keys.")
            return 401, self._error_body(401, message, "invalid_api_key")
        if kind == "reject_schema":
            return 400, {"error": {"message": "Invalid parameter: 'response_format' of type 'json_schema' is not "
                                              "supported with this model.", "type": "invalid_request_error",
                                   "param": "response_format", "code": None}}
        raise ValueError(kind)
