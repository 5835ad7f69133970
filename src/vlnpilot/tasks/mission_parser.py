"""The deterministic mission parser: an instruction in plain English -> a `Mission` (for the oracle, offline runs
and the tests; model pilots plan with the model, `pilots/planning.py`).

The grammar, on the normalised instruction (lower case, `_-/` as spaces, the end's punctuation dropped):

1. Every room and object name of the scene (ids, names, aliases; the longest first) is masked as one token, so
   that "living room and kitchen" or "living room/kitchen" stay one name.
2. The rest is cut into clauses at sentence ends, `;`, commas, "and then", "then", "after that", "afterwards",
   "and", and before "without", "avoiding", "but", "don't", "do not", "never". Leading fillers (and, then,
   please, first, next, finally, but) are dropped.
3. Each clause is one of:
   - avoid:     "don't go to X", "do not enter X", "avoid X", "stay out of X", "without going through X", "never X"
                -> X (rooms only) is avoided for the whole mission;
   - not:       "not (to) the X" -> X is named as not wanted (no stage);
   - return:    "come back", "go back", "return", "back to where you started" -> a stage back to the start room,
                or to the room or object it names ("come back to the living room");
   - landmark:  "through the X", "via the X", "past the X" -> a room stage (the drone declares it is there);
   - a goal:    names one object (and perhaps its room) -> an object stage; else one room -> a room stage.
4. A clause that names nothing it can read, names two different goals ("the bedroom or the bathroom"), an
   unknown object after a find-word, or an object in the wrong room is refused: `PlanError`, naming the clause
   and what the map offers. Nothing is dropped silently.

A one-clause instruction that is a plain goal is read by `tasks.parse_query`, exactly as before.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from vlnpilot.core.exits import shorten
from vlnpilot.scene.model import Scene, _norm
from vlnpilot.tasks.mission import Mission, PlanError, Stage, offers, validate_mission
from vlnpilot.tasks.task import _FIND_WORDS, QueryError, parse_query

_TOKEN = re.compile(r"@(\d+)@")
_SPLIT = re.compile(r"\s*(?:;|[.!?]\s+|,\s*and then\b|,\s*then\b|,\s*after that\b|,\s*afterwards\b|,\s*and\b|,|"
                    r"\band then\b|\bthen\b|\bafter that\b|\bafterwards\b|\band\b|(?=\bwithout\b)|"
                    r"(?=\bavoiding\b)|(?=\bbut\b)|(?=\b(?:don't|do not|never)\b))\s*")
_FILLER = re.compile(r"^(?:and|then|please|first|next|finally|lastly|but|also|now|ok|okay)\b\s*")
_AVOID = re.compile(r"^(?:don t|don't|dont|do not|never|avoid|avoiding|stay out of|keep out of|"
                    r"without (?:going|passing|flying|entering)|(?:but )?not (?:through|via|into))\b")
_NOT = re.compile(r"^(?:not|but not)\b")
_RETURN = re.compile(r"\b(?:come back|go back|fly back|head back|get back|return|returning|back to)\b")
_LANDMARK = re.compile(r"^(?:(?:go|fly|head|pass|passing|travel)\s+)?(?:through|via|past|by way of)\b")
_LANDMARK_TO = re.compile(r"^(?P<via>.*?@\d+@.*?)\s+(?:on\s+)?(?:to|into|towards)\s+(?P<goal>.*@\d+@.*)$")
_GOAL_VIA = re.compile(r"^(?P<goal>.*@\d+@.*?)\s+(?:via|through|passing through|by way of)\s+(?P<via>.*@\d+@.*)$")
_END_PUNCT = re.compile(r"[.!?]+\s*$")


@dataclass(frozen=True)
class _Name:
    kind: str  # room | object
    id: str
    text: str


def _vocabulary(scene: Scene) -> list[tuple[str, _Name]]:
    """Every name of every room and object, normalised, the longest first (objects before rooms on a tie)."""
    out = [(_norm(n), _Name("object", t.id, n)) for t in scene.targets for n in t.names()]
    out += [(_norm(n), _Name("room", r.id, n)) for r in scene.rooms for n in r.names()]
    return sorted((p for p in out if p[0]), key=lambda p: (-len(p[0]), p[1].kind != "object"))


def _mask(text: str, scene: Scene) -> tuple[str, list[_Name]]:
    names: list[_Name] = []
    for key, name in _vocabulary(scene):
        pattern = re.compile(rf"(?<![\w@]){re.escape(key)}(?![\w@])")
        if pattern.search(text):
            names.append(name)
            text = pattern.sub(f"@{len(names) - 1}@", text)
    return text, names


def _unmask(text: str, names: list[_Name]) -> str:
    return _TOKEN.sub(lambda m: names[int(m.group(1))].text, text)


def _named(clause: str, names: list[_Name]) -> list[_Name]:
    return [names[int(i)] for i in _TOKEN.findall(clause)]


def _distinct(found: list[_Name], kind: str) -> list[str]:
    return list(dict.fromkeys(n.id for n in found if n.kind == kind))


def _refuse(why: str, clause: str, query: str, scene: Scene) -> PlanError:
    return PlanError(f"could not read {shorten(clause)!r} in {shorten(query)!r}: {why}; {offers(scene)}")


def _clauses(masked: str) -> list[str]:
    out = []
    for part in _SPLIT.split(masked):
        part = part.strip(" ,")
        while (stripped := _FILLER.sub("", part)) != part:
            part = stripped
        if part:
            out.append(part)
    return out


def parse_mission(query: str, scene: Scene) -> Mission:
    """Read `query` into a Mission (not yet validated against reachability: `mission.validate_mission`)."""
    text = _END_PUNCT.sub("", _norm(query))
    if not text:
        raise PlanError("the query is empty; try e.g. 'Go to the bedroom' or 'Go to the bedroom, then come back'")
    masked, names = _mask(text, scene)
    clauses = _clauses(masked)
    if len(clauses) == 1 and not (_AVOID.match(clauses[0]) or _NOT.match(clauses[0])
                                  or _RETURN.search(clauses[0]) or _LANDMARK.match(clauses[0])
                                  or _GOAL_VIA.match(clauses[0])):
        try:
            task = parse_query(query, scene)  # today's reading and refusals, byte for byte
        except QueryError as exc:
            raise PlanError(str(exc)) from None
        _goal(clauses[0], names, query, scene)  # and the refusals of a clause of a longer one (two rooms, ...)
        return Mission.from_task(task)
    stages: list[Stage] = []
    avoid: list[str] = []
    not_goals: list[str] = []
    for clause in clauses:
        found = _named(clause, names)
        words = _unmask(clause, names)
        if _AVOID.match(clause):
            rooms = _distinct(found, "room")
            if not rooms or _distinct(found, "object"):
                raise _refuse("only rooms can be avoided", words, query, scene)
            avoid += [r for r in rooms if r not in avoid]
        elif _NOT.match(clause):
            if not found:
                raise _refuse("'not' names nothing on the map", words, query, scene)
            not_goals += [n.id for n in found if n.id not in not_goals]
        elif _LANDMARK.match(clause) or _GOAL_VIA.match(clause):
            m = _LANDMARK_TO.match(clause) if _LANDMARK.match(clause) else _GOAL_VIA.match(clause)
            via, goal = (m.group("via"), m.group("goal")) if m else (clause, None)
            rooms = _distinct(_named(via, names), "room")
            if len(rooms) != 1 or _distinct(_named(via, names), "object"):
                raise _refuse("a route passes through one room", _unmask(via, names), query, scene)
            stages.append(Stage("room", rooms[0], None, _unmask(via, names)))
            if goal is not None:
                stages.append(_goal(goal, names, query, scene))
        elif _RETURN.search(clause) and not found:
            stages.append(Stage("return", None, None, words))
        else:
            stages.append(_goal(clause, names, query, scene))
    if not stages:
        raise PlanError(f"no goal in {shorten(query)!r}: it names only what to avoid or not to do; {offers(scene)}")
    return Mission(query=query, stages=tuple(stages), avoid=tuple(avoid), not_goals=tuple(not_goals))


def _goal(clause: str, names: list[_Name], query: str, scene: Scene) -> Stage:
    """A clause that names one goal: an object (perhaps with its room) or a room."""
    found, words = _named(clause, names), _unmask(clause, names)
    objects, rooms = _distinct(found, "object"), _distinct(found, "room")
    if len(objects) > 1:
        raise _refuse(f"it names {len(objects)} objects ({', '.join(objects)}): say which one", words, query, scene)
    if objects:
        target = scene.target(objects[0])
        if len(rooms) > 1 or (rooms and rooms[0] != target.room):
            raise _refuse(f"the {target.name} is in the {scene.room(target.room).name}", words, query, scene)
        return Stage("object", target.room, target.id, words)
    if _norm(words).startswith(_FIND_WORDS):
        raise _refuse("no known object", words, query, scene)
    if len(rooms) > 1:
        raise _refuse(f"it names {len(rooms)} rooms ({', '.join(rooms)}): say which one", words, query, scene)
    if not rooms:
        raise _refuse("it names no room or object of the map", words, query, scene)
    return Stage("room", rooms[0], None, words)


def plan_mission(query: str, scene: Scene, start_room: str | None) -> Mission:
    """The deterministic parser's plan of `query`, validated against the map and resolved against the start."""
    return validate_mission(parse_mission(query, scene), scene, start_room)
