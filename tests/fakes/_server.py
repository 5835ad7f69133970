"""A scriptable fake model server: a real HTTP server on 127.0.0.1 that records every request.

Each provider fake (see openai_fake.py, gemini_fake.py, anthropic_fake.py) speaks that provider's wire
protocol, so the official SDKs are exercised for real. A fake answers, in this order of precedence:

1. the next scripted action (`fake.push("rate_limit", retry_after=0.05)`, `fake.push("decision", decision={...})`),
2. the `oracle` callback (`oracle(request) -> dict | str`: a decision dict, or raw reply text),
3. `fake.decision` if set, else `auto_decision(request)`: the first allowed value of each enum in the request's schema.

Actions: decision, text, prose, not_json, missing_field, wrong_enum, refusal, truncated, content_filter,
rate_limit, server_error, status, bad_key, hang, bad_body, reject_schema (OpenAI: 400 on json_schema).
`delay` (seconds) is slept before every normal answer; the server is threaded, so concurrent clients overlap;
`rendezvous=N` makes normal answers wait until N requests are in flight together. Each answer reports the cached
tokens of its provider's prompt cache (`prompt_cache.py`: a prefix seen in the last five minutes; `fake.prompt_cache
.clock` may be injected), or `cached_tokens=N` as a fixed count.
"""

from __future__ import annotations

import base64
import json
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

from .limits import Usage, Windows
from .prompt_cache import PromptCache, Segment

Oracle = Any  # Callable[[RecordedRequest], dict | str]

ACTIONS = frozenset({
    "decision", "text", "prose", "not_json", "missing_field", "wrong_enum", "refusal", "truncated",
    "content_filter", "rate_limit", "server_error", "status", "bad_key", "hang", "bad_body", "reject_schema",
})


@dataclass
class RecordedRequest:
    """One request the fake received, parsed into what tests and oracles care about."""

    method: str
    path: str
    query: dict[str, list[str]]
    headers: dict[str, str]  # lower-case names
    body: bytes
    json: Any
    model: str | None = None
    system: str = ""
    texts: list[str] = field(default_factory=list)  # user text parts, in order
    images: list[bytes] = field(default_factory=list)  # decoded image bytes, in order
    image_media_types: list[str] = field(default_factory=list)
    schema: dict | None = None  # the answer schema the client asked for (None in plain JSON mode)
    parts: list[str] = field(default_factory=list)  # kinds of the user parts in order: "text" / "image"
    cached_tokens: int = 0  # what the answer reported as read from the prompt cache
    cache_written: int = 0  # and as written to it (Anthropic)

    @property
    def text(self) -> str:
        return "\n".join(self.texts)

    def enum(self, name: str) -> list[str] | None:
        """The allowed values of an answer field, from the request's schema."""
        if not self.schema:
            return None
        prop = (self.schema.get("properties") or {}).get(name) or {}
        values = prop.get("enum")
        return list(values) if values else None

    @property
    def allowed_movements(self) -> list[str] | None:
        return self.enum("movement")

    @property
    def allowed_states(self) -> list[str] | None:
        return self.enum("state")

    @property
    def current_state(self) -> str | None:
        """The FSM state the prompt says the drone is in ('## Current FSM state' section of the step text)."""
        m = re.search(r"## Current FSM state\s*\n\s*(.+)", self.text)
        return m.group(1).strip() if m else None


