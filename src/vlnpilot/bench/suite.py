"""Benchmark suites: YAML files of (spawn, query, goal) rows, validated against the scene before anything runs.

    name: paper                   # optional; defaults to the file name
    scene: cabin
    repetitions: 5
    max_steps: 50
    seed: 0                       # base of the per-repetition seeds (see `episode_seed`)
    profile: paper                # FSM profile
    spawn_jitter: {m: 0.0, deg: 0.0}   # optional seeded spawn offsets, m 0..0.5, deg 0..45 (0: alike)
    spawn_labels: {living_room: Living Room and Kitchen}   # optional display names of starting rooms
    rows:
      - {id: living-bathroom, spawn: living_room, query: Go to the bathroom, goal: {room: bathroom}}

`goal` is optional: the query is always parsed with `tasks.parse_query`, and a goal given in the row must agree
with it (so a parser change can never silently change what a suite measures). `goal: bathroom` is short for
`goal: {room: bathroom}`. The built-in `paper` suite is the paper's Table 4.

A mission suite (`missions`, `missions-houses`; docs/missions.md) reads each query with the mission parser
(`tasks.mission_parser.plan_mission`) against the row's spawn, and a row may record the expected plan, which must agree:

      - {id: bath-back, spawn: living_room, query: "Go to the bathroom, then come back",
         plan: {stages: [{room: bathroom}, {return: living_room}]}}
      - {id: piano, spawn: living_room, query: Find the piano, refuse: no known object}

A row with `refuse` must be refused before take-off with a message containing it; it is never flown
(`Suite.refused`).

An event suite (`events`, `events-houses`; docs/events.md) gives each row its scenario of events (the seed and
the events of `scene.events.Scenario`; the scene is the row's), checked against the row's scene:

      - {id: bath-person, spawn: living_room, query: Go to the bathroom,
         events: {seed: 1, events: [{kind: person, path: [bedroom, bathroom], trigger: {enter: bedroom}}]}}
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

import yaml

from vlnpilot.bench.house_suite import house_suite_dict, is_house_suite
from vlnpilot.core.cameras import CAMERAS
from vlnpilot.core.errors import ConfigError, VLNPilotError
from vlnpilot.core.fsm import PROFILES
from vlnpilot.core.limits import MAX_REPS, MAX_STEPS
from vlnpilot.prompting.context import CONTEXT_PRESETS
from vlnpilot.safety.shields import SHIELD_REGISTRY
from vlnpilot.scene import SCENES, Scene, load_scene
from vlnpilot.scene.houses import PREFIX as HOUSE_PREFIX
from vlnpilot.tasks.mission import Mission, PlanError, as_mission, validate_mission
from vlnpilot.tasks.mission_parser import plan_mission
from vlnpilot.tasks.task import Task, parse_query

_TOP_KEYS = ("name", "description", "scene", "repetitions", "max_steps", "seed", "profile", "context", "shield",
             "camera", "spawn_jitter", "spawn_labels", "randomize", "rows")
# a row's own scene overrides the suite's (house suites); a row's `sensors` (none, tof, multiranger:
# vlnpilot.core.ranging) the bench's --sensors; plan / refuse: what a mission suite expects; a row's `randomize`
# (a domain randomisation seed, docs/camera.md) the suite's, and the suite's the bench's --randomize; a row's
# `events`: its scenario (docs/events.md)
_ROW_KEYS = ("id", "spawn", "query", "goal", "scene", "sensors", "randomize", "plan", "planned_by", "refuse", "events")
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


class SuiteError(ConfigError):
    """A suite that cannot run; the message names the file, every bad row and the valid choices."""


def builtin_suites() -> list[str]:
    """Names of the suites shipped with the package (`paper`, ...)."""
    root = resources.files("vlnpilot.bench") / "suites"
    return sorted(p.name.removesuffix(".yaml") for p in root.iterdir() if p.name.endswith(".yaml"))


@dataclass(frozen=True)
class SuiteRow:
    id: str
    spawn: str
    query: str
    goal_room: str
    goal_target: str | None = None
    scene: str | None = None  # this row's scene when it differs from the suite's (e.g. 'house:7')
    sensors: str | None = None  # the range sensors this row's drone carries, when it names them (else --sensors)
    mission: dict[str, Any] | None = None  # a mission of several stages (Mission.to_dict), resolved at the spawn
    randomize: int | None = None  # this row's domain randomisation seed (docs/camera.md), when it names one
    events: dict[str, Any] | None = None  # the row's scenario of events (scene.events.Scenario.to_dict), issue 24

    @property
    def events_named(self) -> str:
        """The row's events as its table cell names them: 'person, door_closes'; '' without any."""
        return ", ".join(e["kind"] for e in (self.events or {}).get("events", ()))

    @property
    def task(self) -> Task | Mission:
        if self.mission is not None:
            return Mission.from_dict(self.mission)
        return Task(query=self.query, goal_room=self.goal_room, goal_target=self.goal_target)

    def canonical(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id, "spawn": self.spawn, "query": self.query, "goal_room": self.goal_room,
                               "goal_target": self.goal_target}
        out = {**out, "scene": self.scene} if self.scene else out
        if self.sensors:
            out = {**out, "sensors": self.sensors}
        if self.randomize is not None:
            out = {**out, "randomize": self.randomize}
        if self.events:
            out = {**out, "events": self.events}
        return {**out, "plan": Mission.from_dict(self.mission).plan()} if self.mission else out


