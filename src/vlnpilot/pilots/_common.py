"""What the model pilots share: API keys, error mapping, retries, and turning a reply into a Decision.

Each provider module only speaks its SDK: it sends the Prompt and hands back a `Reply` (text or
parsed tool input, normalised stop reason, token counts). Everything after that (refusals,
truncation, parsing, validation, usage and cost) happens here, once, so that the pilots fail alike.
"""

from __future__ import annotations

import email.utils
import logging
import math
import os
import random
import re
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal, TypedDict, TypeVar

from vlnpilot.core.decision import (
    DECISION_ERROR_CODES,
    INVALID_ENUM,
    MAX_REPLY_CHARS,
    TOO_LONG,
    Decision,
    DecisionError,
    PilotInput,
    PilotTraits,
    Usage,
    normalize_decision,
    parse_decision,
    validate_decision,
)
from vlnpilot.pilots import pricing
from vlnpilot.pilots._gate import CallGate
from vlnpilot.pilots._history import Conversation, Message, messages
from vlnpilot.pilots.attempts import AttemptLog, event_hooks
from vlnpilot.pilots.base import BasePilot, PilotError
from vlnpilot.pilots.options import ModelOptions

log = logging.getLogger(__name__)
_UNPRICED_WARNED: set[tuple[str, str]] = set()
T = TypeVar("T")

# Reasons of PilotError that mean "the provider is (temporarily) not answering": the server maps
# them to 503, everything else to 502.
TRANSIENT_REASONS = frozenset({"rate_limited", "unavailable", "timeout", "connection_error"})
# Reasons of a reply that arrived but cannot be used; the controller re-asks (at most twice).
REPLY_REASONS = frozenset({"refusal", "content_filter", "truncated", "empty", *DECISION_ERROR_CODES})
# The provider says the model is unknown or gone (OpenAI 404 model_not_found, Gemini 404 "is not found",
# a 400/410 for a shut-down model): said in one line with the current models of the price table.
_MODEL_GONE = re.compile(r"model_not_found|does not exist|not found|no longer (available|supported)|deprecated|"
                         r"retired|shut ?down|decommissioned|discontinued")
_MODEL_FAMILIES = ("gpt-", "gemini-", "claude-")

DEFAULT_MAX_RETRIES = 2  # of call_with_retries (the pilots take theirs from their options)
MAX_RETRY_AFTER_S = 60.0  # a server asking for a longer wait is not retried: the step would stall


class PilotReplyError(PilotError):
    """A reply arrived but is unusable (refusal, truncated, not JSON, wrong enum...). Never fatal.

    Carries the raw text and the usage of the call, so that the controller can log the reply and
    still count the tokens it paid for.
    """

    def __init__(self, message: str, *, reason: str, raw_text: str | None = None, usage: Usage | None = None,
                 feedback: str | None = None):
        super().__init__(message, fatal=False, reason=reason)
        self.raw_text = raw_text
        self.usage = usage or Usage()
        self.feedback = feedback or message  # one line for the model on a re-ask


# ---------------------------------------------------------------- secrets

_KEY_PATTERNS = re.compile(
    r"(sk-ant-[A-Za-z0-9_\-]{6,}|sk-[A-Za-z0-9_\-]{6,}|AIza[0-9A-Za-z_\-]{20,}|(?<=Bearer )[A-Za-z0-9._\-]{8,})"
)


def redact(text: object, *secrets: str | None) -> str:
    """`text` with the given secrets and anything shaped like an API key replaced by '***'."""
    out = str(text)
    for secret in secrets:
        if secret and len(secret) >= 4:
            out = out.replace(secret, "***")
    return _KEY_PATTERNS.sub("***", out)


class Secret:
    """Holds an API key so that repr(), str() and logs of the holder never show it."""

    __slots__ = ("value",)

    def __init__(self, value: str | None):
        self.value = value

    def __repr__(self) -> str:
        return "Secret('***')"

    __str__ = __repr__


_E = TypeVar("_E", bound=BaseException)


def scrub(exc: _E, *secrets: str | None) -> _E:
    """Remove secrets from an exception's message in place (a provider may echo the key back)."""
    if exc.args and any(s and len(s) >= 4 and s in str(a) for s in secrets for a in exc.args):
        exc.args = tuple(redact(a, *secrets) if isinstance(a, str) else a for a in exc.args)
    return exc


