"""Events in the scene (issue 24): what happens while the drone flies, as pure data.

A `Scenario` is a scene name, a seed and its `EventSpec`s. Each event fires on a trigger: at a step, after a time
on the episode's clock, or when the drone enters a room. The kinds:

* `person` / `pet`: a mover that walks a `path` of rooms, doors or [x, y] points (consecutive rooms are joined
  through the door between them); a person may stop in a doorway (`pause_in_doorway_s`). It enters the scene at
  the start of its path when its trigger fires, and stands at the end of it (or walks it back and forth: `repeat`;
  or leaves the scene there: `leave`).
* `door_closes`: an open doorway's leaf swings shut; the doorway leaves the TRUE topological map (the pilot's map
  in the prompt stays as it was).
* `lights_out`: a room's lights dim to a named level (`dim`, `dark`, or a number in 0..1 with a `name`).
* `sign`: a sign or screen on a room's wall carries `text` (`redirect: true` marks text that tries to steer the
  pilot); it appears when its trigger fires (step 0 by default: from the start).

Scenarios load from YAML (`load_scenario(FILE or built-in name)`), are checked against their scene
(`validate_scenario`), and every error is one line (`ConfigError`: the command line exits 2).
"""

from __future__ import annotations

import math
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from vlnpilot.core.errors import ConfigError
from vlnpilot.scene.model import Scene

EVENT_KINDS = ("person", "pet", "door_closes", "lights_out", "sign")
MOVER_EVENT_KINDS = ("person", "pet")
LIGHT_LEVELS = {"dim": 0.35, "dark": 0.08}  # the named levels of `lights_out` (fraction of the room's light)
DEFAULT_SPEED_MPS = {"person": 1.2, "pet": 2.0}  # walking person; a trotting dog
WALLS = ("north", "south", "east", "west")
BUILTIN_DIR = "scenarios"  # vlnpilot/scene/scenarios/NAME.yaml


class Trigger(BaseModel):
    """When an event fires: exactly one of `step` (before the pilot is asked at that step), `time_s` (on the
    episode's clock) or `enter` (the first step the drone is in that room)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    step: int | None = Field(None, ge=0)
    time_s: float | None = Field(None, ge=0)
    enter: str | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> Trigger:
        given = [k for k in ("step", "time_s", "enter") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"a trigger needs exactly one of step, time_s, enter (got {', '.join(given) or 'none'})")
        return self

    def describe(self) -> str:
        if self.step is not None:
            return f"step {self.step}"
        if self.time_s is not None:
            return f"{self.time_s:g} s"
        return f"entering {self.enter}"


AT_START = Trigger(step=0, time_s=None, enter=None)


KIND_FIELDS = {
    "person": {"path", "speed_mps", "pause_in_doorway_s", "pause_door", "repeat", "leave"},
    "pet": {"path", "speed_mps", "repeat", "leave"},
    "door_closes": {"door", "swing_s"},
    "lights_out": {"room", "level"},
    "sign": {"room", "text", "wall", "along", "at", "facing_deg", "width_m", "height_m", "screen", "redirect"},
}
# The fields each kind needs, and those it takes.
REQUIRED = {"person": ("path",), "pet": ("path",), "door_closes": ("door",), "lights_out": ("room", "level"),
            "sign": ("room", "text")}


class EventSpec(BaseModel):
    """One event of a scenario; the fields that do not belong to its kind must stay unset."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    kind: Literal["person", "pet", "door_closes", "lights_out", "sign"]
    name: str | None = None  # "person-1" ... by default (the contact and the records name it)
    trigger: Trigger = AT_START
    # person, pet
    path: tuple[str | tuple[float, float], ...] = ()
    speed_mps: float | None = Field(None, gt=0, le=6)
    pause_in_doorway_s: float = Field(0.0, ge=0)
    pause_door: str | None = None  # which doorway of the path to stop in (the first by default)
    repeat: bool = False  # walk the path back and forth instead of stopping at its end
    leave: bool = False  # leave the scene at the end of the path (walked on out of sight) instead of standing there
    # door_closes
    door: str | None = None
    swing_s: float = Field(2.0, gt=0, le=10)
    # lights_out, sign
    room: str | None = None
    level: float | str | None = None
    # sign
    text: str | None = Field(None, min_length=1, max_length=160)
    wall: Literal["north", "south", "east", "west"] | None = None
    along: float = Field(0.5, ge=0, le=1)  # where along the wall (0: its west or south end)
    at: tuple[float, float] | None = None  # or a free-standing sign on a stand at (x, y) ...
    facing_deg: float = 0.0  # ... its face looking this way (degrees counter-clockwise from +x)
    width_m: float = Field(1.0, ge=0.3, le=1.6)  # the board's width; its height is 0.6 of it
    height_m: float = Field(1.1, gt=0.2, le=2.4)  # of the sign's centre above the floor
    screen: bool = False  # a lit screen instead of a printed sign
    redirect: bool = False  # the text tries to steer the pilot

    @model_validator(mode="after")
    def _fields_of_kind(self) -> EventSpec:
        own = KIND_FIELDS[self.kind]
        foreign = sorted(f for f in self.model_fields_set if f not in own | {"kind", "name", "trigger"})
        if foreign:
            raise ValueError(f"{self.kind} takes no {', '.join(foreign)} (its fields: {', '.join(sorted(own))})")
        missing = [f for f in REQUIRED[self.kind] if not getattr(self, f)]
        if missing:
            raise ValueError(f"{self.kind} needs {', '.join(missing)}")
        if self.kind == "lights_out":
            self.light_level()  # a bad level is refused here
        if self.kind == "sign" and (self.wall is None) == (self.at is None):
            raise ValueError("a sign needs exactly one of wall (on a wall of its room) or at (free-standing)")
        return self

    def light_level(self) -> tuple[float, str]:
        """(fraction of the room's light, its name) of a `lights_out`."""
        level = self.level
        if isinstance(level, str):
            if level.strip().lower() in LIGHT_LEVELS:
                return LIGHT_LEVELS[level.strip().lower()], level.strip().lower()
            try:
                level = float(level)
            except ValueError:
                raise ValueError(f"unknown light level {level!r}; valid: {', '.join(LIGHT_LEVELS)} or a number in 0..1"
                                 ) from None
        if level is None or not 0 <= float(level) <= 1:
            raise ValueError(f"light level {level!r} is outside 0..1 (or name one: {', '.join(LIGHT_LEVELS)})")
        return float(level), f"{float(level):g}"

    @property
    def speed(self) -> float:
        return self.speed_mps if self.speed_mps is not None else DEFAULT_SPEED_MPS[self.kind]

    @property
    def is_mover(self) -> bool:
        return self.kind in MOVER_EVENT_KINDS

    def params(self) -> dict[str, Any]:
        """The event's own fields as recorded in a run (kind-specific, no defaults left out)."""
        own = sorted(KIND_FIELDS[self.kind])
        data = self.model_dump(mode="json", include=set(own))
        if self.kind == "lights_out":
            data["level"], data["level_name"] = self.light_level()
        if self.is_mover:
            data["speed_mps"] = self.speed
        return data


