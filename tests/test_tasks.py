"""Query parsing, the success monitor (judge), SPL, the shortest-path estimate and the per-episode metrics."""

from __future__ import annotations

import math

import pytest

from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.environment import GroundTruth
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Motion, Pose
from vlnpilot.scene import Scene
from vlnpilot.tasks.success import recorded_success
from vlnpilot.tasks.task import (
    Oscillations,
    PathLength,
    QueryError,
    SuccessConfig,
    Task,
    judge,
    parse_query,
    shortest_path_length,
    spl,
)

# -- parse_query ---------------------------------------------------------------------------------------------
PAPER_QUERIES = [  # Table 4 of the paper, and the goal each one names in the cabin
    ("Go to the bathroom", "bathroom", None),
    ("Go to the bedroom", "bedroom", None),
    ("Go to the living room/kitchen", "living_room", None),
    ("Find the refrigerator in the living room or kitchen", "living_room", "refrigerator"),
    ("Find the mirror in the bedroom", "bedroom", "mirror"),
    ("Find the sink in the bathroom", "bathroom", "sink"),
]

ALIASES = [
    ("Go to the kitchen", "living_room", None),
    ("go to the LIVING ROOM", "living_room", None),
    ("Go to the bed room", "bedroom", None),
    ("Fly to the restroom", "bathroom", None),
    ("Find the fridge", "living_room", "refrigerator"),
    ("Find the fridge in the kitchen", "living_room", "refrigerator"),
    ("find the washbasin", "bathroom", "sink"),
    ("Look for the full-length mirror", "bedroom", "mirror"),
    ("Find the refrigerator.", "living_room", "refrigerator"),
]


@pytest.mark.parametrize(("query", "room", "target"), PAPER_QUERIES + ALIASES)
def test_parse_query(scene: Scene, query: str, room: str, target: str | None) -> None:
    task = parse_query(query, scene)
    assert task == Task(query=query, goal_room=room, goal_target=target)
    assert task.kind == ("object" if target else "room")


@pytest.mark.parametrize(("query", "must_name"), [
    ("Go to the garage", ["no known room", "living room / kitchen", "bedroom", "bathroom"]),
    ("Go somewhere nice", ["known rooms:", "bedroom", "bathroom"]),
    ("Find the red cup in the kitchen", ["unknown object", "refrigerator (living room / kitchen)",
                                         "mirror (bedroom)", "sink (bathroom)"]),
    ("Find the piano", ["unknown object", "refrigerator", "mirror", "sink"]),
    ("Find the mirror in the bathroom", ["no mirror in the bathroom", "the mirror is in the bedroom",
                                         "known objects:"]),
    ("Find the refrigerator in the bedroom", ["no refrigerator in the bedroom", "living room / kitchen"]),
    ("", ["empty", "Go to the bedroom"]),
    ("   ", ["empty"]),
])
def test_parse_query_errors_list_the_known_ones(scene: Scene, query: str, must_name: list[str]) -> None:
    with pytest.raises(QueryError) as info:
        parse_query(query, scene)
    message = str(info.value)
    assert "\n" not in message
    for part in must_name:
        assert part in message, (part, message)


def test_words_must_match_whole(scene: Scene) -> None:
    # 'sinking' is not 'sink', 'bedrooms' is not ... a room either: nothing known remains.
    with pytest.raises(QueryError):
        parse_query("Go to the sinking ship", scene)


# -- judge with a fake ground truth --------------------------------------------------------------------------
class FakeGroundTruth:
    def __init__(self, scene: Scene, room: str | None, dist: float = 5.0, bearing: float = 90.0,
                 visible: bool = False):
        self._scene, self._room, self._db, self._visible = scene, room, (dist, bearing), visible

    @property
    def scene(self) -> Scene:
        return self._scene

    def pose(self) -> Pose:
        return Pose(0.0, 0.0, 1.0, 0.0)

    def room(self) -> str | None:
        return self._room

    def target_distance_bearing(self, target_id: str) -> tuple[float, float]:
        return self._db

    def target_footprint(self, target_id: str) -> tuple[tuple[tuple[float, float], ...], ...]:
        """One point at (dist, bearing) from the drone (at the origin, heading +x)."""
        dist, bearing = self._db
        return (((dist * math.cos(math.radians(bearing)), dist * math.sin(math.radians(bearing))),),)

    def target_visible(self, target_id: str) -> bool:
        return self._visible

    def clearance_at(self, pose: Pose, max_distance: float) -> tuple[float, str, str] | None:
        return None

    def movers(self) -> tuple:
        return ()

    def substeps(self, motion: Motion) -> int:
        return 1