def resolve_api_key(
    api_key: str | None, env_vars: Iterable[str], provider: str, *, optional: bool = False
) -> str | None:
    """The explicit key, else the first env var that is set; a missing key is fatal and names the env vars."""
    if api_key:
        return api_key
    env_vars = tuple(env_vars)
    for var in env_vars:
        value = os.environ.get(var, "").strip()
        if value:
            return value
    if optional:
        return None
    raise PilotError(
        f"no {provider} API key: set {' or '.join(env_vars)} (or pass the api_key option)",
        fatal=True, reason="missing_key",
    )


# ---------------------------------------------------------------- HTTP errors and retries

def parse_retry_after(headers: Mapping[str, str] | Any | None) -> float | None:
    """Seconds to wait from `retry-after-ms` or `Retry-After` (seconds or an HTTP date), or None."""
    if headers is None:
        return None
    get = getattr(headers, "get", None)
    if get is None:
        return None
    for name, divisor in (("retry-after-ms", 1000.0), ("retry-after", 1.0)):
        value = get(name)
        if value is None:
            continue
        try:
            seconds = float(value) / divisor
        except (TypeError, ValueError):
            if divisor == 1000.0:
                continue
            try:
                parsed = email.utils.parsedate_to_datetime(str(value))
            except (TypeError, ValueError, IndexError):
                continue
            seconds = parsed.timestamp() - time.time()
        if math.isfinite(seconds):
            return max(0.0, seconds)
    return None


def is_retryable_status(status: int) -> bool:
    return status in (408, 409, 429) or status >= 500


def backoff_delay(attempt: int, base_delay: float = 0.5, max_delay: float = 8.0) -> float:
    """Capped exponential backoff with up to 25% jitter (attempt 0 is the first retry)."""
    return min(base_delay * (2.0 ** attempt), max_delay) * (1.0 - 0.25 * random.random())


def call_with_retries(
    fn: Callable[[], T],
    *,
    classify: Callable[[BaseException], tuple[bool, float | None]],
    max_retries: int = DEFAULT_MAX_RETRIES,
    base_delay: float = 0.5,
    max_delay: float = 8.0,
    what: str = "request",
    sleep: Callable[[float], None] | None = None,
) -> T:
    """Call `fn`, retrying up to `max_retries` times when `classify(exc)` says (retry, retry_after_s).

    A server-given Retry-After is honoured (up to MAX_RETRY_AFTER_S; longer means no retry),
    otherwise the delay is capped exponential backoff. `sleep` defaults to `time.sleep` looked up at each wait,
    so that a test can stand in for it as it does for the SDKs' own retry waits.
    """
    attempt = 0
    while True:
        try:
            return fn()
        except Exception as exc:
            retry, retry_after = classify(exc)
            if not retry or attempt >= max_retries:
                raise
            if retry_after is not None:
                if retry_after > MAX_RETRY_AFTER_S:
                    raise
                delay = retry_after
            else:
                delay = backoff_delay(attempt, base_delay, max_delay)
            attempt += 1
            log.info("%s failed (%s); retry %d/%d in %.2f s", what, type(exc).__name__, attempt, max_retries, delay)
            (sleep or time.sleep)(delay)


def status_error(provider: str, status: int, message: str, *, key_env: str, model: str | None,
                 code: str | None = None) -> PilotError:
    """Map an HTTP error of a provider (after retries) onto a PilotError with a clear message.

    400/401/403/404 and other client errors are fatal (asking again cannot help); 408/409/429 and
    5xx are not (the provider may recover; the controller decides whether to re-ask).
    """
    detail = redact(message).strip()
    if len(detail) > 300:
        detail = detail[:300] + "..."
    suffix = f": {detail}" if detail else ""
    low = f"{message} {code or ''}".lower()
    if status == 401 or "api key not valid" in low or "api_key_invalid" in low or "invalid_api_key" in low:
        return PilotError(f"the {provider} API rejected the key ({status}): check {key_env}", fatal=True, reason="auth")
    if status == 403:
        return PilotError(f"the {provider} API refused access ({status}): the key in {key_env} may lack access to "
                          f"model {model!r}, or the region is not served{suffix}", fatal=True, reason="permission")
    named = model is not None and (model.lower() in low or "model_not_found" in low)  # not another parameter
    if status in (400, 404, 410) and model is not None and named and _MODEL_GONE.search(low):
        return PilotError(f"the {provider} API says model {model!r} is unknown or retired ({status}); "
                          f"{current_models_hint(provider, model)}", fatal=True, reason="model_unavailable")
    if status == 404:
        return PilotError(f"the {provider} API does not know model {model!r} or the endpoint (404){suffix}",
                          fatal=True, reason="not_found")
    if status == 429:
        if "insufficient_quota" in low or "quota" in low and "exceeded your current quota" in low:
            return PilotError(f"the {provider} account is out of quota (429): check billing{suffix}",
                              fatal=True, reason="quota")
        return PilotError(f"the {provider} API is rate limiting (429) and retries did not help{suffix}",
                          reason="rate_limited")
    if status == 408:
        return PilotError(f"the {provider} API timed out the request (408){suffix}", reason="timeout")
    if status == 409 or status >= 500:
        return PilotError(f"the {provider} API is unavailable ({status}) and retries did not help{suffix}",
                          reason="unavailable")
    return PilotError(f"the {provider} API rejected the request ({status}){suffix}", fatal=True, reason="bad_request")


