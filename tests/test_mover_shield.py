"""The mover shield (issue 24): no command carries the drone within its margin of a person's or a pet's predicted
position over the command's duration; such a command becomes a hover with the reason `mover:<name>`."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlnpilot.core import tello_spec
from vlnpilot.core.commands import COMMANDS, HOVER, Command
from vlnpilot.core.environment import Capabilities
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.movers import JUMP_MARGIN_M, MOVER_HEIGHT, MOVER_RADIUS, SHIELD_MARGIN_M, MoverState
from vlnpilot.core.records import Motion, Pose
from vlnpilot.safety import SafetyConfig, Shield
from vlnpilot.safety.layer import make_safety
from vlnpilot.safety.movers import MOVER_REASON, MoverShield, least_clearance, motion_seconds
from vlnpilot.scene import load_scene

START = Pose(0.0, 0.0, 1.0, 0.0)  # facing +x


def mover(x: float, y: float, vx: float = 0.0, vy: float = 0.0, kind: str = "person") -> MoverState:
    return MoverState(f"{kind}-1", kind, x, y, vx, vy, MOVER_RADIUS[kind], MOVER_HEIGHT[kind])


class OpenSpace(Shield):
    """An inner shield that sees no walls (counts its calls), so only movers can block."""

    name = "geometry"

    def __init__(self) -> None:
        super().__init__(SafetyConfig())
        self.calls = 0

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        self.calls += 1
        return None


class ShortensForward(OpenSpace):
    """An inner shield that lets forward moves through only as A1 (a wall 12 cm ahead, say)."""

    def hazard(self, pose: Pose, motion: Motion) -> str | None:
        return "a wall" if motion.forward_m > 0.1 else None


def shield(*movers: MoverState, inner: Shield | None = None) -> MoverShield:
    return MoverShield(inner or OpenSpace(), lambda: movers)


def test_durations_come_from_the_tello_spec() -> None:
    moving, total = motion_seconds(COMMANDS["A3"].motion())
    assert moving == pytest.approx(0.5 / tello_spec.MOVE_SPEED_MPS)
    assert total == pytest.approx(moving + tello_spec.SETTLE_S)
    assert motion_seconds(Motion()) == (0.0, tello_spec.HOVER_S)


def test_a_person_standing_ahead_blocks_a_forward_move_but_not_a_rotation() -> None:
    person = mover(1.2, 0.0)  # 0.88 m between the outlines now; A3 would leave 0.38 m
    s = shield(person)
    cmd, why = s.filter(START, COMMANDS["A3"])
    assert cmd is HOVER and why is not None and why.startswith(f"{MOVER_REASON}person-1")
    assert s.filter(START, COMMANDS["A1"]) == (COMMANDS["A1"], None)  # 0.78 m left: beyond 0.5 m
    assert s.filter(START, COMMANDS["B3"]) == (COMMANDS["B3"], None)  # the centre does not move


def test_the_prediction_sees_a_person_walking_into_the_path() -> None:
    """Clear now (1.8 m away), but walking at 1.2 m/s across the line the drone flies: the shield must
    predict it (it fails if the mover is taken as standing still)."""
    crossing = mover(1.0, -1.5, vy=1.2)
    a3 = COMMANDS["A3"].motion()
    assert least_clearance(START, a3, crossing, hover=True) > 0.5  # hovering: it passes 1 m ahead
    assert least_clearance(START, a3, mover(1.0, -1.5)) > 0.5  # standing where it is now: no hazard
    cmd, why = shield(crossing).filter(START, COMMANDS["A3"])
    assert cmd is HOVER and why is not None and why.startswith("mover:person-1")
    walking_away = mover(1.2, 0.0, vx=1.2)
    assert shield(walking_away).filter(START, COMMANDS["A3"]) == (COMMANDS["A3"], None)


def test_a_pet_keeps_its_own_margin() -> None:
    gap = 0.45  # between the outlines after A1: beyond a pet's 0.4 m, within a person's 0.5 m
    x = 0.1 + tello_spec.BOUNDING_RADIUS + gap
    assert shield(mover(x + MOVER_RADIUS["pet"], 0.0, kind="pet")).filter(START, COMMANDS["A1"])[1] is None
    assert shield(mover(x + MOVER_RADIUS["person"], 0.0)).filter(START, COMMANDS["A1"])[0] is HOVER
    assert SHIELD_MARGIN_M == {"person": 0.5, "pet": 0.4}


def test_a_pet_far_below_the_drone_does_not_block_it_but_a_person_always_does() -> None:
    """EVFIX item 1: the clearance is three-dimensional. A pet (0.35 m) right ahead of a drone at 1 m: its bottom is
    beyond the pet's top plus the jump margin, so the pet blocks nothing; at 0.5 m it does; a person always does.
    Under the recorded "column" rule (the events trials) the pet blocks at any height, as those trials were flown."""
    pet, person = mover(0.45, 0.0, kind="pet"), mover(0.45, 0.0)
    assert shield(pet).filter(START, COMMANDS["A3"]) == (COMMANDS["A3"], None)
    assert shield(pet).filter(Pose(0.0, 0.0, 0.5, 0.0), COMMANDS["A3"])[0] is HOVER
    assert shield(person).filter(START, COMMANDS["A3"])[0] is HOVER
    assert shield(person).filter(Pose(0.0, 0.0, 2.2, 0.0), COMMANDS["A3"])[0] is HOVER
    column = MoverShield(OpenSpace(), lambda: (pet,))
    column.clearance = "column"
    assert column.filter(START, COMMANDS["A3"])[0] is HOVER
    assert JUMP_MARGIN_M == 0.3 and SafetyConfig().mover_clearance == "3d"
    with pytest.raises(ConfigError, match="mover_clearance 'sphere' is not one of column, 3d"):
        SafetyConfig(mover_clearance="sphere")


def test_a_replay_flies_under_the_mover_rule_its_recording_was_flown_with(tmp_path) -> None:
    """The events trials were flown under the column rule, recorded without the setting: a replay keeps it; a new run
    records the 3-D rule and replays under it."""
    from pathlib import Path

    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import _as_recorded
    from vlnpilot.pilots.base import make_pilot
    from vlnpilot.pilots.replay import recorded_mover_clearance

    trial = Path(__file__).resolve().parents[1] / "trials" / "events-houses" / "h4-1door-pet"
    pilot = make_pilot(f"replay:{trial}")
    assert pilot.recorded_mover_clearance == "column"
    assert _as_recorded(pilot, EpisodeConfig()).safety.mover_clearance == "column"
    assert recorded_mover_clearance({"safety": EpisodeConfig().safety.to_dict()}) == "3d"
    assert _as_recorded(make_pilot("oracle"), EpisodeConfig()).safety.mover_clearance == "3d"


def test_inside_the_margin_the_drone_may_back_away_but_never_close_in() -> None:
    near = mover(0.55, 0.0)  # 0.23 m between the outlines: already within the margin
    s = shield(near)
    assert s.filter(START, COMMANDS["A1"])[0] is HOVER  # towards it
    assert s.filter(START, COMMANDS["D1"]) == (COMMANDS["D1"], None)  # sideways: the gap grows
    assert s.filter(START, COMMANDS["E"]) == (COMMANDS["E"], None)


def test_the_inner_shield_still_decides_about_walls_and_its_choice_is_checked_for_movers() -> None:
    inner = OpenSpace()
    s = shield(inner=inner)
    assert s.filter(START, COMMANDS["A3"]) == (COMMANDS["A3"], None) and inner.calls > 0
    assert shield(inner=ShortensForward()).filter(START, COMMANDS["A3"]) == (COMMANDS["A1"], "a wall")
    # the wall shortens A3 to A1, and A1 would still come within the margin of the person: hover
    close = mover(0.1 + tello_spec.BOUNDING_RADIUS + 0.45 + MOVER_RADIUS["person"] + 0.1, 0.0)
    assert shield(close, inner=ShortensForward()).filter(START, COMMANDS["A1"])[0] is COMMANDS["A1"]
    cmd, why = shield(mover(0.75, 0.0), inner=ShortensForward()).filter(START, COMMANDS["A3"])
    assert cmd is HOVER and why is not None and why.startswith("mover:")


@settings(max_examples=300, deadline=None)
@given(x=st.floats(-2, 2), y=st.floats(-2, 2), vx=st.floats(-2, 2), vy=st.floats(-2, 2),
       yaw=st.floats(-180, 180), code=st.sampled_from(sorted(COMMANDS)))
def test_an_allowed_command_never_comes_closer_than_the_margin_or_the_hover(x, y, vx, vy, yaw, code) -> None:
    """Checked densely (every 5 ms) against the prediction, independently of the shield's closed form."""
    pose, person = Pose(0.0, 0.0, 1.0, yaw), mover(x, y, vx, vy)
    cmd: Command = shield(person).filter(pose, COMMANDS[code])[0]
    motion = cmd.motion()
    moving, total = motion_seconds(motion)

    def gap(t: float, m: Motion) -> float:
        at = m.apply(pose, min(1.0, t / moving) if moving else 1.0)
        p = person.at(t)
        return math.hypot(p.x - at.x, p.y - at.y) - tello_spec.BOUNDING_RADIUS - person.radius

    times = [total * i / 400 for i in range(401)]
    flown = min(gap(t, motion) for t in times)
    hover = min(gap(t, Motion()) for t in times)
    # The hover's least gap may fall between two samples: at most what the two close in on each other in one
    # sample's time (a person crossing the drone's spot reaches the same least gap however the drone moves).
    between = (math.hypot(vx, vy) + tello_spec.MOVE_SPEED_MPS) * total / 400
    assert flown >= min(SHIELD_MARGIN_M["person"], hover - between) - 1e-6