class Scenario(BaseModel):
    """A scene and the events that happen in it, seeded."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str = "scenario"
    scene: str = "cabin"
    seed: int = Field(default=0, ge=0)  # numpy's generators take no negative seed
    description: str = ""
    events: tuple[EventSpec, ...] = Field(default=(), max_length=16)

    @model_validator(mode="after")
    def _names(self) -> Scenario:
        counts: dict[str, int] = {}
        named = []
        for e in self.events:
            counts[e.kind] = counts.get(e.kind, 0) + 1
            named.append(e if e.name else e.model_copy(update={"name": f"{e.kind.replace('_', '-')}-{counts[e.kind]}"}))
        names = [e.name for e in named]
        dupes = sorted({str(n) for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"event names must be unique: {', '.join(str(d) for d in dupes)}")
        object.__setattr__(self, "events", tuple(named))
        return self

    @property
    def movers(self) -> tuple[EventSpec, ...]:
        return tuple(e for e in self.events if e.is_mover)

    def to_dict(self) -> dict[str, Any]:
        """As recorded in a run's header (what `scenario_from_dict` reads back): the fields that were set."""
        return {"name": self.name, "scene": self.scene, "seed": self.seed,
                **self.model_dump(mode="json", exclude_defaults=True, include={"description", "events"})}


def _one_line(exc: ValidationError, source: str) -> ConfigError:
    """A pydantic error as one line: where in the scenario, and what is wrong."""
    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"]) or "scenario"
    msg = str(err["msg"]).removeprefix("Value error, ")
    if err["type"] == "extra_forbidden":
        msg = "unknown field"
    elif err["type"] == "literal_error":
        msg = f"{msg} (got {err.get('input')!r})"
    return ConfigError(f"scenario {source}: {where}: {msg}")


def scenario_from_dict(data: Any, source: str = "<dict>") -> Scenario:
    if not isinstance(data, dict):
        raise ConfigError(f"scenario {source}: expected a mapping with scene, seed, events")
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise _one_line(exc, source) from None


