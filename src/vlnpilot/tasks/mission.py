"""Missions: an instruction as an ordered tuple of stages, validated against the map before take-off.

A `Stage` is a room goal, an object goal, or a return to the room the drone started in. A `Mission` is the
instruction, its stages, and the rooms it must avoid on the way. A one-stage mission with nothing to avoid is
today's `tasks.Task` (`Mission.from_task`, `Mission.task`), so every run, bench and trial keeps its meaning.

`plan_mission` reads an instruction with the deterministic parser (`vlnpilot.tasks.mission_parser`) and validates it
(`validate_mission`): every stage exists, every object is in its room, and every stage is reachable from the
one before through open doors without entering a room to avoid. A model pilot's plan goes through the same
validation (`pilots/planning.py`). Anything that cannot be planned raises `PlanError`, one line naming what was
not understood and what the map offers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

from vlnpilot.core.environment import GroundTruth
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Pose
from vlnpilot.scene.model import EXTERIOR, Scene
from vlnpilot.tasks.success import DEFAULT_SUCCESS, SuccessConfig
from vlnpilot.tasks.task import QueryError, Task, judge, shortest_path_length, shortest_path_points

StageKind = Literal["room", "object", "return"]
STAGE_KINDS: tuple[str, ...] = ("room", "object", "return")
STEPS_PER_STAGE_NOTE = "max_steps x stages"  # how the default budget scales (EpisodeConfig.max_steps is per stage)


class PlanError(QueryError):
    """An instruction that cannot be planned: the message names the part not understood and what the map offers."""


PARSER = "parser"  # the source of a mission the rule-based parser planned (tasks/mission_parser.py)


@dataclass(frozen=True)
class Stage:
    """One goal of a mission. `room` is None only for a return not yet resolved against the start."""

    kind: StageKind
    room: str | None = None
    target: str | None = None
    words: str = ""  # the part of the instruction this stage was read from

    def plan(self) -> dict[str, Any]:
        """The plan as the suites write it: {room: X}, {object: T} or {return: true} (resolved: {return: X})."""
        if self.kind == "object":
            return {"object": self.target}
        if self.kind == "return":
            return {"return": self.room or True}
        return {"room": self.room}

    def task(self, query: str) -> Task:
        if self.room is None:
            raise PlanError("a return stage must be resolved against the start room before it is flown")
        return Task(query=query, goal_room=self.room, goal_target=self.target)


@dataclass(frozen=True)
class Mission:
    query: str
    stages: tuple[Stage, ...]
    avoid: tuple[str, ...] = ()  # rooms the drone must never enter ("don't go to the bathroom")
    not_goals: tuple[str, ...] = ()  # rooms or objects the instruction names as not wanted ("not the bathroom")
    source: str = PARSER  # parser | the pilot that planned it
    planning: tuple[dict[str, Any], ...] = field(default=(), compare=False)  # the planning calls (pilots/planning)

    @classmethod
    def from_task(cls, task: Task) -> Mission:
        kind: StageKind = "object" if task.goal_target else "room"
        return cls(query=task.query, stages=(Stage(kind, task.goal_room, task.goal_target, task.query),))

    @property
    def recorded(self) -> bool:
        """Whether a run's header records the mission: several stages, or a plan that a pilot made."""
        return not self.is_single or self.source != PARSER

    @property
    def is_single(self) -> bool:
        """One stage and nothing to avoid: today's Task, flown and prompted exactly as before."""
        return len(self.stages) == 1 and not self.avoid and not self.not_goals and self.stages[0].kind != "return"

    def task(self, k: int = 0) -> Task:
        """Stage k as the Task the judge, the oracle and SPL read (stage 0 of a single mission: today's Task)."""
        return self.stages[k].task(self.query)

    # Today's Task attributes, of the last stage, so that readers of a Task read a mission too.
    @property
    def goal_room(self) -> str:
        return self.stages[-1].room or ""

    @property
    def goal_target(self) -> str | None:
        return self.stages[-1].target

    @property
    def kind(self) -> str:
        return "object" if self.goal_target else "room"

    def resolved(self, start_room: str | None) -> Mission:
        """Returns point at the start room."""
        if not any(s.kind == "return" and s.room is None for s in self.stages):
            return self
        if start_room is None:
            raise PlanError("a return to the start needs a start inside a room of the map")
        return replace(self, stages=tuple(replace(s, room=start_room) if s.kind == "return" and s.room is None
                                          else s for s in self.stages))

    def plan(self) -> dict[str, Any]:
        out: dict[str, Any] = {"stages": [s.plan() for s in self.stages]}
        if self.avoid:
            out["avoid"] = list(self.avoid)
        if self.not_goals:
            out["not"] = list(self.not_goals)
        return out

    def suite_row(self) -> dict[str, Any]:
        """What a suite row writes of this mission: its plan, and who planned it where the parser did not (a suite flies
        a pilot's plan as written, bench/suite.py)."""
        return {"plan": self.plan(), **({"planned_by": self.source} if self.source != PARSER else {})}

    def to_dict(self) -> dict[str, Any]:
        """As recorded in a run's header and sent to pilots: the stages with their rooms and targets."""
        return {"query": self.query, "source": self.source, "avoid": list(self.avoid),
                "not_goals": list(self.not_goals),
                "stages": [{"kind": s.kind, "room": s.room, "target": s.target, "words": s.words}
                           for s in self.stages], **({"planning": list(self.planning)} if self.planning else {})}

    @classmethod
    def from_plan(cls, query: str, plan: Mapping[str, Any], scene: Scene, source: str) -> Mission:
        """A plan as the suites write it (`plan()`: {room: X}, {object: T}, {return: X or true}, avoid, not) as a
        Mission planned by `source`; not yet validated (`validate_mission`). An unreadable plan is a PlanError."""
        stages = plan.get("stages") if isinstance(plan, Mapping) else None
        if not isinstance(stages, list) or not stages:
            raise PlanError(f"a plan is a mapping with a non-empty list of stages, got {plan!r}")
        targets = {t.id: t.room for t in scene.targets}
        out = []
        for s in stages:
            if not isinstance(s, Mapping) or len(s) != 1 or next(iter(s)) not in ("room", "object", "return"):
                raise PlanError(f"a plan's stage is {{room: X}}, {{object: T}} or {{return: X}}, got {s!r}")
            (kind, value), = s.items()
            if kind == "object":
                out.append(Stage("object", targets.get(str(value)), str(value)))
            else:
                out.append(Stage(kind, None if value is True else str(value)))
        return cls(query=query, stages=tuple(out), avoid=tuple(plan.get("avoid") or ()),
                   not_goals=tuple(plan.get("not") or ()), source=source)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Mission:
        stages = tuple(Stage(s["kind"], s.get("room"), s.get("target"), s.get("words", ""))
                       for s in data["stages"])
        return cls(query=data["query"], stages=stages, avoid=tuple(data.get("avoid") or ()),
                   not_goals=tuple(data.get("not_goals") or ()), source=data.get("source", PARSER),
                   planning=tuple(data.get("planning") or ()))

    def describe(self) -> str:
        """One line per stage, for `vln-pilot plan` and the console."""
        parts = []
        for i, s in enumerate(self.stages, 1):
            goal = f"find {s.target} in {s.room}" if s.kind == "object" else (
                f"return to the start ({s.room or 'the start room'})" if s.kind == "return" else f"go to {s.room}")
            parts.append(f"{i}. {goal}")
        if self.avoid:
            parts.append(f"avoid: {', '.join(self.avoid)}")
        return "\n".join(parts)


