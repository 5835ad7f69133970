"""Tasks, query parsing, the success monitor and per-episode metrics.

A query ("Go to the bathroom", "Find the mirror in the bedroom") is parsed against the scene's room and
target aliases. The monitor judges a final state against ground truth, as the paper's controller does.
Metrics follow habitat-lab's Measure shape: small objects with reset/update/value.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from vlnpilot.core.commands import OPPOSITE, Command, Kind
from vlnpilot.core.environment import GroundTruth
from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Pose
from vlnpilot.scene.geodesic import geodesic_length
from vlnpilot.scene.model import Scene, _norm
from vlnpilot.scene.validate import CLEARANCE_M, occupancy
from vlnpilot.tasks.success import DEFAULT_SUCCESS, SuccessConfig, object_view


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


MAX_QUERY_CHARS = 2000  # the pilot server's limit too (server.app.DecideRequest): a run must fit through it


def check_query_text(query: str) -> None:
    """QueryError for a query no pilot could be sent: over MAX_QUERY_CHARS, or bytes that are not UTF-8."""
    from vlnpilot.core.exits import shorten, undecodable

    if len(query) > MAX_QUERY_CHARS:
        raise QueryError(f"the query is {len(query)} characters; the limit is {MAX_QUERY_CHARS} "
                         f"(the pilot server's): {shorten(query)!r}")
    bad = undecodable(query)
    if bad:
        raise QueryError(f"the query is not valid UTF-8 ({bad}); retype it, or set a UTF-8 locale")


def parse_query(query: str, scene: Scene) -> Task:
    """Turn a free-form query into a Task. Unknown rooms or objects raise QueryError listing the known ones."""
    from vlnpilot.core.exits import shorten
    check_query_text(query)
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
    seen = object_view(gt, task.goal_target, config)
    return seen.reached(config), seen.reason(task.goal_target, config)


def shortest_path_length(scene: Scene, start: Pose, task: Task, config: SuccessConfig = DEFAULT_SUCCESS) -> float:
    """The shortest path for SPL: geodesic on the validated occupancy grid at flight height (around furniture,
    through doorways; `scene.geodesic`), from the start to the goal point.

    For a room goal the path ends 0.1 m inside the goal room past the last door on the room path; for an object
    it ends on the target's facing axis, 0.2 m inside the success distance. Where no clear path joins them (a
    start inside the margins of a solid), the straight segments through the door centres stand in.
    """
    through_doors = shortest_path_points(scene, start, task, config)
    if len(through_doors) < 2:
        return 0.0
    grid = occupancy(scene, CLEARANCE_M)
    geodesic = geodesic_length(grid, through_doors[0], through_doors[-1])
    if geodesic is not None:
        return geodesic
    return sum(math.dist(p, q) for p, q in zip(through_doors, through_doors[1:], strict=False))


def shortest_path_points(scene: Scene, start: Pose, task: Task, config: SuccessConfig) -> list[tuple[float, float]]:
    """The start, the centres of the doors on the room path, and the goal point (the start alone when there): the
    ends of the geodesic path, and where a mission's next stage starts."""
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
    return pts


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