def current_models_hint(provider: str, model: str) -> str:
    """'current models of the price table (DATE): gpt-5, ...', of the model's own family (gpt-, gemini-, claude-)."""
    prefix = next((p for p in _MODEL_FAMILIES if model.lower().startswith(p)), None)
    models = [m for m in pricing.DEFAULT_PRICES if prefix and m.startswith(prefix) and m != model]
    if not models:
        return "pick another model"
    return f"current models in the price table ({pricing.PRICES_AS_OF}): {', '.join(models)}"


def timeout_error(provider: str, timeout_s: float) -> PilotError:
    return PilotError(f"the {provider} API did not answer within {timeout_s:g} s (after retries)", reason="timeout")


def connection_error(provider: str, url: str | None, exc: BaseException) -> PilotError:
    where = f" at {url}" if url else ""
    return PilotError(f"cannot reach the {provider} API{where}: {redact(exc) or type(exc).__name__}",
                      reason="connection_error")


# ---------------------------------------------------------------- replies

StopKind = Literal["stop", "truncated", "refusal", "content_filter"]


@dataclass(frozen=True)
class Reply:
    """A provider's answer, normalised: `text` (JSON hopefully) or `data` (an already-parsed tool input)."""

    text: str | None = None
    data: dict[str, Any] | None = None
    stop: StopKind = "stop"
    stop_detail: str = ""  # the provider's own finish reason or refusal message
    input_tokens: int = 0  # every prompt token, cached ones included
    cached_tokens: int = 0
    output_tokens: int = 0  # thinking tokens included: they are billed as output
    cache_write_tokens: int = 0


class TokenCounts(TypedDict, total=False):
    """A provider's token counts, as the keywords of `Reply` they become."""

    input_tokens: int
    cached_tokens: int
    output_tokens: int
    cache_write_tokens: int


def _int(value: Any) -> int:
    try:
        return max(0, int(value or 0))
    except (TypeError, ValueError):
        return 0