class WithMovers:
    """An environment that declares ground truth and movers (what the simulator declares with a scenario)."""

    capabilities = Capabilities(ground_truth=True, movers=True)

    def __init__(self, sim, people: tuple[MoverState, ...]):
        self._sim, self._people = sim, people
        self.scene = sim.scene

    def ground_truth(self):
        return self._sim.ground_truth()

    def movers(self) -> tuple[MoverState, ...]:
        return self._people

    @property
    def seconds(self) -> float:
        return 0.0


def test_make_safety_adds_the_mover_shield_where_people_move(geo_sim) -> None:
    env = WithMovers(geo_sim, (mover(1.0, 1.0),))
    layer = make_safety("geometry", env, geo_sim.scene)
    assert isinstance(layer.shield, MoverShield) and layer.name == "geometry"  # recorded as before
    assert not isinstance(make_safety("geometry", geo_sim, geo_sim.scene).shield, MoverShield)  # a still scene
    assert make_safety("off", env, geo_sim.scene).shield is None  # off: counted, not prevented


def test_a_mover_hover_is_recorded_as_a_shield_intervention(geo_sim) -> None:
    from vlnpilot.core.fsm import State

    scene = load_scene("cabin")
    spawn = scene.spawns[0].pose
    c, s = spawn.heading()
    person = mover(spawn.x + 0.9 * c, spawn.y + 0.9 * s)
    layer = make_safety("geometry", WithMovers(geo_sim, (person,)), scene)
    verdict = layer.filter(1, State.SEARCH_OBJECT, COMMANDS["A3"], State.SEARCH_OBJECT, spawn)
    assert verdict.command is HOVER
    (iv,) = verdict.interventions
    assert (iv.source, iv.proposed, iv.executed) == ("shield", "A3", "E") and iv.reason.startswith("mover:person-1")
    assert layer.interventions == [iv] and "mover:person-1" in verdict.feedback[0]


