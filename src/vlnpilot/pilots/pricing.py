"""A dated, overridable table of model prices, and the cost of one call.

Prices are USD per million tokens: fresh input, cached input (read from a prompt cache), output, and
(Anthropic only) cache writes. Provider prices change: the table says when it was compiled
(`PRICES_AS_OF`), and a JSON or YAML file named by the env var `VLN_PILOT_PRICES` (or passed to
`load_prices`) overrides or extends it:

    {"as_of": "2026-11-01", "models": {"gpt-4.1": {"input": 2.0, "cached": 0.5, "output": 8.0}}}

(the bare mapping `{"gpt-4.1": {...}}` is accepted too). A model that is not in the table costs 0
and is flagged (`Cost.known` is False), so a report can say "cost unknown" instead of "free".
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlnpilot.core.errors import ConfigError

PRICES_AS_OF = "2025-12-01"
"""When the built-in table was compiled from the providers' public price pages (standard tier,
prompts under 200k tokens). Check the pages, or override with VLN_PILOT_PRICES, before quoting costs."""

PRICES_ENV = "VLN_PILOT_PRICES"


@dataclass(frozen=True)
class Price:
    """USD per million tokens. `cache_write` defaults to the input price (providers that bill it alike)."""

    input: float
    cached: float
    output: float
    cache_write: float | None = None

    def __post_init__(self) -> None:
        for name in ("input", "cached", "output", "cache_write"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, int | float) and value >= 0):
                raise ConfigError(f"price {name} must be a non-negative number, got {value!r}")


@dataclass(frozen=True)
class Cost:
    usd: float
    known: bool  # False: the model is not in the price table and usd is 0


DEFAULT_PRICES: dict[str, Price] = {
    # OpenAI (cached input is 25% of input for the 4.1 family, 10% for the 5 family).
    "gpt-4.1": Price(2.00, 0.50, 8.00),
    "gpt-4.1-mini": Price(0.40, 0.10, 1.60),
    "gpt-4.1-nano": Price(0.10, 0.025, 0.40),
    "gpt-4o": Price(2.50, 1.25, 10.00),
    "gpt-4o-mini": Price(0.15, 0.075, 0.60),
    "gpt-5": Price(1.25, 0.125, 10.00),
    "gpt-5-mini": Price(0.25, 0.025, 2.00),
    "gpt-5-nano": Price(0.05, 0.005, 0.40),
    # Google Gemini API (paid tier, text/image/video input; output includes thinking tokens).
    "gemini-2.5-flash": Price(0.30, 0.03, 2.50),
    "gemini-2.5-flash-lite": Price(0.10, 0.01, 0.40),
    "gemini-2.5-pro": Price(1.25, 0.125, 10.00),
    "gemini-2.0-flash": Price(0.10, 0.025, 0.40),
    # Anthropic (cache reads 0.1x input, 5-minute cache writes 1.25x input).
    "claude-sonnet-4-6": Price(3.00, 0.30, 15.00, 3.75),  # assumed equal to Sonnet 4.5: verify
    "claude-sonnet-4-5": Price(3.00, 0.30, 15.00, 3.75),
    "claude-sonnet-4": Price(3.00, 0.30, 15.00, 3.75),
    "claude-haiku-4-5": Price(1.00, 0.10, 5.00, 1.25),
    "claude-opus-4-5": Price(5.00, 0.50, 25.00, 6.25),
    "claude-opus-4-1": Price(15.00, 1.50, 75.00, 18.75),
}

_lock = threading.Lock()
_cache: dict[tuple[str, float], dict[str, Price]] = {}


def _read_file(path: Path) -> Mapping[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read the price file {str(path)!r} ({PRICES_ENV}): {exc.strerror}") from None
    try:
        if path.suffix.lower() in (".yaml", ".yml"):
            import yaml

            data = yaml.safe_load(text)
        else:
            data = json.loads(text)
    except Exception as exc:  # noqa: BLE001 - any parse error is a config error with the file name
        raise ConfigError(f"the price file {str(path)!r} is not valid JSON/YAML: {exc}") from None
    if not isinstance(data, Mapping):
        raise ConfigError(f"the price file {str(path)!r} must hold a mapping of model -> prices")
    models = data.get("models", data)
    if not isinstance(models, Mapping):
        raise ConfigError(f"'models' in the price file {str(path)!r} must be a mapping")
    return models


def _to_price(model: str, value: Any) -> Price:
    if isinstance(value, Price):
        return value
    if not isinstance(value, Mapping) or not {"input", "output"} <= set(value):
        raise ConfigError(f"price of {model!r} needs at least 'input' and 'output' (USD per million tokens)")
    extra = set(value) - {"input", "cached", "output", "cache_write"}
    if extra:
        raise ConfigError(f"price of {model!r} has unknown keys {sorted(extra)}; "
                          "use input, cached, output, cache_write")
    return Price(value["input"], value.get("cached", value["input"]), value["output"], value.get("cache_write"))


def load_prices(path: str | os.PathLike[str] | None = None) -> dict[str, Price]:
    """The built-in table overlaid with the file `path` (default: env VLN_PILOT_PRICES, if set)."""
    if path is None:
        path = os.environ.get(PRICES_ENV) or None
    if path is None:
        return dict(DEFAULT_PRICES)
    p = Path(path)
    try:
        key = (str(p.resolve()), p.stat().st_mtime)
    except OSError:
        key = (str(p), -1.0)
    with _lock:
        if key in _cache:
            return dict(_cache[key])
    table = dict(DEFAULT_PRICES)
    for model, value in _read_file(p).items():
        table[str(model)] = _to_price(str(model), value)
    with _lock:
        _cache[key] = table
    return dict(table)


def find_price(model: str | None, prices: Mapping[str, Price] | None = None) -> Price | None:
    """The price of a model: exact name, else the longest table entry that is a '-'-prefix of it
    ('gpt-4.1-2025-04-14' -> 'gpt-4.1', 'models/gemini-2.5-flash' -> 'gemini-2.5-flash')."""
    if not model:
        return None
    table = load_prices() if prices is None else prices
    name = model.strip().lower().removeprefix("models/")
    if name in table:
        return table[name]
    best = None
    for key in table:
        if name.startswith(key + "-") and (best is None or len(key) > len(best)):
            best = key
    return table[best] if best is not None else None


def cost_usd(
    model: str | None,
    input_tokens: int,
    cached_tokens: int = 0,
    output_tokens: int = 0,
    *,
    cache_write_tokens: int = 0,
    prices: Mapping[str, Price] | None = None,
) -> Cost:
    """Cost of one call. `input_tokens` counts every prompt token, cached and cache writes included."""
    price = find_price(model, prices)
    if price is None:
        return Cost(0.0, False)
    cached = max(0, min(cached_tokens, input_tokens))
    writes = max(0, min(cache_write_tokens, input_tokens - cached))
    fresh = input_tokens - cached - writes
    write_price = price.input if price.cache_write is None else price.cache_write
    usd = (fresh * price.input + cached * price.cached + writes * write_price + output_tokens * price.output) / 1e6
    return Cost(round(usd, 8), True)
