"""Talking to a provider: retries with backoff and Retry-After, and HTTP or SDK errors mapped onto PilotError.

Every failure a provider can cause ends as one PilotError whose `reason` says whether asking again may help
(`TRANSIENT_REASONS`) and whose message is one line a user can act on, with no key in it.
"""

from __future__ import annotations

import email.utils
import logging
import math
import random
import re
import time
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from vlnpilot.pilots import pricing
from vlnpilot.pilots.base import PilotError
from vlnpilot.pilots.secrets import redact

log = logging.getLogger(__name__)
T = TypeVar("T")

# Reasons of PilotError that mean "the provider is (temporarily) not answering": the server maps
# them to 503, everything else to 502.
TRANSIENT_REASONS = frozenset({"rate_limited", "unavailable", "timeout", "connection_error"})
# The provider says the model is unknown or gone (OpenAI 404 model_not_found, Gemini 404 "is not found",
# a 400/410 for a shut-down model): said in one line with the current models of the price table.
_MODEL_GONE = re.compile(r"model_not_found|does not exist|not found|no longer (available|supported)|deprecated|"
                         r"retired|shut ?down|decommissioned|discontinued")
_MODEL_FAMILIES = ("gpt-", "gemini-", "claude-")

DEFAULT_MAX_RETRIES = 2  # of call_with_retries (the pilots take theirs from their options)
MAX_RETRY_AFTER_S = 60.0  # a server asking for a longer wait is not retried: the step would stall


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