@dataclass(frozen=True)
class RefusedRow:
    """A suite row that must be refused before take-off, and the refusal it got."""

    id: str
    spawn: str
    query: str
    refusal: str
    scene: str | None = None


class SuitePins(NamedTuple):
    """What a suite pins (None where it pins nothing): the bench flies it unless an option says otherwise."""

    context: str | None
    shield: str | None
    camera: str | None


@dataclass(frozen=True)
class Suite:
    name: str
    rows: tuple[SuiteRow, ...]
    scene: str = "cabin"
    repetitions: int = 5
    max_steps: int = 50
    seed: int = 0
    profile: str = "paper"
    # What the suite pins, so that its table means one thing (the paper suite: the paper's context and no shield; a
    # set of trials: what it was flown with, its camera too); None: the bench's --context / --shield / --camera, or
    # their defaults. An explicit option still overrides a pin.
    context: str | None = None
    shield: str | None = None
    camera: str | None = None
    spawn_jitter_m: float = 0.0
    spawn_jitter_deg: float = 0.0
    spawn_labels: dict[str, str] = field(default_factory=dict)
    description: str = ""
    source: str = ""  # 'builtin:paper' or the file path, for the manifest
    refused: tuple[RefusedRow, ...] = ()  # rows refused before take-off, as the suite expects (never flown)
    randomize: int | None = None  # the domain randomisation seed of every row that names none (docs/camera.md)

    def row(self, row_id: str) -> SuiteRow:
        for r in self.rows:
            if r.id == row_id:
                return r
        raise SuiteError(f"suite {self.name!r} has no row {row_id!r}; rows: {', '.join(r.id for r in self.rows)}")

    def spawn_label(self, spawn: str) -> str:
        """How the tables name a starting room: the suite's label, else the scene room's name in title case."""
        if spawn in self.spawn_labels:
            return self.spawn_labels[spawn]
        scene = load_scene(self.scene)
        if spawn not in {s.id for s in scene.spawns}:  # a spawn of another row's own scene (house suites)
            return spawn.replace("_", " ").title()
        room = scene.spawn(spawn).room
        return scene.room(room).name.title()

    def canonical(self) -> dict[str, Any]:
        """What the suite measures (no names, descriptions or labels): the part that enters the config hash."""
        return {"scene": self.scene, "profile": self.profile, "spawn_jitter_m": self.spawn_jitter_m,
                "spawn_jitter_deg": self.spawn_jitter_deg, "rows": [r.canonical() for r in self.rows],
                **({"randomize": self.randomize} if self.randomize is not None else {})}

    def to_dict(self) -> dict[str, Any]:
        """The whole suite as plain data (YAML-able; `suite_from_dict` reads it back)."""
        return {"name": self.name, "description": self.description, "scene": self.scene,
                "repetitions": self.repetitions, "max_steps": self.max_steps, "seed": self.seed,
                "profile": self.profile, **{k: v for k, v in self.pins()._asdict().items() if v},
                "spawn_jitter": {"m": self.spawn_jitter_m, "deg": self.spawn_jitter_deg},
                "spawn_labels": dict(self.spawn_labels),
                **({"randomize": self.randomize} if self.randomize is not None else {}),
                "rows": [_row_dict(r) for r in self.rows]}

    def dump(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, allow_unicode=True)

    def pins(self) -> SuitePins:
        return SuitePins(context=self.context, shield=self.shield, camera=self.camera)


