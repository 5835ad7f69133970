"""Prompts of the paper's "VLLM Module" (Appendices A-C); reading the answer is `vlnpilot.core.decision`'s job.

The prompt has three parts: a system prompt identical for every episode (Appendix A + the output format of
Appendix C), the episode context (query + topological map), and a per-state prompt (Appendix B) whose
movement list, next states and valid answer values are rendered from `commands.COMMANDS` and the FSM table,
so that prompt, JSON schema and validation cannot disagree. The wording lives in `prompting/templates/*.md`.
"""

from __future__ import annotations

import hashlib
import io
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from string import Template
from typing import Any

import numpy as np
from PIL import Image

from vlnpilot.core.commands import COMMANDS, Command, Kind, get_command
from vlnpilot.core.decision import DOOR_POSITIONS, FIELDS, PilotInput
from vlnpilot.core.errors import ConfigError, UnknownNameError, VLNPilotError
from vlnpilot.core.fsm import ASKED_STATES, FINAL_STATES, PROFILES, State, StateSpec, parse_state, state_spec
from vlnpilot.core.movers import SHIELD_MARGIN_M
from vlnpilot.tasks.success import visual_cue_values

__all__ = [
    "Prompt",
    "IN_STATE_HEADING",
    "PromptTemplateError",
    "build_prompt",
    "decision_schema",
    "encode_jpeg",
    "map_rooms",
    "prompt_hash",
    "render_state_prompt",
    "render_state_template",
    "system_prompt",
]



UNREACHABLE_STATE = State.GOAL_UNREACHABLE.value  # the FSM's addition (issue 24) the events rules name

# The step text's section on the current state (`PilotInput.in_state`); the state prompts' rules refer to it by name.
IN_STATE_HEADING = "Flown in this state"


class PromptTemplateError(VLNPilotError):
    """A prompt template disagrees with the command or FSM table (raised at render time, never silently)."""


# --------------------------------------------------------------------------------------------------- templates

_TEMPLATE_DIR = "templates"


@cache
def _template(name: str) -> str:
    path = files("vlnpilot.prompting") / _TEMPLATE_DIR / name
    try:
        return path.read_text(encoding="utf-8").strip() + "\n"
    except FileNotFoundError:
        raise PromptTemplateError(f"prompt template {_TEMPLATE_DIR}/{name} is missing") from None


def _template_name(state: State) -> str:
    return f"state_{state.name.lower()}.md"


def _check_asked(state: State) -> None:
    if state not in ASKED_STATES:
        raise ConfigError(
            f"the pilot is never asked in state '{state}' (the controller handles Start; Final is terminal); "
            f"asked states: {', '.join(s.value for s in ASKED_STATES)}"
        )


def _codes(codes: Sequence[str]) -> str:
    return ", ".join(f"`{c}`" for c in codes)


def _prose_codes(codes: Sequence[str]) -> str:
    """'`A1`', '`A1` or `A2`', '`B1`, `B2` or `C1`': command lists inside policy sentences."""
    quoted = [f"`{c}`" for c in codes]
    return quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]


def _kind_title(kind: Kind) -> str:
    return {
        Kind.FORWARD: "Forward movement",
        Kind.ROTATE_RIGHT: "Right rotation (in place)",
        Kind.ROTATE_LEFT: "Left rotation (in place)",
        Kind.LATERAL_LEFT: "Lateral movement (sideways, no rotation)",
        Kind.LATERAL_RIGHT: "Lateral movement (sideways, no rotation)",
        Kind.NONE: "No movement",
    }[kind]


