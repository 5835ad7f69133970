"""A rate budget per provider and model, shared by a bench's workers: a file-locked AIMD token bucket.

Every HTTP attempt of a model pilot takes one request from the budget before it leaves (the httpx request hook,
so the SDK's own retries wait too), and its response adapts the budget: the providers' rate-limit headers set
the limit (OpenAI `x-ratelimit-*`, Anthropic `anthropic-ratelimit-*`), a 429 halves the allowed rate
(multiplicative decrease) and its Retry-After pauses the whole budget, every worker's, until then; a success raises
it by a step (additive increase) up to the limit. Without headers the limit is the bench's `--rate-limit RPM,TPM`;
without either a budget grants at once until the first 429.

The workers share it through one small JSON state file per provider and model in the bench directory, read and
written under `fcntl.flock`: processes of the local executor and Ray workers on one machine (or on a shared
filesystem) see one budget, a crashed worker leaves no lock held, and nothing else has to run. A Ray cluster without
a shared filesystem reaches the same budgets through one Ray actor on the driver's node (`ratelimit_ray.py`): its
address, `ray-actor:NAME`, stands where the directory would.
"""

from __future__ import annotations

import contextlib
import datetime
import fcntl
import json
import os
import re
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots.transport import parse_retry_after

WINDOW_S = 60.0  # the providers' limits are per minute
BURST_S = 1.0  # a full bucket holds one second of the allowed rate (at least one request)
DECREASE = 0.5  # a 429 halves the allowed rate
MIN_RPM = 6.0  # the allowed rate never falls below one request every 10 s (or a tenth of a lower limit)
MAX_WAIT_S = 1.0  # a waiting worker looks again at least this often (another may have learned the limit)
STATE_SUFFIX = ".json"
EPSILON = 1e-6  # rounding: a bucket this close to a whole request holds one


@dataclass(frozen=True)
class RateLimit:
    """Requests and tokens per minute (None: not limited)."""

    rpm: float | None
    tpm: float | None = None

    def __str__(self) -> str:
        return f"{self.rpm or 0:g} rpm, {self.tpm or 0:g} tpm" if self.tpm else f"{self.rpm or 0:g} rpm"


def parse_rate_limit(text: str | None) -> RateLimit | None:
    """'RPM,TPM' or 'RPM' (positive numbers) -> RateLimit; a bad value is one ConfigError line naming it."""
    if text is None or not str(text).strip():
        return None
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if not 1 <= len(parts) <= 2 or len(values) != len(parts) or not all(0 < v < float("inf") for v in values):
        raise ConfigError(f"--rate-limit must be RPM or RPM,TPM with positive numbers (requests and tokens per "
                          f"minute), e.g. 500,200000; got {text!r}")
    return RateLimit(values[0], values[1] if len(values) == 2 else None)


# ------------------------------------------------------------------ the providers' headers
_OPENAI = {"limit_rpm": "x-ratelimit-limit-requests", "limit_tpm": "x-ratelimit-limit-tokens",
           "left_requests": "x-ratelimit-remaining-requests", "left_tokens": "x-ratelimit-remaining-tokens",
           "reset_requests_s": "x-ratelimit-reset-requests"}
_ANTHROPIC = {"limit_rpm": "anthropic-ratelimit-requests-limit", "limit_tpm": "anthropic-ratelimit-tokens-limit",
              "left_requests": "anthropic-ratelimit-requests-remaining",
              "left_tokens": "anthropic-ratelimit-tokens-remaining",
              "reset_requests_s": "anthropic-ratelimit-requests-reset"}


@dataclass(frozen=True)
class LimitHeaders:
    """What a response's rate-limit headers say (None: not sent)."""

    limit_rpm: float | None = None
    limit_tpm: float | None = None
    left_requests: float | None = None
    left_tokens: float | None = None
    reset_requests_s: float | None = None  # seconds until a request is free again


def read_limit_headers(headers: Mapping[str, str] | Any) -> LimitHeaders | None:
    """The OpenAI or Anthropic rate-limit headers of a response, or None if it sends neither."""
    for names in (_OPENAI, _ANTHROPIC):
        values = {field: (parse_reset(headers.get(name)) if field == "reset_requests_s" else _number(headers.get(name)))
                  for field, name in names.items()}
        if any(v is not None for v in values.values()):
            return LimitHeaders(**values)
    return None


