"""Planning before take-off: one call asks the pilot to turn the instruction into a mission's stages.

The call carries the instruction, the topological map (rooms, doors and the objects of each room) and a JSON
schema whose enums are the scene's room and object ids (`plan_schema`). The answer is the stages and the rooms
to avoid, or a refusal with its reason (a clarification question is a refusal that names the choices). The
controller validates the plan against the map (`mission.validate_mission`: every stage exists and is reachable)
and re-asks once, with the reason, when it is invalid; an instruction that cannot be planned is a `PlanError`
(one line, exit code 2), and nothing is flown.

Who plans: a model pilot (`ModelPilot.complete`, the same SDK call as a step, without an image), and any pilot
with a `plan(prompt) -> (text, Usage)` method: `stdin`, `files` and `remote` (and through it the server's
`POST /v1/plan`). The oracle, the replay and the other pilots fly the deterministic parser's plan
(`tasks.mission_parser.plan_mission`).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from string import Template
from typing import Any, TypeGuard

from vlnpilot.core.decision import Usage
from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.exits import shorten
from vlnpilot.pilots.base import Pilot, PilotError
from vlnpilot.prompting.render import Prompt, _template
from vlnpilot.scene.model import Scene
from vlnpilot.tasks.mission import STAGE_KINDS, Mission, PlanError, Stage, offers, validate_mission
from vlnpilot.tasks.mission_parser import plan_mission
from vlnpilot.tasks.task import check_query_text

MAX_REASKS = 1  # an invalid plan is asked again once, with the reason
PLANNERS = ("auto", "pilot", "parser")  # auto: the pilot plans what is not a plain one-goal query, if it plans


def plan_schema(scene: Scene) -> dict[str, Any]:
    """The answer's JSON schema, in the subset OpenAI strict structured outputs accept; the enums are the map's."""
    rooms, targets = [r.id for r in scene.rooms], [t.id for t in scene.targets]
    stage = {"type": "object", "additionalProperties": False, "required": ["kind", "room", "target"],
             "properties": {
                 "kind": {"type": "string", "enum": list(STAGE_KINDS)},
                 "room": {"type": ["string", "null"], "enum": [*rooms, None], "description": "a room id"},
                 "target": {"type": ["string", "null"], "enum": [*targets, None], "description": "an object id"}}}
    return {"type": "object", "additionalProperties": False, "required": ["stages", "avoid", "refusal"],
            "properties": {
                "stages": {"type": "array", "items": stage, "description": "the stages in order; empty if refused"},
                "avoid": {"type": "array", "items": {"type": "string", "enum": rooms},
                          "description": "rooms never to enter"},
                "refusal": {"type": ["string", "null"],
                            "description": "why the instruction cannot be flown, or a question naming the choices"}}}


def plan_map(scene: Scene) -> dict[str, Any]:
    """The topological map of the step prompts, plus the objects (the planner must name them by id)."""
    return {**scene.topological_map(),
            "objects": [{"id": t.id, "name": t.name, "room": t.room, "aliases": list(t.aliases)}
                        for t in scene.targets]}


def plan_prompt(query: str, scene: Scene, start_room: str | None, feedback: str | None = None) -> Prompt:
    """The planning call in `Prompt`'s shape (no image), so that every model pilot sends it as it sends a step."""
    dumped = json.dumps(plan_map(scene), indent=2, sort_keys=True, ensure_ascii=False)
    rules = Template(_template("plan.md")).substitute(start_room=start_room or "unknown")
    context = (f"## User instruction\n{query.strip()}\n\n## Topological map\n"
               f"Nodes are rooms, edges open doors, objects are what the drone can find.\n\n```json\n{dumped}\n```\n")
    step = f"## Take-off room\n{start_room or 'unknown'}\n"
    if feedback:
        step += f"\n## Controller feedback\n- Your previous plan was rejected: {feedback} Answer again.\n"
    return Prompt(system=rules, context=context, state_prompt="", step_text=step, image_jpeg=b"",
                  schema=plan_schema(scene))


def can_plan(pilot: Pilot | None) -> TypeGuard[Pilot]:
    """Whether this pilot answers the planning call (else the deterministic parser plans)."""
    return pilot is not None and (callable(getattr(pilot, "plan", None)) or callable(getattr(pilot, "complete", None)))


def planning_call(pilot: Pilot) -> Callable[[Prompt], tuple[str, Usage]]:
    """The call that plans: the pilot's own `plan`, else its `complete` (a pilot `can_plan` accepts has one)."""
    ask: Callable[[Prompt], tuple[str, Usage]] | None = getattr(pilot, "plan", None) or getattr(pilot, "complete", None)
    if ask is None:
        raise PlanError(f"pilot {pilot.name!r} does not plan")
    return ask