def _movement_commands(spec: StateSpec) -> str:
    """The MOVEMENT COMMANDS body of Appendix B, grouped by command letter, from the command and FSM tables."""
    groups: dict[str, list[Command]] = {}
    for code, command in COMMANDS.items():  # table order, not the order of `moves`
        if code in spec.answer_moves:
            groups.setdefault(code[0], []).append(command)
    finals = " or ".join(f"`{s.value}`" for s in spec.next_states if s in FINAL_STATES)
    lines = ["Only return **ONE** movement command from the list below:"]
    for letter, commands in groups.items():
        lines += ["", f"### {letter}. {_kind_title(commands[0].kind)}:"]
        lines += [f"- `{c.code}`: {c.description}{_use_of(c, spec, finals)}" for c in commands]
    lines += ["", "The movement is flown now, in this state; the moves of the next state apply from the next step."]
    return "\n".join(lines)


def _use_of(command: Command, spec: StateSpec, finals: str) -> str:
    """What a move is for, where the list must say it: `E` beside a final state only, or `E` in a state that goes
    on (the FSM's hover in every asked state, issue 24)."""
    if command.code not in spec.moves:
        return f", only together with the final state {finals}"
    if command.kind is Kind.NONE and not spec.final:
        return (": to wait for a person to pass, to look again from the same place, or to change state without "
                "moving; it costs a step")
    return ""


_SECTION_RE = re.compile(r"^## OUTPUT STATE RULES[ \t]*$(.*?)(?=^## |^---[ \t]*$|\Z)", re.M | re.S)
_RULE_RE = re.compile(r"^[ \t]*[-*][ \t]*`([^`]+)`[ \t]*:", re.M)
_CODE_RE = re.compile(r"`([A-Ea-e][1-3]?)`")


def _rule_states(text: str, where: str) -> list[State]:
    sections = _SECTION_RE.findall(text)
    if len(sections) != 1:
        raise PromptTemplateError(f"{where}: needs exactly one '## OUTPUT STATE RULES' section, found {len(sections)}")
    names = _RULE_RE.findall(sections[0])
    states: list[State] = []
    for name in names:
        try:
            states.append(parse_state(name))
        except UnknownNameError as exc:
            raise PromptTemplateError(f"{where}: OUTPUT STATE RULES: {exc}") from None
    return states


def render_state_template(template: str, spec: StateSpec, *, where: str = "state template") -> str:
    """Render one Appendix-B state template against its table row; fail loudly if they disagree.

    Checks: the OUTPUT STATE RULES name each allowed next state exactly once and nothing else; every
    command code quoted in the template's own prose is allowed in the state; every placeholder is known.
    """
    rule_states = _rule_states(template, where)
    allowed = set(spec.next_states)
    duplicated = sorted({s.value for s in rule_states if rule_states.count(s) > 1})
    extra = [s.value for s in rule_states if s not in allowed]
    missing = [s.value for s in spec.next_states if s not in rule_states]
    if duplicated or extra or missing:
        raise PromptTemplateError(
            f"{where}: OUTPUT STATE RULES disagree with the FSM table for '{spec.state}': "
            f"not allowed: {extra or 'none'}; missing: {missing or 'none'}; duplicated: {duplicated or 'none'}; "
            f"allowed next states: {', '.join(s.value for s in spec.next_states)}"
        )
    if "$movement_commands" not in template:
        raise PromptTemplateError(f"{where}: must contain the $movement_commands placeholder")
    named = {c.upper() for c in _CODE_RE.findall(template)}
    bad = sorted(c for c in named if c not in spec.answer_moves)
    if bad:
        raise PromptTemplateError(
            f"{where}: names commands {bad} that are not allowed in '{spec.state}' (allowed: {', '.join(spec.moves)})"
        )

    def of(*kinds: Kind) -> list[str]:
        return [c for c in spec.moves if COMMANDS[c].kind in kinds]

    values: dict[str, str] = {
        "state": spec.state.value,
        "goal": spec.goal,
        "movement_commands": _movement_commands(spec),
    }
    groups = {
        "forward_moves": of(Kind.FORWARD),
        "rotations": of(Kind.ROTATE_RIGHT, Kind.ROTATE_LEFT),
    }
    values.update({name: _prose_codes(codes) for name, codes in groups.items() if codes})  # empty group: KeyError below
    # Direction words come from the command table, so a template cannot pair a code with the wrong direction.
    smallest = {"left_turn": Kind.ROTATE_LEFT, "right_turn": Kind.ROTATE_RIGHT, "slide_left": Kind.LATERAL_LEFT,
                "slide_right": Kind.LATERAL_RIGHT}
    for name, kind in smallest.items():
        if codes := sorted(of(kind), key=lambda c: COMMANDS[c].amount):
            values[name] = f"`{codes[0]}`"
    values.update(visual_cue_values())
    try:
        body = Template(template).substitute(values)
    except (KeyError, ValueError) as exc:
        raise PromptTemplateError(
            f"{where}: bad or unavailable placeholder {exc} in state '{spec.state}'; available: {sorted(values)}"
        ) from None
    output_values = Template(_template("output_values.md")).substitute(
        movements=_codes(spec.answer_moves),
        states=_codes([s.value for s in spec.next_states]),
        door_positions=_codes(DOOR_POSITIONS),
    )
    return body.rstrip() + "\n\n---\n\n" + output_values