def episode_seed(base: int, row_id: str, rep: int) -> int:
    """The seed of one repetition: a stable hash of (base seed, row id, repetition), in [0, 2**31).

    It does not depend on the pilot, so every pilot flies repetition r of a row from the same seed.
    """
    digest = hashlib.sha256(f"{int(base)}/{row_id}/{int(rep)}".encode()).digest()
    return int.from_bytes(digest[:4], "big") & 0x7FFFFFFF


def _pin(data: dict[str, Any], key: str, valid: Iterable[str], errors: list[str]) -> str | None:
    """A suite's pinned context, shield or camera (None when it pins none); an unknown name is an error naming the
    valid."""
    value = data.get(key)
    if value is None:
        return None
    if str(value) not in valid:
        errors.append(f"unknown {key} {value!r}; valid: {', '.join(valid)}")
        return None
    return str(value)


def _row_dict(r: SuiteRow) -> dict[str, Any]:
    """A row as plain data that `suite_from_dict` reads back: a mission row by its plan (its goal alone would be
    read back as a one-goal query, which a mission's instruction is not)."""
    what = (Mission.from_dict(r.mission).suite_row() if r.mission is not None else
            {"goal": {"room": r.goal_room, **({"target": r.goal_target} if r.goal_target else {})}})
    return {"id": r.id, "spawn": r.spawn, "query": r.query, **what, **({"scene": r.scene} if r.scene else {}),
            **({"sensors": r.sensors} if r.sensors else {}),
            **({"randomize": r.randomize} if r.randomize is not None else {}),
            **({"events": {k: v for k, v in r.events.items() if k not in ("name", "scene")}} if r.events else {})}


def suite_pins(suite: str | Path) -> SuitePins:
    """The context, shield and camera a suite pins (None where it pins none)."""
    return load_suite(suite).pins()


def load_suite(suite: str | Path) -> Suite:
    """A built-in suite by name (`paper`, `houses`, `houses:SEEDS`) or a YAML file; refused with every problem
    listed if it is invalid."""
    if isinstance(suite, str) and is_house_suite(suite):
        return suite_from_dict(house_suite_dict(suite), source=f"builtin:{suite.strip()}", default_name="houses")
    text, source, default_name = _read(suite)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)  # one line: where, and what (not the parser's context lines)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        what = " ".join(str(getattr(exc, "problem", None) or exc).split())
        raise SuiteError(f"suite {source}: not valid YAML{where}: {what}") from None
    return suite_from_dict(data, source=source, default_name=default_name)


def _read(suite: str | Path) -> tuple[str, str, str]:
    name = str(suite)
    if isinstance(suite, str) and name in builtin_suites():
        text = (resources.files("vlnpilot.bench") / "suites" / f"{name}.yaml").read_text(encoding="utf-8")
        return text, f"builtin:{name}", name
    path = Path(suite).expanduser()
    if path.is_file():
        try:
            return path.read_text(encoding="utf-8"), str(path), path.stem
        except (OSError, UnicodeDecodeError) as exc:
            raise SuiteError(f"cannot read suite file {path}: {exc}") from None
    raise SuiteError(f"unknown suite {name!r}: not a built-in suite ({', '.join(builtin_suites())}) "
                     f"and no such file")