class ModelPilot(BasePilot):
    """Base of the SDK pilots: options, the decide() skeleton, reply checks, usage and cost.

    Subclasses set the class attributes and implement `_call(prompt, chat) -> Reply`, raising PilotError
    on transport/HTTP failures (after the SDK's or our retries).
    """

    model: str  # always named: the options give each provider's default
    provider: str  # a class attribute; the OpenAI pilot names an OpenAI-compatible server per instance
    key_envs: ClassVar[tuple[str, ...]]
    _secret: Secret = Secret(None)  # subclasses keep their key here (the SDK client holds it too)

    def __init__(self, options: ModelOptions):
        """Read the settings every model pilot shares from its validated options (a subclass builds them)."""
        self.options = options
        self.model = options.model
        self.timeout = options.timeout
        self.max_retries = options.max_retries
        self.max_output_tokens = options.max_output_tokens
        self.temperature = options.temperature
        self.jpeg_quality = options.jpeg_quality
        self.max_side = options.max_side
        self.validate = options.validate_replies
        # Conversation memory (pilots/_history.py): 'none', or the last N turns sent again as chat messages.
        self.conversation = Conversation(options.history, options.history_images)
        self.memory = self.conversation.label
        prices = options.prices
        self._prices = pricing.load_prices(prices) if isinstance(prices, Path) else prices
        self._gate = CallGate()  # subclasses hook it into their SDK's HTTP client (see cancel_pending)
        self._attempts = AttemptLog()  # every HTTP attempt of a call, through the same hooks (`_event_hooks`)
        self.price_known = pricing.find_price(self.model, self._prices) is not None
        if not self.price_known and (self.provider, self.model) not in _UNPRICED_WARNED:
            _UNPRICED_WARNED.add((self.provider, self.model))  # once per model and process, not per pilot
            log.warning("no price for %s model %r (prices as of %s): its cost is reported as 0",
                        self.provider, self.model, pricing.PRICES_AS_OF)

    @property
    def traits(self) -> PilotTraits:  # type: ignore[override]
        """It waits on a network; its decisions come back checked against the FSM unless `validate_replies` is off."""
        return PilotTraits(validates_decisions=self.validate, uses_step_deadline=True)

    def __repr__(self) -> str:  # never the key: the SDK client holds it, not us
        return f"{type(self).__name__}(model={self.model!r}, timeout={self.timeout:g})"

    def _event_hooks(self) -> dict[str, list[Callable[[Any], None]]]:
        """The httpx event hooks a subclass gives its SDK client: the call gate, then the attempt log."""
        return event_hooks(self._gate.on_request, self._attempts)

    def cancel_pending(self) -> None:
        """Abandon the calls in flight: no further HTTP request of theirs (SDK retries included) is sent."""
        self._gate.cancel()

    def close(self) -> None:
        """Cancel what is in flight and close the SDK client (its connection pool)."""
        self.cancel_pending()
        close = getattr(getattr(self, "_client", None), "close", None)
        if callable(close):
            close()

    # -- the skeleton
    def decide(self, pilot_input: PilotInput) -> Decision:
        earlier = self.conversation.earlier(pilot_input)
        prompt, chat = messages(pilot_input, earlier, jpeg_quality=self.jpeg_quality, max_side=self.max_side)
        self._start_call()
        t0 = time.perf_counter()
        try:
            reply = self._call(prompt, chat)
        except PilotError as exc:
            raise self._failed(exc) from None
        except Exception as exc:  # an SDK failure our mapping did not foresee: still a PilotError, never a crash
            raise self._failed(self._unexpected(exc)) from None
        usage = self._usage(reply, time.perf_counter() - t0)
        decision = self._decision(reply, usage, pilot_input)
        self.conversation.remember(pilot_input, decision.raw_text)
        return decision

    def complete(self, prompt: Any) -> tuple[str, Usage]:
        """One call with any prompt of `Prompt`'s shape (the planning call, pilots/planning.py): its raw text
        (structured output as JSON) and usage. Errors as `decide`'s; a refusal or an empty reply is a PilotError."""
        import json

        self._start_call()
        t0 = time.perf_counter()
        try:
            reply = self._call(prompt)
        except PilotError as exc:
            raise self._failed(exc) from None
        except Exception as exc:  # as in decide: never a crash
            raise self._failed(self._unexpected(exc)) from None
        usage = self._usage(reply, time.perf_counter() - t0)
        raw = reply.text if reply.data is None else json.dumps(reply.data, ensure_ascii=False)
        if reply.stop in ("refusal", "content_filter", "truncated") or raw is None or not raw.strip():
            raise PilotReplyError(f"the {self.provider} model {self.model!r} gave no usable answer "
                                  f"({reply.stop}: {reply.stop_detail or 'no content'})",
                                  reason=reply.stop if reply.stop != "stop" else "empty",
                                  raw_text=raw, usage=usage)
        return raw, usage

    def abandoned_attempts(self) -> tuple[dict[str, Any], ...]:
        """The HTTP attempts of the call the controller just abandoned (episode/ask.Deadline records them)."""
        return self._attempts.abandoned()

    def _start_call(self) -> None:
        self._gate.enter()
        self._attempts.begin()

    def _failed(self, exc: PilotError) -> PilotError:
        """The call failed: scrubbed of the key, with its HTTP attempts in its usage (as a reply error has)."""
        usage = getattr(exc, "usage", None) or Usage(priced=self.price_known)
        exc.usage = usage.model_copy(update={"attempts": self._attempts.end(exc.reason)})  # type: ignore[attr-defined]
        return scrub(exc, self._secret.value)

    def _call(self, prompt: Any, chat: Sequence[Message] | None = None) -> Reply:  # pragma: no cover - abstract
        """Send `chat` (pilots/_history.messages: the earlier turns, then this step's; None: this step's alone)."""
        raise NotImplementedError

    def _unexpected(self, exc: BaseException) -> PilotError:
        if isinstance(exc, ValueError) and "json" in type(exc).__name__.lower() + str(exc).lower():
            return PilotError(f"the {self.provider} API sent a response that is not JSON: {redact(exc)}",
                              reason="bad_response")
        return PilotError(f"the {self.provider} client failed: {type(exc).__name__}: {redact(exc)}",
                          reason="client_error")

    def _usage(self, reply: Reply, latency_s: float) -> Usage:
        inp, cached, out = _int(reply.input_tokens), _int(reply.cached_tokens), _int(reply.output_tokens)
        cost = pricing.cost_usd(self.model, inp, cached, out, cache_write_tokens=_int(reply.cache_write_tokens),
                                prices=self._prices)
        return Usage(input_tokens=inp, cached_tokens=min(cached, inp), output_tokens=out,
                     latency_s=round(latency_s, 4), cost_usd=cost.usd, priced=self.price_known,
                     attempts=self._attempts.end())

    def _decision(self, reply: Reply, usage: Usage, pilot_input: PilotInput) -> Decision:
        import json

        raw = reply.text if reply.data is None else json.dumps(reply.data, ensure_ascii=False)
        who = f"{self.provider} model {self.model!r}"

        def fail(message: str, reason: str, feedback: str | None = None) -> PilotReplyError:
            return PilotReplyError(message, reason=reason, raw_text=raw, usage=usage, feedback=feedback)

        if reply.stop == "refusal":
            detail = f": {reply.stop_detail.strip()[:200]}" if reply.stop_detail.strip() else ""
            raise fail(f"the {who} refused to answer{detail}", "refusal")
        if reply.stop == "content_filter":
            raise fail(f"the {who} reply was blocked by the provider's safety filter ({reply.stop_detail})",
                       "content_filter")
        if reply.stop == "truncated":
            raise fail(f"the {who} reply was cut off at the output token limit ({self.max_output_tokens}; "
                       f"{reply.stop_detail}): raise max_output_tokens", "truncated")
        if raw is None or not raw.strip():
            raise fail(f"the {who} returned an empty reply ({reply.stop_detail or 'no content'})", "empty")
        if len(raw) > MAX_REPLY_CHARS:  # parse_decision searches only this far: say so, rather than "not JSON"
            raise fail(f"the {who} reply is {len(raw)} characters long, over the {MAX_REPLY_CHARS} a decision may "
                       f"take (max_output_tokens is {self.max_output_tokens})", TOO_LONG,
                       f"your reply was {len(raw)} characters; answer with the short JSON object only")
        try:
            decision = parse_decision(raw)
        except DecisionError as exc:
            raise fail(f"the {who} reply is not a valid decision: {exc.reason}", exc.code, exc.reason) from None
        if self.validate:
            problem = validate_decision(decision, pilot_input.state, pilot_input.profile)
            if problem is not None:
                raise fail(f"the {who} reply breaks the rules of state '{pilot_input.state}': {problem}",
                           INVALID_ENUM, problem)
            decision = normalize_decision(decision)
        return decision.model_copy(update={"raw_text": raw, "usage": usage, "model": self.model})