@cache
def render_state_prompt(state: State | str, profile: str = "paper") -> str:
    """This state's prompt (Appendix B style) for an FSM profile, rendered from the command and FSM tables."""
    spec = state_spec(state, profile)
    _check_asked(spec.state)
    name = _template_name(spec.state)
    return render_state_template(_template(name), spec, where=f"{_TEMPLATE_DIR}/{name}")


@cache
def system_prompt() -> str:
    """Appendix A + Appendix C: the same text for every episode, state and profile (a cacheable prefix), with the
    rules on people, pets, closed doors and text in the scene added beside the paper's (issue 24, `events.md`)."""
    return _template("system.md").rstrip() + "\n\n" + events_rules().rstrip() + "\n\n---\n\n" + _template("output.md")


def events_rules() -> str:
    """The system prompt's added section on people, pets, closed doors and scene text; its numbers are the mover
    shield's margins (`core.movers.SHIELD_MARGIN_M`) and its state is the FSM's."""
    margins = {f"{kind}_margin": f"{metres * 100:.0f}" for kind, metres in SHIELD_MARGIN_M.items()}
    return Template(_template("events.md")).substitute(margins, unreachable=UNREACHABLE_STATE)


# ----------------------------------------------------------------------------------------------------- inputs


def map_rooms(topological_map: Mapping[str, Any]) -> list[str]:
    """Room ids of a topological map (nodes as dicts with `id`/`name`, as plain strings, or an id->node mapping)."""
    nodes = topological_map.get("nodes", topological_map.get("rooms", ()))
    if isinstance(nodes, Mapping):
        return [str(k) for k in nodes]
    rooms: list[str] = []
    for node in nodes or ():
        if isinstance(node, Mapping):
            room = node.get("id", node.get("name"))
            if room is not None:
                rooms.append(str(room))
        else:
            rooms.append(str(node))
    return list(dict.fromkeys(rooms))


def _context(query: str, topological_map: Mapping[str, Any], mission: Mapping[str, Any] | None = None,
             stage: int = 0) -> str:
    dumped = json.dumps(topological_map, indent=2, sort_keys=True, ensure_ascii=False, default=str)
    plan = "" if mission is None else mission_text(mission, stage) + "\n"
    return (
        f"## User query\n{query.strip()}\n\n{plan}"
        "## Topological map\n"
        "Nodes are rooms (`id`, `name`); edges are open doors between two rooms.\n\n"
        f"```json\n{dumped}\n```\n"
    )


_STAGE_GOALS = {  # a stage's goal in the plan, by kind (vlnpilot.tasks.mission.STAGE_KINDS)
    "room": "go to the room `{room}` and declare `{stay}` there",
    "object": "find the object `{target}` in the room `{room}` and declare `{describe}` in front of it",
    "return": "return to the room `{room}`, where the drone started, and declare `{stay}` there",
}