def _read_text(path: Path) -> str:
    """A scenario file's text, or one ConfigError line: not UTF-8 text, or unreadable."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"--events {path.name}: not UTF-8 text (byte {exc.object[exc.start:exc.start + 1].hex()} "
                          f"at offset {exc.start}); a scenario is a YAML file") from None
    except OSError as exc:
        raise ConfigError(f"--events {path.name}: cannot read it: {exc.strerror or exc}") from None


def builtin_scenarios() -> list[str]:
    root = resources.files("vlnpilot.scene") / BUILTIN_DIR
    return sorted(p.name.removesuffix(".yaml") for p in root.iterdir() if p.name.endswith(".yaml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A scenario from a YAML file, or a built-in one by name (`builtin_scenarios()`)."""
    text_name = str(name_or_path)
    path = Path(text_name)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError(f"--events {text_name}: no such file; built-in scenarios: "
                              f"{', '.join(builtin_scenarios())}")
        text, source = _read_text(path), path.name
    elif text_name in builtin_scenarios():
        text = (resources.files("vlnpilot.scene") / BUILTIN_DIR / f"{text_name}.yaml").read_text(encoding="utf-8")
        source = text_name
    else:
        raise ConfigError(f"unknown scenario {text_name!r}; valid: a YAML file or one of "
                          f"{', '.join(builtin_scenarios())}")
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"scenario {source}: not valid YAML{at}") from None
    data = dict(data) if isinstance(data, dict) else data
    if isinstance(data, dict):
        data.setdefault("name", Path(source).stem)
    return scenario_from_dict(data, source)


def with_scenario(scene: Scene, scenario: Scenario | None) -> Scene:
    """The scene with its events (validated against it); the scene itself without a scenario."""
    if scenario is None:
        return scene
    validate_scenario(scenario, scene)
    return replace(scene, scenario=scenario)


def scene_with_recorded(name: str, scenario: dict[str, Any] | None, source: str = "of the recording") -> Scene:
    """The scene `name` with a scenario as a run or a suite row records it (`Scenario.to_dict`); the scene as
    built without one: what a replay, a trial or a bench row flies in."""
    from vlnpilot.scene import load_scene  # the scene registry imports this module's package

    scene = load_scene(name)
    return with_scenario(scene, scenario_from_dict(scenario, source)) if scenario else scene


def _point_problem(point: tuple[float, float], bounds: tuple[tuple[float, float], tuple[float, float]]) -> str | None:
    """What is wrong with a path's [x, y] point, if anything: it must be finite and inside the scene (a mover walks
    there; one outside the house was accepted, one at NaN was misreported as touching the drone's spawn)."""
    (xmin, ymin), (xmax, ymax) = bounds
    x, y = point
    if math.isfinite(x) and math.isfinite(y) and xmin <= x <= xmax and ymin <= y <= ymax:
        return None
    return (f"path point {[x, y]} is outside the scene: x must be in {xmin:g}..{xmax:g} and y in {ymin:g}..{ymax:g} "
            "(metres, finite)")


def validate_scenario(scenario: Scenario, scene: Scene) -> None:
    """Refuse, in one line, an event that names a room, door or wall the scene does not have, or a path that
    does not connect (consecutive rooms must share an open door)."""
    if scenario.scene != scene.name and not scene.name.startswith(scenario.scene):
        raise ConfigError(f"scenario {scenario.name} is for scene {scenario.scene!r}, not {scene.name!r}; "
                          f"fly it with --scene {scenario.scene}")
    rooms = {r.id for r in scene.rooms}
    doors = {d.id: d for d in scene.open_doors()}

    def fail(e: EventSpec, what: str) -> None:
        raise ConfigError(f"scenario {scenario.name}: event {e.name}: {what}")

    def check_room(e: EventSpec, room: str | None, what: str = "room") -> None:
        if room not in rooms:
            fail(e, f"unknown {what} {room!r}; valid rooms: {', '.join(sorted(rooms))}")

    for e in scenario.events:
        if e.trigger.enter is not None:
            check_room(e, e.trigger.enter, "trigger room")
        if e.is_mover:
            prev: str | None = None
            for p in e.path:
                problem = None if isinstance(p, str) else _point_problem(p, scene.bounds)
                if problem is not None:
                    fail(e, problem)
                if isinstance(p, str):
                    if p not in rooms and p not in doors:
                        fail(e, f"path names {p!r}, which is neither a room nor an open door; valid: "
                                f"{', '.join(sorted(rooms | set(doors)))}")
                    if p in rooms and prev in rooms and p != prev and not scene.doors_between(prev, p):
                        fail(e, f"path goes from {prev} to {p}, which share no open door")
                    prev = p
            if e.pause_door is not None and e.pause_door not in doors:
                fail(e, f"unknown pause_door {e.pause_door!r}; valid: {', '.join(sorted(doors))}")
        elif e.kind == "door_closes" and e.door not in doors:
            fail(e, f"unknown open door {e.door!r}; valid: {', '.join(sorted(doors))}")
        elif e.kind in ("lights_out", "sign"):
            check_room(e, e.room)
            if e.at is not None and scene.room_at(*e.at) != e.room:
                fail(e, f"at {list(e.at)} is not in the room {e.room}")
