"""Issue 24: events in the scene. Scenarios (YAML, validation), the walk of people and pets, the simulator's
events (triggers, doors that close, lights, signs, contact with a mover), the true map, the unreachable outcome,
the oracle's reactions, recording and replay. The episode clock is the commands' durations (no wall clock)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cli_support import run_main
from vlnpilot.core.commands import get_command
from vlnpilot.core.environment import capabilities_of, mover_sensing_of
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.fsm import State
from vlnpilot.core.movers import MoverState, is_mover_contact
from vlnpilot.core.records import Pose
from vlnpilot.core.tello_spec import HOVER_S, motion_duration_s
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.run import run_recorded_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.safety.config import OscillationConfig
from vlnpilot.safety.guard import OscillationGuard
from vlnpilot.scene import load_scene
from vlnpilot.scene.events import (
    EventSpec,
    builtin_scenarios,
    load_scenario,
    scenario_from_dict,
    validate_scenario,
    with_scenario,
)
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.sim.events import SIGN_LEGIBLE_PX, sign_png, sign_view
from vlnpilot.sim.movers import PASS_CLEARANCE_M, YIELD_WAIT_S, Walker, route
from vlnpilot.tasks.mission import judge_unreachable
from vlnpilot.tasks.task import parse_query

CABIN = load_scene("cabin")


def scenario(*events: dict, seed: int = 0) -> object:
    return scenario_from_dict({"name": "t", "scene": "cabin", "seed": seed, "events": list(events)})


def sim_with(*events: dict, seed: int = 0, render: bool = False) -> Simulator:
    cfg = SimConfig(render=render, width=64, height=48, rear_camera=False)
    return Simulator(with_scenario(CABIN, scenario(*events, seed=seed)), cfg)


# -- scenarios ------------------------------------------------------------------------------------------------
def test_every_builtin_scenario_loads_and_fits_the_cabin() -> None:
    names = builtin_scenarios()
    kinds = {e.kind for n in names for e in load_scenario(n).events}
    assert kinds == {"person", "pet", "door_closes", "lights_out", "sign"}
    for name in names:
        validate_scenario(load_scenario(name), CABIN)


@pytest.mark.parametrize(("events", "says"), [
    ([{"kind": "ghost"}], "events.0.kind"),
    ([{"kind": "person"}], "person needs path"),
    ([{"kind": "person", "path": ["bedroom"], "door": "x"}], "person takes no door"),
    ([{"kind": "lights_out", "room": "bedroom", "level": "murky"}], "valid: dim, dark"),
    ([{"kind": "lights_out", "room": "bedroom", "level": 1.5}], "outside 0..1"),
    ([{"kind": "sign", "room": "bedroom", "text": "x"}], "exactly one of wall"),
    ([{"kind": "pet", "path": ["bedroom"], "trigger": {"step": 1, "enter": "bedroom"}}], "exactly one of step"),
    ([{"kind": "pet", "path": ["bedroom"], "name": "a"}, {"kind": "pet", "path": ["bedroom"], "name": "a"}],
     "unique"),
])
def test_a_bad_scenario_is_refused_in_one_line(events: list, says: str) -> None:
    with pytest.raises(ConfigError) as info:
        scenario(*events)
    assert says in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(("event", "says"), [
    ({"kind": "door_closes", "door": "front_door"}, "unknown open door 'front_door'"),
    ({"kind": "person", "path": ["living_room", "bathroom"]}, "share no open door"),
    ({"kind": "lights_out", "room": "attic", "level": "dark"}, "unknown room 'attic'"),
    ({"kind": "pet", "path": ["bedroom"], "trigger": {"enter": "garage"}}, "unknown trigger room"),
    ({"kind": "sign", "room": "bedroom", "text": "x", "at": [1.0, 1.0]}, "is not in the room bedroom"),
    ({"kind": "person", "path": [[1000, 1000], "bathroom"]}, r"path point \[1000.0, 1000.0\] is outside the scene: x "
                                                            r"must be in -0.15..8.75 and y in -0.15..3.75"),
    ({"kind": "pet", "path": [[math.nan, math.inf], "bathroom"]}, r"path point \[nan, inf\] is outside the scene"),
])
def test_a_scenario_that_does_not_fit_its_scene_is_refused(event: dict, says: str) -> None:
    with pytest.raises(ConfigError, match=says):
        validate_scenario(scenario(event), CABIN)


def test_run_refuses_a_bad_scenario_with_exit_2(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                                  tmp_path: Path) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--pilot", "oracle", "--events", "nope",
                            "--out", str(tmp_path / "r"))
    assert code == 2 and "unknown scenario 'nope'" in err and "cabin-person" in err
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: cabin\nevents:\n  - kind: door_closes\n    door: nowhere\n")
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--pilot", "oracle", "--events", str(bad),
                            "--out", str(tmp_path / "r2"))
    assert code == 2 and "unknown open door 'nowhere'" in err and len(err.strip().splitlines()) == 1


def test_the_fingerprint_of_a_still_scene_is_unchanged_and_a_scenario_changes_it() -> None:
    with_events = with_scenario(CABIN, load_scenario("cabin-door"))
    assert CABIN.fingerprint() == load_scene("cabin").fingerprint()
    assert with_events.fingerprint() != CABIN.fingerprint()
    assert with_events.topological_map() == CABIN.topological_map()  # the pilot's map is the scene's


def test_a_scenario_reads_back_from_its_record() -> None:
    for name in builtin_scenarios():
        s = load_scenario(name)
        assert scenario_from_dict(json.loads(json.dumps(s.to_dict()))) == s


# -- the walk ---------------------------------------------------------------------------------------------------
def test_a_path_of_rooms_crosses_the_door_between_them_on_its_centre_line() -> None:
    spec = EventSpec(kind="person", path=("bedroom", "bathroom"), pause_in_doorway_s=3, name="p")
    points, pause = route(spec, CABIN)
    assert points == [(5.0, 1.1), (6.0, 1.1), (7.0, 1.1)] and pause == 1
    back = EventSpec(kind="person", path=("bathroom", "bedroom"), name="q")
    assert route(back, CABIN)[0] == [(7.0, 1.1), (6.0, 1.1), (5.0, 1.1)]


def test_a_person_walks_at_its_speed_stops_in_the_doorway_and_stands_at_the_end() -> None:
    w = Walker("p", "person", [(0.0, 0.0), (1.2, 0.0), (2.4, 0.0)], 1.2, pause_at=1, pause_s=2.0, started=True)
    far = (50.0, 50.0)
    w.advance(0.5, far)
    assert (round(w.x, 6), w.vx) == (0.6, 1.2)
    w.advance(0.5, far)  # at the doorway: it stops there for 2 s
    assert (w.x, w.pause_left) == (1.2, 2.0)
    for _ in range(4):
        w.advance(0.5, far)
        assert w.x == 1.2 and w.vx == 0.0
    w.advance(2.0, far)
    assert w.x == 2.4 and w.done
    w.advance(1.0, far)
    assert w.x == 2.4


def test_a_walker_yields_to_a_drone_in_its_way_but_a_pet_walks_under_a_flying_drone() -> None:
    person = Walker("p", "person", [(0.0, 0.0), (5.0, 0.0)], 1.2, started=True)
    person.advance(0.5, (1.0, 0.0), 1.0)  # its next 0.5 s (0.6 m) would bring it within 0.3 m: it waits
    assert person.x == 0.0 and person.yielding
    person.advance(0.5, (1.0, 2.0), 1.0)  # the drone moved aside
    assert person.x > 0.0
    pet = Walker("d", "pet", [(0.0, 0.0), (5.0, 0.0)], 2.0, started=True)
    pet.advance(0.5, (1.1, 0.0), 1.0)
    assert pet.x == 1.0
    low = Walker("d", "pet", [(0.0, 0.0), (5.0, 0.0)], 2.0, started=True)
    low.advance(0.5, (1.1, 0.0), 0.3)  # a drone low enough to touch it
    assert low.x == 0.0


def test_a_walker_that_waited_for_a_drone_walks_on_past_it_when_there_is_room() -> None:
    w = Walker("p", "person", [(0.0, 0.0), (5.0, 0.0)], 1.0, started=True)
    drone = (1.5, 0.25 + PASS_CLEARANCE_M + 0.02)  # beside its line: too close to walk by politely, room to pass
    while not w.yielding:
        w.advance(0.1, drone)
    stopped = w.x
    for _ in range(round(YIELD_WAIT_S / 0.1) - 1):
        w.advance(0.1, drone)
        assert w.yielding and w.x == stopped  # it waits for the drone ...
    w.advance(0.1, drone)
    w.advance(0.1, drone)
    assert w.x > stopped and not w.yielding  # ... for YIELD_WAIT_S, then walks on past it
    while w.x < 2.0:
        w.advance(0.1, drone)
        assert math.hypot(w.x - drone[0], w.y - drone[1]) - w.radius >= PASS_CLEARANCE_M - 1e-9


def test_a_walker_blocked_by_a_drone_steps_back_stands_aside_and_tries_again_or_leaves() -> None:
    w = Walker("p", "person", [(0.0, 0.0), (1.0, 0.0), (5.0, 0.0)], 1.0, started=True)
    drone = (2.0, 0.0)  # right on its path
    xs = []
    for _ in range(40):
        w.advance(0.5, drone)
        xs.append(w.x)
    assert max(xs) < 2.0 - 0.25 and min(xs[10:]) < 1.0 + 1e-9  # it never walks into the drone, and steps back
    assert xs[-1] == 1.0 and xs.count(0.5) >= 4  # and does not stand still for good: it tries again
    for _ in range(10):
        w.advance(1.0, (50.0, 50.0))  # the drone made way
    assert w.done and w.x == 5.0
    cornered = Walker("p", "person", [(0.0, 0.0), (5.0, 0.0)], 1.0, started=True)
    for _ in range(int(YIELD_WAIT_S / 0.5) + 1):
        cornered.advance(0.5, (0.5, 0.0))  # at the start of its path, nowhere to step back to: it leaves
    assert not cornered.present


def test_repeat_walks_the_path_back_and_forth() -> None:
    w = Walker("d", "pet", [(0.0, 0.0), (1.0, 0.0)], 1.0, repeat=True, started=True)
    w.advance(1.5, (50.0, 50.0))
    assert math.isclose(w.x, 0.5) and w.vx == -1.0 and not w.done


def test_a_mover_state_extrapolates_at_constant_velocity() -> None:
    m = MoverState("p", "person", 1.0, 2.0, 0.5, -1.0, 0.25, 1.75)
    assert (m.at(2.0).x, m.at(2.0).y) == (2.0, 0.0) and m.contact_name == "mover:p"
    assert is_mover_contact("mover:p") and not is_mover_contact("wall_x") and not is_mover_contact(None)


def test_each_command_takes_its_time_on_the_episode_clock() -> None:
    assert motion_duration_s() == HOVER_S
    assert math.isclose(motion_duration_s(forward_m=0.5), 1.3) and math.isclose(motion_duration_s(yaw_deg=90), 1.3)


# -- the simulator ---------------------------------------------------------------------------------------------------
def test_triggers_fire_once_at_their_step_time_or_room_and_are_in_the_observation() -> None:
    sim = sim_with({"kind": "lights_out", "room": "bedroom", "level": "dim", "trigger": {"step": 2}},
                   {"kind": "lights_out", "room": "bathroom", "level": 0.5, "trigger": {"time_s": 2.5}},
                   {"kind": "door_closes", "door": "door_bedroom_bathroom", "trigger": {"enter": "bedroom"}})
    obs = sim.reset("living_room")
    assert obs.events == ()
    fired = {}
    for cmd in ("E", "E", "E", "C1"):
        obs = sim.step(cmd)
        fired.update({e.name: e for e in obs.events})
    assert fired["lights-out-1"].step == 2 and fired["lights-out-1"].params["level_name"] == "dim"
    assert fired["lights-out-2"].step == 3 and fired["lights-out-2"].time_s == 3.0  # the first step past 2.5 s
    assert "door-closes-1" not in fired
    sim.reset(Pose(4.6, 1.0, 1.0, 0.0))
    assert [e.name for e in sim.reset(Pose(4.6, 1.0, 1.0, 0.0)).events] == ["door-closes-1"]
    later = [e.name for _ in range(3) for e in sim.step("E").events]
    assert later == ["lights-out-1", "lights-out-2"]  # each once per episode, the door already fired


def test_a_person_enters_walks_on_the_clock_and_is_the_same_for_the_same_seed() -> None:
    person = {"kind": "person", "path": ["bedroom", "bathroom"], "trigger": {"step": 1}}
    a, b, c = sim_with(person, seed=1), sim_with(person, seed=1), sim_with(person, seed=1)
    assert capabilities_of(a).movers and mover_sensing_of(a) is a
    tracks = []
    for sim, seed in ((a, 3), (b, 3), (c, 4)):
        assert sim.reset("living_room", seed=seed).movers == ()  # not in the scene before its trigger
        tracks.append([(m.x, m.y) for _ in range(4) for m in sim.step("E").movers])
    assert tracks[0] == tracks[1] and tracks[0] != tracks[2]  # the seed varies the walking speed
    assert tracks[0][0] == (5.0, 1.1) and tracks[0][1][0] > 5.9  # entered at step 1, then ~1.2 m/s for a 1 s hover
    assert math.isclose(a.seconds, 4 * HOVER_S)


HOVER_STEPS_FOR_A_PERSON = 8  # a person who stopped for a hovering drone is out of its way within this many hovers


@pytest.mark.parametrize(("drone_y", "passes"), [(1.62, True), (1.1, False)])
def test_a_pilot_that_always_hovers_facing_a_person_in_a_doorway_sees_them_pass(drone_y: float,
                                                                                  passes: bool) -> None:
    """The person walks from the bathroom through the doorway into the bedroom, towards a drone that hovers in
    front of the doorway facing it. It stops for the drone in the doorway, waits a while, then walks on past the
    drone (beside its way) or steps back out of the doorway (in its way): it never waits there for good."""
    sim = sim_with({"kind": "person", "path": ["bathroom", "bedroom", [4.3, 1.1]]})
    sim.reset(Pose(4.9, drone_y, 1.0, math.degrees(math.atan2(1.1 - drone_y, 1.1))))
    in_doorway = []
    for _ in range(3):
        (m,) = sim.step("E").movers
        in_doorway.append(abs(m.x - 6.0) < 0.4)
    assert any(in_doorway) and m.vx == 0.0  # it stopped in or at the doorway for the drone
    for _ in range(HOVER_STEPS_FOR_A_PERSON):
        obs = sim.step("E")
        assert not obs.collided
        (m,) = obs.movers
        if (m.x < 4.9 - 0.3) if passes else (m.x > 6.0 + 0.6):
            break
    else:
        pytest.fail(f"the person is still at x={m.x:.2f} after {HOVER_STEPS_FOR_A_PERSON} hovers")


def test_contact_with_a_person_is_named_as_the_mover() -> None:
    sim = sim_with({"kind": "person", "path": [[5.0, 1.0], [5.0, 1.01]]})
    sim.reset(Pose(4.55, 1.0, 1.0, 0.0))
    obs = sim.step("A3")
    assert obs.collided and obs.contact == "mover:person-1"
    gt = sim.ground_truth()
    assert gt.clearance_at(Pose(4.6, 1.0, 1.0, 0.0), 0.2)[1] == "mover:person-1"  # the geometry shield sees it


def test_a_closed_door_is_solid_and_gone_from_the_true_map_but_not_from_the_pilots() -> None:
    sim = sim_with({"kind": "door_closes", "door": "door_bedroom_bathroom", "swing_s": 1.0})
    sim.reset(Pose(4.9, 1.1, 1.0, 0.0))  # beyond the leaf's swing
    assert "door_bedroom_bathroom" not in {d.id for d in sim.ground_truth().scene.open_doors()}
    assert "door_bedroom_bathroom" in {d.id for d in sim.scene.open_doors()}
    sim.step("E")  # the leaf swings shut within the hover
    obs = None
    for _ in range(12):
        obs = sim.step("A1")
        if obs.collided:
            break
    assert obs is not None and obs.contact == "door_leaf:door_bedroom_bathroom" and obs.pose.x < 6.0


def test_a_closing_leaf_stops_short_of_a_drone_in_its_swing() -> None:
    sim = sim_with({"kind": "door_closes", "door": "door_bedroom_bathroom", "swing_s": 1.0})
    sim.reset(Pose(5.3, 1.1, 1.0, 0.0))  # on the arc the free edge sweeps
    obs = sim.step("E")
    leaf = next(iter(sim.events.leaves.values()))
    assert not obs.collided and 0 < leaf.angle_deg < 90


def test_an_open_leaf_stands_where_the_scenes_own_leaf_stood_until_it_swings() -> None:
    still, events = Simulator(CABIN, SimConfig(render=False)), sim_with({"kind": "door_closes",
                                                                          "door": "door_bedroom_bathroom",
                                                                          "trigger": {"step": 5}})
    events.reset("bedroom")
    for pose in (Pose(5.54, 0.95, 1.0, 0.0), Pose(5.2, 1.1, 1.0, 0.0)):
        a, b = still.clearance_at(pose, 0.3), events.clearance_at(pose, 0.3)
        assert (a is None) == (b is None) and (a is None or abs(a[0] - b[0]) < 0.05)


def test_lights_out_darkens_the_front_image_in_that_room() -> None:
    lit = sim_with({"kind": "lights_out", "room": "bedroom", "level": "dark", "trigger": {"step": 99}}, render=True)
    dark = sim_with({"kind": "lights_out", "room": "bedroom", "level": "dark"}, render=True)
    pose = Pose(4.6, 1.0, 1.0, 0.0)
    assert dark.reset(pose).front_rgb.mean() < 0.4 * lit.reset(pose).front_rgb.mean()


def test_a_sign_appears_at_its_trigger_with_its_text_legible() -> None:
    sim = sim_with({"kind": "sign", "room": "living_room", "text": "Land here", "at": [2.35, 1.95],
                    "facing_deg": -55, "trigger": {"step": 1}}, render=True)
    before = sim.reset("living_room").front_rgb
    after = sim.step("E").front_rgb
    assert np.abs(after.astype(int) - before.astype(int)).mean() > 5
    face = sign_png("Land here", screen=False)
    from io import BytesIO

    from PIL import Image
    img = np.asarray(Image.open(BytesIO(face)))
    assert (img.mean(axis=2) < 60).mean() > 0.02  # dark text on the light board


WALL_SIGN = {"kind": "sign", "room": "living_room", "wall": "south", "along": 0.75, "text": "Land here"}  # x 3.0


@pytest.mark.parametrize(("pose", "width", "legible"), [
    (Pose(3.0, 1.4, 1.0, -90.0), 1.0, True),  # 1.3 m before it, facing it: letters ~29 px high
    (Pose(3.0, 1.4, 1.0, -90.0), 0.4, False),  # a small sign there: its letters are too small (~12 px)
    (Pose(3.0, 1.4, 1.0, 0.0), 1.0, False),  # turned away: not in the frame
    (Pose(2.1, 1.3, 1.0, -90.0), 1.0, False),  # it is cut by the frame's edge
    (Pose(1.2, 0.4, 1.0, -5.0), 1.0, False),  # along the wall, seen edge-on: the letters are squeezed
])
def test_a_sign_is_legible_only_when_its_text_is_large_and_whole_in_the_front_image(pose: Pose, width: float,
                                                                                     legible: bool) -> None:
    sign = {**WALL_SIGN, "width_m": width}
    sim = sim_with(sign)
    sim.reset(pose)
    px = sim.sign_text_px("sign-1")
    assert (px >= SIGN_LEGIBLE_PX) is legible and (sim.legible_signs() == ("sign-1",)) is legible
    assert sim.ground_truth().sign_text_px("sign-1") == px
    assert sign_view(load_scenario_event(sign), CABIN, pose).legible is legible  # the projection agrees


def load_scenario_event(event: dict) -> EventSpec:
    return scenario(event).events[0]


def test_a_sign_hidden_by_a_person_or_not_yet_there_is_not_legible() -> None:
    near = Pose(3.0, 1.4, 1.0, -90.0)
    hidden = sim_with(WALL_SIGN, {"kind": "person", "path": [[3.0, 0.8], [3.0, 0.81]]})
    hidden.reset(near)
    assert hidden.sign_text_px("sign-1") == 0.0  # the projection alone would say legible: the render says hidden
    assert sign_view(load_scenario_event(WALL_SIGN), CABIN, near).legible
    later = sim_with({**WALL_SIGN, "trigger": {"step": 2}})
    later.reset(near)
    assert later.sign_text_px("sign-1") == 0.0
    later.step("E")
    later.step("E")
    assert later.sign_text_px("sign-1") >= SIGN_LEGIBLE_PX
    with pytest.raises(UnknownNameError, match="valid signs: sign-1"):
        later.sign_text_px("nowhere")


def _sign_rows() -> list[tuple[str, str]]:
    from vlnpilot.bench.suite import load_suite

    return [(name, r.id) for name in ("events", "events-houses") for r in load_suite(name).rows
            if any(e["kind"] == "sign" for e in r.events["events"])]


@pytest.mark.parametrize(("suite", "row_id"), _sign_rows())
def test_every_sign_of_the_event_suites_is_legible_on_the_oracles_route(suite: str, row_id: str) -> None:
    """The real pilots never saw the sign of h3-1door-sign-redirect (it hung cut by the frame, behind a TV);
    scripts/check_event_signs.py does the same check on a bench's flights."""
    from vlnpilot.bench.suite import load_suite

    loaded = load_suite(suite)
    row = next(r for r in loaded.rows if r.id == row_id)
    sim = Simulator(with_scenario(load_scene(str(row.scene or loaded.scene)), scenario_from_dict(row.events)),
                    SimConfig(render=False, rear_camera=False))
    seen_from: list[Pose] = []  # the pose of each image the pilot was given (the suites' signs fire at take-off)
    config = EpisodeConfig(max_steps=loaded.max_steps, seed=1)
    result = run_episode(sim, OraclePilot(), parse_query(row.query, sim.scene), config, spawn=row.spawn,
                         on_step=lambda rec: seen_from.append(Pose(**rec["pose_before"])))
    assert result.outcome == "success"
    assert any(sim.reset(pose) and sim.legible_signs() == ("sign-1",) for pose in seen_from[:5])