def mission_text(mission: Mapping[str, Any], stage: int) -> str:
    """The plan of a mission of several stages: every stage, which are done and which is current."""
    lines = []
    for i, s in enumerate(mission["stages"]):
        status = "done" if i < stage else ("current" if i == stage else "to do")
        goal = _STAGE_GOALS[s["kind"]].format(room=s.get("room"), target=s.get("target"),
                                              stay=State.STAY_ON_ROOM.value, describe=State.DESCRIBE_OBJECT.value)
        lines.append(f"- Stage {i + 1} ({status}): {goal}.")
    if mission.get("avoid"):
        lines.append("- Throughout: never enter " + ", ".join(f"`{r}`" for r in mission["avoid"])
                     + ", not even to pass through.")
    finals = " or ".join(f"`{s.value}`" for s in (State.STAY_ON_ROOM, State.DESCRIBE_OBJECT))
    return Template(_template("mission.md")).substitute(count=len(mission["stages"]), finals=finals,
                                                        first_state=State.RECOGNIZE_ROOM.value,
                                                        stages="\n".join(lines)).rstrip() + "\n"


def _step_text(state: State, previous_movement: str | None, step: int, feedback: Sequence[str],
               context: Sequence[str] = (), in_state: str | None = None) -> str:
    if previous_movement is None or not str(previous_movement).strip():
        previous = "none (this is the first step of the episode)"
    else:
        try:
            command = get_command(previous_movement)
            previous = f"`{command.code}` ({command.description})"
        except UnknownNameError:
            previous = f"`{previous_movement}`"
    text = f"## Current FSM state\n{state.value}\n\n## Previous movement\n{previous}\n\n"
    if in_state:  # what the previous states and movements imply: the rules that count moves read it
        text += f"## {IN_STATE_HEADING}\n{' '.join(in_state.split())}\n\n"
    text += f"## Step\n{step}\n"
    if context:
        nested = ("  - " if line.startswith(" ") else "- " for line in context)  # memory items nest
        items = zip(nested, context, strict=True)
        # explained where it appears, never in the system prompt: under the paper's inputs it does not exist
        text += "\n## Pilot context\n" + _template("pilot_context.md").strip() + "\n" + \
            "".join(f"{b}{line.strip()}\n" for b, line in items)
    lines = [" ".join(str(line).split()) for line in feedback if line and str(line).strip()]
    if lines:
        text += "\n## Controller feedback\n" + "\n".join(f"- {line}" for line in lines) + "\n"
    return text


def encode_jpeg(image: np.ndarray, quality: int = 85, max_side: int | None = None) -> bytes:
    """Encode an HxWx3 uint8 RGB image (HxWx4 and HxW accepted) as JPEG, downscaled so that max(H, W) <= max_side."""
    arr = np.asarray(image)
    if arr.dtype != np.uint8:
        raise ConfigError(f"image must be uint8, got {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] == 4:
        arr = arr[:, :, :3]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)) or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ConfigError(f"image must be HxWx3 (RGB), got shape {arr.shape}")
    if not 1 <= int(quality) <= 100:
        raise ConfigError(f"jpeg quality must be in 1..100, got {quality}")
    if max_side is not None and max_side < 1:
        raise ConfigError(f"max_side must be >= 1, got {max_side}")
    img = Image.fromarray(np.ascontiguousarray(arr))
    if max_side is not None and max(img.size) > max_side:
        scale = max_side / max(img.size)
        size = (max(1, round(img.width * scale)), max(1, round(img.height * scale)))
        img = img.resize(size, Image.Resampling.BILINEAR, reducing_gap=2.0)
    buf = io.BytesIO()
    img.save(buf, format="JPEG", quality=int(quality))
    return buf.getvalue()


# ------------------------------------------------------------------------------------------------------ prompt


