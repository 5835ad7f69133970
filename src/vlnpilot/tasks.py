"""Tasks, query parsing, the success monitor and per-episode metrics.

A query ("Go to the bathroom", "Find the mirror in the bedroom") is parsed against the scene's room and
target aliases. The monitor judges a final state against ground truth, as the paper's controller does.
Metrics follow habitat-lab's Measure shape: small objects with reset/update/value.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from vlnpilot.commands import OPPOSITE, Command, Kind
from vlnpilot.errors import VLNPilotError
from vlnpilot.fsm import State
from vlnpilot.scene.model import Scene, _norm
from vlnpilot.success import DEFAULT_SUCCESS, SuccessConfig
from vlnpilot.types import GroundTruth, Pose


class QueryError(VLNPilotError, ValueError):
    """A query that names no known room or object; the message lists the known ones."""


@dataclass(frozen=True)
class Task:
    query: str
    goal_room: str
    goal_target: str | None = None

    @property
    def kind(self) -> str:
        return "object" if self.goal_target else "room"


_FIND_WORDS = ("find", "look for", "search for", "search", "locate", "where is", "show me")


def _mentions(text: str, names: tuple[str, ...]) -> int:
    """Length of the longest name found in `text` on word boundaries (0 if none)."""
    best = 0
    for n in names:
        key = _norm(n)
        if key and re.search(rf"(?<!\w){re.escape(key)}(?!\w)", text):
            best = max(best, len(key))
    return best


def parse_query(query: str, scene: Scene) -> Task:
    """Turn a free-form query into a Task. Unknown rooms or objects raise QueryError listing the known ones."""
    from vlnpilot.exits import shorten
    text = _norm(query)
    if not text:
        raise QueryError("the query is empty; try e.g. 'Go to the bedroom' or 'Find the mirror in the bedroom'")
    rooms = sorted(((_mentions(text, r.names()), r) for r in scene.rooms), key=lambda p: -p[0])
    targets = sorted(((_mentions(text, t.names()), t) for t in scene.targets), key=lambda p: -p[0])
    room = rooms[0][1] if rooms and rooms[0][0] else None
    target = targets[0][1] if targets and targets[0][0] else None
    known_rooms = ", ".join(r.name for r in scene.rooms)
    known_targets = ", ".join(f"{t.name} ({scene.room(t.room).name})" for t in scene.targets)
    wants_object = text.startswith(_FIND_WORDS)
    if target is not None:
        if room is not None and room.id != target.room:
            raise QueryError(f"there is no {target.name} in the {room.name}: the {target.name} is in the "
                             f"{scene.room(target.room).name}; known objects: {known_targets}")
        return Task(query=query, goal_room=target.room, goal_target=target.id)
    if wants_object:
        raise QueryError(f"unknown object in {shorten(query)!r}; known objects: {known_targets}")
    if room is None:
        raise QueryError(f"no known room in {shorten(query)!r}; known rooms: {known_rooms}")
    return Task(query=query, goal_room=room.id)


def judge(task: Task, final_state: State, gt: GroundTruth, config: SuccessConfig = DEFAULT_SUCCESS) -> tuple[bool, str]:
    """Whether the pilot's final state achieves the task, with a one-line reason."""
    room = gt.room()
    if task.goal_target is None:
        if final_state is not State.STAY_ON_ROOM:
            return False, f"declared {final_state.value} for a room goal"
        ok = room == task.goal_room
        return ok, f"drone is in {room or 'no room'}; goal room {task.goal_room}"
    if final_state is not State.DESCRIBE_OBJECT:
        return False, f"declared {final_state.value} for an object goal"
    dist, bearing = gt.target_distance_bearing(task.goal_target)
    visible = gt.target_visible(task.goal_target)
    ok = (dist <= config.object_distance_m and abs(bearing) <= config.object_facing_deg
          and (visible or not config.object_must_be_visible))
    return ok, (f"{task.goal_target} at {dist:.2f} m (max {config.object_distance_m}), bearing {bearing:+.0f}° "
                f"(max ±{config.object_facing_deg:.0f}°), {'visible' if visible else 'not visible'}")


def shortest_path_length(scene: Scene, start: Pose, task: Task, config: SuccessConfig = DEFAULT_SUCCESS) -> float:
    """Geodesic estimate for SPL: straight segments through the centres of the doors on the room path.

    For a room goal the path ends 0.1 m inside the goal room; for an object it ends on the target's facing
    axis, 0.2 m inside the success distance. Furniture is ignored, so this is a lower bound.
    """
    start_room = scene.room_at(start.x, start.y)
    pts = [(start.x, start.y)]
    if start_room is not None and start_room != task.goal_room:
        path = scene.room_path(start_room, task.goal_room)
        for a, b in zip(path, path[1:], strict=False):
            door = scene.doors_between(a, b)[0]
            pts.append(door.center)
            if b == task.goal_room and task.goal_target is None:
                nx, ny = door.normal if door.rooms[0] == a else (-door.normal[0], -door.normal[1])
                pts.append((door.center[0] + 0.1 * nx, door.center[1] + 0.1 * ny))
    if task.goal_target is not None:
        t = scene.target(task.goal_target)
        d = config.object_distance_m - 0.2
        facing = math.radians(t.facing_deg)
        pts.append((t.position[0] + d * math.cos(facing), t.position[1] + d * math.sin(facing)))
    return sum(math.dist(p, q) for p, q in zip(pts, pts[1:], strict=False))


# -- metrics (reset / update / value) -----------------------------------------------------------------
class PathLength:
    def reset(self) -> None:
        self.total = 0.0

    def update(self, before: Pose, after: Pose) -> None:
        self.total += math.dist((before.x, before.y, before.z), (after.x, after.y, after.z))

    def value(self) -> float:
        return self.total


class Oscillations:
    """Direction reversals of rotation or lateral moves in a row (C after B, D2 after D1, ...)."""

    def reset(self) -> None:
        self.count = 0
        self._last: Kind | None = None

    def update(self, executed: Command) -> bool:
        """Count `executed`; True when it reverses the previous move."""
        reversal = self._last is not None and OPPOSITE.get(executed.kind) is self._last
        self.count += reversal
        self._last = executed.kind
        return reversal

    def value(self) -> int:
        return self.count


def spl(success: bool, shortest: float, taken: float) -> float:
    """Success weighted by Path Length (Anderson et al. 2018)."""
    if not success:
        return 0.0
    if shortest <= 1e-9:
        return 1.0
    return shortest / max(taken, shortest)

