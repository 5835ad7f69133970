"""The remote pilot: asks our own pilot server (`vln-pilot serve`) over HTTP, `POST {url}/v1/decide`.

`remote` uses the server's default pilot; `remote:gemini:gemini-2.5-flash` asks the server for that pilot.
The server already retried the provider, so a structured provider error (502/503 with a `reason`) is
raised as the same PilotError at once; only transport failures and bare 408/409/429/5xx (a proxy, a
restarting server) are retried here, honouring Retry-After.
"""

from __future__ import annotations

import base64
import os
import time
from typing import Any, ClassVar

import httpx
from pydantic import Field, SecretStr

from vlnpilot.core.decision import Decision, EarlierTurn, PilotInput, PilotTraits, Usage
from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots._gate import CallCancelled, CallGate
from vlnpilot.pilots._history import Conversation
from vlnpilot.pilots.attempts import AttemptLog, event_hooks
from vlnpilot.pilots.base import BasePilot, PilotError, register_pilot
from vlnpilot.pilots.model import REPLY_REASONS, PilotReplyError
from vlnpilot.pilots.options import ConversationOptions, secret_value
from vlnpilot.pilots.secrets import redact
from vlnpilot.pilots.transport import (
    call_with_retries,
    connection_error,
    is_retryable_status,
    parse_retry_after,
    status_error,
    timeout_error,
)

URL_ENV = "VLN_PILOT_URL"
TOKEN_ENV = "VLN_PILOT_TOKEN"
DEFAULT_URL = "http://127.0.0.1:8000"


class _Retryable(Exception):
    def __init__(self, response: httpx.Response):
        super().__init__(f"HTTP {response.status_code}")
        self.response = response


class RemoteOptions(ConversationOptions):
    """The options of the remote pilot. `transport` is programmatic (an httpx transport, for tests). `history` and
    `history_images` are the model pilots' conversation memory: this pilot keeps it and sends it with each request
    (the server is stateless and shared)."""

    programmatic: ClassVar[frozenset[str]] = frozenset({"transport"})

    model: str | None = None  # the server-side pilot SPEC, e.g. "openai:gpt-4.1"; None: the server's default
    url: str | None = None  # default: env VLN_PILOT_URL, else DEFAULT_URL
    token: SecretStr | None = Field(None, repr=False)  # default: env VLN_PILOT_TOKEN
    # The server's own provider call may take its timeout (30 s) times its retries: wait longer than that.
    timeout: float = Field(90.0, gt=0)  # seconds per HTTP call
    max_retries: int = Field(2, ge=0)
    retry_base_delay: float = 0.5
    jpeg_quality: int = Field(85, ge=1, le=100)
    max_side: int | None = None
    transport: httpx.BaseTransport | None = Field(None, repr=False)