@dataclass(frozen=True)
class Prompt:
    """One step's prompt, split so that the stable parts come first (provider prompt caches key on prefixes)."""

    system: str  # Appendix A + Appendix C: identical for every episode (cache-friendly prefix)
    context: str  # the user query + topological map JSON: constant within an episode
    state_prompt: str  # this state's prompt (Appendix B style), rendered from the FSM + command tables
    step_text: str  # current FSM state, previous movement, step number, controller feedback lines
    image_jpeg: bytes  # the front image as JPEG
    schema: dict  # JSON schema of this state's answer (see decision_schema)

    def user_text(self) -> str:
        """context + state_prompt + step_text, in that order (stable parts first)."""
        return "\n---\n\n".join(part.rstrip() + "\n" for part in (self.context, self.state_prompt, self.step_text))


def build_prompt(pilot_input: PilotInput, *, jpeg_quality: int = 85, max_side: int | None = None) -> Prompt:
    """Everything a model pilot sends for one step: texts from the templates and tables, JPEG, answer schema."""
    state = pilot_input.state if isinstance(pilot_input.state, State) else parse_state(pilot_input.state)
    return Prompt(
        system=system_prompt(),
        context=_context(pilot_input.query, pilot_input.topological_map, pilot_input.mission, pilot_input.stage),
        state_prompt=render_state_prompt(state, pilot_input.profile),
        step_text=_step_text(state, pilot_input.previous_movement, pilot_input.step, pilot_input.feedback,
                             pilot_input.context, pilot_input.in_state),
        image_jpeg=encode_jpeg(pilot_input.image, jpeg_quality, max_side),
        schema=decision_schema(state, pilot_input.profile, map_rooms(pilot_input.topological_map)),
    )


def decision_schema(state: State, profile: str = "paper", rooms: Sequence[str] | None = None) -> dict:
    """JSON schema of this state's answer, in the subset that OpenAI strict structured outputs accept."""
    spec = state_spec(state, profile)
    _check_asked(spec.state)
    room: dict[str, Any] = {"type": "string", "description": "id of the current room in the map, or unknown"}
    if rooms is not None:
        room["enum"] = list(dict.fromkeys([*(str(r) for r in rooms), "unknown"]))
    properties: dict[str, Any] = {
        "room": room,
        "movement": {"type": "string", "enum": list(spec.answer_moves), "description": "one movement command"},
        "state": {"type": "string", "enum": [s.value for s in spec.next_states], "description": "next FSM state"},
        "description": {"type": "string", "description": "what the drone sees and why it decides so"},
        "door_position": {"type": "string", "enum": list(DOOR_POSITIONS), "description": "where a door is"},
    }
    return {"type": "object", "properties": properties, "required": list(FIELDS), "additionalProperties": False}


MESSAGE_LAYOUT = "system; user: context, state prompt, step text, image"  # image last since issue 27


def prompt_hash(profile: str = "paper") -> str:
    """A short sha256 of every prompt text rendered for every asked state of a profile: run provenance."""
    if profile not in PROFILES:
        raise UnknownNameError("FSM profile", profile, PROFILES)
    h = hashlib.sha256()
    sample_map = {"edges": [{"from": "a", "to": "b"}], "nodes": [{"id": "a", "name": "A"}, {"id": "b", "name": "B"}]}
    # the order a model pilot sends them in (pilots/_history.py): a change of it changes what a pilot sees
    parts = [MESSAGE_LAYOUT, system_prompt(), _context("query", sample_map)]
    for state in ASKED_STATES:
        parts += [render_state_prompt(state, profile),
                  _step_text(state, "A1", 1, ("feedback",), ("context",), "in state")]
        parts.append(json.dumps(decision_schema(state, profile, ["a", "b"]), sort_keys=True))
    for part in parts:
        h.update(part.encode("utf-8") + b"\x00")
    return h.hexdigest()[:12]