# ---------------------------------------------------------------- SDK errors

def _httpx_errors(name: str) -> tuple[type[BaseException], ...]:
    out: list[type[BaseException]] = []
    for module in ("httpx", "httpx2"):  # google-genai (and openai, anthropic) use both: not dead
        try:
            mod = __import__(module)
        except ImportError:
            continue
        cls = getattr(mod, name, None)
        if isinstance(cls, type):
            out.append(cls)
    return tuple(out)


HTTPX_TIMEOUTS = _httpx_errors("TimeoutException")
HTTPX_TRANSPORT_ERRORS = _httpx_errors("TransportError")  # connect, read, write, protocol errors


def error_message_and_code(body: object, fallback: str) -> tuple[str, str | None]:
    """The message and code of an error body in the OpenAI, Anthropic or Google shape."""
    if isinstance(body, Mapping):
        err = body.get("error", body)
        if isinstance(err, Mapping):
            message = err.get("message") or fallback
            code = err.get("code") or err.get("type") or err.get("status")
            return str(message), (str(code) if code is not None else None)
        if isinstance(err, str):
            return err, None
    return fallback, None


def map_stainless_error(exc: BaseException, sdk: Any, *, provider: str, key_env: str, model: str | None,
                        base_url: str | None, timeout_s: float) -> PilotError:
    """Map an exception of the `openai` or `anthropic` SDK (same generator, same tree) onto a PilotError."""
    if isinstance(exc, PilotError):
        return exc
    if isinstance(exc, sdk.APITimeoutError):
        return timeout_error(provider, timeout_s)
    if isinstance(exc, sdk.APIConnectionError):
        return connection_error(provider, base_url, exc.__cause__ or exc)
    if isinstance(exc, sdk.APIStatusError):
        message, code = error_message_and_code(exc.body, getattr(exc, "message", "") or str(exc))
        return status_error(provider, exc.status_code, message, key_env=key_env, model=model, code=code)
    if isinstance(exc, sdk.APIResponseValidationError):
        return PilotError(f"the {provider} API sent a response that is not in its documented shape: {redact(exc)}",
                          reason="bad_response")
    return PilotError(f"the {provider} client failed: {type(exc).__name__}: {redact(exc)}", reason="client_error")
