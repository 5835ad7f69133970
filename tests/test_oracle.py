"""The oracle flies every (spawn, query) row of the paper's Table 4 within 50 steps, without a collision.

Each row also has a step bound (measured on the `paper` profile when the test was written, plus a margin of 2):
an oracle, scene or controller change that makes the oracle slower fails here and must update the bound
knowingly.
"""

from __future__ import annotations

from typing import Any

import pytest

from vlnpilot.core.decision import PilotInput
from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.fsm import State, state_spec
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import EpisodeResult
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

MARGIN = 2
# (spawn, query): steps measured on the paper profile (oracle defaults, cabin scene v2). Issue 12 asks for at most
# 35 on every row, so that a real pilot has slack within the paper's 50 steps.
MAX_ORACLE_STEPS = 35
TABLE_4 = {
    ("living_room", "Go to the bathroom"): 33,
    ("living_room", "Go to the bedroom"): 17,
    ("living_room", "Go to the living room/kitchen"): 1,
    ("living_room", "Find the refrigerator in the living room or kitchen"): 10,
    ("bedroom", "Go to the bedroom"): 1,
    ("bedroom", "Go to the living room/kitchen"): 20,
    ("bedroom", "Find the mirror in the bedroom"): 10,
    ("bathroom", "Go to the bathroom"): 1,
    ("bathroom", "Go to the living room/kitchen"): 32,
    ("bathroom", "Find the sink in the bathroom"): 7,
}
ROWS = list(TABLE_4)


@pytest.fixture(scope="module")
def geo() -> Simulator:
    """Render-free simulator: the oracle needs no images (target visibility still uses segmentation)."""
    with Simulator("cabin", SimConfig(render=False)) as sim:
        yield sim


def fly(sim: Simulator, spawn: str, query: str, profile: str = "paper") -> tuple[EpisodeResult, list[dict[str, Any]]]:
    records: list[dict[str, Any]] = []
    result = run_episode(sim, OraclePilot(), parse_query(query, sim.scene), EpisodeConfig(profile=profile),
                         spawn=spawn, on_step=records.append)
    return result, records


@pytest.mark.parametrize(("spawn", "query"), ROWS, ids=[f"{s}:{q}" for s, q in ROWS])
def test_oracle_succeeds_on_table_4(geo: Simulator, spawn: str, query: str) -> None:
    result, records = fly(geo, spawn, query)
    task = parse_query(query, geo.scene)
    assert result.outcome == "success", result.reason
    assert result.collisions == 0 and not any(r["collided"] for r in records)
    assert result.steps <= MAX_ORACLE_STEPS
    assert result.steps <= TABLE_4[(spawn, query)] + MARGIN, f"oracle got slower: {result.steps} steps"
    assert result.final_room == task.goal_room
    assert result.final_state == ("Describe Object" if task.goal_target else "Stay on Room")
    # every answer was valid the first time: one call per step, nothing rejected, nothing hovered instead
    assert result.invalid_decisions == 0 and result.pilot_calls == result.steps
    assert all(not r["failures"] and r["executed"] == r["proposed"] for r in records)
    for rec in records:
        assert rec["executed"] in state_spec(rec["state"]).moves
        true_room = geo.scene.room_at(rec["pose_before"]["x"], rec["pose_before"]["y"])
        if true_room is not None:
            assert rec["decision"]["room"] == true_room
    assert 0 < result.spl <= 1.0


@pytest.mark.parametrize(("spawn", "query"), ROWS, ids=[f"{s}:{q}" for s, q in ROWS])
def test_oracle_fast_profile_is_no_slower(geo: Simulator, spawn: str, query: str) -> None:
    result, _ = fly(geo, spawn, query, profile="fast")
    assert result.outcome == "success", result.reason
    assert result.collisions == 0
    assert result.steps <= TABLE_4[(spawn, query)] + MARGIN


def test_oracle_is_deterministic(geo: Simulator) -> None:
    first = fly(geo, "living_room", "Go to the bedroom")[1]
    second = fly(geo, "living_room", "Go to the bedroom")[1]
    assert [(r["executed"], r["next_state"], r["pose_after"]) for r in first] == \
           [(r["executed"], r["next_state"], r["pose_after"]) for r in second]


def test_oracle_needs_ground_truth(scene) -> None:
    pilot = OraclePilot()
    assert pilot.traits.privileged and pilot.name == "oracle"
    pin = PilotInput(image=None, query="Go to the bedroom", topological_map=scene.topological_map(),
                     state=State.RECOGNIZE_ROOM, previous_movement=None, step=1)
    with pytest.raises(VLNPilotError, match="attach"):
        pilot.decide(pin)


@pytest.mark.parametrize(("key", "value"), [("approach_m", "nan"), ("approach_m", "inf"), ("approach_m", "-1"),
                                            ("view_m", "nan"), ("cross_m", "1e308"), ("lateral_tol_m", "0.5")])
def test_its_distances_must_be_finite_and_in_range(key, value):
    from vlnpilot.core.errors import ConfigError
    from vlnpilot.pilots.oracle import OracleOptions

    named = rf"option '{key}' of the oracle pilot: must be a finite number in [0-9.]+\.\."
    with pytest.raises(ConfigError, match=named):
        OracleOptions.from_command_line("oracle", {key: value})
    assert OracleOptions.from_command_line("oracle", {key: "0.3"}) == {key: 0.3}
