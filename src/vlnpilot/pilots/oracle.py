"""The oracle: a privileged pilot that reads ground truth and answers in exactly the model's protocol.

It walks the same FSM with the same commands as a model would (only the moves each state allows), so it
is the upper bound in every table and the proof that scene, commands, FSM and monitor agree.
Strategy per state: recognise (rotate towards the next waypoint), line up on the doorway's centre line
at an approach point, cross it with A1 moves, move into the new room, and for objects fly to a viewing
point on the object's facing axis and turn to face it.

With events in the scene (issue 24) it reads them through ground truth like everything else: it plans its route
on the true map (a door that closed is gone from it, so it replans around it), reports Goal Unreachable from
Search Open Door when no route is left, hovers while a person stands or walks in its way, and ignores signs.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar

from pydantic import Field

from vlnpilot.core.commands import COMMANDS, Kind
from vlnpilot.core.decision import Decision, DoorPosition, PilotInput, PilotTraits
from vlnpilot.core.environment import GroundTruth
from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.fsm import State, state_spec
from vlnpilot.core.records import Pose, wrap_deg
from vlnpilot.core.tello_spec import horizontal_fov_deg
from vlnpilot.pilots.base import BasePilot, register_pilot
from vlnpilot.pilots.options import PilotOptions, within
from vlnpilot.scene.model import Door
from vlnpilot.tasks.mission import Mission, route
from vlnpilot.tasks.task import SuccessConfig, Task, parse_query

ALIGN_DEG = 7.5  # half of the smallest rotation: closer than this cannot be improved
WAIT_AHEAD_M = 1.3  # a person this far ahead in the drone's corridor makes the oracle wait
WAIT_SIDE_M = 0.35  # the corridor's half width beyond the person's footprint
WAIT_NEAR_M = 0.45  # ... and any walking person whose footprint comes this close within the next second
_TRANSLATIONS = (Kind.FORWARD, Kind.LATERAL_LEFT, Kind.LATERAL_RIGHT)  # a rotation on the spot never meets anyone
HALF_HFOV = horizontal_fov_deg() / 2


def _bearing(pose: Pose, x: float, y: float) -> float:
    return wrap_deg(math.degrees(math.atan2(y - pose.y, x - pose.x)) - pose.yaw_deg)


def _rotation(error_deg: float, allowed: tuple[str, ...]) -> str | None:
    """The allowed rotation that best reduces a heading error (+ = target to the left), or None."""
    best, best_left = None, abs(error_deg)
    for code in allowed:
        c = COMMANDS[code]
        if not c.is_rotation:
            continue
        signed = c.amount if c.kind is Kind.ROTATE_LEFT else -c.amount
        left = abs(error_deg - signed)
        if left < best_left - 1e-9:
            best, best_left = code, left
    return best


def _signed(code: str) -> float:
    c = COMMANDS[code]
    return c.amount if c.kind is Kind.ROTATE_LEFT else -c.amount if c.kind is Kind.ROTATE_RIGHT else 0.0


# Distances an indoor flight can use: a doorway's approach and crossing, an object's viewing point, within a room.
ApproachM = Annotated[float, within(0.1, 1.5, "m")]
CrossM = Annotated[float, within(0.1, 1.5, "m")]
ViewM = Annotated[float, within(0.2, 2.0, "m")]
LateralTolM = Annotated[float, within(0.0, 0.3, "m")]


class OracleOptions(PilotOptions):
    """The oracle's distances (metres). `success` is programmatic: the thresholds its episodes are judged by."""

    programmatic: ClassVar[frozenset[str]] = frozenset({"success"})
    takes_model: ClassVar[bool] = False  # it flies on ground truth, whatever a SPEC says

    model: str = "ground-truth"
    approach_m: ApproachM = 0.45  # the approach point's distance before a doorway
    cross_m: CrossM = 0.35  # how far past the door plane a crossing ends
    view_m: ViewM = 0.7  # the viewing point's distance in front of an object
    lateral_tol_m: LateralTolM = 0.05  # off the doorway's centre line that still counts as centred
    success: SuccessConfig = Field(default_factory=SuccessConfig)


