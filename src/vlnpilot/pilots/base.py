"""The Pilot protocol, PilotError and the pilot registry (the input and answer types are `vlnpilot.decision`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from vlnpilot.decision import Decision, PilotInput
from vlnpilot.errors import UnknownNameError, VLNPilotError


class PilotError(VLNPilotError):
    """A pilot could not produce a decision (provider down, bad key, ...). `fatal` ends the episode."""

    def __init__(self, message: str, *, fatal: bool = False, reason: str = "pilot_error"):
        super().__init__(message)
        self.fatal = fatal
        self.reason = reason


@runtime_checkable
class Pilot(Protocol):
    """Anything that turns a PilotInput into a Decision. `privileged` pilots get ground truth.

    A pilot whose `validates_decisions` is true returns decisions already normalised and allowed in
    `pilot_input.state` (ModelPilot does, with `decision.validate_decision`); the episode checks every other's.
    """

    name: str
    model: str | None

    def decide(self, pilot_input: PilotInput) -> Decision: ...


PilotFactory = Callable[..., Pilot]
_REGISTRY: dict[str, PilotFactory] = {}


def register_pilot(name: str) -> Callable[[PilotFactory], PilotFactory]:
    """Register a pilot factory under a name; the factory takes `model=` and keyword options."""

    def deco(factory: PilotFactory) -> PilotFactory:
        _REGISTRY[name] = factory
        return factory

    return deco


_BUILTIN_MODULES = {"oracle": "oracle", "openai": "openai", "gemini": "gemini", "anthropic": "anthropic",
                    "remote": "remote", "stdin": "stdin", "replay": "replay", "noisy-oracle": "noisy",
                    "files": "files"}


def _load_builtin_pilots(only: str | None = None) -> None:
    """Import pilot modules (lazily, so that the oracle never pays for the provider SDKs' import time)."""
    import importlib

    modules = [_BUILTIN_MODULES[only]] if only in _BUILTIN_MODULES else sorted(set(_BUILTIN_MODULES.values()))
    for module in modules:
        try:
            importlib.import_module(f"vlnpilot.pilots.{module}")
        except ModuleNotFoundError as exc:  # a pilot module that does not exist in this version
            if exc.name and exc.name.startswith("vlnpilot.pilots."):
                continue
            raise


def known_pilots() -> list[str]:
    _load_builtin_pilots()
    return sorted(_REGISTRY)


def parse_spec(spec: str) -> tuple[str, str | None]:
    """'openai:gpt-4.1' -> ('openai', 'gpt-4.1'); 'oracle' -> ('oracle', None)."""
    name, _, model = str(spec).strip().partition(":")
    return name.strip().lower(), (model.strip() or None)


def pilot_factory(name: str) -> PilotFactory:
    """The registered factory of a pilot name (importing only that pilot's module); a bad name lists the known ones."""
    _load_builtin_pilots(only=name)
    if name not in _REGISTRY:
        _load_builtin_pilots()
    if name not in _REGISTRY:
        raise UnknownNameError("pilot", name, _REGISTRY)
    return _REGISTRY[name]


def make_pilot(spec: str, **options: Any) -> Pilot:
    """Build a pilot from a SPEC (`name` or `name:model`); a bad name lists the known ones."""
    name, model = parse_spec(spec)
    factory = pilot_factory(name)
    if model is not None:
        options["model"] = model
    return factory(**options)