def _int(value: Any, what: str, errors: list[str], minimum: int | None = None, maximum: int | None = None) -> int:
    low, high = -math.inf if minimum is None else minimum, math.inf if maximum is None else maximum
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        bound = f" in {minimum}..{maximum}" if maximum is not None else f" >= {minimum}" if minimum is not None else ""
        errors.append(f"{what} must be an integer{bound}, got {value!r}")
        return minimum or 0
    return value


def suite_from_dict(data: Any, *, source: str = "<dict>", default_name: str = "suite") -> Suite:
    """Validate plain data (a parsed YAML document) into a Suite; a SuiteError lists every problem found."""
    if not isinstance(data, dict):
        raise SuiteError(f"suite {source}: expected a mapping with a 'rows' list, got {type(data).__name__}")
    errors: list[str] = []
    unknown = sorted(set(data) - set(_TOP_KEYS))
    if unknown:
        errors.append(f"unknown key(s) {', '.join(map(repr, unknown))}; valid keys: {', '.join(_TOP_KEYS)}")
    scene_name = str(data.get("scene", "cabin"))
    if scene_name.strip().lower() not in SCENES and not scene_name.strip().lower().startswith(HOUSE_PREFIX):
        raise SuiteError(f"suite {source}: unknown scene {scene_name!r}; valid scenes: {', '.join(sorted(SCENES))}, "
                         "house:SEED")
    try:
        scene = load_scene(scene_name)
    except VLNPilotError as exc:
        raise SuiteError(f"suite {source}: {exc}") from None
    reps = _int(data.get("repetitions", 5), "repetitions", errors, 1, MAX_REPS)
    max_steps = _int(data.get("max_steps", 50), "max_steps", errors, 1, MAX_STEPS)  # the command line's caps
    seed = _int(data.get("seed", 0), "seed", errors)
    profile = str(data.get("profile", "paper"))
    if profile not in PROFILES:
        errors.append(f"unknown profile {profile!r}; valid profiles: {', '.join(PROFILES)}")
    context = _pin(data, "context", CONTEXT_PRESETS, errors)
    shield = _pin(data, "shield", SHIELD_REGISTRY.names(), errors)
    camera = _pin(data, "camera", CAMERAS, errors)
    randomize = _randomize_seed(data, "suite", errors)
    jm, jd = _spawn_jitter(data.get("spawn_jitter") or {}, errors)
    labels = data.get("spawn_labels") or {}
    valid_spawns = [s.id for s in scene.spawns]
    if not isinstance(labels, dict):
        errors.append(f"spawn_labels must map spawn names to labels, got {labels!r}")
        labels = {}
    for spawn in labels:
        if spawn not in valid_spawns:
            errors.append(f"spawn_labels: unknown spawn {spawn!r}; valid spawns: {', '.join(valid_spawns)}")
    raw_rows = data.get("rows")
    rows: list[SuiteRow] = []
    refused: list[RefusedRow] = []
    if not isinstance(raw_rows, list) or not raw_rows:
        errors.append("'rows' must be a non-empty list of {spawn, query, goal} rows")
        raw_rows = []
    seen: dict[str, int] = {}
    for i, raw in enumerate(raw_rows, 1):
        row = _row(i, raw, scene, errors)
        if row is None:
            continue
        if isinstance(row, RefusedRow):
            refused.append(row)
            continue
        if row.id in seen:
            errors.append(f"row {i} ({row.id}): the id is also used by row {seen[row.id]}; row ids must be unique")
            continue
        seen[row.id] = i
        rows.append(row)
    if errors:
        raise SuiteError(f"suite {source} is invalid:\n  - " + "\n  - ".join(errors))
    return Suite(name=str(data.get("name") or default_name), rows=tuple(rows), scene=scene.name, repetitions=reps,
                 max_steps=max_steps, seed=seed, profile=profile, context=context, shield=shield, camera=camera,
                 spawn_jitter_m=jm, spawn_jitter_deg=jd,
                 spawn_labels={str(k): str(v) for k, v in labels.items()},
                 description=str(data.get("description") or ""), source=source, refused=tuple(refused),
                 randomize=randomize)


MAX_JITTER_M, MAX_JITTER_DEG = 0.5, 45.0  # farther, a spawn leaves its room (or the house) or faces a wall