def as_mission(task: Task | Mission) -> Mission:
    return task if isinstance(task, Mission) else Mission.from_task(task)


def mission_budget(max_steps: int, mission: Mission) -> int:
    """The default step budget of a mission: `max_steps` per stage, shared by the whole mission."""
    return max_steps * len(mission.stages)


# ---------------------------------------------------------------------------------------------- the map


def offers(scene: Scene) -> str:
    """What the map offers, for the one line of a refusal."""
    rooms = ", ".join(r.id for r in scene.rooms)
    targets = ", ".join(f"{t.id} ({t.room})" for t in scene.targets)
    return f"the map offers rooms: {rooms}; objects: {targets}"


def route(scene: Scene, start: str, goal: str, avoid: Sequence[str] = ()) -> list[str] | None:
    """The shortest room path from start to goal through open doors that enters no room in `avoid`.

    Without anything to avoid it is `scene.room_path` (the oracle's route as before); None if there is none.
    """
    if not avoid:
        try:
            return scene.room_path(start, goal)
        except Exception:  # noqa: BLE001 - the scene says "no path" by raising
            return None
    blocked = set(avoid) - {start}
    if goal in blocked:
        return None
    frontier, parent = [start], {start: start}
    while frontier:
        nxt = []
        for r in frontier:
            for d in scene.open_doors():
                if d.joins(r) and (o := d.other_side(r)) not in parent and o not in blocked:
                    parent[o] = r
                    nxt.append(o)
        frontier = nxt
    if goal not in parent:
        return None
    path = [goal]
    while path[-1] != start:
        path.append(parent[path[-1]])
    return path[::-1]


