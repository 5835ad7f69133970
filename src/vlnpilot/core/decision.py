"""The pilot <-> controller contract: what a pilot sees (PilotInput), what it answers (Decision), and the one
place where an answer is parsed, validated against the FSM table and normalised.

It sits on the floor of `fsm.py` and `commands.py` (it reads their tables) and below every pilot, so that the
prompts, the pilots, the server and the episode loop all read the same definition. The five decision fields
are the fields of `DecisionFields`; `FIELDS`, `Decision.core()`, the JSON schema's `required` list and the
server's response model all derive from it.
"""

from __future__ import annotations

import ast
import json
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from vlnpilot.core.commands import get_command
from vlnpilot.core.errors import UnknownNameError, VLNPilotError
from vlnpilot.core.fsm import State, parse_state, state_spec

DoorPosition = Literal["left", "center", "right", "not_visible"]
DOOR_POSITIONS: tuple[str, ...] = get_args(DoorPosition)

# Short codes of an unusable reply. They are the PilotError reasons a model pilot raises (and the server relays),
# so they are recorded in runs: never rename one.
NOT_JSON = "not_json"  # no object with the decision fields in the reply
MISSING_FIELD = "missing_field"  # an object, but a required field is absent or null
INVALID_VALUE = "invalid_value"  # a field of the wrong type (or a reply that is not text)
INVALID_ENUM = "invalid_enum"  # a value outside its set: door_position, or a move/next state the FSM refuses
TOO_LONG = "too_long"  # longer than MAX_REPLY_CHARS: never searched
DECISION_ERROR_CODES = (NOT_JSON, MISSING_FIELD, INVALID_VALUE, INVALID_ENUM, TOO_LONG)


class Usage(BaseModel):
    """Token usage of one model call as the API reports it, and its wall-clock latency."""

    model_config = ConfigDict(frozen=True)
    input_tokens: int = 0  # every prompt token, cached ones and cache writes included
    cached_tokens: int = 0  # read from the provider's prompt cache (OpenAI, Gemini, Anthropic's cache reads)
    output_tokens: int = 0
    cache_write_tokens: int = 0  # written to the cache (Anthropic's cache_creation_input_tokens; others: 0)
    latency_s: float = 0.0
    cost_usd: float = 0.0
    priced: bool = True  # False when the model is missing from the price table (cost then reads 0)
    # The call's HTTP attempts (pilots/attempts.py), SDK retries included; written in the step's `attempts`, not
    # in `usage`, so that a usage reads as before.
    attempts: tuple[dict[str, Any], ...] = Field(default=(), exclude=True)

    def __add__(self, other: Usage) -> Usage:
        sums = {k: getattr(self, k) + getattr(other, k) for k in Usage.model_fields if k not in ("priced", "attempts")}
        return Usage(**sums, priced=self.priced and other.priced)


class DecisionFields(BaseModel):
    """The paper's output format (Appendix C): the one definition of the five decision fields."""

    model_config = ConfigDict(frozen=True)
    room: str
    movement: str
    state: str
    description: str = ""
    door_position: DoorPosition = "not_visible"


FIELDS: tuple[str, ...] = tuple(DecisionFields.model_fields)


class Decision(DecisionFields):
    """One answer of the pilot, exactly the paper's output format plus metadata.

    `movement` and `state` are kept as the model wrote them; the controller validates them against
    the FSM table before anything moves.
    """

    # metadata (never sent to the model)
    raw_text: str | None = Field(default=None, exclude=False)
    usage: Usage = Field(default_factory=Usage)
    model: str | None = None

    def core(self) -> dict[str, str]:
        """The five fields of the paper's output format."""
        return {k: getattr(self, k) for k in FIELDS}


