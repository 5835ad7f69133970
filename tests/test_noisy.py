"""The noisy oracle: the paper's failure modes with seeded odds, and the safety layer fixing them."""

from __future__ import annotations

import pytest

from vlnpilot.core.errors import ConfigError
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import known_pilots, make_pilot
from vlnpilot.tasks.task import parse_query


def _fly(sim, query: str, spawn: str, seed: int, shield: str = "off", **options):
    pilot = make_pilot("noisy-oracle", **options)
    result = run_episode(sim, pilot, parse_query(query, sim.scene), EpisodeConfig(seed=seed, shield=shield),
                         spawn=spawn)
    return result, pilot


def test_registered_and_validated():
    assert "noisy-oracle" in known_pilots()
    assert make_pilot("noisy-oracle").name == "noisy-oracle"
    with pytest.raises(ConfigError, match="p_offset"):
        make_pilot("noisy-oracle", p_offset=1.5)
    with pytest.raises(ConfigError, match="offset_m"):
        make_pilot("noisy-oracle", offset_m=(0.5, 0.2))


def test_same_seed_same_episode(geo_sim):
    a, pa = _fly(geo_sim, "Go to the bathroom", "living_room", seed=11)
    b, pb = _fly(geo_sim, "Go to the bathroom", "living_room", seed=11)
    assert pa.drawn_failures() == pb.drawn_failures()
    assert (a.outcome, a.steps, a.path_length_m) == (b.outcome, b.steps, b.path_length_m)
    plans = {repr(_fly(geo_sim, "Go to the bathroom", "living_room", seed=s)[1].drawn_failures()) for s in range(12)}
    assert len(plans) > 3  # the seed matters


def test_noiseless_is_the_oracle(geo_sim):
    result, _ = _fly(geo_sim, "Go to the bathroom", "living_room", seed=1, p_offset=0, p_strict=0, p_early=0)
    assert result.outcome == "success"


def test_offset_crossing_collides_without_the_shield_and_succeeds_with_it(geo_sim):
    off, pilot = _fly(geo_sim, "Go to the bedroom", "living_room", seed=2, p_offset=1.0, p_strict=0.0, p_early=0.0)
    assert abs(pilot.drawn_failures()["offsets"]["door_living_bedroom"]) >= 0.36
    assert off.outcome == "collision" and off.contact.startswith("door_living_bedroom")
    on, _ = _fly(geo_sim, "Go to the bedroom", "living_room", seed=2, shield="geometry", p_offset=1.0, p_strict=0.0,
                 p_early=0.0)
    assert on.outcome == "success" and on.interventions >= 1


def test_strict_centring_oscillates_until_the_step_limit_unless_guarded(geo_sim):
    off, _ = _fly(geo_sim, "Go to the living room", "bedroom", seed=3, p_offset=0.0, p_strict=1.0, p_early=0.0)
    assert off.outcome == "max_steps" and off.oscillation_events >= 1 and off.interventions == 0
    on, _ = _fly(geo_sim, "Go to the living room", "bedroom", seed=3, shield="geometry", p_offset=0.0, p_strict=1.0,
                 p_early=0.0)
    assert on.outcome == "success" and on.oscillation_events >= 1


def test_early_final_state_is_a_false_success(geo_sim):
    room, _ = _fly(geo_sim, "Go to the bedroom", "living_room", seed=4, p_offset=0, p_strict=0, p_early=1.0)
    assert room.outcome == "false_success" and room.final_state == "Stay on Room"
    obj, _ = _fly(geo_sim, "Find the refrigerator", "living_room", seed=4, p_offset=0, p_strict=0, p_early=1.0)
    assert obj.outcome == "false_success" and obj.final_state == "Describe Object"


def test_it_is_no_mission_planner_so_the_parser_plans_for_it():
    from vlnpilot.pilots.planning import can_plan, plan_instruction
    from vlnpilot.scene import load_scene

    pilot = make_pilot("noisy-oracle")
    assert not can_plan(pilot)  # its drawn failures are not a planning call
    scene = load_scene("cabin")
    mission, _ = plan_instruction("Go to the bathroom, then come back", scene, "living_room", pilot)
    assert len(mission.stages) == 2


def test_it_flies_a_mission_stage_by_stage_as_the_oracle_does(geo_sim):
    from vlnpilot.tasks.mission_parser import plan_mission

    # the whole query is no one-goal query (the parser reads "fridge ... bathroom" as a fridge in the bathroom)
    mission = plan_mission("Find the fridge and then go to the bathroom", geo_sim.scene, "living_room")
    pilot = make_pilot("noisy-oracle", p_offset=0, p_strict=0, p_early=0)
    result = run_episode(geo_sim, pilot, mission, EpisodeConfig(seed=1), spawn="living_room")
    assert result.outcome == "success" and result.stages_reached == 2