def validate_mission(mission: Mission, scene: Scene, start_room: str | None) -> Mission:
    """The mission resolved against the start, if every stage exists and is reachable; else PlanError."""
    if not mission.stages:
        raise PlanError(f"the instruction {mission.query!r} names no goal; {offers(scene)}")
    rooms, targets = {r.id for r in scene.rooms}, {t.id: t.room for t in scene.targets}
    for name in mission.avoid:
        if name not in rooms:
            raise PlanError(f"the room to avoid {name!r} is not on the map; {offers(scene)}")
    for i, s in enumerate(mission.stages, 1):
        if s.kind not in STAGE_KINDS:
            raise PlanError(f"stage {i} has an unknown kind {s.kind!r}; kinds: {', '.join(STAGE_KINDS)}")
        if s.kind == "object":
            if s.target is None or s.target not in targets:
                raise PlanError(f"stage {i}: there is no object {s.target!r} in this house; {offers(scene)}")
            if s.room is not None and targets[s.target] != s.room:
                raise PlanError(f"stage {i}: the {s.target} is in the {targets[s.target]}, not in the {s.room}; "
                                f"{offers(scene)}")
        if s.kind != "return" and s.kind != "object" and s.room not in rooms:
            raise PlanError(f"stage {i}: there is no room {s.room!r} on the map; {offers(scene)}")
        if s.kind == "return" and s.room is not None and s.room not in rooms:
            raise PlanError(f"stage {i}: there is no room {s.room!r} on the map; {offers(scene)}")
    stages = tuple(replace(s, room=targets[s.target]) if s.kind == "object" and s.target is not None else s
                   for s in mission.stages)  # every object stage has its target: checked above
    resolved = replace(mission, stages=stages).resolved(start_room)
    here = start_room
    for i, s in enumerate(resolved.stages, 1):
        if here is not None and (s.room is None or route(scene, here, s.room, resolved.avoid) is None):
            why = f" without entering {', '.join(resolved.avoid)}" if resolved.avoid else ""
            raise PlanError(f"stage {i} ({s.room}) cannot be reached from {here}{why}; {offers(scene)}")
        here = s.room
    return resolved




# ------------------------------------------------------------------------------------------ judging, paths


@dataclass
class MissionProgress:
    """Where a mission stands during an episode: the current stage, the stages done, the rooms entered."""

    mission: Mission
    stage: int = 0
    boundaries: list[int] = field(default_factory=list)  # the step at which each stage was judged a success
    entered: set[str] = field(default_factory=set)

    @property
    def task(self) -> Task:
        return self.mission.task(self.stage)

    @property
    def last(self) -> bool:
        return self.stage == len(self.mission.stages) - 1

    def saw(self, room: str | None) -> None:
        if room is not None:
            self.entered.add(room)

    def judge(self, state: State, gt: GroundTruth, config: SuccessConfig) -> tuple[bool, str]:
        """The stage's final state judged as today's Task; a room to avoid that was entered fails it. A report of
        Goal Unreachable is right only if no route of the true map (`gt.scene`) leads to the stage's goal."""
        if state is State.GOAL_UNREACHABLE:
            return judge_unreachable(self.task, gt, self.mission.avoid)
        ok, why = judge(self.task, state, gt, config)
        broken = sorted(self.entered & set(self.mission.avoid))
        if ok and broken:
            return False, f"entered {', '.join(broken)}, which the instruction says to avoid; {why}"
        return ok, why

    def advance(self, step: int) -> None:
        self.boundaries.append(step)
        self.stage += 1

    def prefix(self, ok: bool, why: str) -> str:
        """A multi-stage judgement names its stage."""
        if len(self.mission.stages) == 1:
            return why
        return f"stage {self.stage + 1}/{len(self.mission.stages)} ({self.mission.stages[self.stage].plan()}): {why}"


def judge_unreachable(task: Task, gt: GroundTruth, avoid: Sequence[str] = ()) -> tuple[bool, str]:
    """Whether a report that the goal is unreachable is true: no route of the true map (the ground truth's scene,
    with the doorways closed since take-off) leads from where the drone is (either side, in a doorway) to it."""
    scene, pose = gt.scene, gt.pose()
    here = gt.room()
    starts = [here] if here is not None else list(_rooms_beside(scene, pose.x, pose.y))
    open_routes = [r for s in starts if (r := route(scene, s, task.goal_room, avoid)) is not None]
    if open_routes:
        path = open_routes[0]
        return False, f"reported the goal unreachable, but {task.goal_room} is reachable: {' -> '.join(path)}"
    closed = sorted(d.id for d in scene.doors if not d.open and EXTERIOR not in d.rooms)
    return True, f"{task.goal_room} is unreachable from {here or ' or '.join(starts)} (closed: {', '.join(closed)})"


def _rooms_beside(scene: Scene, x: float, y: float) -> tuple[str, ...]:
    """The rooms of the doorway nearest to (x, y): where a drone in a doorway may be."""
    doors = [d for d in scene.doors if EXTERIOR not in d.rooms]
    if not doors:
        return ()
    return min(doors, key=lambda d: math.dist(d.center, (x, y))).rooms


def stage_shortest_paths(scene: Scene, start: Pose, mission: Mission,
                         config: SuccessConfig = DEFAULT_SUCCESS) -> list[float]:
    """The shortest path of each stage, each from where the one before ends (SPL over the whole mission path).

    The first is exactly `tasks.shortest_path_length` (a one-stage mission's SPL is today's).
    """
    out, here = [], start
    for k in range(len(mission.stages)):
        pts = shortest_path_points(scene, here, mission.task(k), config)
        out.append(shortest_path_length(scene, here, mission.task(k), config))
        end, before = pts[-1], pts[-2] if len(pts) > 1 else (here.x, here.y)
        yaw = math.degrees(math.atan2(end[1] - before[1], end[0] - before[0])) if end != before else here.yaw_deg
        here = Pose(end[0], end[1], here.z, yaw)
    return out