def parse_reset(value: str | None, now: float | None = None) -> float | None:
    """Seconds until a reset header: OpenAI's '1s', '6m0s', '20ms'; Anthropic's RFC 3339 time."""
    if not value:
        return None
    units = {"ms": 0.001, "s": 1.0, "m": 60.0, "h": 3600.0}
    parts = re.findall(r"(\d+(?:\.\d+)?)(ms|s|m|h)", value)
    if parts and "".join(n + u for n, u in parts) == value.strip():
        return sum(float(n) * units[u] for n, u in parts)
    try:
        at = datetime.datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    return max(0.0, at.timestamp() - (time.time() if now is None else now))


def _number(value: Any) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if number >= 0 else None


# ------------------------------------------------------------------ the budget
def _fresh_state(default: RateLimit | None) -> dict[str, Any]:
    rpm, tpm = (default.rpm, default.tpm) if default else (None, None)
    return {"limit_rpm": rpm, "limit_tpm": tpm, "source": "option" if default else None, "rate_rpm": rpm,
            "bucket": 1.0, "tokens": tpm or 0.0, "at": None, "sent": [], "calls": 0, "throttled": 0,
            "closed_until": 0.0}


class RateBudget:
    """One provider and model's budget; `path` None keeps it in this process only. Clock and sleep are injected
    (`clock`: seconds, the same in every process sharing the file: wall time by default)."""

    def __init__(self, path: Path | None, default: RateLimit | None = None,
                 clock: Callable[[], float] = time.time, sleep: Callable[[float], None] = time.sleep):
        self.path, self.default, self.clock, self.sleep = path, default, clock, sleep
        self._memory: dict[str, Any] | None = None
        self._lock = threading.Lock()

    # -- the state, under the lock
    @contextlib.contextmanager
    def _state(self) -> Iterator[dict[str, Any]]:
        with self._lock:
            if self.path is None:
                self._memory = self._memory or _fresh_state(self.default)
                yield self._memory
                return
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.path.with_suffix(".lock"), "a+") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                try:
                    state = json.loads(self.path.read_text()) if self.path.is_file() else _fresh_state(self.default)
                    yield state
                    tmp = self.path.with_suffix(".tmp")
                    tmp.write_text(json.dumps(state))
                    os.replace(tmp, self.path)
                finally:
                    fcntl.flock(lock, fcntl.LOCK_UN)

    def snapshot(self) -> dict[str, Any]:
        """The state as it stands (for the progress line), with `sent_per_min`: requests sent in the last minute."""
        with self._state() as state:
            _refill(state, self.clock())
            return {**state, "sent_per_min": len(state["sent"])}

    # -- the three events
    def acquire(self) -> float:
        """Wait for a request of the budget (and a non-negative token balance); the seconds waited."""
        return wait_for(self.try_take, self.sleep)

    def try_take(self) -> float:
        """Take a request if the budget allows now (0.0), else the seconds until it will (nothing taken)."""
        with self._state() as state:
            return _take(state, self.clock())

    def observe(self, status: int, headers: Mapping[str, str] | Any) -> None:
        """A response came: learn the limits from its headers; a 429 backs off, a success grows the rate."""
        limits = read_limit_headers(headers)
        with self._state() as state:
            now = self.clock()
            _refill(state, now)
            if limits is not None:
                _learn(state, limits, now)
            if status == 429:
                _back_off(state, now)
                _pause(state, now, parse_retry_after(headers))
            elif 200 <= status < 300:
                _grow(state)

    def charge(self, tokens: int) -> None:
        """A reply's tokens (input and output) leave the token balance, which may go below zero: the next
        request then waits until the balance has refilled."""
        if tokens <= 0:
            return
        with self._state() as state:
            if state["limit_tpm"]:
                _refill(state, self.clock())
                state["tokens"] -= tokens