@dataclass(frozen=True)
class EarlierTurn:
    """One earlier step of a pilot's conversation (the `history` option): what the pilot was asked then and what it
    answered. The query, map and profile are the episode's; `image` is None when it is not sent again."""

    step: int
    state: State
    previous_movement: str | None
    answer: str  # the model's own reply text
    image: np.ndarray | None = field(default=None, repr=False)
    feedback: tuple[str, ...] = ()
    context: tuple[str, ...] = ()
    in_state: str | None = None


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
    context: tuple[str, ...] = ()  # pilot context beyond the paper (prompting.context): odometry, budget, memory
    # What the previous states and movements imply about the current state (the moves flown in it), stated by the
    # controller in every context so that no rule needs the pilot's memory (vlnpilot.prompting.context.StateProgress).
    in_state: str | None = None
    # The conversation so far, when the caller holds it (the pilot server's client): None lets a model pilot use
    # its own `history` option; a tuple (even empty) is the whole conversation, and the pilot remembers nothing.
    history: tuple[EarlierTurn, ...] | None = None
    # A mission of several stages (vlnpilot.tasks.mission: Mission.to_dict()) and the current stage (0-based); None for
    # a one-stage mission, whose prompt is the paper's.
    mission: Mapping[str, Any] | None = None
    stage: int = 0


class DecisionError(VLNPilotError):
    """A model reply that cannot be read as a Decision.

    `reason` says why in one line (it is fed back on a re-ask); `code` is one of DECISION_ERROR_CODES.
    """

    def __init__(self, reason: str, raw_text: str | None = None, *, code: str = NOT_JSON):
        super().__init__(reason)
        self.reason = reason
        self.raw_text = raw_text
        self.code = code


# ------------------------------------------------------------------------------------------------------ parse

MAX_REPLY_CHARS = 100_000  # characters of a reply that are searched for the JSON object
_MAX_STARTS = 200  # '{' positions tried (bounds the work on adversarial replies)
_MAX_OBJECT = 8_000  # characters a Python-dict style answer may span
_DICT_START_RE = re.compile(r"\{\s*['\"]")
_FENCE_RE = re.compile(r"```[ \t]*([A-Za-z0-9_+-]*)[ \t]*\n?(.*?)```", re.S)
_DOOR_ALIASES = {"centre": "center", "middle": "center", "notvisible": "not_visible", "none": "not_visible"}


def _balanced_end(text: str, start: int) -> int | None:
    """Index of the '}' closing the '{' at `start`, skipping '...' and "..." strings; None if unbalanced."""
    depth, quote, escaped = 0, "", False
    for i in range(start, min(len(text), start + _MAX_OBJECT)):
        ch = text[i]
        if quote:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
            if depth == 0:
                return i
    return None


def _decode_at(text: str, start: int) -> Any:
    try:
        return json.JSONDecoder().raw_decode(text, start)[0]
    except (ValueError, RecursionError):
        pass
    if not _DICT_START_RE.match(text, start):
        return None
    end = _balanced_end(text, start)
    if end is None:
        return None
    try:  # the paper's Appendix D: a Python dict with single quotes
        return ast.literal_eval(text[start : end + 1])
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        return None


def _dicts(text: str) -> Iterator[dict]:
    """Every dict found in the reply: fenced blocks first, then the whole text, outer objects before inner ones."""
    sources = [m.group(2) for m in _FENCE_RE.finditer(text)] + [text]
    tried = 0
    for source in sources:
        for match in re.finditer(r"\{", source):
            tried += 1
            if tried > _MAX_STARTS:
                return
            obj = _decode_at(source, match.start())
            if isinstance(obj, dict):
                yield obj


def _string_field(obj: Mapping[str, Any], name: str, default: str | None = None) -> str:
    value = obj.get(name, default)
    if value is None:
        if default is None:
            raise DecisionError(f"field {name!r} is missing or null", code=MISSING_FIELD)
        value = default
    if not isinstance(value, str):
        raise DecisionError(f"field {name!r} must be a string, got {type(value).__name__} {value!r:.60}",
                            code=INVALID_VALUE)
    return value.strip()


