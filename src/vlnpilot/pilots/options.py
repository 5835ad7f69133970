"""Typed pilot options: each registered pilot names a `PilotOptions` class that validates what it is given.

The options class is the one place that lists a pilot's settings and their defaults; `make_pilot`, the
command line (`--pilot-option KEY=VALUE`), the bench (does this pilot take `base_url`? a suite `row`?) and
the server (the default model) ask it, rather than probing the pilot's constructor. A bad key or value is
one line naming the pilot, the problem and the valid option names; a secret never appears in it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal, Self

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    ValidationError,
    ValidationInfo,
    field_validator,
)

from vlnpilot.core.errors import ConfigError
from vlnpilot.core.exits import shorten


def within(low: float, high: float, unit: str) -> AfterValidator:
    """A float option's check: finite and within low..high, its refusal naming the range (NaN passes `ge`).
    Use: `Annotated[float, within(0.1, 1.5, "m")]`."""
    def check(value: float) -> float:
        if not (math.isfinite(value) and low <= value <= high):
            raise ValueError(f"must be a finite number in {low:g}..{high:g} {unit}")
        return value

    return AfterValidator(check)


class PilotOptions(BaseModel):
    """The base of every pilot's options: `model` (the SPEC's part after the colon) and nothing unknown.

    Fields a command line cannot express (a transport, a clock, IO streams) are `programmatic`: library
    users and tests pass them as keywords; `--pilot-option` refuses them.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True, populate_by_name=True)
    programmatic: ClassVar[frozenset[str]] = frozenset()
    # Whether a SPEC may name a model (name:MODEL); a pilot that has none (the oracle) is refused one, so that
    # no result is ever labelled with a model that did not fly it.
    takes_model: ClassVar[bool] = True

    model: str | None = None

    @classmethod
    def option_names(cls) -> list[str]:
        """The option names a user writes (a field's alias where it has one), sorted."""
        return sorted(f.alias or name for name, f in cls.model_fields.items())

    @classmethod
    def accepts(cls, option: str) -> bool:
        return option in cls.option_names()

    @classmethod
    def default_model(cls) -> str | None:
        return cls.model_fields["model"].default

    @classmethod
    def secret_names(cls) -> set[str]:
        return {f.alias or name for name, f in cls.model_fields.items() if _is_secret(f.annotation)}

    @classmethod
    def build(cls, pilot: str, /, **values: Any) -> Self:
        """Validated options of the pilot named `pilot` (a missing or None `model` keeps the class's default)."""
        if values.get("model") is None:
            values.pop("model", None)
        try:
            return cls(**values)
        except ValidationError as exc:
            raise ConfigError(cls._problem(pilot, exc)) from None

    @classmethod
    def _problem(cls, pilot: str, exc: ValidationError) -> str:
        errors = exc.errors(include_url=False)
        first = errors[0]
        key = ".".join(str(p) for p in first["loc"][:1]) or "?"
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        valid = f"valid options: {', '.join(cls.option_names())}"
        if first["type"] == "extra_forbidden":
            return f"unknown option {key!r} for the {pilot} pilot{more}; {valid}"
        message = str(first["msg"]).removeprefix("Value error, ")
        got = "" if key in cls.secret_names() else f", got {shorten(repr(first.get('input')))}"
        return f"bad value for option {key!r} of the {pilot} pilot: {message}{got}{more}; {valid}"

    @classmethod
    def settable(cls) -> list[str]:
        """The options `--pilot-option` may set: not the model (the SPEC's), no secret, nothing programmatic."""
        hidden = {"model", *cls.programmatic, *cls.secret_names()}
        return [name for name in cls.option_names() if name not in hidden]

    @classmethod
    def from_command_line(cls, pilot: str, pairs: Mapping[str, str]) -> dict[str, Any]:
        """`--pilot-option` strings, coerced and checked by this class: {option: JSON value} (what a bench records)."""
        for key in pairs:
            if key not in cls.settable():
                raise ConfigError(f"--pilot-option {key!r} of the {pilot} pilot: {cls._why_not(key)}; "
                                  f"valid keys: {', '.join(cls.settable()) or '(none)'}")
        options = cls.build(pilot, **pairs)
        fields = {f.alias or name: name for name, f in cls.model_fields.items()}
        return options.model_dump(mode="json", by_alias=True, include={fields[key] for key in pairs})

    @classmethod
    def _why_not(cls, key: str) -> str:
        if key in cls.secret_names():
            return "a secret does not go on the command line (shell history, bench.json): set its environment variable"
        if key == "model":
            return "the model is the SPEC's (--pilot name:model)"
        if key in cls.programmatic:
            return "not a command-line option (Python callers only)"
        return "unknown option"

    def given(self) -> dict[str, Any]:
        """The options that were set explicitly, by their user-facing names (what a factory is called with)."""
        fields = type(self).model_fields
        out = {(fields[k].alias or k): getattr(self, k) for k in self.model_fields_set if k in fields}
        return {**out, **(self.model_extra or {})}