def wait_for(try_take: Callable[[], float], sleep: Callable[[float], None]) -> float:
    """Try until a request is granted, sleeping at most MAX_WAIT_S at a time; the seconds waited."""
    waited = 0.0
    while True:
        wait = try_take()
        if wait <= 0:
            return waited
        wait = min(wait, MAX_WAIT_S)
        sleep(wait)
        waited += wait


def _token_rate(state: dict[str, Any]) -> float | None:
    """Tokens per minute allowed now: the token limit scaled as the request rate is (a 429 slows both)."""
    tpm, rpm, rate = state["limit_tpm"], state["limit_rpm"], state["rate_rpm"]
    if not tpm:
        return None
    return tpm * (min(1.0, rate / rpm) if rpm and rate else 1.0)


def _refill(state: dict[str, Any], now: float) -> None:
    last = state["at"] if state["at"] is not None else now
    elapsed = max(0.0, now - last)
    state["at"] = now
    state["sent"] = [t for t in state["sent"] if t > now - WINDOW_S]
    rate = state["rate_rpm"]
    if rate:
        state["bucket"] = min(max(1.0, rate * BURST_S / WINDOW_S), state["bucket"] + elapsed * rate / WINDOW_S)
    token_rate = _token_rate(state)
    if token_rate:
        state["tokens"] = min(token_rate, state["tokens"] + elapsed * token_rate / WINDOW_S)


def _take(state: dict[str, Any], now: float) -> float:
    """Take one request if the budget allows (0.0), else the seconds until it will."""
    _refill(state, now)
    rate, token_rate = state["rate_rpm"], _token_rate(state)
    waits = []
    if state.get("closed_until", 0.0) > now:  # the provider said: nothing is left until then
        waits.append(state["closed_until"] - now)
    if rate and state["bucket"] < 1.0 - EPSILON:
        waits.append((1.0 - state["bucket"]) * WINDOW_S / rate)
    if token_rate and state["tokens"] < -EPSILON:
        waits.append(-state["tokens"] * WINDOW_S / token_rate)
    if waits:
        return max(max(waits), EPSILON)
    if rate:
        state["bucket"] = max(0.0, state["bucket"] - 1.0)
    state["sent"].append(now)
    state["calls"] += 1
    return 0.0


def _learn(state: dict[str, Any], limits: LimitHeaders, now: float) -> None:
    """The provider's headers win over the option: its limits; no request left closes the budget until the reset."""
    if limits.left_requests == 0 and limits.reset_requests_s is not None:
        state["closed_until"] = max(state.get("closed_until", 0.0), now + limits.reset_requests_s)
    first = state["source"] != "headers"
    if limits.limit_rpm:
        state["limit_rpm"], state["source"] = limits.limit_rpm, "headers"
        rate = state["rate_rpm"]
        state["rate_rpm"] = (limits.limit_rpm if rate is None or (first and not state["throttled"])
                             else min(rate, limits.limit_rpm))
    if limits.limit_tpm:
        state["limit_tpm"] = limits.limit_tpm
    if first:  # the account may be busy already (another bench): start from what is left. Later, a remaining
        # count near 0 only means the window is full at the allowed rate, which the bucket already paces.
        if limits.left_requests is not None and state["rate_rpm"]:
            state["bucket"] = min(state["bucket"], limits.left_requests)
        if limits.left_tokens is not None and state["limit_tpm"]:
            state["tokens"] = min(state["tokens"], limits.left_tokens)


def _back_off(state: dict[str, Any], now: float) -> None:
    """Multiplicative decrease: half the allowed rate (or of the rate actually sent, when none was set yet)."""
    state["throttled"] += 1
    current = state["rate_rpm"] or float(len(state["sent"]))
    floor = min(MIN_RPM, 0.1 * state["limit_rpm"]) if state["limit_rpm"] else MIN_RPM
    state["rate_rpm"] = max(floor, current * DECREASE)
    state["bucket"] = min(state["bucket"], 0.0)


def _pause(state: dict[str, Any], now: float, retry_after_s: float | None) -> None:
    """A 429's Retry-After closes the whole budget until then: every worker that shares it waits, not only the one
    that was refused (which its SDK retries after the same delay)."""
    if retry_after_s:
        state["closed_until"] = max(state.get("closed_until", 0.0), now + retry_after_s)


