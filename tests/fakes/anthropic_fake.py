"""A fake Anthropic Messages API server: `POST /v1/messages`.

    with FakeAnthropic() as fake:
        pilot = make_pilot("anthropic", base_url=fake.base_url, api_key="sk-ant-test")

When the request forces a tool, decisions come back as that tool's `tool_use` input (as the real API
does); plain text actions (text, prose, not_json) come back as a text block.
"""

from __future__ import annotations

import datetime
import json
import uuid

from ._server import FakeServer, RecordedRequest
from .limits import Usage
from .prompt_cache import PromptCache, Segment, text_tokens

_ERROR_TYPES = {400: "invalid_request_error", 401: "authentication_error", 403: "permission_error",
                404: "not_found_error", 408: "timeout_error", 413: "request_too_large", 429: "rate_limit_error",
                500: "api_error", 529: "overloaded_error"}


class FakeAnthropic(FakeServer):
    provider = "anthropic"

    def _route(self, method: str, path: str) -> str | None:
        return "" if method == "POST" and path.rstrip("/") == "/v1/messages" else None

    def _parse(self, req: RecordedRequest) -> None:
        body = req.json
        req.model = body.get("model")
        system = body.get("system") or ""
        req.system = system if isinstance(system, str) else "".join(b.get("text", "") for b in system)
        for message in body.get("messages") or []:
            content = message.get("content")
            blocks = [{"type": "text", "text": content}] if isinstance(content, str) else (content or [])
            for block in blocks:
                if block.get("type") == "text":
                    req.texts.append(block.get("text", ""))
                    req.parts.append("text")
                elif block.get("type") == "image":
                    source = block.get("source") or {}
                    req.image_media_types.append(source.get("media_type", ""))
                    req.images.append(self._b64(source.get("data", "")))
                    req.parts.append("image")
        tools = body.get("tools") or []
        choice = body.get("tool_choice") or {}
        forced = next((t for t in tools if t.get("name") == choice.get("name")), tools[0] if tools else None)
        if forced is not None:
            req.schema = forced.get("input_schema")

    def _prompt_cache(self) -> PromptCache:
        return PromptCache(breakpoints_only=True)  # only where cache_control marks a breakpoint

    def _cache_segments(self, req: RecordedRequest) -> list[Segment]:
        """Anthropic's order: the tools, the system blocks, then the messages' blocks."""
        body = req.json or {}
        tools = json.dumps(body.get("tools") or [], sort_keys=True)
        out = [Segment(tools, 0)]  # keys the prefix; the fakes bill only the messages
        system = body.get("system") or []
        blocks = [{"type": "text", "text": system}] if isinstance(system, str) else list(system)
        for message in body.get("messages") or []:
            content = message.get("content")
            blocks += [{"type": "text", "text": content}] if isinstance(content, str) else list(content or [])
        for block in blocks:
            mark = bool(block.get("cache_control"))
            if block.get("type") == "text":
                out.append(Segment(block.get("text", ""), text_tokens(block.get("text", "")), mark))
            else:
                out.append(Segment(json.dumps(block, sort_keys=True), 85, mark))
        return out

    def _tool_name(self, req: RecordedRequest) -> str | None:
        body = req.json or {}
        choice = body.get("tool_choice") or {}
        if choice.get("type") == "tool":
            return choice.get("name")
        tools = body.get("tools") or []
        return tools[0].get("name") if tools and choice.get("type") == "any" else None

    def _message(self, req: RecordedRequest, content: list[dict], stop: str, usage_text: str) -> dict:
        inp, cached, out = self._usage_counts(req, usage_text)
        return {
            "id": f"msg_{uuid.uuid4().hex[:24]}",
            "type": "message",
            "role": "assistant",
            "model": req.model or "claude-sonnet-4-6",
            "content": content,
            "stop_reason": stop,
            "stop_sequence": None,
            "usage": {"input_tokens": inp - cached - req.cache_written, "output_tokens": out,
                      "cache_read_input_tokens": cached, "cache_creation_input_tokens": req.cache_written},
        }

    def _success(self, req: RecordedRequest, text: str, *, data: dict | None = None) -> dict:
        tool = self._tool_name(req)
        if data is not None and tool:
            block = {"type": "tool_use", "id": f"toolu_{uuid.uuid4().hex[:20]}", "name": tool, "input": data}
            return self._message(req, [block], "tool_use", text)
        return self._message(req, [{"type": "text", "text": text}], "end_turn", text)

    def _limit_headers(self, usage: Usage) -> dict[str, str]:
        def at(seconds: float) -> str:  # RFC 3339, as Anthropic sends it
            moment = datetime.datetime.now(datetime.UTC) + datetime.timedelta(seconds=seconds)
            return moment.strftime("%Y-%m-%dT%H:%M:%SZ")

        return {"anthropic-ratelimit-requests-limit": str(usage.rpm or 0),
                "anthropic-ratelimit-requests-remaining": str(usage.left_requests),
                "anthropic-ratelimit-requests-reset": at(usage.reset_requests_s),
                "anthropic-ratelimit-tokens-limit": str(usage.tpm or 0),
                "anthropic-ratelimit-tokens-remaining": str(usage.left_tokens),
                "anthropic-ratelimit-tokens-reset": at(usage.reset_tokens_s)}

    def _limit_error(self, usage: Usage) -> tuple[str, str]:
        what = "requests" if usage.refused == "requests" else "input tokens"
        limit = usage.rpm if usage.refused == "requests" else usage.tpm
        return (f"This request would exceed the rate limit for your organization of {limit} {what} per minute. "
                "For details, refer to: https://docs.claude.com/en/api/rate-limits.", "")

    def _error_body(self, status: int, message: str, code: str) -> dict:
        kind = _ERROR_TYPES.get(status, "api_error" if status >= 500 else "invalid_request_error")
        return {"type": "error", "error": {"type": kind, "message": message},
                "request_id": f"req_{uuid.uuid4().hex[:20]}"}

    def _special(self, req: RecordedRequest, kind: str, params: dict) -> tuple[int, dict]:
        if kind in ("refusal", "content_filter"):
            text = params.get("message", "I can't help with piloting this request.")
            return 200, self._message(req, [{"type": "text", "text": text}], "refusal", text)
        if kind == "truncated":
            tool = self._tool_name(req) or "submit_decision"
            block = {"type": "tool_use", "id": f"toolu_{uuid.uuid4().hex[:20]}", "name": tool,
                     "input": {"room": "kitchen"}}
            return 200, self._message(req, [block], "max_tokens", "x" * 40)
        if kind == "bad_key":
            return 401, self._error_body(401, "invalid x-api-key", "")
        if kind == "reject_schema":
            return 400, self._error_body(400, "tools.0.input_schema: JSON schema is invalid", "")
        raise ValueError(kind)