def _spawn_jitter(jitter: Any, errors: list[str]) -> tuple[float, float]:
    """The suite's `spawn_jitter: {m, deg}`, each finite and within its range (0, 0 for a bad one, said in errors)."""
    if not isinstance(jitter, dict) or set(jitter) - {"m", "deg"}:
        errors.append(f"spawn_jitter must be a mapping with keys m and deg, got {jitter!r}")
        return 0.0, 0.0
    try:
        jm, jd = float(jitter.get("m", 0.0)), float(jitter.get("deg", 0.0))
    except (TypeError, ValueError, OverflowError):
        jm = jd = math.nan
    if not (0 <= jm <= MAX_JITTER_M and 0 <= jd <= MAX_JITTER_DEG):  # NaN fails both comparisons
        errors.append(f"spawn_jitter must have m in 0..{MAX_JITTER_M:g} (metres) and deg in 0..{MAX_JITTER_DEG:g} "
                      f"(degrees), finite numbers; got {jitter!r}")
        return 0.0, 0.0
    return jm, jd


def _row(i: int, raw: Any, scene: Scene, errors: list[str]) -> SuiteRow | RefusedRow | None:
    if not isinstance(raw, dict):
        errors.append(f"row {i}: expected a mapping with spawn, query and goal, got {raw!r}")
        return None
    where = f"row {i}" + (f" ({raw['id']})" if raw.get("id") else "")
    unknown = sorted(set(raw) - set(_ROW_KEYS))
    if unknown:
        errors.append(f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; valid keys: {', '.join(_ROW_KEYS)}")
    spawn, query = raw.get("spawn"), raw.get("query")
    before = len(errors)
    row_scene = raw.get("scene")
    if row_scene is not None:
        try:
            scene = load_scene(str(row_scene))
        except VLNPilotError as exc:
            errors.append(f"{where}: {exc}")
            return None
    valid_spawns = [s.id for s in scene.spawns]
    if spawn not in valid_spawns:
        errors.append(f"{where}: unknown spawn {spawn!r}; valid spawns: {', '.join(valid_spawns)}")
    if not isinstance(query, str) or not query.strip():
        errors.append(f"{where}: 'query' must be a non-empty string, got {query!r}")
        return None
    if spawn not in valid_spawns:
        return None
    mission = _planned(raw, where, scene, row_scene is not None, errors)
    if not isinstance(mission, Mission):
        return mission
    task = mission.task(len(mission.stages) - 1)
    goal = raw.get("goal")
    if goal is not None:
        if isinstance(goal, str):
            goal = {"room": goal}
        if not isinstance(goal, dict) or set(goal) - {"room", "target"} or "room" not in goal:
            errors.append(f"{where}: 'goal' must be a room name or a mapping {{room, target}}, got {goal!r}")
        else:
            room_ids, target_ids = [r.id for r in scene.rooms], [t.id for t in scene.targets]
            room, target = goal.get("room"), goal.get("target")
            if room not in room_ids:
                errors.append(f"{where}: unknown goal room {room!r}; valid rooms: {', '.join(room_ids)}")
            elif target is not None and target not in target_ids:
                errors.append(f"{where}: unknown goal target {target!r}; valid targets: "
                              + ", ".join(f"{t.id} (in {t.room})" for t in scene.targets))
            elif target is not None and scene.target(target).room != room:
                errors.append(f"{where}: goal target {target!r} is in {scene.target(target).room}, not in {room}")
            elif (room, target) != (task.goal_room, task.goal_target):
                parsed = task.goal_room + (f" / {task.goal_target}" if task.goal_target else "")
                errors.append(f"{where}: the goal says {room}" + (f" / {target}" if target else "")
                              + f" but the query {query!r} parses to {parsed}")
    sensors = _row_sensors(raw, where, errors)
    randomize = _randomize_seed(raw, where, errors)
    events = _row_events(raw, where, scene, errors)
    row_id = raw.get("id")
    if row_id is None:
        row_id = _slug(f"{spawn}-{query}")
    elif not isinstance(row_id, str) or not _ID_RE.match(row_id):
        errors.append(f"{where}: id {row_id!r} must be letters, digits, '.', '_' or '-' (it names a directory)")
    if len(errors) > before:
        return None
    return SuiteRow(id=row_id, spawn=str(spawn), query=query, goal_room=task.goal_room, goal_target=task.goal_target,
                    scene=scene.name if row_scene is not None else None,
                    mission=None if mission.is_single else mission.to_dict(),
                    sensors=str(sensors) if sensors is not None else None, randomize=randomize,
                    events=events)


def _randomize_seed(raw: dict[str, Any], where: str, errors: list[str]) -> int | None:
    """A suite's or a row's `randomize:` seed (docs/camera.md), if it names one."""
    value = raw.get("randomize")
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**31:
        errors.append(f"{where}: 'randomize' must be a seed in "
                      f"0..{2**31 - 1}, got {value!r}")
        return None
    return value



def _row_events(raw: dict[str, Any], where: str, scene: Scene, errors: list[str]) -> dict[str, Any] | None:
    """The row's scenario of events (issue 24), checked against its scene; as recorded (`Scenario.to_dict`)."""
    from vlnpilot.scene.events import scenario_from_dict, validate_scenario

    given = raw.get("events")
    if given is None:
        return None
    if not isinstance(given, dict):
        errors.append(f"{where}: 'events' must be a mapping with seed and events, got {given!r}")
        return None
    try:
        scenario = scenario_from_dict({"name": str(raw.get("id") or "row"), **given, "scene": scene.name}, where)
        validate_scenario(scenario, scene)
    except VLNPilotError as exc:
        errors.append(f"{where}: {exc}")
        return None
    return scenario.to_dict()


def _row_sensors(raw: dict[str, Any], where: str, errors: list[str]) -> Any:
    """The row's own range sensors (none, tof, multiranger: vlnpilot.core.ranging), if it names them."""
    from vlnpilot.core.ranging import SENSORS

    sensors = raw.get("sensors")
    if sensors is not None and str(sensors) not in SENSORS:
        errors.append(f"{where}: unknown sensors {sensors!r}; valid: {', '.join(SENSORS)}")
    return sensors


def _planned(raw: dict[str, Any], where: str, scene: Scene, own_scene: bool,
             errors: list[str]) -> Mission | RefusedRow | None:
    """The row's mission as the parser plans it at its spawn, checked against its `plan` or `refuse`; or, where the
    row says who planned it (`planned_by`: a recorded trial's pilot), its `plan` as written, checked against the map."""
    spawn, query = raw["spawn"], raw["query"]
    if raw.get("planned_by") is not None:
        try:
            return validate_mission(Mission.from_plan(query, raw.get("plan") or {}, scene, str(raw["planned_by"])),
                                    scene, scene.spawn(spawn).room)
        except VLNPilotError as exc:
            errors.append(f"{where}: the plan {raw.get('plan')!r} by {raw['planned_by']}: {exc}")
            return None
    if raw.get("goal") is not None and raw.get("plan") is None and raw.get("refuse") is None:
        try:  # a one-goal row (the paper's, the trials'): its query is read as before missions, the goal checks it
            return as_mission(parse_query(query, scene))
        except VLNPilotError as exc:
            errors.append(f"{where}: {exc}")
            return None
    try:
        mission = plan_mission(query, scene, scene.spawn(spawn).room)
    except VLNPilotError as exc:
        if isinstance(raw.get("refuse"), str) and isinstance(exc, PlanError) and raw["refuse"] in str(exc):
            return RefusedRow(id=str(raw.get("id") or _slug(f"{spawn}-{query}")), spawn=spawn, query=query,
                              refusal=str(exc), scene=scene.name if own_scene else None)
        errors.append(f"{where}: {exc}")
        return None
    if raw.get("refuse") is not None:
        errors.append(f"{where}: the suite expects a refusal ({raw['refuse']!r}) but {query!r} plans to "
                      f"{mission.plan()}")
        return None
    if raw.get("plan") is not None and raw["plan"] != mission.plan():
        errors.append(f"{where}: the plan says {raw['plan']} but the query {query!r} plans to {mission.plan()}")
        return None
    return mission


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:60] or "row"