def _grow(state: dict[str, Any]) -> None:
    """Additive increase: 1 % of the limit (at least one request per minute) per success, up to the limit."""
    rate, limit = state["rate_rpm"], state["limit_rpm"]
    if rate is None:
        return
    step = max(1.0, 0.01 * (limit or rate * 5))
    state["rate_rpm"] = min(limit, rate + step) if limit else rate + step


# ------------------------------------------------------------------ the budgets of this process
_shared: dict[str, Any] = {"directory": None, "default": None, "budgets": {}, "clock": time.time,
                          "sleep": time.sleep}
_shared_lock = threading.Lock()


RAY_ACTOR = "ray-actor:"  # a budget address that names the Ray actor holding the budgets (ratelimit_ray.py)
NAMESPACE = "vlnpilot"  # named actors are found by name within a namespace; the workers' jobs share this one


def share_budgets(directory: str | Path | None, default: RateLimit | None = None,
                  clock: Callable[[], float] = time.time, sleep: Callable[[float], None] = time.sleep) -> None:
    """Give this process's model pilots the budgets in `directory` (a bench's `rate/`, or `ray-actor:NAME`); None:
    no budgets."""
    where = directory if isinstance(directory, str) and directory.startswith(RAY_ACTOR) else \
        Path(directory) if directory else None
    settings = {"directory": where, "default": default, "clock": clock, "sleep": sleep}
    with _shared_lock:
        if any(_shared[k] != v for k, v in settings.items()):  # a worker's next episode of the same bench: kept
            _shared.update(settings, budgets={})


def budget_for(provider: str, model: str) -> RateBudget | Any | None:
    """The shared budget of a provider and model (a `RateBudget`, or a `RayBudget` with the same methods), or None
    when this process runs no bench with budgets."""
    with _shared_lock:
        directory = _shared["directory"]
        if directory is None:
            return None
        if isinstance(directory, str):  # ray-actor:NAME
            key: Any = (directory, provider, model)
            if key not in _shared["budgets"]:
                _shared["budgets"][key] = RayBudget(directory.removeprefix(RAY_ACTOR), provider, model,
                                                    _shared["sleep"])
            return _shared["budgets"][key]
        key = budget_file(directory, provider, model)
        if key not in _shared["budgets"]:
            _shared["budgets"][key] = RateBudget(key, _shared["default"], _shared["clock"], _shared["sleep"])
        budget: RateBudget = _shared["budgets"][key]
        return budget


def budget_file(directory: Path, provider: str, model: str) -> Path:
    slug = re.sub(r"[^A-Za-z0-9._-]+", "_", f"{provider}-{model}").strip("_")
    return Path(directory) / f"{slug}{STATE_SUFFIX}"


def budget_files(directory: Path) -> list[Path]:
    return sorted(Path(directory).glob(f"*{STATE_SUFFIX}")) if Path(directory).is_dir() else []


class RayBudget:
    """A worker's handle on one provider and model's budget in the Ray actor that holds a bench's budgets
    (`ratelimit_ray.BudgetKeeper`): a `RateBudget`'s methods, each an actor call (Ray is imported on the first)."""

    def __init__(self, name: str, provider: str, model: str, sleep: Callable[[float], None] = time.sleep):
        self.name, self.provider, self.model, self.sleep = name, provider, model, sleep
        self._actor: Any = None

    def _call(self, method: str, *args: Any) -> Any:
        import ray

        if self._actor is None:
            self._actor = ray.get_actor(self.name, namespace=NAMESPACE)
        return ray.get(getattr(self._actor, method).remote(self.provider, self.model, *args))

    def try_take(self) -> float:
        return float(self._call("try_take"))

    def acquire(self) -> float:
        return wait_for(self.try_take, self.sleep)

    def observe(self, status: int, headers: Mapping[str, str] | Any) -> None:
        self._call("observe", status, {str(k).lower(): str(v) for k, v in headers.items()})

    def charge(self, tokens: int) -> None:
        if tokens > 0:
            self._call("charge", tokens)

    def snapshot(self) -> dict[str, Any]:
        return dict(self._call("snapshot"))
