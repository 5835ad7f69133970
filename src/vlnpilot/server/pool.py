"""The pilots a server serves: an explicit allow-list of SPECs and a bounded cache of built pilots.

Any client can name a pilot in a request, so the server builds only the SPECs its operator allowed (the default
is the one it was started with): a request for anything else costs nothing and gets 403 with the allowed list.
Built pilots hold SDK clients (sockets, threads), so the cache is bounded and closes what it evicts.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable
from typing import Any

from vlnpilot.core.decision import traits_of
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.pilots.base import Pilot, check_spec_syntax, close_pilot, parse_spec, pilot_factory, pilot_options_class

DEFAULT_MAX_CACHED = 8


def canonical_spec(spec: str) -> str:
    """'openai' and 'OpenAI:gpt-4.1' both become 'openai:gpt-4.1' (the registered pilot's default model)."""
    name, model = parse_spec(spec)
    if model is None:
        try:
            model = pilot_options_class(name).default_model()
        except UnknownNameError:
            model = None
    return f"{name}:{model}" if model else name


def check_specs(specs: Iterable[str]) -> None:
    """Before a server starts: every SPEC names a registered pilot (UnknownNameError lists them), a model after
    a ':' (ConfigError), and no pilot that needs ground truth (`refuse_privileged`)."""
    for spec in specs:
        check_spec_syntax(spec)
        pilot_factory(parse_spec(spec)[0])
    refuse_privileged(specs)


def refuse_privileged(specs: Iterable[str]) -> None:
    """ConfigError for a pilot that needs the simulator's ground truth (the oracle): a server has none."""
    for spec in specs:
        try:
            factory = pilot_factory(parse_spec(spec)[0])
        except UnknownNameError:
            continue  # a custom factory's name: it is checked when it is built
        if traits_of(factory).privileged:
            raise ConfigError(f"pilot {spec!r} needs the simulator's ground truth, which a server does not have; "
                              "serve a model pilot, e.g. --pilot openai:gpt-4.1")


class PilotPool:
    """Builds allowed pilots on first use and keeps at most `max_cached` of them (least recently used go first)."""

    def __init__(self, factory: Callable[..., Pilot], allowed: Iterable[str], options: dict[str, Any] | None = None,
                 max_cached: int = DEFAULT_MAX_CACHED):
        if max_cached < 1:
            raise ConfigError(f"max_cached must be >= 1, got {max_cached!r}")
        self._factory, self._options, self.max_cached = factory, dict(options or {}), max_cached
        self._allowed: dict[str, str] = {}  # canonical SPEC -> the SPEC as the operator wrote it
        for spec in allowed:
            self._allowed.setdefault(canonical_spec(spec), spec.strip())
        self._names = {parse_spec(s)[0] for s in self._allowed}
        self._cache: OrderedDict[str, Pilot] = OrderedDict()
        self._lock = threading.Lock()

    @property
    def allowed(self) -> list[str]:
        return list(self._allowed.values())

    def resolve(self, spec: str) -> str | None:
        """The allowed SPEC that `spec` names, or None (checked by name first: an unknown name costs nothing)."""
        if parse_spec(spec)[0] not in self._names:
            return None
        return self._allowed.get(canonical_spec(spec))

    def get(self, spec: str) -> Pilot:
        """The built pilot of an allowed SPEC (see `resolve`); building it may raise what the factory raises."""
        with self._lock:
            pilot = self._cache.get(spec)
            if pilot is not None:
                self._cache.move_to_end(spec)
                return pilot
            pilot = self._factory(spec, **self._options)
            self._cache[spec] = pilot
            while len(self._cache) > self.max_cached:
                close_pilot(self._cache.popitem(last=False)[1])
            return pilot

    def close(self) -> None:
        with self._lock:
            while self._cache:
                close_pilot(self._cache.popitem()[1])

    def __len__(self) -> int:
        return len(self._cache)