# -- the unreachable outcome and the oracle -------------------------------------------------------------------------
def test_unreachable_is_judged_on_the_true_map_at_that_moment() -> None:
    sim = sim_with({"kind": "door_closes", "door": "door_bedroom_bathroom", "trigger": {"step": 1}})
    task = parse_query("Go to the bathroom", CABIN)
    sim.reset("bedroom")
    ok, why = judge_unreachable(task, sim.ground_truth())
    assert not ok and "reachable: bedroom -> bathroom" in why
    sim.step("E")
    ok, why = judge_unreachable(task, sim.ground_truth())
    assert ok and "closed: door_bedroom_bathroom" in why


def oracle_episode(name: str, query: str, tmp_path: Path | None = None, spawn: str = "living_room"):
    sim = Simulator(with_scenario(CABIN, load_scenario(name)), SimConfig(render=False, rear_camera=False))
    config = EpisodeConfig(max_steps=60, seed=1)
    if tmp_path is None:
        return run_episode(sim, OraclePilot(), parse_query(query, sim.scene), config, spawn=spawn), None
    result = run_recorded_episode(sim, OraclePilot(), parse_query(query, sim.scene), config, run_dir=tmp_path,
                                  spawn=spawn, pilot_spec="oracle")
    return result, sim


def test_the_oracle_reports_a_goal_behind_a_closed_door_unreachable() -> None:
    result, _ = oracle_episode("cabin-door", "Go to the bathroom")
    assert result.outcome == "unreachable" and result.final_state == State.GOAL_UNREACHABLE.value
    assert (result.unreachable, result.unreachable_reported, result.collisions) == (1, 1, 0)
    assert not result.success
    reachable, _ = oracle_episode("cabin-door", "Go to the bedroom")
    assert reachable.outcome == "success" and reachable.unreachable_reported == 0


