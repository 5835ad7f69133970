"""Range sensors (`--sensors tof|multiranger`) read the scene's geometry: MuJoCo ray casts from the drone's pose,
checked against distances worked out by hand from the cabin's plan (see tests/test_sim_ground_truth.py): walls,
furniture and a door leaf, within 1 cm without noise; out of range is "beyond N m", never 8.192 m.
"""

from __future__ import annotations

import pytest

from vlnpilot.core.environment import Capabilities, check_sensors, range_sensing_of
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.ranging import SENSORS, RangeReading, range_sensor, readings_text, tof_reading
from vlnpilot.core.records import Pose
from vlnpilot.sim import SimConfig, Simulator, drone

NORTH_FACE_Y = 3.6  # the living room's north wall, inner face
FRIDGE_FRONT_Y = 2.90  # refrigerator_body: y 2.90..3.58, x 2.08..2.80
FRIDGE_SIDE_X = 2.80
LEAF_SOUTH_Y = 1.36  # door_living_bedroom_leaf, open into the living room: y 1.36..1.40, x 3.15..3.93
FRONT_START = drone.LENGTH / 2 + 0.002  # the front beam leaves at the camera's lens
SIDE_START = drone.WIDTH / 2
NORTH, EAST, WEST = 90.0, 0.0, 180.0
CM = 0.01


@pytest.fixture(scope="module")
def exact():
    with Simulator("cabin", SimConfig(render=False, sensors="multiranger", range_noise=False)) as sim:
        yield sim


def _read(sim: Simulator, pose: Pose) -> dict[str, float | None]:
    sim.reset(pose)
    return {r.direction: r.metres for r in sim.ranges()}


@pytest.mark.parametrize(("what", "pose", "expected"), [
    ("wall", Pose(3.0, 3.0, 1.0, NORTH), NORTH_FACE_Y - 3.0 - FRONT_START),
    ("wall, near", Pose(3.0, 3.4, 1.0, NORTH), NORTH_FACE_Y - 3.4 - FRONT_START),
    ("fridge front", Pose(2.44, 2.2, 1.0, NORTH), FRIDGE_FRONT_Y - 2.2 - FRONT_START),
    ("fridge side", Pose(3.4, 3.2, 1.0, WEST), 3.4 - FRIDGE_SIDE_X - FRONT_START),
    ("door leaf", Pose(3.5, 0.9, 1.0, NORTH), LEAF_SOUTH_Y - 0.9 - FRONT_START),
])
def test_front_range_agrees_with_the_geometry(exact: Simulator, what: str, pose: Pose, expected: float) -> None:
    assert _read(exact, pose)["front"] == pytest.approx(expected, abs=CM), what


def test_side_back_and_up_ranges_agree_with_the_geometry(exact: Simulator) -> None:
    got = _read(exact, Pose(3.0, 3.2, 1.0, EAST))  # facing east: the north wall on the left, the fridge behind
    assert got["left"] == pytest.approx(NORTH_FACE_Y - 3.2 - SIDE_START, abs=CM)
    assert got["back"] == pytest.approx(3.0 - drone.LENGTH / 2 - FRIDGE_SIDE_X, abs=CM)
    assert got["up"] == pytest.approx(exact.scene.ceiling_height - 1.0 - drone.HEIGHT / 2, abs=CM)
    assert got["right"] is not None and got["right"] > 1.0  # the open living room (the drone's own geoms ignored)


def test_tof_has_one_beam_and_a_short_range(exact: Simulator) -> None:
    with Simulator("cabin", SimConfig(render=False, sensors="tof", range_noise=False)) as sim:
        sim.reset(Pose(2.0, 1.8, 1.0, NORTH))  # the fridge is 1.1 m ahead-right, the wall 1.75 m ahead
        (reading,) = sim.ranges()
        assert reading == RangeReading("front", None, 1.2)
        assert reading.text() == "beyond 1.2 m"
        assert sim.capabilities.range_sensor == "tof" and range_sensing_of(sim) is sim


def test_noise_is_seeded_and_of_the_modelled_size() -> None:
    tof = SENSORS["tof"]
    with Simulator("cabin", SimConfig(render=False, sensors="tof")) as sim:
        runs = []
        for _ in range(2):
            sim.reset(Pose(3.0, 2.6, 1.0, NORTH), seed=5)
            runs.append([sim.ranges()[0].metres for _ in range(40)])
    true = NORTH_FACE_Y - 2.6 - FRONT_START
    assert runs[0] == runs[1]  # the same seed, the same readings
    errors = [r - true for r in runs[0]]
    assert max(abs(e) for e in errors) < 4 * tof.sigma(true) and len(set(runs[0])) > 30


