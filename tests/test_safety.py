"""The safety layer: shield (geometry and depth), door-crossing assist, oscillation guard, corridor overlay."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from vlnpilot.bench.suite import load_suite
from vlnpilot.core import tello_spec
from vlnpilot.core.commands import COMMANDS, HOVER, get_command
from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Pose
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.safety import (
    ASSIST_NOTE,
    GUARD_NOTE,
    DoorAssist,
    OscillationConfig,
    OscillationGuard,
    SafetyConfig,
    SafetyLayer,
    corridor_pixels,
    draw_corridor,
    make_safety,
    make_shield,
)
from vlnpilot.scene.model import Spawn
from vlnpilot.tasks.task import parse_query

PAPER_ROWS = [(row.spawn, row.query) for row in load_suite("paper").rows]  # the paper's Table 4
CODES = sorted(COMMANDS)
REACH = 0.5 + tello_spec.BOUNDING_RADIUS  # no command moves any part of the drone further than this


@pytest.fixture(scope="module")
def geometry(geo_sim):
    return make_shield("geometry", geo_sim)


def _free(sim, pose: Pose) -> bool:
    try:
        sim.reset(pose)
    except ConfigError:
        return False
    return True


# -- poses near walls, furniture and door frames ----------------------------------------------------------------
def _near_solid(scene):
    solids = [s for s in scene.solids if s.collide and s.shape != "plane" and s.name not in ("floor", "ceiling")
              and s.pos[2] - s.size[2] - 0.3 <= scene.flight_altitude <= s.pos[2] + s.size[2] + 0.3]

    @st.composite
    def strat(draw):
        s = draw(st.sampled_from(solids))
        u, v = draw(st.floats(-1, 1)), draw(st.floats(-1, 1))
        a = math.radians(s.yaw_deg)
        px = s.pos[0] + u * s.size[0] * math.cos(a) - v * s.size[1] * math.sin(a)
        py = s.pos[1] + u * s.size[0] * math.sin(a) + v * s.size[1] * math.cos(a)
        d, phi = draw(st.floats(0.0, 0.35)), draw(st.floats(-math.pi, math.pi))
        return Pose(px + d * math.cos(phi), py + d * math.sin(phi), scene.flight_altitude + draw(st.floats(-0.1, 0.1)),
                    draw(st.floats(-180, 180)))
    return strat()


def _near_door(scene):
    @st.composite
    def strat(draw):
        door = draw(st.sampled_from(scene.open_doors()))
        depth, lateral = draw(st.floats(-0.5, 0.5)), draw(st.floats(-0.6, 0.6))
        nx, ny = door.normal
        x = door.center[0] + depth * nx - lateral * ny
        y = door.center[1] + depth * ny + lateral * nx
        yaw = door.normal_deg + draw(st.sampled_from([0.0, 180.0])) + draw(st.floats(-60, 60))
        return Pose(x, y, scene.flight_altitude, yaw)
    return strat()


@settings(max_examples=70, deadline=None, suppress_health_check=[HealthCheck.filter_too_much,
                                                                   HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_geometry_shield_lets_nothing_through_that_collides(geo_sim, geometry, data):
    """Property: for every command, what the geometry shield executes never collides in the simulator."""
    scene = geo_sim.scene
    pose = data.draw(st.one_of(_near_solid(scene), _near_door(scene)), label="pose")
    assume(_free(geo_sim, pose))
    for code in CODES:
        executed, _ = geometry.filter(pose, COMMANDS[code])
        geo_sim.reset(pose)
        obs = geo_sim.step(executed)
        assert not obs.collided, (pose, code, executed.code, obs.contact)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.filter_too_much,
                                                                   HealthCheck.function_scoped_fixture])
@given(x=st.floats(0.3, 8.3), y=st.floats(0.3, 3.3), yaw=st.floats(-180, 180))
def test_no_false_vetoes_in_open_space(geo_sim, geometry, x, y, yaw):
    """Nothing within reach of any motion (plus the margin): the layer never changes a command, in any state."""
    pose = Pose(x, y, geo_sim.scene.flight_altitude, yaw)
    margin = geometry.config.margin_m
    assume(geo_sim.clearance_at(pose, REACH + margin + 0.02) is None)
    layer = SafetyLayer(geo_sim.scene, geometry.config, geometry)
    for state in (State.SEARCH_OPEN_DOOR, State.ORIENTED_TOWARDS_DOOR, State.GO_THROUGH_DOOR):
        for code in CODES:
            layer.guard.reset()
            verdict = layer.filter(1, state, COMMANDS[code], state, pose)
            assert verdict.command.code == code and not verdict.interventions and not verdict.feedback


@pytest.mark.parametrize("kind", ["geometry", "depth"])
def test_shield_shortens_then_hovers_in_front_of_a_wall(geo_sim, kind):
    """A wall 45 cm ahead: A3 is shortened to A2; 8 cm ahead every forward move becomes E; backing off is fine."""
    shield = make_shield(kind, geo_sim)
    wall_x = 3.95  # west face of the living-bedroom wall at y = 2.0 (no door there)
    pose = Pose(wall_x - 0.45, 2.0, 1.0, 0.0)
    shield.reset(geo_sim.reset(pose))
    executed, why = shield.filter(pose, COMMANDS["A3"])
    assert executed.code == "A2" and why
    assert shield.filter(pose, COMMANDS["A1"]) == (COMMANDS["A1"], None)
    close = Pose(wall_x - tello_spec.LENGTH / 2 - 0.08, 2.0, 1.0, 0.0)
    shield.reset(geo_sim.reset(close))
    for code in ("A1", "A2", "A3"):
        assert shield.filter(close, COMMANDS[code])[0] is HOVER
    for code in ("B1", "C1", "D1", "D2"):  # rotations and sideways moves keep their distance to the wall
        assert shield.filter(close, COMMANDS[code]) == (COMMANDS[code], None)


def test_depth_shield_back_projects_a_flat_wall(geo_sim):
    """The depth image is z-depth along the optical axis: a wall ahead back-projects onto its plane."""
    shield = make_shield("depth", geo_sim)
    pose = Pose(3.0, 2.0, 1.0, 0.0)
    geo_sim.reset(pose)
    depth = geo_sim.render("front", 160, 120, depth=True)
    pts = shield.points_from_depth(depth, pose)
    wall = pts[(np.abs(pts[:, 1] - 2.0) < 0.2)]  # straight ahead: the bare wall
    assert len(wall) > 50
    assert np.allclose(wall[:, 0], 3.95, atol=0.02)


def test_shield_names_and_errors(geo_sim):
    assert make_shield("off", geo_sim) is None
    assert make_shield("geometry", geo_sim).name == "geometry"
    with pytest.raises(UnknownNameError, match="geometry"):
        make_shield("lidar", geo_sim)
    with pytest.raises(ConfigError, match="geometry shield"):
        make_shield("geometry", object())
    with pytest.raises(ConfigError):
        EpisodeConfig(shield="lidar")
    with pytest.raises(ConfigError):
        EpisodeConfig(overlay="grid")
    with pytest.raises(ConfigError):
        SafetyConfig(margin_m=-0.1)
    with pytest.raises(ConfigError):
        OscillationConfig(window=4, threshold=4)
    assert make_safety("off", geo_sim, geo_sim.scene).name == "off"


# -- door-crossing assist -----------------------------------------------------------------------------------------
class StraightThroughPilot:
    """Believes it is centred on the doorway ahead: flies A1 through the FSM to Go Through Door and on."""

    name, model = "straight", None

    def __init__(self):
        self.inputs: list[PilotInput] = []

    def decide(self, pin: PilotInput) -> Decision:
        self.inputs.append(pin)
        nxt = {State.RECOGNIZE_ROOM: State.SEARCH_OPEN_DOOR, State.SEARCH_OPEN_DOOR: State.ORIENTED_TOWARDS_DOOR,
               State.ORIENTED_TOWARDS_DOOR: State.GO_THROUGH_DOOR}.get(pin.state, pin.state)
        return Decision(room="living room", movement="A1", state=nxt.value, description="Centred; going through.")


def _off_centre_spawn(scene) -> Spawn:
    door = scene.door("door_living_bedroom")  # opening y 0.6..1.4; the open leaf stands at y > 1.36
    return Spawn("off_centre", "living_room", Pose(door.center[0] - 0.6, door.center[1] - 0.38, 1.0, 0.0))


def test_door_assist_prevents_the_off_centre_crossing_collision(geo_sim):
    task = parse_query("Go to the bedroom", geo_sim.scene)
    spawn = _off_centre_spawn(geo_sim.scene)
    off = run_episode(geo_sim, StraightThroughPilot(), task, EpisodeConfig(max_steps=14), spawn=spawn)
    assert off.outcome == "collision" and off.contact.startswith("door_living_bedroom_frame")

    records: list[dict] = []
    pilot = StraightThroughPilot()
    on = run_episode(geo_sim, pilot, task, EpisodeConfig(max_steps=14, shield="geometry"), spawn=spawn,
                     on_step=records.append)
    assert on.collisions == 0 and on.outcome == "max_steps"
    assert geo_sim.pose.x > 4.2  # through the doorway, into the bedroom
    assists = [i for r in records for i in r["interventions"] if i["source"] == "door_assist"]
    assert assists and all(i["proposed"] == "A1" and i["executed"] == "D1" for i in assists)
    assert on.interventions == len(assists)
    step = assists[0]["step"]  # told to the pilot in the next prompt
    assert any(line.startswith(ASSIST_NOTE) for line in pilot.inputs[step].feedback)


def test_door_assist_geometry(scene):
    assist = DoorAssist(scene, SafetyConfig())
    door = scene.door("door_living_bedroom")
    centred = Pose(door.center[0] - 0.2, door.center[1], 1.0, 0.0)
    assert assist.correction(centred, COMMANDS["A2"]) is None
    a = assist.alignment(centred)
    assert a.door is door and a.fits and a.distance_m == pytest.approx(0.2)
    left = Pose(door.center[0] - 0.1, door.center[1] + 0.33, 1.0, 0.0)  # left of the line, facing the bedroom
    assert assist.correction(left, COMMANDS["A1"])[0].code == "D2"
    back = Pose(door.center[0] + 0.1, door.center[1] + 0.33, 1.0, 180.0)  # same place, crossing the other way
    assert assist.correction(back, COMMANDS["A1"])[0].code == "D1"
    assert assist.correction(left, COMMANDS["B1"]) is None  # only forward moves are corrected


# -- oscillation guard ----------------------------------------------------------------------------------------------
def test_guard_fires_after_threshold_reversals_and_forward_progress_resets_it():
    guard = OscillationGuard(OscillationConfig(window=6, threshold=3))
    seq = [("C1", None), ("B1", None), ("C1", None), ("B1", 3)]
    for code, expected in seq:
        assert guard.propose(State.ORIENTED_TOWARDS_DOOR, COMMANDS[code]) == expected
        guard.executed(COMMANDS[code])
    guard.committed = False
    for code in ("C1", "A1", "B1", "A1", "C1", "A1", "B1"):  # progress between the turns: no oscillation
        assert guard.propose(State.SEARCH_OPEN_DOOR, COMMANDS[code]) is None
        guard.executed(COMMANDS[code])


def test_guard_commits_to_the_crossing_when_the_drone_fits(scene):
    layer = SafetyLayer(scene, SafetyConfig(), shield=None, active=True)
    door = scene.door("door_living_bedroom")
    pose = Pose(door.center[0] - 0.45, door.center[1] + 0.04, 1.0, 4.0)
    verdicts = [layer.filter(i, State.ORIENTED_TOWARDS_DOOR, COMMANDS[c], State.ORIENTED_TOWARDS_DOOR, pose)
                for i, c in enumerate(("D2", "D1", "D2", "D1"), start=1)]
    assert [v.command.code for v in verdicts[:3]] == ["D2", "D1", "D2"]
    last = verdicts[-1]
    assert last.oscillation is not None and last.oscillation.acted and last.oscillation.reversals == 3
    assert last.command.code == "A1" and last.next_state is State.GO_THROUGH_DOOR
    assert [i.source for i in last.interventions] == ["oscillation_guard"]
    assert any(f.startswith(GUARD_NOTE) for f in last.feedback)


def test_guard_only_detects_when_the_safety_layer_is_off(scene):
    layer = SafetyLayer(scene, SafetyConfig(), shield=None, active=False)
    pose = Pose(2.0, 2.0, 1.0, 0.0)
    verdicts = [layer.filter(i, State.REACH_OBJECT, COMMANDS[c], State.REACH_OBJECT, pose)
                for i, c in enumerate(("B1", "C1", "B1", "C1", "B1"), start=1)]
    assert [v.command.code for v in verdicts] == ["B1", "C1", "B1", "C1", "B1"]
    assert len(layer.events) == 1 and not layer.events[0].acted
    assert not any(v.feedback or v.interventions for v in verdicts)


# -- episodes: records, summary, the oracle ------------------------------------------------------------------
def test_interventions_and_oscillations_are_recorded(geo_sim, tmp_path):
    pilot = make_pilot("noisy-oracle", p_offset=1.0, p_strict=1.0, p_early=0.0)
    task = parse_query("Go to the bedroom", geo_sim.scene)
    rec = Recorder(tmp_path / "run")
    result = run_episode(geo_sim, pilot, task, EpisodeConfig(seed=0, shield="geometry"), spawn="living_room",
                         recorder=rec)
    assert result.collisions == 0 and result.interventions > 0 and result.oscillation_events > 0
    assert result.shield == "geometry"
    summary, steps = load_run(tmp_path / "run")
    assert summary["result"]["interventions"] == result.interventions
    assert summary["result"]["oscillation_events"] == result.oscillation_events
    assert summary["config"]["shield"] == "geometry"
    logged = [i for s in steps for i in s["interventions"]]
    assert len(logged) == len(summary["safety"]["interventions"]) == result.interventions
    assert {"step", "source", "proposed", "executed", "reason"} <= set(logged[0])
    events = [s["oscillation_event"] for s in steps if s["oscillation_event"]]
    assert events == summary["safety"]["oscillation_events"] and len(events) == result.oscillation_events
    for line in (tmp_path / "run" / "episode.jsonl").read_text().splitlines():
        json.loads(line)


@pytest.mark.parametrize("shield", ["geometry", "depth"])
def test_oracle_succeeds_on_every_paper_row_without_interventions(geo_sim, shield):
    for spawn, query in PAPER_ROWS:
        result = run_episode(geo_sim, make_pilot("oracle"), parse_query(query, geo_sim.scene),
                             EpisodeConfig(shield=shield), spawn=spawn)
        assert result.outcome == "success", (spawn, query, result.reason)
        assert result.interventions == 0 and result.oscillation_events == 0, (spawn, query)


# -- corridor overlay ------------------------------------------------------------------------------------------------
def test_corridor_lines_mark_the_drone_width_at_each_depth():
    w, h = 640, 480
    left, right = corridor_pixels(w, h, depths=(0.5, 1.0, 2.0))
    f = (h / 2) / math.tan(math.radians(tello_spec.vertical_fov_deg()) / 2)
    for (xl, yl), (xr, yr), d in zip(left, right, (0.5, 1.0, 2.0), strict=True):
        assert xr - xl == pytest.approx(2 * f * tello_spec.HALF_WIDTH / d)
        assert yl == yr and (xl + xr) / 2 == pytest.approx(w / 2)
    image = np.full((h, w, 3), 90, np.uint8)
    out = draw_corridor(image)
    changed = (out != image).any(axis=2)
    assert out.shape == image.shape and 0 < changed.mean() < 0.01
    assert changed[:, : w // 2].sum() == pytest.approx(changed[:, w // 2:].sum(), rel=0.1)
    tiny = np.zeros((1, 1, 3), np.uint8)
    assert draw_corridor(tiny) is tiny


def test_overlay_reaches_the_pilot_but_not_the_recording(sim):
    pilot = StraightThroughPilot()
    task = parse_query("Go to the bedroom", sim.scene)
    run_episode(sim, pilot, task, EpisodeConfig(max_steps=1, overlay="corridor"), spawn="living_room")
    raw = sim.reset("living_room").front_rgb
    seen = pilot.inputs[0].image
    assert seen.shape == raw.shape and not np.array_equal(seen, raw)
    assert np.array_equal(seen, draw_corridor(raw))


def test_shortened_commands_stay_in_the_table():
    from vlnpilot.safety import shorter_commands

    assert [c.code for c in shorter_commands(get_command("A3"))] == ["A2", "A1"]
    assert [c.code for c in shorter_commands(get_command("B3"))] == ["B2", "B1"]
    assert shorter_commands(get_command("D1")) == []


@pytest.mark.parametrize(("spawn", "query"), [("living_room", "Go to the bathroom"), ("bathroom", "Go to the bedroom")])
def test_safety_feedback_never_names_the_scene(geo_sim, spawn, query):
    """What the pilot is told about an intervention must not leak ground truth that the camera cannot show: no room,
    door or solid name (a real pilot read the room's name off 'wall_living_room')."""
    names = {r.id for r in geo_sim.scene.rooms} | {d.id for d in geo_sim.scene.doors} | \
        {s.name for s in geo_sim.scene.solids}
    lines: list[str] = []
    for seed in range(4):
        pilot = make_pilot("noisy-oracle", p_offset=1.0, p_strict=1.0, p_early=0.0)
        task = parse_query(query, geo_sim.scene)
        run_episode(geo_sim, pilot, task, EpisodeConfig(seed=seed, shield="geometry"), spawn=spawn,
                    on_step=lambda rec: lines.extend(rec["safety_feedback"]))
    assert any(line.startswith(("Safety shield", "Door assist")) for line in lines)  # the shield did speak
    leaked = [(line, n) for line in lines for n in names if n in line]
    assert not leaked, leaked[:3]


def test_safety_never_imports_the_simulator():
    """The shields see an environment only through what it declares (`environment`), never `vlnpilot.sim`."""
    from test_layers import PACKAGE, imports

    found = {(path.name, name) for path in (PACKAGE / "safety").glob("*.py") for name in imports(path)
             if name == "vlnpilot.sim" or name.startswith("vlnpilot.sim.")}
    assert not found