def test_a_report_of_unreachable_for_a_reachable_goal_is_a_false_success() -> None:
    class Liar(OraclePilot):
        def decide(self, pilot_input):  # noqa: ANN001, ANN202
            d = super().decide(pilot_input)
            if pilot_input.state is State.SEARCH_OPEN_DOOR:
                return d.model_copy(update={"state": State.GOAL_UNREACHABLE.value, "movement": "E"})
            return d

    sim = Simulator(with_scenario(CABIN, load_scenario("cabin-pet")), SimConfig(render=False, rear_camera=False))
    result = run_episode(sim, Liar(), parse_query("Go to the bathroom", sim.scene), EpisodeConfig(max_steps=20))
    assert result.outcome == "false_success" and (result.unreachable, result.unreachable_reported) == (0, 1)
    assert "is reachable" in result.reason


def test_the_oracle_waits_for_a_person_in_the_doorway_and_succeeds(tmp_path: Path) -> None:
    result, _ = oracle_episode("cabin-person", "Go to the bathroom", tmp_path)
    assert result.outcome == "success" and result.collisions == 0
    steps = [json.loads(line) for line in (tmp_path / "episode.jsonl").read_text().splitlines()]
    waits = [s for s in steps if s["executed"] == "E" and s["state"] in ("Go Through Door", "Oriented Towards Door",
                                                                          "Search Open Door")]
    assert waits, "the oracle never waited for the person"
    fired = [e for s in steps for e in s.get("events") or []]
    assert [(e["name"], e["trigger"]) for e in fired] == [("person-1", "entering bedroom")]
    assert all("movers" in s for s in steps if s["step"] > fired[0]["step"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["scenario"]["name"] == "cabin-person" and summary["capabilities"]["movers"] is True


def test_hovering_to_wait_never_makes_the_guard_fire() -> None:
    guard = OscillationGuard(OscillationConfig())
    hover = get_command("E")
    assert all(guard.propose(State.GO_THROUGH_DOOR, hover) is None for _ in range(40))


def test_hovers_between_reversals_do_not_hide_an_oscillation_nor_count_as_one() -> None:
    """The guard counts the moves a pilot flies, not its waits: B1, C1, B1 then six hovers, then C1 is three
    reversals among four moves (window 8), as without the hovers."""
    guard = OscillationGuard(OscillationConfig())
    moves = [get_command(c) for c in ("B1", "C1", "B1", "E", "E", "E", "E", "E", "E", "C1")]
    fired = [guard.propose(State.ORIENTED_TOWARDS_DOOR, m) for m in moves]
    assert fired[:-1] == [None] * 9 and fired[-1] == 3


@pytest.mark.parametrize("name", ["cabin-person", "cabin-door"])
def test_a_replayed_run_with_events_reaches_its_recorded_outcome(name: str, tmp_path: Path) -> None:
    result, _ = oracle_episode(name, "Go to the bathroom", tmp_path / "rec")
    summary = json.loads((tmp_path / "rec" / "summary.json").read_text())
    scene = with_scenario(CABIN, scenario_from_dict(summary["scenario"]))
    sim = Simulator(scene, SimConfig(render=False, rear_camera=False))
    replayed = run_episode(sim, make_pilot(f"replay:{tmp_path / 'rec'}"), parse_query("Go to the bathroom", scene),
                           EpisodeConfig(max_steps=60, seed=1), spawn="living_room")
    assert (replayed.outcome, replayed.steps) == (result.outcome, result.steps)
    with pytest.raises(ConfigError, match="--events"):  # without its scenario the replay is refused
        run_episode(Simulator(CABIN, SimConfig(render=False)), make_pilot(f"replay:{tmp_path / 'rec'}"),
                    parse_query("Go to the bathroom", CABIN), EpisodeConfig(max_steps=60, seed=1),
                    spawn="living_room")


def test_still_scenes_record_as_before() -> None:
    sim = Simulator(CABIN, SimConfig(render=False))
    obs = sim.reset("living_room")
    assert "movers" not in capabilities_of(sim).to_dict() and obs.events == () and obs.movers == ()
    assert replace(sim.step("A1"), front_rgb=None).movers == ()


# -- suites ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["events", "events-houses"])
def test_the_event_suites_have_every_kind_on_one_and_two_door_routes(name: str) -> None:
    from vlnpilot.bench.suite import load_suite

    suite = load_suite(name)
    assert len(suite.rows) * suite.repetitions >= 30
    covered = set()
    for row in suite.rows:
        scene = load_scene(row.scene or suite.scene)
        doors = len(scene.room_path(scene.spawn(row.spawn).room, row.goal_room)) - 1
        covered |= {(e["kind"], min(doors, 2)) for e in row.events["events"]}
        assert row.events_named  # each row names its events
    kinds = ("person", "pet", "door_closes", "lights_out", "sign")
    assert {(k, d) for k in kinds for d in (1, 2)} <= covered


def test_a_suite_row_with_a_bad_event_is_refused_naming_the_row(tmp_path: Path) -> None:
    from vlnpilot.bench.suite import SuiteError, load_suite

    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: cabin\nrows:\n  - {id: r1, spawn: living_room, query: Go to the bedroom,\n"
                   "     events: {seed: 1, events: [{kind: door_closes, door: nowhere}]}}\n")
    with pytest.raises(SuiteError, match=r"row 1 \(r1\).*unknown open door 'nowhere'"):
        load_suite(bad)


def test_a_mission_stage_reported_unreachable_ends_the_mission_unreachable() -> None:
    from vlnpilot.tasks.mission_parser import plan_mission

    sim = Simulator(with_scenario(CABIN, load_scenario("cabin-door")), SimConfig(render=False, rear_camera=False))
    mission = plan_mission("Go to the bedroom, then go to the bathroom", sim.scene, "living_room")
    result = run_episode(sim, OraclePilot(), mission, EpisodeConfig(max_steps=60, seed=1), spawn="living_room")
    assert result.outcome == "unreachable" and result.stages_reached == 1 and result.failed_stage == 2
    assert "stage 2/2" in result.reason


def test_the_oracle_plans_on_the_true_map_and_takes_the_other_way_round_a_closed_door() -> None:
    from vlnpilot.scene.model import Door, Room, Scene

    def room(rid: str, x0: float) -> Room:
        return Room(rid, rid, ((x0, 0.0), (x0 + 3, 0.0), (x0 + 3, 3.0), (x0, 3.0)))

    ring = Scene("ring", "three rooms in a ring", (room("a", 0), room("b", 3), room("c", 6)),
                 (Door("ab", ("a", "b"), (3.0, 1.0), 0.8, 2.0, 0.0), Door("bc", ("b", "c"), (6.0, 1.0), 0.8, 2.0, 0.0),
                  Door("ac", ("a", "c"), (4.5, 3.0), 0.8, 2.0, 90.0)), (), ())

    class Truth:
        def __init__(self, scene: Scene):
            self.scene = scene

    oracle = OraclePilot()
    oracle.attach(Truth(ring))  # type: ignore[arg-type]
    assert oracle._next_door("a", "c")[0].id == "ac"
    closed = replace(ring, doors=tuple(replace(d, open=False) if d.id == "ac" else d for d in ring.doors))
    oracle.attach(Truth(closed))  # type: ignore[arg-type]
    assert oracle._next_door("a", "c")[0].id == "ab"  # replanned round the closed door


def test_a_scenario_for_another_scene_is_refused() -> None:
    with pytest.raises(ConfigError, match="is for scene 'cabin', not 'house:1'; fly it with --scene cabin"):
        with_scenario(load_scene("house:1"), load_scenario("cabin-person"))


@pytest.mark.parametrize(("event", "prefix"), [
    ({"kind": "person", "path": [[5.2, 1.1], [5.2, 1.11]]}, "mover:person-1"),
    ({"kind": "pet", "path": [[6.2, 1.1], [6.2, 1.11]]}, "mover:pet-1"),
    ({"kind": "door_closes", "door": "door_bedroom_bathroom"}, "door_leaf:door_bedroom_bathroom"),
])
def test_each_mover_and_a_closed_door_are_in_the_front_image(event: dict, prefix: str) -> None:
    sim = sim_with(event, render=True)
    sim.reset(Pose(4.0, 1.1, 1.0, 0.0))
    sim.step("E")  # a door swings shut within a hover
    ids = sim.segmentation()
    mine = [g for g in range(sim.model.ngeom) if sim.geom_name(g).startswith(prefix)]
    assert np.isin(ids, mine).mean() > 0.01
