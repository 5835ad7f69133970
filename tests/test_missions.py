"""Missions (issue 22): the model, the parser against the suites, execution stage by stage, the stage metrics."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest
import yaml

from vlnpilot.bench.suite import load_suite
from vlnpilot.core.decision import Decision, PilotInput, PilotTraits
from vlnpilot.core.fsm import State
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import StageRate
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.prompting.render import build_prompt
from vlnpilot.scene import load_scene
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.mission import Mission, PlanError
from vlnpilot.tasks.mission_parser import parse_mission, plan_mission
from vlnpilot.tasks.task import parse_query


@pytest.fixture(scope="module")
def sim() -> Simulator:
    return Simulator("cabin", SimConfig(render=False))


def _fly(sim: Simulator, query: str, spawn: str = "living_room", pilot=None, records=None):
    mission = plan_mission(query, sim.scene, sim.scene.spawn(spawn).room)
    return mission, run_episode(sim, pilot or OraclePilot(), mission, EpisodeConfig(), spawn=spawn,
                                on_step=None if records is None else records.append)


# -- the three instructions, flown as written ----------------------------------------------------------
def test_there_and_back_is_two_stages_and_the_drone_comes_back(sim):
    records: list[dict] = []
    mission, result = _fly(sim, "Go to the bathroom, then come back to the living room", records=records)
    assert mission.plan() == {"stages": [{"room": "bathroom"}, {"room": "living_room"}]}
    assert result.outcome == "success" and result.stages == 2 and result.stages_reached == 2
    assert result.final_room == "living_room" and result.steps > 30  # it flew there and back, not 1 step
    boundary = result.stage_starts[1]
    assert {r["room_true"] for r in records if r["stage"] == 1} >= {"bathroom"}
    assert records[boundary - 2]["next_state"] == "Stay on Room"  # stage 1 ended in a judged final state
    assert records[boundary - 1]["state"] == "Recognize Room" and records[boundary - 1]["stage"] == 2


def test_dont_go_to_the_bathroom_flies_to_the_bedroom_and_never_enters_the_bathroom(sim):
    records: list[dict] = []
    mission, result = _fly(sim, "Don't go to the bathroom, go to the bedroom", records=records)
    assert mission.plan() == {"stages": [{"room": "bedroom"}], "avoid": ["bathroom"]}
    assert result.outcome == "success" and result.final_room == "bedroom"
    assert "bathroom" not in {r["room_true"] for r in records}


def test_bedroom_then_sink_judges_both_stages(sim):
    records: list[dict] = []
    mission, result = _fly(sim, "Go to the bedroom and then find the sink in the bathroom", records=records)
    assert mission.plan() == {"stages": [{"room": "bedroom"}, {"object": "sink"}]}
    assert result.outcome == "success" and result.stages_reached == 2 and result.final_state == "Describe Object"
    first = [r for r in records if r["stage"] == 1]
    assert first[-1]["next_state"] == "Stay on Room" and first[-1]["room_true"] == "bedroom"


# -- a stage judged a failure ends the mission -----------------------------------------------------------------
class HastyAtStage:
    """The oracle, except that at stage `k` (0-based) it declares Stay on Room at once, wherever it is."""

    name, model = "hasty", "test"
    traits = PilotTraits(privileged=True)

    def __init__(self, k: int):
        self.k, self.oracle = k, OraclePilot()

    def attach(self, gt):
        self.oracle.attach(gt)

    def decide(self, pin: PilotInput) -> Decision:
        if pin.stage == self.k and pin.state.value == "Recognize Room":
            return Decision(room="unknown", movement="E", state="Stay on Room", description="done")
        return self.oracle.decide(pin)


@pytest.mark.parametrize("k", [0, 1])
def test_a_stage_judged_a_failure_ends_the_mission_there(sim, k):
    _, result = _fly(sim, "Go to the bathroom, then the bedroom, then come back", pilot=HastyAtStage(k))
    assert result.outcome == "false_success" and result.stages == 3
    assert result.stages_reached == k and result.failed_stage == k + 1
    assert result.reason.startswith(f"stage {k + 1}/3") and result.spl == 0.0


def test_the_step_budget_is_max_steps_per_stage_for_the_whole_mission(sim):
    mission = plan_mission("Go to the bathroom, then come back", sim.scene, "living_room")
    result = run_episode(sim, OraclePilot(), mission, EpisodeConfig(max_steps=20), spawn="living_room")
    assert result.outcome == "max_steps" and result.steps == 40  # 20 x 2 stages, shared


# -- the prompt --------------------------------------------------------------------------------------------------
def _pin(**extra) -> PilotInput:
    return PilotInput(image=np.zeros((8, 8, 3), np.uint8), query="Go to the bathroom, then come back",
                      topological_map=load_scene("cabin").topological_map(), state=State.RECOGNIZE_ROOM,
                      previous_movement=None, step=3, **extra)


def test_the_prompt_shows_the_plan_done_and_current_stages_and_a_single_goal_prompt_is_unchanged():
    scene = load_scene("cabin")
    mission = plan_mission("Go to the bathroom, then come back", scene, "living_room")
    plain = build_prompt(_pin())
    assert "Mission plan" not in plain.context
    text = build_prompt(_pin(mission=mission.to_dict(), stage=1)).context
    assert "## Mission plan" in text and "mission of 2 stages" in text
    assert "Stage 1 (done): go to the room `bathroom`" in text
    assert "Stage 2 (current): return to the room `living_room`" in text
    single = Mission.from_task(parse_query("Go to the bedroom", scene))
    assert single.is_single and plan_mission("Go to the bedroom", scene, "living_room") == single


# -- the parser: the suites' expected plans, refusals, paraphrases -----------------------------------------------
@pytest.mark.parametrize("name", ["missions", "missions-houses"])
def test_the_parser_gets_every_expected_plan_and_refusal_of_the_suites(name):
    raw = yaml.safe_load((resources.files("vlnpilot.bench") / "suites" / f"{name}.yaml").read_text())
    suite = load_suite(name)  # the loader fails on any plan or refusal the parser does not produce exactly
    planned = [r for r in raw["rows"] if "plan" in r]
    refused = [r for r in raw["rows"] if "refuse" in r]
    assert len(planned) + len(refused) == len(raw["rows"])
    assert len(suite.rows) == len(planned) and len(suite.refused) == len(refused) > 0
    for row in raw["rows"]:
        scene = load_scene(row.get("scene", raw["scene"]))
        start = scene.spawn(row["spawn"]).room
        if "plan" in row:
            assert plan_mission(row["query"], scene, start).plan() == row["plan"], row["id"]
        else:
            with pytest.raises(PlanError, match=row["refuse"]):
                plan_mission(row["query"], scene, start)


def test_the_suites_hold_sixty_instructions_of_every_kind():
    root = resources.files("vlnpilot.bench") / "suites"
    rows = [r for name in ("missions", "missions-houses")
            for r in yaml.safe_load((root / f"{name}.yaml").read_text())["rows"]]
    plans = [r["plan"] for r in rows if "plan" in r]
    assert len(rows) >= 60
    assert any(len(p["stages"]) == 2 for p in plans) and any(len(p["stages"]) == 3 for p in plans)
    assert any("return" in s for p in plans for s in p["stages"]) and any("avoid" in p for p in plans)
    assert any("not" in p for p in plans) and sum("refuse" in r for r in rows) >= 10


@pytest.mark.parametrize(("query", "why"), [
    ("Go to the bedroom and dance", "could not read 'dance'"),
    ("Go to the bedroom or the bathroom", "names 2 rooms"),
    ("Go to the bedroom, then find the piano", "no known object"),
    ("Find the piano in the bedroom", "unknown object"),
    ("Don't go to the bathroom", "no goal"),
    ("Go to the bathroom without going through the bedroom", "cannot be reached from living_room without entering"),
    ("Avoid the sink, go to the bedroom", "only rooms can be avoided"),
])
def test_the_parser_refuses_naming_what_it_could_not_read_and_what_the_map_offers(query, why):
    with pytest.raises(PlanError, match=why) as err:
        plan_mission(query, load_scene("cabin"), "living_room")
    assert "\n" not in str(err.value)


def test_paraphrases_plan_alike_and_aliases_still_read():
    scene = load_scene("cabin")
    plans = {str(plan_mission(q, scene, "living_room").plan()) for q in (
        "Go to the bathroom, then come back", "Fly to the restroom and then return to where you started",
        "Visit the washroom. After that, go back to the start.", "go to the bath room; then come back")}
    assert len(plans) == 1
    assert parse_mission("Find the fridge", scene).plan() == {"stages": [{"object": "refrigerator"}]}


# -- the stage metrics -------------------------------------------------------------------------------------------
def test_isr_csr_and_cgt_after_lhpr_vln():
    results = [
        {"outcome": "success", "stages": 2, "stages_reached": 2, "stage_paths_m": [1.0, 3.0]},
        {"outcome": "false_success", "stages": 3, "stages_reached": 1, "stage_paths_m": [2.0, 1.0, 1.0]},
        {"outcome": "collision"},  # recorded before missions: one stage, not reached
    ]
    assert StageRate("isr").over(results) == pytest.approx(3 / 5)  # 3 judged successes of 5 stages flown
    assert StageRate("csr").over(results) == pytest.approx(3 / 6)  # of all 6 stages
    # path-weighted: 1 + 3 + 2 of 1 + 3 + 2 + 1 + 1 + (the old one's shortest path, 0 here)
    assert StageRate("cgt").over(results) == pytest.approx(6 / 8)


def test_the_episode_report_marks_the_stage_boundaries(sim, tmp_path):
    from vlnpilot.episode.run import run_recorded_episode
    from vlnpilot.report.html import write_episode_report

    mission = plan_mission("Go to the bedroom and then find the sink in the bathroom", sim.scene, "living_room")
    result = run_recorded_episode(sim, OraclePilot(), mission, EpisodeConfig(), run_dir=tmp_path / "run",
                                  spawn="living_room", pilot_spec="oracle")
    page = write_episode_report(tmp_path / "run").read_text()
    assert result.success and page.count('<tr class="stage-start">') == 2
    assert "<strong>Stage 2</strong>: find sink in bathroom" in page


@pytest.mark.parametrize("name", ["missions", "missions-houses"])
def test_a_mission_suite_reads_back_from_its_manifest(name):
    """A bench writes its suite into bench.json and its tables read it back: a mission row must come back as the
    same mission (by its plan), not as a one-goal query that no longer parses to its goal."""
    from vlnpilot.bench.suite import load_suite, suite_from_dict

    suite = load_suite(name)
    again = suite_from_dict(suite.to_dict(), source="bench.json")
    assert [r.canonical() for r in again.rows] == [r.canonical() for r in suite.rows]
    assert any(r.mission is not None for r in again.rows)


def test_a_row_planned_by_a_pilot_flies_its_plan_as_written_and_reads_back():
    """A recorded trial's row carries the plan its pilot made (`planned_by`): the suite flies that plan, checked
    against the map, not the parser's reading ("come back to the living room": the pilot's return, the parser's
    room); the suite writes it back the same way."""
    from vlnpilot.bench.suite import SuiteError, suite_from_dict

    row = {"id": "back", "spawn": "living_room", "query": "Go to the bathroom, then come back to the living room",
           "plan": {"stages": [{"room": "bathroom"}, {"return": "living_room"}]}, "planned_by": "stdin"}
    suite = suite_from_dict({"name": "t", "scene": "cabin", "rows": [row]}, source="test")
    mission = Mission.from_dict(suite.rows[0].mission)
    assert [(s.kind, s.room) for s in mission.stages] == [("room", "bathroom"), ("return", "living_room")]
    assert mission.source == "stdin"
    assert suite_from_dict(suite.to_dict(), source="again").to_dict()["rows"][0]["planned_by"] == "stdin"
    with pytest.raises(SuiteError, match="the plan says"):  # without planned_by the parser's reading must agree
        suite_from_dict({"name": "t", "scene": "cabin", "rows": [{k: v for k, v in row.items() if k != "planned_by"}]},
                        source="test")
    bad = {**row, "plan": {"stages": [{"room": "attic"}]}}
    with pytest.raises(SuiteError, match="attic"):
        suite_from_dict({"name": "t", "scene": "cabin", "rows": [bad]}, source="test")


def test_a_plan_reads_back_as_the_mission_it_was_written_from(sim):
    mission = plan_mission("Don't go into the bathroom; find the mirror, then come back", sim.scene, "living_room")
    again = Mission.from_plan(mission.query, mission.plan(), sim.scene, "parser")
    assert again.plan() == mission.plan() and again.stages[0].room == "bedroom"
    with pytest.raises(PlanError, match="stage"):
        Mission.from_plan("q", {"stages": [{"fly": "up"}]}, sim.scene, "stdin")
