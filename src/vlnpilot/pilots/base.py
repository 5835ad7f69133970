"""The Pilot protocol, PilotError and the pilot registry (the input and answer types are `vlnpilot.core.decision`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from vlnpilot.core.decision import NO_TRAITS, Decision, PilotInput, PilotTraits, traits_of
from vlnpilot.core.environment import GroundTruth
from vlnpilot.core.errors import ConfigError, VLNPilotError
from vlnpilot.core.exits import shorten
from vlnpilot.core.extras import require
from vlnpilot.core.registry import Registry
from vlnpilot.pilots.options import OpenPilotOptions, PilotOptions


class PilotError(VLNPilotError):
    """A pilot could not produce a decision (provider down, bad key, ...). `fatal` ends the episode."""

    def __init__(self, message: str, *, fatal: bool = False, reason: str = "pilot_error"):
        super().__init__(message)
        self.fatal = fatal
        self.reason = reason


@runtime_checkable
class Pilot(Protocol):
    """Anything that turns a PilotInput into a Decision. The least a pilot is; `BasePilot` adds its traits and
    the hooks the episode calls, as no-ops (a pilot written to this bare protocol is adapted by `as_base_pilot`)."""

    @property
    def name(self) -> str: ...  # read-only here, so that a pilot may narrow them (a model pilot always has a model)

    @property
    def model(self) -> str | None: ...

    def decide(self, pilot_input: PilotInput) -> Decision: ...


class BasePilot:
    """A pilot with its traits declared and every hook the episode calls, each a no-op until overridden.

    `traits` (`core.decision.PilotTraits`) says what the pilot is: privileged (reads ground truth), whether it
    validates its own decisions, whether it waits on a network. The hooks, in the order an episode calls them:
    `attach(gt)` (privileged pilots only), `reseed(seed)`, `episode_started(scene, config)`, then `decide` each
    step (`cancel_pending()` when a step's deadline passes), `episode_finished(result)`, and `close()`.
    """

    name: str = "pilot"
    model: str | None = None
    traits: PilotTraits = NO_TRAITS

    def decide(self, pilot_input: PilotInput) -> Decision:
        raise NotImplementedError

    def attach(self, ground_truth: GroundTruth) -> None:
        """Receive ground truth before the episode (only a pilot whose traits say `privileged`)."""

    def reseed(self, seed: int) -> None:
        """Take the episode's seed (a stochastic pilot)."""

    def episode_started(self, scene: Any, config: Any) -> None:
        """See the scene and the episode's configuration first (the replay pilot checks them)."""

    def episode_finished(self, result: Any) -> None:
        """Learn the outcome (the files pilot writes done.txt)."""

    def cancel_pending(self) -> None:
        """Abandon a call still under way: the step's deadline passed."""

    def close(self) -> None:
        """Release what the pilot holds (an SDK client's sockets, a server connection)."""


class _ProtocolPilot(BasePilot):
    """A pilot written to the bare `Pilot` protocol, given the base class's traits and hooks: it declares no traits,
    and of the hooks it keeps the ones it defines."""

    def __init__(self, pilot: Pilot):
        self._pilot = pilot
        self.name, self.model = pilot.name, getattr(pilot, "model", None)
        self.traits = traits_of(pilot)
        for hook in ("attach", "reseed", "episode_started", "episode_finished", "cancel_pending", "close"):
            own = getattr(pilot, hook, None)
            if callable(own):
                setattr(self, hook, own)

    def decide(self, pilot_input: PilotInput) -> Decision:
        return self._pilot.decide(pilot_input)


def as_base_pilot(pilot: Pilot) -> BasePilot:
    """The pilot itself if it is a `BasePilot`, else the pilot adapted to one (its hooks found once, here)."""
    return pilot if isinstance(pilot, BasePilot) else _ProtocolPilot(pilot)


PilotFactory = Callable[..., Pilot]


@dataclass(frozen=True)
class Registration:
    """A registered pilot: its factory and the class that validates its options (and knows their defaults)."""

    factory: PilotFactory
    options: type[PilotOptions]


# The built-in pilots' modules are imported only when their name is asked for, so that the oracle never pays for
# the provider SDKs' import time; third parties register with `@register_pilot` in a module of theirs, loaded
# by `--plugin` or through the `vlnpilot.pilots` entry-point group.
PILOT_REGISTRY: Registry[Registration] = Registry("pilot", group="vlnpilot.pilots", builtins={
    name: f"vlnpilot.pilots.{module}" for name, module in {
        "oracle": "oracle", "openai": "openai", "gemini": "gemini", "anthropic": "anthropic", "remote": "remote",
        "stdin": "stdin", "replay": "replay", "noisy-oracle": "noisy", "files": "files",
        "gullible": "gullible"}.items()})


def register_pilot(name: str, *, options: type[PilotOptions] = OpenPilotOptions
                   ) -> Callable[[PilotFactory], PilotFactory]:
    """Register a pilot factory under a name with its options class; the factory takes `model=` and the options.

    Without an options class (a plugin's quick pilot) the options reach the factory unchecked.
    """

    def deco(factory: PilotFactory) -> PilotFactory:
        PILOT_REGISTRY.add(name, Registration(factory, options))
        return factory

    return deco


# The pip extra each built-in pilot's SDK comes with (vlnpilot.core.extras); the others need only the plain install.
_BUILTIN_EXTRAS = {"openai": ("openai",), "gemini": ("gemini",), "anthropic": ("anthropic",), "remote": ("server",)}


def known_pilots() -> list[str]:
    """Every pilot name, the built-in ones too when their extra is not installed (listing imports none of them)."""
    return sorted(PILOT_REGISTRY.names())


def parse_spec(spec: str) -> tuple[str, str | None]:
    """'openai:gpt-4.1' -> ('openai', 'gpt-4.1'); 'oracle' -> ('oracle', None)."""
    name, _, model = str(spec).strip().partition(":")
    return name.strip().lower(), (model.strip() or None)


def check_spec_syntax(spec: str) -> None:
    """ConfigError for a SPEC that names no pilot, or a ':' with no model after it ('openai:')."""
    name, sep, model = str(spec).strip().partition(":")
    if not name.strip():
        raise ConfigError(f"pilot SPEC {spec!r} names no pilot; write NAME or NAME:MODEL, e.g. openai:gpt-4.1")
    if sep and not model.strip() and _has_default_model(name.strip().lower()):
        raise ConfigError(f"pilot SPEC {spec!r} has nothing after ':'; write {name.strip()} for its default "
                          f"model, or {name.strip()}:MODEL")


def _has_default_model(name: str) -> bool:
    """Whether NAME alone flies (a default model); a pilot whose SPEC needs its part after ':' (files:DIR,
    replay:RUN) says itself what it needs. An unknown name is refused later, with the valid names."""
    try:
        return pilot_options_class(name).default_model() is not None
    except VLNPilotError:
        return True


def registration(name: str) -> Registration:
    """The registration of a pilot name (importing only that pilot's module); a bad name lists the known ones."""
    require(*_BUILTIN_EXTRAS.get(name, ()), what=f"the {name} pilot")  # a missing extra says which, up front
    return PILOT_REGISTRY.get(name)


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
    check_spec_syntax(spec)
    name, model = parse_spec(spec)
    entry = registration(name)
    if model is not None:
        _check_takes_model(name, model, entry.options)
        options["model"] = model
    return entry.factory(**entry.options.build(name, **options).given())


def _check_takes_model(name: str, model: str, options: type[PilotOptions]) -> None:
    """ConfigError for `name:model` when the pilot has no model to choose (its results would carry a wrong one)."""
    if options.takes_model:
        return
    takers = [n for n in known_pilots() if _takes_model(n)]
    raise ConfigError(f"the {name} pilot takes no model (got {name}:{shorten(model, 40)}); write {name}. "
                      f"Pilots that take a model or a path after ':': {', '.join(takers)}")


def _takes_model(name: str) -> bool:
    try:
        return pilot_options_class(name).takes_model
    except VLNPilotError:  # a pilot whose extra is missing still takes its model
        return True


def close_pilot(pilot: Pilot) -> None:
    """Release what a pilot holds (an SDK client's sockets, a server connection)."""
    as_base_pilot(pilot).close()
