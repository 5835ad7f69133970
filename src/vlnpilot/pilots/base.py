"""The Pilot protocol, its input and its Decision (the paper's output format), and the pilot registry."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Protocol, runtime_checkable

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from vlnpilot.errors import UnknownNameError, VLNPilotError
from vlnpilot.fsm import State
from vlnpilot.types import GroundTruth

DoorPosition = Literal["left", "center", "right", "not_visible"]
DOOR_POSITIONS: tuple[str, ...] = ("left", "center", "right", "not_visible")


class Usage(BaseModel):
    """Token usage of one model call as the API reports it, and its wall-clock latency."""

    model_config = ConfigDict(frozen=True)
    input_tokens: int = 0
    cached_tokens: int = 0
    output_tokens: int = 0
    latency_s: float = 0.0
    cost_usd: float = 0.0
    priced: bool = True  # False when the model is missing from the price table (cost then reads 0)

    def __add__(self, other: Usage) -> Usage:
        sums = {k: getattr(self, k) + getattr(other, k) for k in Usage.model_fields if k != "priced"}
        return Usage(**sums, priced=self.priced and other.priced)


class Decision(BaseModel):
    """One answer of the pilot, exactly the paper's output format plus metadata.

    `movement` and `state` are kept as the model wrote them; the controller validates them against
    the FSM table before anything moves.
    """

    model_config = ConfigDict(frozen=True)
    room: str
    movement: str
    state: str
    description: str = ""
    door_position: DoorPosition = "not_visible"
    # metadata (never sent to the model)
    raw_text: str | None = Field(default=None, exclude=False)
    usage: Usage = Field(default_factory=Usage)
    model: str | None = None

    def core(self) -> dict[str, str]:
        """The five fields of the paper's output format."""
        return {k: getattr(self, k) for k in ("room", "movement", "state", "description", "door_position")}


@dataclass(frozen=True)
class PilotInput:
    """What a pilot sees at one step: the paper's five inputs plus controller feedback."""

    image: np.ndarray = field(repr=False)  # front camera, HxWx3 uint8
    query: str
    topological_map: dict[str, Any]
    state: State
    previous_movement: str | None
    step: int = 0
    profile: str = "paper"  # FSM profile: which moves each state allows
    feedback: tuple[str, ...] = ()  # validation errors of a re-ask, shield and oscillation notes
    context: tuple[str, ...] = ()  # pilot context beyond the paper (vlnpilot.context): odometry, budget, memory


class PilotError(VLNPilotError):
    """A pilot could not produce a decision (provider down, bad key, ...). `fatal` ends the episode."""

    def __init__(self, message: str, *, fatal: bool = False, reason: str = "pilot_error"):
        super().__init__(message)
        self.fatal = fatal
        self.reason = reason


@runtime_checkable
class Pilot(Protocol):
    """Anything that turns a PilotInput into a Decision. `privileged` pilots get ground truth."""

    name: str
    model: str | None

    def decide(self, pilot_input: PilotInput) -> Decision: ...


class PrivilegedPilot(Pilot, Protocol):
    privileged: ClassVar[bool]

    def attach(self, ground_truth: GroundTruth) -> None:
        """Receive the narrow ground-truth interface at the start of an episode."""


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