def parse_decision(text: str) -> Decision:
    """Read a Decision out of a model reply (JSON, fenced JSON, prose around it, or Appendix D's Python dict).

    Raises DecisionError(reason) when there is no object, a field is missing or mistyped, or door_position is
    not one of left/center/right/not_visible. Movement and state are kept as written (see validate_decision).
    """
    if not isinstance(text, str):
        raise DecisionError(f"the reply must be text, got {type(text).__name__}", code=INVALID_VALUE)
    searched = text[:MAX_REPLY_CHARS]
    found: dict | None = None
    partial: dict | None = None
    for obj in _dicts(searched):
        keys = {str(k).strip().lower(): v for k, v in obj.items()}
        if {"movement", "state"} <= keys.keys():
            found = keys
            break
        if partial is None and keys.keys() & set(FIELDS):
            partial = keys
    if found is None:
        if partial is not None:
            missing = [f for f in ("room", "movement", "state") if f not in partial]
            raise DecisionError(f"the JSON object lacks the field(s) {', '.join(missing)}", text, code=MISSING_FIELD)
        raise DecisionError(
            f"no JSON object with the fields {', '.join(FIELDS)} found in the reply ({len(text)} characters)", text
        )
    if "room" not in found:
        raise DecisionError("the JSON object lacks the field(s) room", text, code=MISSING_FIELD)
    try:
        room = _string_field(found, "room", "unknown")
        movement = _string_field(found, "movement")
        state = _string_field(found, "state")
        description = _string_field(found, "description", "")
        door = _string_field(found, "door_position", "not_visible").lower()
    except DecisionError as exc:
        raise DecisionError(exc.reason, text, code=exc.code) from None
    door = re.sub(r"[\s\-]+", "_", door)
    door = _DOOR_ALIASES.get(door.replace("_", ""), door)
    if door not in DOOR_POSITIONS:
        raise DecisionError(f"door_position {door!r:.60} is not one of {', '.join(DOOR_POSITIONS)}", text,
                            code=INVALID_ENUM)
    return Decision(
        room=room or "unknown",
        movement=movement,
        state=state,
        description=description,
        door_position=door,  # type: ignore[arg-type]
        raw_text=text,
    )


# --------------------------------------------------------------------------------------------------- validate


def validate_decision(decision: Decision, state: State, profile: str = "paper") -> str | None:
    """None if the decision's movement and next state are allowed in `state`, else a one-line reason.

    The reason names the valid choices so that it can be fed back to the model on a re-ask.
    """
    spec = state_spec(state, profile)
    reasons: list[str] = []
    allowed_moves = ", ".join(spec.moves)
    allowed_next = ", ".join(f"'{s.value}'" for s in spec.next_states)
    nxt: State | None = None
    try:
        nxt = parse_state(decision.state)
    except UnknownNameError:
        reasons.append(f"next state {decision.state!r:.60} is not an FSM state; allowed from '{spec.state}': "
                       f"{allowed_next}")
    else:
        if nxt not in spec.next_states:
            reasons.append(f"next state '{nxt.value}' is not allowed from '{spec.state}'; allowed: {allowed_next}")
    try:
        code = get_command(decision.movement).code
    except UnknownNameError:
        reasons.insert(0, f"movement {decision.movement!r:.40} is not a movement command; allowed in "
                          f"'{spec.state}': {allowed_moves}")
    else:
        if not spec.allows(code, nxt if nxt in spec.next_states else spec.state):
            why = f"movement {code!r} is not allowed in state '{spec.state}'; allowed: {allowed_moves}"
            if nxt is not None and nxt is not spec.state and code in state_spec(nxt, profile).moves:
                why += (f" (the movement is flown now, in '{spec.state}'; the moves of '{nxt.value}' apply from "
                        "the next step)")
            reasons.insert(0, why)
    return "; ".join(reasons) or None


# -------------------------------------------------------------------------------------------------- normalise


def normalize_decision(decision: Decision) -> Decision:
    """The decision with its canonical movement code ('a1' -> 'A1') and state value ('search object' -> 'Search
    Object'); a field that names no command or state is left as written (validate_decision reports it)."""
    update: dict[str, str] = {}
    try:
        update["movement"] = get_command(decision.movement).code
    except UnknownNameError:
        pass
    try:
        update["state"] = parse_state(decision.state).value
    except UnknownNameError:
        pass
    return decision.model_copy(update=update)


@dataclass(frozen=True)
class PilotTraits:
    """What a pilot declares about itself (its class's `traits`), as an environment declares its `Capabilities`:
    what it does not declare, it does not get."""

    privileged: bool = False  # flies on ground truth (the oracle): `attach(gt)` first; refused where there is none
    validates_decisions: bool = False  # returns decisions already normalised and allowed in the state: checked once
    uses_step_deadline: bool = False  # waits on a network: the episode bounds each step (EpisodeConfig.step_deadline_s)


NO_TRAITS = PilotTraits()


def traits_of(pilot: object) -> PilotTraits:
    """A pilot's declared traits; `NO_TRAITS` if it declares none (a pilot written to the bare protocol)."""
    declared = getattr(pilot, "traits", None)
    return declared if isinstance(declared, PilotTraits) else NO_TRAITS