@dataclass
class Planning:
    """The planning exchange, for the run's header: each call's answer, its rejection, its usage."""

    calls: list[dict[str, Any]] = field(default_factory=list)

    @property
    def usage(self) -> Usage:
        total = Usage()
        for call in self.calls:
            total = total + Usage(**call["usage"])
        return total


def read_plan(raw: str, query: str, scene: Scene, source: str) -> Mission:
    """A planning answer as a Mission (not yet validated); a refusal or an unreadable answer is a PlanError."""
    try:
        data = json.loads(raw[raw.index("{"): raw.rindex("}") + 1])
    except ValueError:
        raise PlanError(f"the plan is not a JSON object: {shorten(raw)!r}") from None
    if not isinstance(data, dict):
        raise PlanError("the plan is not a JSON object")
    if data.get("refusal"):
        raise Refused(str(data["refusal"]))
    stages = data.get("stages")
    if not isinstance(stages, list) or not stages:
        raise PlanError("the plan has no stages and no refusal")
    out = []
    for i, s in enumerate(stages, 1):
        if not isinstance(s, dict) or s.get("kind") not in STAGE_KINDS:
            raise PlanError(f"stage {i} must be an object whose kind is one of {', '.join(STAGE_KINDS)}")
        room = s.get("room") if s["kind"] != "return" else None  # a return goes where the drone took off
        out.append(Stage(s["kind"], room, s.get("target") if s["kind"] == "object" else None, ""))
    avoid = data.get("avoid") or []
    if not isinstance(avoid, list):
        raise PlanError("avoid must be a list of room ids")
    return Mission(query=query, stages=tuple(out), avoid=tuple(str(a) for a in avoid), source=source)


class Refused(PlanError):
    """The pilot refused the instruction (or asked which of several things was meant)."""


def check_planner(planner: str) -> str:
    """`planner` if it is one of PLANNERS, else a PlanError naming them."""
    if planner not in PLANNERS:
        raise PlanError(f"unknown planner {planner!r}; valid planners: {', '.join(PLANNERS)}")
    return planner


def plan_instruction(query: str, scene: Scene, start_room: str | None, pilot: Pilot | None = None,
                     say: Callable[[str], None] | None = None, planner: str = "auto") -> tuple[Mission, Planning]:
    """The mission to fly, by `planner`: `parser`; `pilot` (a pilot that plans; validated, re-asked once); or
    `auto`: a plain one-goal query the parser reads as today (no planning call, so every such run flies as
    before), anything else by the pilot if it plans, else by the parser."""
    check_query_text(query)  # before any planning call: no pilot is sent a query it could not be sent
    planning = Planning()
    check_planner(planner)
    if planner == "pilot" and not can_plan(pilot):
        raise PlanError(f"pilot {getattr(pilot, 'name', None)!r} does not plan; pilots that plan: the model "
                        "pilots, stdin, files, remote (or use --planner parser)")
    if planner == "parser" or not can_plan(pilot) or (planner == "auto" and _plain(query, scene, start_room)):
        return plan_mission(query, scene, start_room), planning
    feedback = None
    for attempt in range(MAX_REASKS + 1):
        raw, usage, error = _ask(pilot, plan_prompt(query, scene, start_room, feedback))
        call: dict[str, Any] = {"attempt": attempt, "raw_text": raw, "usage": usage.model_dump(),
                                **({"attempts": list(usage.attempts)} if usage.attempts else {})}  # its HTTP attempts
        planning.calls.append(call)
        if error is not None:
            call["error"] = error
            raise PlanError(f"the pilot could not plan {shorten(query)!r}: {error}")
        try:
            mission = validate_mission(read_plan(raw, query, scene, pilot.name), scene, start_room)
        except Refused as exc:
            call["refusal"] = str(exc)
            raise PlanError(f"the pilot refused {shorten(query)!r}: {exc}; {offers(scene)}") from None
        except PlanError as exc:
            call["error"] = feedback = str(exc)
            if say is not None:
                say(f"plan rejected: {exc}")
            continue
        return replace(mission, planning=tuple(planning.calls)), planning
    raise PlanError(f"the pilot's plan for {shorten(query)!r} was invalid twice: {feedback}")


def _plain(query: str, scene: Scene, start_room: str | None) -> bool:
    try:
        return plan_mission(query, scene, start_room).is_single
    except PlanError:
        return False


def _ask(pilot: Any, prompt: Prompt) -> tuple[str, Usage, str | None]:
    """One planning call: (the answer's text, its usage, an error or None)."""
    ask = planning_call(pilot)
    try:
        raw, usage = ask(prompt)
    except PilotError as exc:
        return getattr(exc, "raw_text", None) or "", getattr(exc, "usage", None) or Usage(), f"{exc.reason}: {exc}"
    except VLNPilotError as exc:
        return "", Usage(), str(exc)
    return raw, usage, None