def auto_decision(request: RecordedRequest | None = None) -> dict[str, str]:
    """A valid answer to any request: the first allowed value of each enum of its schema (without a schema,
    e.g. in JSON mode, the first allowed move and next state of the prompt's current FSM state)."""
    moves: list[str] | None = None
    states: list[str] | None = None
    if request is not None:
        moves, states = request.allowed_movements, request.allowed_states
        if (moves is None or states is None) and request.current_state:
            from vlnpilot.core.fsm import state_spec

            try:
                spec = state_spec(request.current_state)
                moves = moves or list(spec.moves)
                states = states or [s.value for s in spec.next_states]
            except Exception:  # noqa: BLE001 - unknown state: keep the defaults
                pass
    rooms = request.enum("room") if request is not None else None
    doors = request.enum("door_position") if request is not None else None
    return {
        "room": next((r for r in rooms if r != "unknown"), "unknown") if rooms else "unknown",
        "movement": moves[0] if moves else "A1",
        "state": states[0] if states else "Recognize Room",
        "description": "a fake view of a room",
        "door_position": doors[0] if doors else "not_visible",
    }


@dataclass
class Action:
    kind: str
    params: dict[str, Any]


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    disable_nagle_algorithm = True  # headers and body go out as separate writes: avoid 40 ms delayed-ACK stalls
    server: _HTTPServer

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - keep test output quiet
        pass

    def _reply(self, status: int, body: bytes, headers: dict[str, str] | None = None,
               content_type: str = "application/json") -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        for k, v in (headers or {}).items():
            self.send_header(k, v)
        self.end_headers()
        try:
            self.wfile.write(body)
            self.wfile.flush()
        except (BrokenPipeError, ConnectionResetError):
            self.close_connection = True

    def do_GET(self) -> None:  # noqa: N802
        self.server.fake._not_found(self)

    def do_POST(self) -> None:  # noqa: N802
        length = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(length) if length else b""
        try:
            self.server.fake._handle(self, body)
        except (BrokenPipeError, ConnectionResetError):
            self.close_connection = True


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    request_queue_size = 128
    allow_reuse_address = True
    fake: FakeServer


