"""The Pilot protocol, PilotError and the pilot registry (the input and answer types are `vlnpilot.decision`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from vlnpilot.decision import Decision, PilotInput
from vlnpilot.errors import UnknownNameError, VLNPilotError
from vlnpilot.pilots.options import OpenPilotOptions, PilotOptions


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


@dataclass(frozen=True)
class Registration:
    """A registered pilot: its factory and the class that validates its options (and knows their defaults)."""

    factory: PilotFactory
    options: type[PilotOptions]


_REGISTRY: dict[str, Registration] = {}


def register_pilot(name: str, *, options: type[PilotOptions] = OpenPilotOptions
                   ) -> Callable[[PilotFactory], PilotFactory]:
    """Register a pilot factory under a name with its options class; the factory takes `model=` and the options.

    Without an options class (a plugin's quick pilot) the options reach the factory unchecked.
    """

    def deco(factory: PilotFactory) -> PilotFactory:
        _REGISTRY[name] = Registration(factory, options)
        return factory

    return deco


_BUILTIN_MODULES = {"oracle": "oracle", "openai": "openai", "gemini": "gemini", "anthropic": "anthropic",
                    "remote": "remote", "stdin": "stdin", "replay": "replay", "noisy-oracle": "noisy",
                    "files": "files"}


# The pip extra each built-in pilot's SDK comes with (vlnpilot.extras); the others need only the plain install.
_BUILTIN_EXTRAS = {"openai": ("openai",), "gemini": ("gemini",), "anthropic": ("anthropic",), "remote": ("server",)}


def _load_builtin_pilots(only: str | None = None) -> None:
    """Import pilot modules (lazily, so that the oracle never pays for the provider SDKs' import time).

    The pilot asked for by name must load (a missing extra says which); listing all of them skips the pilots
    whose extra is not installed."""
    import importlib

    from vlnpilot.extras import MissingExtraError, needs

    names = [only] if only in _BUILTIN_MODULES else sorted(_BUILTIN_MODULES)
    for name in names:
        try:
            with needs(*_BUILTIN_EXTRAS.get(name, ()), what=f"the {name} pilot"):
                importlib.import_module(f"vlnpilot.pilots.{_BUILTIN_MODULES[name]}")
        except MissingExtraError:
            if only is not None:
                raise
        except ModuleNotFoundError as exc:  # a pilot module that does not exist in this version
            if exc.name and exc.name.startswith("vlnpilot.pilots."):
                continue
            raise


def known_pilots() -> list[str]:
    """Every pilot name, the built-in ones too when their extra is not installed."""
    _load_builtin_pilots()
    return sorted(set(_REGISTRY) | set(_BUILTIN_MODULES))


def parse_spec(spec: str) -> tuple[str, str | None]:
    """'openai:gpt-4.1' -> ('openai', 'gpt-4.1'); 'oracle' -> ('oracle', None)."""
    name, _, model = str(spec).strip().partition(":")
    return name.strip().lower(), (model.strip() or None)


def registration(name: str) -> Registration:
    """The registration of a pilot name (importing only that pilot's module); a bad name lists the known ones."""
    _load_builtin_pilots(only=name)
    if name not in _REGISTRY:
        _load_builtin_pilots()
    if name not in _REGISTRY:
        raise UnknownNameError("pilot", name, known_pilots())
    return _REGISTRY[name]


def pilot_factory(name: str) -> PilotFactory:
    """The registered factory of a pilot name; a bad name lists the known ones."""
    return registration(name).factory


def pilot_options_class(name: str) -> type[PilotOptions]:
    """The options class of a pilot name: what it accepts, its defaults (`default_model()`); a bad name lists them."""
    return registration(name).options


def make_pilot(spec: str, **options: Any) -> Pilot:
    """Build a pilot from a SPEC (`name` or `name:model`) and its options, validated by its options class.

    A bad name lists the known pilots; a bad option is one ConfigError line with the valid option names.
    """
    name, model = parse_spec(spec)
    entry = registration(name)
    if model is not None:
        options["model"] = model
    return entry.factory(**entry.options.build(name, **options).given())


def close_pilot(pilot: object) -> None:
    """Release what a pilot holds (an SDK client's sockets, a server connection), if it has a `close()`."""
    close = getattr(pilot, "close", None)
    if callable(close):
        close()