class OpenPilotOptions(PilotOptions):
    """The options of a pilot registered without an options class (a plugin): anything goes to its factory."""

    model_config = ConfigDict(extra="allow")


MAX_HISTORY = 20  # earlier turns a pilot may send again (each is a state prompt, a step text and perhaps an image)


class ConversationOptions(PilotOptions):
    """Conversation memory (`pilots._history`): `history` is 'none' (one message per step, the paper's pilot) or the
    number N of earlier turns sent again as chat messages (text always); `history_images` of them (the last ones)
    keep their image."""

    history: int | Literal["none"] = "none"
    history_images: int = Field(0, ge=0)

    @field_validator("history", mode="before")
    @classmethod
    def _turns(cls, value: Any) -> int | str:
        text = str(value).strip().lower()
        if text in ("none", "0"):
            return "none"
        if text.isdigit() and 1 <= int(text) <= MAX_HISTORY and not isinstance(value, bool):
            return int(text)
        raise ValueError(f"history is 'none' or a number of earlier turns from 1 to {MAX_HISTORY}")

    @field_validator("history_images")
    @classmethod
    def _images(cls, value: int, info: ValidationInfo) -> int:
        turns = info.data.get("history")
        turns = 0 if turns in (None, "none") else turns
        if value > turns:
            raise ValueError(f"history_images ({value}) cannot exceed the earlier turns sent "
                             f"(history={turns or 'none'})")
        return value


class ModelOptions(ConversationOptions):
    """What every SDK pilot (`pilots.model.ModelPilot`) takes; each provider's class adds its own and its model."""

    model: str
    api_key: SecretStr | None = Field(None, repr=False)  # default: the provider's environment variable
    base_url: str | None = None  # default: the provider's environment variable, else its official API
    timeout: float = Field(30.0, gt=0)  # seconds per HTTP call
    max_retries: int = Field(2, ge=0)
    max_output_tokens: int = Field(512, gt=0)  # a decision is ~100 tokens: this caps the request too
    temperature: float | None = None
    jpeg_quality: int = Field(85, ge=1, le=100)
    max_side: int | None = None
    validate_replies: bool = Field(True, alias="validate")  # `validate` would shadow BaseModel.validate
    prices: Path | dict[str, Any] | None = None  # a price file, or a table {model: pricing.Price}


def parse_option_pairs(pairs: Iterable[str]) -> dict[str, str]:
    """['detail=high', 'timeout=30'] -> {'detail': 'high', 'timeout': '30'}; no '=' or a key twice is refused."""
    out: dict[str, str] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--pilot-option takes KEY=VALUE (e.g. detail=high), got {shorten(pair)!r}")
        if key in out:
            raise ConfigError(f"--pilot-option {key!r} given twice")
        out[key] = value.strip()
    return out


def _is_secret(annotation: Any) -> bool:
    return annotation is SecretStr or SecretStr in getattr(annotation, "__args__", ())


def secret_value(secret: SecretStr | None) -> str | None:
    return secret.get_secret_value() if secret is not None else None
