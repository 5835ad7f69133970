"""A fake Gemini API server: `POST /v1beta/models/{model}:generateContent`.

    with FakeGemini() as fake:
        pilot = make_pilot("gemini", base_url=fake.base_url, api_key="AIza-test")

Like the real API, a bad key is a 400 INVALID_ARGUMENT with reason API_KEY_INVALID, and a 429 carries a
google.rpc.RetryInfo detail: `push("rate_limit", retry_info=0.5)` sends only that, `retry_after=0.5`
also a Retry-After header.
"""

from __future__ import annotations

import json
import re
import uuid
from typing import Any

from ._server import FakeServer, RecordedRequest
from .prompt_cache import Segment, text_tokens

_ROUTE = re.compile(r"^/v1(?:beta|alpha)?/models/([^/:]+):generateContent$")
_STATUS = {400: "INVALID_ARGUMENT", 401: "UNAUTHENTICATED", 403: "PERMISSION_DENIED", 404: "NOT_FOUND",
           408: "DEADLINE_EXCEEDED", 409: "ABORTED", 429: "RESOURCE_EXHAUSTED", 500: "INTERNAL",
           502: "UNAVAILABLE", 503: "UNAVAILABLE", 504: "DEADLINE_EXCEEDED"}


class FakeGemini(FakeServer):
    provider = "gemini"

    def _route(self, method: str, path: str) -> str | None:
        m = _ROUTE.match(path) if method == "POST" else None
        return m.group(1) if m else None

    def _parse(self, req: RecordedRequest) -> None:
        body = req.json
        system = body.get("systemInstruction") or body.get("system_instruction") or {}
        req.system = "".join(p.get("text", "") for p in system.get("parts", []) if isinstance(p, dict))
        for content in body.get("contents") or []:
            for part in content.get("parts") or []:
                if "text" in part:
                    req.texts.append(part["text"])
                    req.parts.append("text")
                inline = part.get("inlineData") or part.get("inline_data")
                if inline:
                    req.image_media_types.append(inline.get("mimeType") or inline.get("mime_type") or "")
                    req.images.append(self._b64(inline.get("data", "")))
                    req.parts.append("image")
        config = body.get("generationConfig") or body.get("generation_config") or {}
        req.schema = config.get("responseJsonSchema") or config.get("response_json_schema") \
            or config.get("responseSchema") or config.get("response_schema")

    def _cache_segments(self, req: RecordedRequest) -> list[Segment]:
        """Implicit caching: the system instruction and the generation config, then the contents' parts."""
        body = req.json or {}
        head = json.dumps({k: body.get(k) for k in ("systemInstruction", "generationConfig", "tools")}, sort_keys=True)
        out = [Segment(head, text_tokens(req.system))]
        for content in body.get("contents") or []:
            for part in content.get("parts") or []:
                text = part.get("text")
                out.append(Segment(text, text_tokens(text)) if text is not None else
                           Segment(json.dumps(part, sort_keys=True), 85))
        return out

    def _answer(self, req: RecordedRequest, action: Any) -> tuple[int, Any, dict]:
        status, body, headers = super()._answer(req, action)
        params = action.params if action is not None else {}
        delay = params.get("retry_info", params.get("retry_after"))
        if status == 429 and isinstance(body, dict) and delay is not None:
            body["error"].setdefault("details", []).append({
                "@type": "type.googleapis.com/google.rpc.RetryInfo", "retryDelay": f"{float(delay):g}s"})
        return status, body, headers

    def _response(self, req: RecordedRequest, text: str | None, *, finish: str = "STOP",
                  prompt_block: str | None = None) -> dict:
        inp, cached, out = self._usage_counts(req, text or "")
        usage = {"promptTokenCount": inp, "candidatesTokenCount": out if text else 0,
                 "totalTokenCount": inp + (out if text else 0), "thoughtsTokenCount": 0}
        if cached:
            usage["cachedContentTokenCount"] = cached
        body: dict[str, Any] = {"usageMetadata": usage, "modelVersion": req.model or "gemini-2.5-flash",
                                "responseId": uuid.uuid4().hex[:20]}
        if prompt_block:
            body["promptFeedback"] = {"blockReason": prompt_block}
            return body
        candidate: dict[str, Any] = {"finishReason": finish, "index": 0}
        if text is not None:
            candidate["content"] = {"parts": [{"text": text}], "role": "model"}
        if finish == "SAFETY":
            candidate["safetyRatings"] = [{"category": "HARM_CATEGORY_DANGEROUS_CONTENT", "probability": "HIGH",
                                           "blocked": True}]
        body["candidates"] = [candidate]
        return body

    def _success(self, req: RecordedRequest, text: str, *, data: dict | None = None) -> dict:
        return self._response(req, text)

    def _error_body(self, status: int, message: str, code: str) -> dict:
        return {"error": {"code": status, "message": message,
                          "status": _STATUS.get(status, "INTERNAL" if status >= 500 else "FAILED_PRECONDITION")}}

    def _special(self, req: RecordedRequest, kind: str, params: dict) -> tuple[int, dict]:
        if kind == "refusal":
            return 200, self._response(req, None, prompt_block=params.get("block_reason", "PROHIBITED_CONTENT"))
        if kind == "truncated":
            return 200, self._response(req, '{"room": "kitchen", "movement": "A1", "sta', finish="MAX_TOKENS")
        if kind == "content_filter":
            return 200, self._response(req, None, finish="SAFETY")
        if kind == "bad_key":
            body = self._error_body(400, "API key not valid. Please pass a valid API key.", "")
            body["error"]["details"] = [{"@type": "type.googleapis.com/google.rpc.ErrorInfo",
                                         "reason": "API_KEY_INVALID", "domain": "googleapis.com"}]
            return 400, body
        if kind == "reject_schema":
            return 400, self._error_body(400, "Invalid JSON payload: unknown name responseJsonSchema", "")
        raise ValueError(kind)