# -- in the simulator: a pilot that always flies at the nearest mover ------------------------------------------
class Chaser:
    """Flies straight at the nearest person or pet (ground truth) for the whole episode: the worst pilot there is."""

    name = model = "chaser"

    def __init__(self, sim) -> None:  # noqa: ANN001
        self.sim = sim

    def decide(self, pilot_input):  # noqa: ANN001, ANN201
        from vlnpilot.core.decision import Decision
        from vlnpilot.core.records import wrap_deg

        pose, movers = self.sim.ground_truth().pose(), self.sim.movers()
        move = "B2"  # look around until someone appears
        if movers:
            m = min(movers, key=lambda m: math.hypot(m.x - pose.x, m.y - pose.y))
            err = wrap_deg(math.degrees(math.atan2(m.y - pose.y, m.x - pose.x)) - pose.yaw_deg)
            move = "A2" if abs(err) < 10 else ("C1" if err > 0 else "B1") if abs(err) < 30 else ("C2" if err > 0 else
                                                                                                   "B2")
        return Decision(room="unknown", movement=move, state="Recognize Room", model=self.model)


def chase(kind: str, path: list, speed: float, shield: str, seed: int):  # noqa: ANN201
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.loop import run_episode
    from vlnpilot.scene.events import scenario_from_dict, with_scenario
    from vlnpilot.sim import SimConfig, Simulator
    from vlnpilot.tasks.task import parse_query

    scenario = scenario_from_dict({"scene": "cabin", "seed": seed, "events": [
        {"kind": kind, "path": path, "speed_mps": speed, "repeat": True}]})
    scene = with_scenario(load_scene("cabin"), scenario)
    sim = Simulator(scene, SimConfig(render=False))
    try:
        return run_episode(sim, Chaser(sim), parse_query("Go to the kitchen", scene),
                           EpisodeConfig(max_steps=60, shield=shield, profile="fast", seed=seed), spawn="living_room")
    finally:
        sim.close()


WALKS = [("person", ["bedroom", "living_room"], 1.2), ("person", ["living_room", "bedroom", "bathroom"], 1.6),
         ("person", ["bathroom", "bedroom"], 0.6), ("pet", ["living_room", "bedroom"], 2.0)]


@pytest.mark.parametrize("shield", ["geometry", "assist"])
@pytest.mark.parametrize(("kind", "path", "speed"), WALKS)
def test_a_pilot_that_flies_at_people_never_touches_one(kind: str, path: list, speed: float, shield: str) -> None:
    result = chase(kind, path, speed, shield, seed=3)
    assert result.mover_collisions == 0 and not str(result.contact or "").startswith("mover:"), result.reason
    # stopped again and again by a person; a pet far below the drone needs no stop (the 3-D clearance), nor gets one
    assert result.interventions > 0 or kind == "pet"


def test_without_the_shield_the_same_pilot_touches_a_person_and_it_is_counted() -> None:
    result = chase("person", ["bedroom", "living_room"], 1.2, "off", seed=3)
    assert (result.outcome, result.mover_collisions) == ("collision", 1) and result.contact == "mover:person-1"