@register_pilot("oracle", options=OracleOptions)
class OraclePilot(BasePilot):
    """Privileged pilot: `attach(ground_truth)` before the first `decide`."""

    name = "oracle"
    traits = PilotTraits(privileged=True)

    def __init__(self, model: str | None = None, **options: Any):
        self._configure(OracleOptions.build(self.name, model=model, **options))

    def _configure(self, o: OracleOptions) -> None:
        self.model = o.model
        self.approach_m, self.cross_m, self.view_m, self.lateral_tol_m = o.approach_m, o.cross_m, o.view_m, \
            o.lateral_tol_m
        self.success = o.success
        self._gt: GroundTruth | None = None
        self._task: Task | None = None
        self._avoid: tuple[str, ...] = ()  # rooms the mission never enters
        self._stage = 0  # the mission's stage the oracle flies
        self._waypoint: tuple[float, float] | None = None  # a free point to fly to first (missions)
        self._centred: set[str | None] = set()  # rooms whose spawn point this stage has flown to
        self._room: str | None = None

    def attach(self, ground_truth: GroundTruth) -> None:
        self._gt, self._task, self._room = ground_truth, None, None

    @property
    def _truth(self) -> GroundTruth:
        if self._gt is None:
            raise VLNPilotError("the oracle needs ground truth: call attach(ground_truth) first")
        return self._gt

    @property
    def _goal(self) -> Task:
        if self._task is None:
            raise VLNPilotError("the oracle has no task yet: decide() reads it from the step")
        return self._task

    def _target(self) -> str:
        """The id of the object the current task goes to (only asked in the object states)."""
        target = self._goal.goal_target
        if target is None:
            raise VLNPilotError("the oracle's task has no object to reach")
        return target

    # -- geometry helpers ----------------------------------------------------------------------------
    def _next_door(self, room: str, goal: str) -> tuple[Door, tuple[float, float]] | None:
        """The door to cross next on the way to `goal`, and its normal pointing away from `room`."""
        scene = self._truth.scene
        if room == goal:
            return None
        path = route(scene, room, goal, self._avoid)
        if path is None:
            raise VLNPilotError(f"the oracle finds no route from {room} to {goal}")
        door = scene.doors_between(path[0], path[1])[0]
        nx, ny = door.normal
        return (door, (nx, ny)) if door.rooms[0] == room else (door, (-nx, -ny))

    def _viewing_point(self) -> tuple[float, float]:
        t = self._truth.scene.target(self._target())
        a = math.radians(t.facing_deg)
        return t.position[0] + self.view_m * math.cos(a), t.position[1] + self.view_m * math.sin(a)

    def _goto(self, pose: Pose, x: float, y: float, allowed: tuple[str, ...]) -> str:
        """Rotate towards (x, y) if needed, else fly the longest allowed forward move that does not overshoot."""
        dist, err = math.hypot(x - pose.x, y - pose.y), _bearing(pose, x, y)
        # Turn only when flying on would miss the point by more than a few centimetres (no zig-zag).
        miss = dist * math.sin(math.radians(min(abs(err), 90.0)))
        if abs(err) > ALIGN_DEG and (miss > 0.06 or abs(err) > 45.0) and (rot := _rotation(err, allowed)):
            return rot
        forwards = sorted((c for c in allowed if COMMANDS[c].kind is Kind.FORWARD), key=lambda c: -COMMANDS[c].amount)
        for code in forwards:
            if COMMANDS[code].amount <= dist + 0.03:
                return code
        return forwards[-1] if forwards else "E"

    # -- the policy -------------------------------------------------------------------------------------
    def decide(self, pilot_input: PilotInput) -> Decision:
        if self._gt is None:
            raise VLNPilotError("the oracle needs ground truth: call attach(ground_truth) first")
        self._task = self._current_task(pilot_input)
        pose = self._truth.pose()
        self._room = self._truth.room() or self._room
        state = pilot_input.state
        if pilot_input.mission is not None:
            self._mission_waypoint(pilot_input, state)
        spec = state_spec(state, pilot_input.profile)
        allowed = spec.moves
        blocked = self._unreachable_goal()
        move, nxt, note = self._no_route(state, allowed) if blocked else self._policy(state, pose, allowed)
        if COMMANDS[move].kind in _TRANSLATIONS and self._mover_in_the_way(pose, move):
            move, nxt, note = self._wait(state, allowed, spec.next_states, move, nxt)
        assert move in spec.answer_moves, (state, move)
        return Decision(room=self._room or "unknown", movement=move, state=nxt.value, description=note,
                        door_position=self._door_position(pose), model=self.model)

    def _current_task(self, pilot_input: PilotInput) -> Task:
        """The goal of this step: the mission's current stage (and its rooms to avoid), or the parsed query."""
        mission = pilot_input.mission
        if mission is not None:
            self._avoid = tuple(mission.get("avoid") or ())
            return Mission.from_dict(mission).task(pilot_input.stage)
        if self._task is None or self._task.query != pilot_input.query:
            self._avoid = ()
            return parse_query(pilot_input.query, self._truth.scene)
        return self._task

    def _policy(self, state: State, pose: Pose, allowed: tuple[str, ...]) -> tuple[str, State, str]:
        task, room = self._goal, self._room
        nd = self._next_door(room, task.goal_room) if room else None
        S = State
        if state is S.RECOGNIZE_ROOM:
            if self._waypoint is not None and math.hypot(self._waypoint[0] - pose.x, self._waypoint[1] - pose.y) > 0.12:
                return self._goto(pose, *self._waypoint, allowed), S.RECOGNIZE_ROOM, "Moving into the open room."
            self._waypoint = None
            if nd is None:
                if task.goal_target is None:
                    return (_rotation(15.0, allowed) or allowed[0]), S.STAY_ON_ROOM, f"I am in the {room}, the goal."
                x, y = self._viewing_point()
                return self._goto(pose, x, y, allowed), S.SEARCH_OBJECT, f"In the {room}; searching the object."
            px, py = self._approach_point(*nd)
            return self._goto(pose, px, py, allowed), S.SEARCH_OPEN_DOOR, f"In the {room}; looking for {nd[0].id}."
        if state is S.SEARCH_OPEN_DOOR:
            nd = self._door_needed(nd, state)
            px, py = self._approach_point(*nd)
            err = _bearing(pose, px, py)
            near = math.hypot(px - pose.x, py - pose.y) < 0.08
            if near:  # at the approach point: face along the door normal
                err = wrap_deg(math.degrees(math.atan2(nd[1][1], nd[1][0])) - pose.yaw_deg)
            rot = _rotation(err, allowed) if abs(err) > ALIGN_DEG else None
            if rot and abs(err - _signed(rot)) > ALIGN_DEG:
                return rot, S.SEARCH_OPEN_DOOR, "Turning to look for the open door."
            ahead = "A1" if near else self._goto(pose, px, py, allowed)  # never turn back to a point just passed
            return (rot or ahead), S.ORIENTED_TOWARDS_DOOR, "Open door found ahead."
        if state is S.ORIENTED_TOWARDS_DOOR:
            return self._orient(pose, *self._door_needed(nd, state), allowed)
        if state is S.GO_THROUGH_DOOR:
            depth = self._door_depth(pose)
            nxt = S.POSITION_IN_CENTER if depth + 0.1 >= self.cross_m else S.GO_THROUGH_DOOR
            return "A1", nxt, "Crossing the doorway."
        if state is S.POSITION_IN_CENTER:
            if nd is None:
                return self._goto(pose, *self._room_entry_point(pose), allowed), S.RECOGNIZE_ROOM, "Entering the room."
            px, py = self._approach_point(*nd)
            far = math.hypot(px - pose.x, py - pose.y) > 0.4  # A2 here is faster than A1 in the door states
            return self._goto(pose, px, py, allowed), (S.POSITION_IN_CENTER if far else S.RECOGNIZE_ROOM), \
                "Moving into the room."
        if state is S.SEARCH_OBJECT:
            vx, vy = self._viewing_point()
            if math.hypot(vx - pose.x, vy - pose.y) > 0.12:
                return self._goto(pose, vx, vy, allowed), S.SEARCH_OBJECT, "Searching the object."
            t = self._truth.scene.target(self._target())
            err = _bearing(pose, t.position[0], t.position[1])
            rot = _rotation(err, allowed) if abs(err) > ALIGN_DEG else None
            if rot is None:
                return "A1", S.REACH_OBJECT, f"The {t.name} is centred ahead."
            done = abs(err - _signed(rot)) <= ALIGN_DEG
            return rot, (S.REACH_OBJECT if done else S.SEARCH_OBJECT), f"Turning towards the {t.name}."
        if state is S.REACH_OBJECT:
            dist, err = self._truth.target_distance_bearing(self._target())
            if abs(err) > ALIGN_DEG and (rot := _rotation(err, allowed)):
                return rot, S.REACH_OBJECT, "Centring the object."
            if dist > self.success.object_distance_m - 0.1:
                return "A1", S.REACH_OBJECT, "Approaching the object."
            return "E", S.DESCRIBE_OBJECT, f"The {task.goal_target} is right in front of me, about {dist:.1f} m away."
        if state in (S.STAY_ON_ROOM, S.DESCRIBE_OBJECT):
            return "E", S.FINAL, "Done."
        raise VLNPilotError(f"the oracle has no policy for state {state.value}")

    # -- events (issue 24) ------------------------------------------------------------------------------------
    def _unreachable_goal(self) -> bool:
        """Whether no route of the true map leads from this room to the goal room (a door on it has closed)."""
        room = self._room
        return room is not None and room != self._goal.goal_room and \
            route(self._truth.scene, room, self._goal.goal_room, self._avoid) is None

    def _no_route(self, state: State, allowed: tuple[str, ...]) -> tuple[str, State, str]:
        """On the way to Goal Unreachable, which only Search Open Door may declare (the FSM's addition)."""
        S, goal = State, self._goal.goal_room
        if state is S.SEARCH_OPEN_DOOR:
            return "E", S.GOAL_UNREACHABLE, f"Every door towards the {goal} is closed: the goal is unreachable."
        note = f"The door towards the {goal} has closed; looking for another way."
        if state is S.RECOGNIZE_ROOM:
            return (_rotation(15.0, allowed) or allowed[0]), S.SEARCH_OPEN_DOOR, note
        if state in (S.ORIENTED_TOWARDS_DOOR, S.GO_THROUGH_DOOR):
            return "E", (S.SEARCH_OPEN_DOOR if state is S.ORIENTED_TOWARDS_DOOR else S.ORIENTED_TOWARDS_DOOR), note
        if state is S.POSITION_IN_CENTER:
            return (_rotation(15.0, allowed) or allowed[0]), S.RECOGNIZE_ROOM, note
        raise VLNPilotError(f"the oracle finds no route to {goal} in state {state.value}")

    def _mover_in_the_way(self, pose: Pose, move: str) -> bool:
        """Whether a person (a mover tall enough to reach the drone) stands or walks in the corridor ahead, or
        walks close within the next second. A pet walks under the drone."""
        c, s = pose.heading()
        lateral = COMMANDS[move].kind in (Kind.LATERAL_LEFT, Kind.LATERAL_RIGHT)
        for m in self._truth.movers():
            if m.height < pose.z - 0.2:
                continue
            for seen in (m, m.at(1.0)):
                dx, dy = seen.x - pose.x, seen.y - pose.y
                along, side = dx * c + dy * s, -dx * s + dy * c
                if (m.vx or m.vy) and math.hypot(dx, dy) - m.radius < WAIT_NEAR_M:
                    return True
                if not lateral and -0.1 < along < WAIT_AHEAD_M + m.radius and abs(side) < m.radius + WAIT_SIDE_M:
                    return True
        return False

    def _wait(self, state: State, allowed: tuple[str, ...], next_states: tuple[State, ...], move: str,
              nxt: State) -> tuple[str, State, str]:
        """Hover (where the state allows it, else turn on the spot, always the same way) until the way is clear."""
        stay = state if state in next_states else nxt
        if "E" in allowed:
            return "E", stay, "A person is in the way: waiting for them to pass."
        rot = next((c for c in ("C1", "B1") if c in allowed), move)
        return rot, stay, "A person is in the way: turning on the spot while they pass."

    def _door_needed(self, nd: tuple[Door, tuple[float, float]] | None, state: State
                     ) -> tuple[Door, tuple[float, float]]:
        if nd is None:
            raise VLNPilotError(f"the oracle is in the goal room {self._room}, with no door to find in {state.value}")
        return nd

    def _mission_waypoint(self, pilot_input: PilotInput, state: State) -> None:
        """In a mission, Recognize Room first flies to the room's spawn point when a stage starts away from its
        goal (it starts wherever the last one ended: in front of an object, beside a door leaf; the oracle's
        straight lines are proven from the spawn points), and 0.8 m straight on when an object's room is entered
        (a turn at once may graze the door leaf just passed). One-stage episodes fly exactly as before."""
        task = self._goal
        if pilot_input.stage != self._stage:
            self._stage, self._centred = pilot_input.stage, set()
            if task.goal_room != self._room:
                self._centred.add(self._room)
                self._waypoint = self._room_spawn()
        entering = task.goal_target is not None and self._room == task.goal_room and pilot_input.step > 1
        if state is State.RECOGNIZE_ROOM and entering and self._room not in self._centred:
            self._centred.add(self._room)  # straight on, away from the door leaf just passed
            self._waypoint = self._ahead(self._truth.pose(), 0.8)

    def _ahead(self, pose: Pose, metres: float) -> tuple[float, float] | None:
        """The point `metres` straight ahead, if it is still in this room."""
        c, sn = pose.heading()
        x, y = pose.x + metres * c, pose.y + metres * sn
        return (x, y) if self._truth.scene.room_at(x, y) == self._room else None

    def _room_spawn(self) -> tuple[float, float] | None:
        """The room's spawn point: free space from which every route of the room is flown (a stage that ended
        in front of an object or beside a door leaf would cut a corner on its way to the next door)."""
        spawn = next((s for s in self._truth.scene.spawns if s.room == self._room), None)
        return None if spawn is None else (spawn.pose.x, spawn.pose.y)

    def _approach_point(self, door: Door, normal: tuple[float, float]) -> tuple[float, float]:
        return door.center[0] - self.approach_m * normal[0], door.center[1] - self.approach_m * normal[1]

    def _door_depth(self, pose: Pose) -> float:
        """Signed distance past the plane of the door being crossed (the nearest open door)."""
        door = min(self._truth.scene.open_doors(), key=lambda d: math.dist(d.center, (pose.x, pose.y)))
        depth, _ = door.frame_of(pose.x, pose.y)
        heading_along = math.cos(math.radians(pose.yaw_deg - door.normal_deg))
        return depth if heading_along >= 0 else -depth

    def _room_entry_point(self, pose: Pose) -> tuple[float, float]:
        """A point 0.5 m further into the room along the current heading."""
        c, s = pose.heading()
        return pose.x + 0.5 * c, pose.y + 0.5 * s

    def _orient(self, pose: Pose, door: Door, normal: tuple[float, float], allowed: tuple[str, ...]):
        S = State
        nx, ny = normal
        dx, dy = pose.x - door.center[0], pose.y - door.center[1]
        depth, lateral = dx * nx + dy * ny, -dx * ny + dy * nx  # lateral > 0: left of the centre line
        heading_err = wrap_deg(math.degrees(math.atan2(ny, nx)) - pose.yaw_deg)
        aligned = abs(heading_err) <= ALIGN_DEG
        # 1 mm of slack: a doorway exactly one lateral move (10 cm) wide of the line would swing D1/D2 forever
        if aligned and abs(lateral) <= self.lateral_tol_m + 1e-3:
            return "A1", S.GO_THROUGH_DOOR, "Centred on the doorway; going through."
        if aligned and abs(lateral) <= 0.25 and depth < -0.15:
            return ("D2" if lateral > 0 else "D1"), S.ORIENTED_TOWARDS_DOOR, "Centring on the doorway."
        px, py = self._approach_point(door, normal)
        if math.hypot(px - pose.x, py - pose.y) > 0.08:
            return self._goto(pose, px, py, allowed), S.ORIENTED_TOWARDS_DOOR, "Approaching the doorway."
        rot = _rotation(heading_err, allowed) or "A1"
        if abs(heading_err) > 22.5:  # a long turn: Search Open Door allows the larger rotations
            return rot, S.SEARCH_OPEN_DOOR, "The doorway is to my side; turning to face it."
        return rot, S.ORIENTED_TOWARDS_DOOR, "Facing the doorway."

    def _door_position(self, pose: Pose) -> DoorPosition:
        room, task = self._room, self._goal
        nd = self._next_door(room, task.goal_room) if room and not self._unreachable_goal() else None
        if nd is None:
            return "not_visible"
        err = _bearing(pose, *nd[0].center)
        if abs(err) > HALF_HFOV:
            return "not_visible"
        return "center" if abs(err) <= 10 else ("left" if err > 0 else "right")