@register_pilot("remote", options=RemoteOptions)
class RemotePilot(BasePilot):
    """A pilot that lives on a pilot server.

    Options (`RemoteOptions`): model (the server-side pilot SPEC, e.g. "openai:gpt-4.1"; default: the server's),
    url (default env VLN_PILOT_URL or http://127.0.0.1:8000), token (default env VLN_PILOT_TOKEN),
    timeout (seconds per HTTP call, default 90), max_retries (default 2), retry_base_delay,
    jpeg_quality, max_side, history and history_images (conversation memory, sent with each request), transport
    (an httpx transport, for tests).
    """

    traits = PilotTraits(uses_step_deadline=True)  # waits on a network: the controller bounds each step

    name = "remote"

    def __init__(self, model: str | None = None, **options: Any):
        o = RemoteOptions.build(self.name, model=model, **options)
        self.model = o.model
        self.url = (o.url or os.environ.get(URL_ENV) or DEFAULT_URL).rstrip("/")
        if not self.url.startswith(("http://", "https://")):
            raise ConfigError(f"the pilot server URL must start with http:// or https://, got {self.url!r}")
        self.timeout = o.timeout
        self.max_retries = o.max_retries
        self.retry_base_delay = o.retry_base_delay
        self.jpeg_quality = o.jpeg_quality
        self.max_side = o.max_side
        self.conversation = Conversation(o.history, o.history_images)
        self.memory = self.conversation.label
        token = secret_value(o.token) or os.environ.get(TOKEN_ENV) or None
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self._gate = CallGate()  # abandoned calls send nothing more (see cancel_pending)
        self._attempts = AttemptLog()  # every HTTP attempt of a call, retries included
        self._client = httpx.Client(base_url=self.url, timeout=self.timeout, headers=headers, transport=o.transport,
                                    event_hooks=event_hooks(self._gate.on_request, self._attempts))

    def __repr__(self) -> str:
        return f"RemotePilot(url={self.url!r}, model={self.model!r})"

    def cancel_pending(self) -> None:
        """Abandon the calls in flight: none of them sends another request (retries included)."""
        self._gate.cancel()

    def abandoned_attempts(self) -> tuple[dict[str, Any], ...]:
        """The HTTP attempts of the call the controller just abandoned (episode/ask.Deadline records them)."""
        return self._attempts.abandoned()

    def close(self) -> None:
        self.cancel_pending()
        self._client.close()

    def _payload(self, pilot_input: PilotInput) -> dict[str, Any]:
        from vlnpilot.prompting.render import encode_jpeg

        jpeg = encode_jpeg(pilot_input.image, self.jpeg_quality, self.max_side)
        payload: dict[str, Any] = {
            "image": base64.b64encode(jpeg).decode("ascii"),
            "query": pilot_input.query,
            "topological_map": pilot_input.topological_map,
            "state": str(pilot_input.state),
            "previous_movement": pilot_input.previous_movement,
            "profile": pilot_input.profile,
            "feedback": list(pilot_input.feedback),
            "context": list(pilot_input.context),
            "step": pilot_input.step,
        }
        if pilot_input.in_state is not None:
            payload["in_state"] = pilot_input.in_state
        if self.conversation.turns:
            payload["history"] = [self._turn(t) for t in self.conversation.earlier(pilot_input)]
        if self.model:
            payload["pilot"] = self.model
        if pilot_input.mission is not None:  # a mission of several stages: the server's prompt shows the plan
            payload.update(mission=dict(pilot_input.mission), stage=pilot_input.stage)
        return payload

    def _turn(self, turn: EarlierTurn) -> dict[str, Any]:
        from vlnpilot.prompting.render import encode_jpeg

        image = (None if turn.image is None else
                 base64.b64encode(encode_jpeg(turn.image, self.jpeg_quality, self.max_side)).decode("ascii"))
        return {"step": turn.step, "state": str(turn.state), "previous_movement": turn.previous_movement,
                "answer": turn.answer, "image": image, "feedback": list(turn.feedback), "context": list(turn.context),
                "in_state": turn.in_state}

    def _post(self, payload: dict[str, Any]) -> httpx.Response:
        response = self._client.post("/v1/decide", json=payload)
        if is_retryable_status(response.status_code) and not _structured(response):
            raise _Retryable(response)
        return response

    def _classify(self, exc: BaseException) -> tuple[bool, float | None]:
        if isinstance(exc, _Retryable):
            return True, parse_retry_after(exc.response.headers)
        return isinstance(exc, httpx.TransportError), None

    def decide(self, pilot_input: PilotInput) -> Decision:
        payload = self._payload(pilot_input)
        self._gate.enter()
        self._attempts.begin()
        try:
            decision = self._decide(pilot_input, payload)
        except PilotError as exc:  # with its attempts, as a model pilot's failure
            usage = getattr(exc, "usage", None) or Usage()
            exc.usage = usage.model_copy(update={"attempts": self._attempts.end(exc.reason)})  # type: ignore[attr-defined]
            raise
        return decision.model_copy(update={"usage": decision.usage.model_copy(update={
            "attempts": self._attempts.end()})})

    def _decide(self, pilot_input: PilotInput, payload: dict[str, Any]) -> Decision:
        t0 = time.perf_counter()
        try:
            response = call_with_retries(lambda: self._post(payload), classify=self._classify,
                                         max_retries=self.max_retries, base_delay=self.retry_base_delay,
                                         what=f"pilot server {self.url}")
        except _Retryable as exc:
            response = exc.response
        except httpx.TimeoutException:
            raise timeout_error(f"pilot server at {self.url}", self.timeout) from None
        except httpx.TransportError as exc:
            raise connection_error("pilot server", self.url, exc) from None
        except CallCancelled as exc:
            raise PilotError(str(exc), reason="cancelled") from None
        latency = time.perf_counter() - t0
        if response.status_code == 200:
            try:
                decision = Decision.model_validate(response.json())
            except ValueError as exc:
                raise PilotError(f"the pilot server at {self.url} sent a malformed decision: {redact(exc)[:300]}",
                                 reason="bad_response") from None
            self.conversation.remember(pilot_input, decision.raw_text)
            return decision.model_copy(update={"usage": decision.usage.model_copy(update={"latency_s": round(
                latency, 4)})})
        raise self._error(response)

    def plan(self, prompt: Any) -> tuple[str, Usage]:
        """The planning call (pilots/planning.py), `POST {url}/v1/plan`: the server's pilot plans."""
        payload = {"system": prompt.system, "context": prompt.context, "step_text": prompt.step_text,
                   "schema": prompt.schema, **({"pilot": self.model} if self.model else {})}
        try:
            response = self._client.post("/v1/plan", json=payload)
        except httpx.TimeoutException:
            raise timeout_error(f"pilot server at {self.url}", self.timeout) from None
        except httpx.TransportError as exc:
            raise connection_error("pilot server", self.url, exc) from None
        if response.status_code != 200:
            raise self._error(response)
        body = _json(response) or {}
        return str(body.get("raw_text", "")), Usage.model_validate(body.get("usage") or {})

    def _error(self, response: httpx.Response) -> PilotError:
        status = response.status_code
        body = _json(response)
        detail = str(body.get("detail", "")) if body else response.text[:300]
        reason = str(body.get("reason", "")) if body else ""
        if status == 401:
            return PilotError(f"the pilot server at {self.url} rejected the token (401): check {TOKEN_ENV}",
                              fatal=True, reason="auth")
        if status == 413:
            return PilotError(f"the pilot server at {self.url} refused the request as too large (413): {detail}",
                              fatal=True, reason="too_large")
        if status == 422:
            return PilotError(f"the pilot server at {self.url} rejected the request (422): {detail}",
                              fatal=True, reason=reason or "bad_request")
        if body and reason:
            if reason in REPLY_REASONS:
                usage = body.get("usage")
                return PilotReplyError(detail, reason=reason, raw_text=body.get("raw_text"),
                                       usage=Usage.model_validate(usage) if isinstance(usage, dict) else None)
            return PilotError(detail, fatal=bool(body.get("fatal", False)), reason=reason)
        return status_error(f"pilot server at {self.url}", status, detail, key_env=TOKEN_ENV, model=self.model)


def _json(response: httpx.Response) -> dict[str, Any] | None:
    try:
        body = response.json()
    except ValueError:
        return None
    return body if isinstance(body, dict) else None


def _structured(response: httpx.Response) -> bool:
    """Our server's ErrorBody (the pilot behind it already retried): do not retry it again."""
    body = _json(response)
    return bool(body and "reason" in body and "detail" in body)