ROOM_TASK = Task("Go to the bedroom", "bedroom")
OBJECT_TASK = Task("Find the mirror in the bedroom", "bedroom", "mirror")


def test_fake_is_a_ground_truth(scene: Scene) -> None:
    assert isinstance(FakeGroundTruth(scene, None), GroundTruth)


@pytest.mark.parametrize(("room", "state", "ok", "why"), [
    ("bedroom", State.STAY_ON_ROOM, True, "drone is in bedroom"),
    ("bathroom", State.STAY_ON_ROOM, False, "drone is in bathroom; goal room bedroom"),  # false success
    (None, State.STAY_ON_ROOM, False, "no room"),  # in a doorway
    ("bedroom", State.DESCRIBE_OBJECT, False, "declared Describe Object for a room goal"),
])
def test_judge_room_goal(scene: Scene, room: str | None, state: State, ok: bool, why: str) -> None:
    result, reason = judge(ROOM_TASK, state, FakeGroundTruth(scene, room))
    assert result is ok
    assert why in reason


@pytest.mark.parametrize(("dist", "bearing", "visible", "ok"), [
    (0.8, 5.0, True, True),
    (1.0, 20.0, True, True),  # thresholds are inclusive
    (1.0, -20.0, True, True),
    (1.01, 0.0, True, False),  # too far
    (0.5, 21.0, True, False),  # not facing it
    (0.5, -25.0, True, False),
    (0.5, 0.0, False, False),  # facing it but it is hidden
])
def test_judge_object_goal(scene: Scene, dist: float, bearing: float, visible: bool, ok: bool) -> None:
    gt = FakeGroundTruth(scene, "bedroom", dist, bearing, visible)
    result, reason = judge(OBJECT_TASK, State.DESCRIBE_OBJECT, gt)
    assert result is ok
    assert f"{dist:.2f} m" in reason and ("not visible" in reason) is (not visible)


class FootprintTruth(FakeGroundTruth):
    """A bed 2 m long and 1 m wide (x from 1.0 to 3.0, y from -0.5 to 0.5); the drone at `pose`."""

    def __init__(self, scene: Scene, pose: Pose):
        super().__init__(scene, "bedroom", 9.0, 90.0, True)  # the point monitor's middle of the front: far away
        self._pose = pose

    def pose(self) -> Pose:
        return self._pose

    def target_footprint(self, target_id: str) -> tuple[tuple[tuple[float, float], ...], ...]:
        return (((1.0, -0.5), (3.0, -0.5), (3.0, 0.5), (1.0, 0.5)),)


@pytest.mark.parametrize(("pose", "ok", "why"), [
    (Pose(2.0, 1.4, 1.0, -90.0), True, "0.90 m to its nearest point"),  # beside its middle, facing it
    (Pose(3.5, 1.2, 1.0, 180.0), True, "0.86 m"),  # off a corner, the heading passes beside the bed, 14 deg off
    (Pose(3.5, 1.4, 1.0, 90.0), False, "off the heading"),  # close, looking away
    (Pose(2.0, 1.6, 1.0, -90.0), False, "1.10 m"),  # looking straight at it, 1.1 m out
    (Pose(0.0, 0.0, 1.0, 0.0), True, "1.00 m"),  # at 1 m from the foot of the bed, looking along it
])
def test_judge_measures_to_the_footprint(scene: Scene, pose: Pose, ok: bool, why: str) -> None:
    result, reason = judge(OBJECT_TASK, State.DESCRIBE_OBJECT, FootprintTruth(scene, pose))
    assert result is ok, reason
    assert why in reason
    assert not judge(OBJECT_TASK, State.DESCRIBE_OBJECT, FootprintTruth(scene, pose), recorded_success({}))[0]