class FakeServer:
    """Base of the provider fakes. Use as a context manager, or call start()/stop()."""

    provider = "fake"

    def __init__(self, *, decision: dict | None = None, oracle: Oracle | None = None, delay: float = 0.0,
                 cached_tokens: int = 0, host: str = "127.0.0.1", port: int = 0, rendezvous: int = 0):
        self.decision = decision
        self.oracle = oracle
        self.delay = delay
        # With rendezvous=N, normal answers wait until N requests are in flight at once (a 500 after 10 s
        # otherwise): a test of concurrent clients then needs no wall-clock bound.
        self._rendezvous = threading.Barrier(rendezvous) if rendezvous else None
        self.cached_tokens = cached_tokens  # a fixed count (the older tests); 0: the prompt cache decides
        self.prompt_cache = self._prompt_cache()  # tests may set its clock
        self.requests: list[RecordedRequest] = []
        self._script: deque[Action] = deque()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._host, self._port = host, port
        self._windows: Windows | None = None
        self.throttled = 0  # requests answered 429 by the rate limit (`limit`)
        self._httpd: _HTTPServer | None = None
        self._thread: threading.Thread | None = None

    # ---------------------------------------------------------------- lifecycle
    def start(self) -> FakeServer:
        if self._httpd is not None:
            return self
        self._stop.clear()
        self._httpd = _HTTPServer((self._host, self._port), _Handler)
        self._httpd.fake = self
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.02},
                                        name=f"fake-{self.provider}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()  # releases hanging handlers
        if self._httpd is not None:
            self._httpd.shutdown()
            self._httpd.server_close()
            self._httpd = None
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None

    def __enter__(self) -> FakeServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def port(self) -> int:
        assert self._httpd is not None, "start the fake first"
        return self._httpd.server_address[1]

    @property
    def url(self) -> str:
        """Root URL of the server, e.g. http://127.0.0.1:54321."""
        return f"http://127.0.0.1:{self.port}"

    @property
    def base_url(self) -> str:
        """The URL to give the provider's SDK as base_url."""
        return self.url

    # ---------------------------------------------------------------- scripting
    def push(self, kind: str, times: int = 1, **params: Any) -> FakeServer:
        """Queue `times` copies of an action for the next requests (FIFO)."""
        if kind not in ACTIONS:
            raise ValueError(f"unknown fake action {kind!r}; known: {', '.join(sorted(ACTIONS))}")
        with self._lock:
            for _ in range(times):
                self._script.append(Action(kind, dict(params)))
        return self

    def limit(self, rpm: int | None = None, tpm: int | None = None,
              clock: Callable[[], float] = time.monotonic) -> FakeServer:
        """Enforce requests and tokens per minute as the provider does: its headers on every answer, its 429
        body beyond the limit (a request's tokens: its input's, as `_usage_counts` counts them)."""
        self._windows = Windows(rpm, tpm, clock)
        return self

    def _limit_headers(self, usage: Usage) -> dict[str, str]:
        """The provider's rate-limit headers (none by default: Gemini sends none)."""
        return {}

    def _limit_error(self, usage: Usage) -> tuple[str, str]:
        """The provider's 429 message and code."""
        return "Resource has been exhausted (e.g. check quota).", "rate_limit_exceeded"

    def reset(self) -> None:
        with self._lock:
            self._script.clear()
            self.requests.clear()

    @property
    def pending(self) -> int:
        with self._lock:
            return len(self._script)

    @property
    def last(self) -> RecordedRequest:
        return self.requests[-1]

    # ---------------------------------------------------------------- provider hooks
    def _route(self, method: str, path: str) -> str | None:
        """The model named by the path if the route is this provider's, else None."""
        raise NotImplementedError

    def _parse(self, req: RecordedRequest) -> None:
        """Fill system/texts/images/schema/model from req.json."""
        raise NotImplementedError

    def _success(self, req: RecordedRequest, text: str, *, data: dict | None = None) -> dict:
        raise NotImplementedError

    def _error_body(self, status: int, message: str, code: str) -> dict:
        raise NotImplementedError

    def _special(self, req: RecordedRequest, kind: str, params: dict) -> tuple[int, dict]:
        """refusal / truncated / content_filter / bad_key / reject_schema in the provider's shape."""
        raise NotImplementedError

    def _prompt_cache(self) -> PromptCache:
        """The provider's prompt cache (OpenAI's by default)."""
        return PromptCache()

    def _cache_segments(self, req: RecordedRequest) -> list[Segment]:
        """The request's segments in the order the provider caches them (none: nothing is ever cached)."""
        return []

    # ---------------------------------------------------------------- helpers for the hooks
    def _input_tokens(self, req: RecordedRequest) -> int:
        return max(1, sum(len(t) for t in [req.system, *req.texts]) // 4) + 85 * len(req.images)

    def _usage_counts(self, req: RecordedRequest, text: str) -> tuple[int, int, int]:
        """(input, cached, output) tokens of an answer; the cache writes go to `req.cache_written`. Call once an
        answer: it serves the request from the prompt cache, and remembers its prefixes."""
        inp = self._input_tokens(req)
        if self.cached_tokens:
            read, written = self.cached_tokens, 0
        else:
            read, written = self.prompt_cache.serve(self._cache_segments(req))
        req.cached_tokens = min(read, inp)
        req.cache_written = min(written, inp - req.cached_tokens)
        return inp, req.cached_tokens, max(1, len(text) // 4)

    @staticmethod
    def _b64(data: str) -> bytes:
        data = data.strip().replace("-", "+").replace("_", "/")  # Google sends URL-safe base64
        try:
            return base64.b64decode(data + "=" * (-len(data) % 4), validate=False)
        except (ValueError, TypeError):
            return b""

    # ---------------------------------------------------------------- dispatch
    def _not_found(self, h: _Handler) -> None:
        body = json.dumps(self._error_body(404, f"no route {h.command} {h.path}", "not_found")).encode()
        h._reply(404, body)

    def _handle(self, h: _Handler, body: bytes) -> None:
        split = urlsplit(h.path)
        model = self._route(h.command, split.path)
        if model is None:
            self._not_found(h)
            return
        try:
            data = json.loads(body) if body else None
        except ValueError:
            data = None
        req = RecordedRequest(method=h.command, path=split.path, query=parse_qs(split.query),
                              headers={k.lower(): v for k, v in h.headers.items()}, body=body, json=data,
                              model=model or None)
        if isinstance(data, dict):
            try:
                self._parse(req)
            except Exception as exc:  # noqa: BLE001 - a fake must answer, not crash
                req.texts.append(f"<fake could not parse the request: {exc}>")
        with self._lock:
            self.requests.append(req)
            action = self._script.popleft() if self._script else None
        if data is None:
            h._reply(400, json.dumps(self._error_body(400, "request body is not JSON", "invalid_request")).encode())
            return
        usage = self._windows.admit(self._input_tokens(req)) if self._windows is not None else None
        if usage is not None and usage.refused:
            with self._lock:
                self.throttled += 1
            message, code = self._limit_error(usage)
            headers = {**self._limit_headers(usage), "retry-after": f"{max(1, round(usage.reset_requests_s))}"}
            h._reply(429, json.dumps(self._error_body(429, message, code)).encode(), headers)
            return
        status, payload, headers = self._answer(req, action)
        if usage is not None:
            headers = {**self._limit_headers(usage), **headers}
        if payload is None:  # hang: the client gave up; close without answering
            h.close_connection = True
            return
        raw = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        h._reply(status, raw, headers)

    def _answer(self, req: RecordedRequest, action: Action | None) -> tuple[int, dict | bytes | None, dict]:
        kind, p = (action.kind, action.params) if action else ("default", {})
        headers: dict[str, str] = {}
        if kind == "hang":
            self._stop.wait(p.get("seconds", 30.0))
            return 0, None, headers
        if kind in ("rate_limit", "server_error", "status"):
            status = {"rate_limit": 429, "server_error": 500}.get(kind) or int(p["status_code"])
            status = int(p.get("status_code", status))
            if "retry_after" in p:
                headers["Retry-After"] = str(p["retry_after"])
            if "retry_after_ms" in p:
                headers["retry-after-ms"] = str(p["retry_after_ms"])
            message = p.get("message", {429: "Rate limit reached, slow down", 500: "internal error"}.get(
                status, f"error {status}"))
            code = p.get("code", {429: "rate_limit_exceeded"}.get(status, "server_error" if status >= 500 else
                                                                      "invalid_request"))
            return status, self._error_body(status, message, code), headers
        if kind in ("refusal", "truncated", "content_filter", "bad_key", "reject_schema"):
            status, body = self._special(req, kind, p)
            return status, body, headers
        if kind == "bad_body":
            return 200, b'{"id": "broken", "choices": [ this is not json', headers
        if self._rendezvous is not None:
            try:
                self._rendezvous.wait(timeout=10)
            except threading.BrokenBarrierError:
                return 500, self._error_body(500, "the requests never overlapped", "server_error"), headers
        if self.delay > 0 or p.get("delay"):
            time.sleep(p.get("delay", self.delay))
        if kind == "text":
            return 200, self._success(req, p["text"]), headers
        if kind == "not_json":
            return 200, self._success(req, p.get("text", "I would turn left a little, then look for the door.")), \
                headers
        decision = dict(p["decision"]) if kind == "decision" else None
        if decision is None and kind == "default" and self.oracle is not None:
            out = self.oracle(req)
            if isinstance(out, str):
                return 200, self._success(req, out), headers
            decision = dict(out)
        if decision is None:
            decision = dict(self.decision) if self.decision is not None else auto_decision(req)
        if kind == "wrong_enum":
            decision.update(p.get("fields", {"movement": "Z9"}))
        if kind == "missing_field":
            decision.pop(p.get("field", "state"), None)
        text = json.dumps(decision)
        if kind == "prose":
            text = f"Sure! Here is my decision:\n{text}\nLet me know if you need anything else."
        return 200, self._success(req, text, data=decision if kind != "prose" else None), headers