def test_the_tello_answer_is_read_in_mm_and_8192_is_beyond_range() -> None:
    tof = SENSORS["tof"]
    assert tof_reading("tof 523", tof) == RangeReading("front", 0.523, 1.2)
    assert tof_reading("tof 8192", tof).text() == "beyond 1.2 m"
    assert readings_text((tof_reading("tof 8192", tof),)) == "front beyond 1.2 m"
    with pytest.raises(ValueError, match="unreadable"):
        tof_reading("error", tof)


def test_a_drone_without_the_sensor_is_refused_in_one_line() -> None:
    with pytest.raises(ConfigError, match="valid: none, tof, multiranger"):
        range_sensor("lidar")
    with pytest.raises(ConfigError, match=r"--sensors tof needs one forward time-of-flight.*Tello does not have"):
        check_sensors(Capabilities(), "Tello", "tof")  # the plain Tello
    check_sensors(Capabilities(range_sensor="tof"), "Tello", "tof")
    check_sensors(Capabilities(), "Tello", "none")
    with pytest.raises(ConfigError, match="--sensors"):
        SimConfig(sensors="sonar")
    with Simulator("cabin", SimConfig(render=False)) as plain:
        assert plain.ranges() == () and range_sensing_of(plain) is None


def _fly(sensors: str, context: str, query: str = "Find the refrigerator",
         profile: str = "paper") -> tuple[list[tuple[str, ...]], list[dict]]:
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.pilots.oracle import OraclePilot
    from vlnpilot.tasks.task import parse_query

    told: list[tuple[str, ...]] = []

    class Listening(OraclePilot):
        def decide(self, pilot_input):
            told.append(pilot_input.context)
            return super().decide(pilot_input)

    records: list[dict] = []
    with Simulator("cabin", SimConfig(render=False, sensors=sensors, range_noise=False)) as sim:
        config = EpisodeConfig(context=context, profile=profile)
        result = run_episode(sim, Listening(), parse_query(query, sim.scene), config, spawn="living_room",
                             on_step=records.append)
    assert result.outcome == "success"
    return told, records


def test_the_plus_context_states_the_readings_and_the_rule_in_range_terms() -> None:
    told, records = _fly("tof", "plus")
    assert all(lines[0].startswith("Range sensor (one forward time-of-flight beam") for lines in told)
    assert "front beyond 1.2 m" in told[0][0] and "a front reading of 0.95 m on the object itself" in told[0][1]
    assert max(len(line) for lines in told for line in lines) <= 500  # the server keeps 500 characters a line
    said = " ".join(lines[0] for lines in told)
    assert all(f"front {r['ranges']['front']['m']:.2f} m" in said for r in records if r["ranges"]["front"]["m"])
    reach = [lines for lines, r in zip(told, records, strict=False) if r["state"] == "Reach Object"]
    assert reach and all(any("front range reads 0.9 m or less" in line for line in lines) for lines in reach)
    assert records[0]["ranges"] == {"front": {"m": None, "max_m": 1.2}}  # recorded per step, beyond range as None


def test_a_pilot_is_told_only_what_its_drone_has() -> None:
    told, records = _fly("none", "plus")
    assert not any("Range sensor" in line for lines in told for line in lines) and "ranges" not in records[0]
    told, records = _fly("tof", "paper")  # the paper context tells nothing beyond the paper's inputs
    assert all(lines == () for lines in told) and "ranges" in records[0]


def test_a_low_object_is_left_to_the_width_rule() -> None:
    from vlnpilot.tasks.success import range_rule

    assert "judge it by Reach Object's width rule" in range_rule("bed_1")
    assert "0.9 m or less" in range_rule("wardrobe_2")


def test_the_ranged_profile_lets_the_range_license_a2_in_reach_object() -> None:
    from vlnpilot.core.fsm import State, state_spec

    assert "A2" in state_spec(State.REACH_OBJECT, "ranged").moves
    assert "A2" not in state_spec(State.REACH_OBJECT, "paper").moves  # the paper's table is untouched
    told, _ = _fly("tof", "plus", profile="ranged")
    assert any("approach with `A2` (25 cm)" in line and "beyond 1.2 m" in line for lines in told for line in lines)
    told, _ = _fly("tof", "plus")
    assert not any("`A2`" in line for lines in told for line in lines)