def test_judge_object_goal_declared_wrong_final_state(scene: Scene) -> None:
    gt = FakeGroundTruth(scene, "bedroom", 0.5, 0.0, True)
    assert judge(OBJECT_TASK, State.STAY_ON_ROOM, gt) == (False, "declared Stay on Room for an object goal")


def test_judge_thresholds_come_from_config(scene: Scene) -> None:
    gt = FakeGroundTruth(scene, "bedroom", 1.4, 30.0, False)
    assert not judge(OBJECT_TASK, State.DESCRIBE_OBJECT, gt)[0]
    loose = SuccessConfig(object_distance_m=1.5, object_facing_deg=35.0, object_must_be_visible=False)
    assert judge(OBJECT_TASK, State.DESCRIBE_OBJECT, gt, loose)[0]


# -- SPL and the shortest path -------------------------------------------------------------------------------
@pytest.mark.parametrize(("success", "shortest", "taken", "expected"), [
    (False, 2.0, 2.0, 0.0),
    (True, 2.0, 4.0, 0.5),
    (True, 2.0, 2.0, 1.0),
    (True, 2.0, 1.0, 1.0),  # never above 1 (the estimate is a lower bound and can exceed the path taken)
    (True, 0.0, 0.0, 1.0),  # already at the goal
    (True, 0.0, 3.0, 1.0),
])
def test_spl(success: bool, shortest: float, taken: float, expected: float) -> None:
    assert spl(success, shortest, taken) == pytest.approx(expected)


def test_shortest_path_length(scene: Scene) -> None:
    living = scene.spawn("living_room").pose
    to_bath = shortest_path_length(scene, living, parse_query("Go to the bathroom", scene))
    to_bed = shortest_path_length(scene, living, parse_query("Go to the bedroom", scene))
    here = shortest_path_length(scene, living, parse_query("Go to the kitchen", scene))
    assert here == 0.0
    assert 0 < to_bed < to_bath
    door2 = scene.door("door_bedroom_bathroom")
    assert to_bath >= math.dist((living.x, living.y), door2.center)  # at least the straight line
    fridge = shortest_path_length(scene, living, parse_query("Find the fridge", scene))
    assert fridge > 0  # to the viewing point in front of it


# -- metrics -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("codes", "count"), [
    ([], 0),
    (["B1", "C1"], 1),
    (["C2", "B3"], 1),
    (["B1", "C1", "B1", "C1"], 3),
    (["D1", "D2", "D1"], 2),
    (["B1", "B2", "B3"], 0),  # same direction
    (["B1", "A1", "C1"], 0),  # not in a row
    (["B1", "E", "C1"], 0),
    (["D1", "C1"], 0),  # lateral then rotation is no reversal
    (["A1", "A1"], 0),
])
def test_oscillations_count_reversals(codes: list[str], count: int) -> None:
    osc = Oscillations()
    osc.reset()
    flags = [osc.update(COMMANDS[c]) for c in codes]
    assert osc.value() == count == sum(flags)
    osc.reset()
    assert osc.value() == 0


def test_path_length() -> None:
    path = PathLength()
    path.reset()
    path.update(Pose(0, 0, 1, 0), Pose(0.3, 0.4, 1, 0))
    path.update(Pose(0.3, 0.4, 1, 0), Pose(0.3, 0.4, 1, 90))  # rotation: no distance
    assert path.value() == pytest.approx(0.5)
    path.reset()
    assert path.value() == 0.0


def test_the_opposite_of_every_direction_is_its_mirror_in_the_command_table() -> None:
    from vlnpilot.core.commands import COMMANDS, OPPOSITE

    for kind, opposite in OPPOSITE.items():
        assert OPPOSITE[opposite] is kind  # an involution
        for code, command in COMMANDS.items():
            if command.kind is kind:  # B1 <-> C1, D1 <-> D2: the same amount, the mirrored motion
                mirror = next(c for c in COMMANDS.values() if c.kind is opposite and c.amount == command.amount)
                m, r = command.motion(), mirror.motion()
                assert (m.yaw_deg, m.lateral_m) == (-r.yaw_deg, -r.lateral_m), code
