"""The model pilots' common part: the decide() skeleton, and turning a provider's reply into a Decision.

Each provider module only speaks its SDK: it sends the Prompt and hands back a `Reply` (text or parsed tool input,
normalised stop reason, token counts). Everything after that (refusals, truncation, parsing, validation, usage and
cost) happens here, once, so that the pilots fail alike. Keys live in `secrets`, retries and errors in `transport`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal, TypedDict

from pydantic import SecretStr

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
from vlnpilot.pilots.ratelimit import budget_for
from vlnpilot.pilots.secrets import redact, scrub

log = logging.getLogger(__name__)
_UNPRICED_WARNED: set[tuple[str, str]] = set()

# Reasons of a reply that arrived but cannot be used; the controller re-asks (at most twice).
REPLY_REASONS = frozenset({"refusal", "content_filter", "truncated", "empty", *DECISION_ERROR_CODES})


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
    _secret: SecretStr = SecretStr("")  # subclasses keep their key here (the SDK client holds it too)

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
        self._budget = budget_for(self.provider, self.model)  # a bench's shared rate budget (pilots/ratelimit.py)
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
        """The httpx event hooks a subclass gives its SDK client: the rate budget's turn (every attempt, the SDK's
        retries included, waits for it), the call gate, the attempt log; each response adapts the budget."""
        hooks = event_hooks(self._gate.on_request, self._attempts)
        budget = self._budget
        if budget is not None:
            def wait_turn(request: Any) -> None:
                budget.acquire()

            def adapt(response: Any) -> None:
                budget.observe(response.status_code, response.headers)

            hooks["request"].insert(0, wait_turn)
            hooks["response"].append(adapt)
        return hooks

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
        return scrub(exc, self._secret.get_secret_value())

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
        if self._budget is not None:
            self._budget.charge(inp + out)
        cached = min(cached, inp)
        written = min(_int(reply.cache_write_tokens), inp - cached)
        cost = pricing.cost_usd(self.model, inp, cached, out, cache_write_tokens=written, prices=self._prices)
        return Usage(input_tokens=inp, cached_tokens=cached, output_tokens=out, cache_write_tokens=written,
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
