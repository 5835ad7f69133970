"""Planning before take-off through the official OpenAI SDK against the fake server (tests/fakes): a valid
plan flown end to end, a plan naming a room the map does not have (rejected and re-asked, then flown), and a
refusal (one line, exit code 2, nothing flown or recorded)."""

from __future__ import annotations

import json
import re
import sys

import numpy as np
import pytest

from cli_support import run_main
from fakes import FakeOpenAI
from vlnpilot import cli
from vlnpilot.core.decision import PilotInput
from vlnpilot.core.fsm import parse_state
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.pilots.planning import plan_instruction

QUERY = "Go to the bathroom, then come back to where you started"
VALID = {"stages": [{"kind": "room", "room": "bathroom", "target": None},
                    {"kind": "return", "room": "living_room", "target": None}], "avoid": [], "refusal": None}
ATTIC = {"stages": [{"kind": "room", "room": "attic", "target": None}], "avoid": [], "refusal": None}
REFUSAL = {"stages": [], "avoid": [], "refusal": "Which room: the bedroom or the bathroom?"}


def _is_plan(request) -> bool:
    return "stages" in ((request.schema or {}).get("properties") or {})


class ModelInTheLoop:
    """The fake provider's answers: the scripted plans in turn, then the oracle's decisions for the stage the
    prompt's plan calls current, so that the mission is flown through the SDK as a model would fly it."""

    def __init__(self, plans: list[dict], sim=None):
        self.plans, self.mission = list(plans), None
        self.oracle = OraclePilot()
        if sim is not None:
            self.oracle.attach(sim.ground_truth())

    def __call__(self, request):
        if _is_plan(request):
            return json.dumps(self.plans.pop(0))
        current = re.search(r"Stage (\d+) \(current\)", request.text)
        pin = PilotInput(image=np.zeros((2, 2, 3), np.uint8), query=QUERY, topological_map={},
                         state=parse_state(request.current_state), previous_movement=None, step=2,
                         mission=self.mission, stage=int(current.group(1)) - 1)
        return self.oracle.decide(pin).core()


def _plan_and_fly(geo_sim, tmp_path, plans):
    geo_sim.reset("living_room")
    model = ModelInTheLoop(plans, geo_sim)
    lines: list[str] = []
    with FakeOpenAI(oracle=model) as fake:
        pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-test-not-a-key")
        mission, planning = plan_instruction(QUERY, geo_sim.scene, "living_room", pilot, say=lines.append)
        model.mission = mission.to_dict()
        result = run_episode(geo_sim, pilot, mission, EpisodeConfig(), spawn="living_room",
                             recorder=Recorder(tmp_path / "run"), pilot_spec="openai:gpt-4.1")
        requests = list(fake.requests)
    return mission, planning, result, requests, lines


def test_a_valid_plan_is_flown_end_to_end(geo_sim, tmp_path):
    mission, planning, result, requests, _ = _plan_and_fly(geo_sim, tmp_path, [VALID])
    plan = requests[0]
    assert _is_plan(plan) and not plan.images  # one planning call first, text only
    stage = plan.schema["properties"]["stages"]["items"]["properties"]
    assert stage["room"]["enum"] == [r.id for r in geo_sim.scene.rooms] + [None]
    assert "sink" in stage["target"]["enum"] and QUERY in plan.text and '"edges"' in plan.text
    assert [_is_plan(r) for r in requests].count(True) == 1 and len(planning.calls) == 1
    assert mission.source == "openai" and mission.plan() == {"stages": [{"room": "bathroom"},
                                                                        {"return": "living_room"}]}
    assert result.outcome == "success" and result.stages_reached == 2 and result.final_room == "living_room"
    assert "## Mission plan" in requests[1].text and "Stage 1 (current)" in requests[1].text
    assert any("Stage 2 (current)" in r.text for r in requests[2:])
    summary, steps = load_run(tmp_path / "run")
    assert summary["mission"]["source"] == "openai" and len(summary["mission"]["planning"]) == 1
    assert [a["status"] for a in summary["mission"]["planning"][0]["attempts"]] == [200]  # its HTTP attempts
    assert {s["stage"] for s in steps} == {1, 2}


def test_a_plan_naming_a_room_that_does_not_exist_is_rejected_and_asked_again(geo_sim, tmp_path):
    mission, planning, result, requests, lines = _plan_and_fly(geo_sim, tmp_path, [ATTIC, VALID])
    plans = [r for r in requests if _is_plan(r)]
    assert len(plans) == 2 and "Your previous plan was rejected" in plans[1].text and "'attic'" in plans[1].text
    assert lines and "attic" in lines[0]
    assert [bool(c.get("error")) for c in planning.calls] == [True, False]
    assert result.outcome == "success" and result.stages_reached == 2


def test_a_refusal_is_refused_before_take_off_with_one_line_and_exit_code_2(monkeypatch, capsys, tmp_path):
    with FakeOpenAI(oracle=ModelInTheLoop([REFUSAL])) as fake:
        out = tmp_path / "run"
        monkeypatch.setattr(sys, "argv", ["vln-pilot", "run", QUERY, "--spawn", "living_room", "--pilot", "openai",
                                          "--base-url", fake.base_url, "--out", str(out), "-q", "--no-video"])
        monkeypatch.setenv("OPENAI_API_KEY", "sk-test-not-a-key")
        with pytest.raises(SystemExit) as exit_info:
            cli.main()
        code, err = exit_info.value.code, capsys.readouterr().err
        requests = list(fake.requests)
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    line = " ".join(err.split())
    assert "the pilot refused" in line and "Which room: the bedroom or the bathroom?" in line
    assert "the map offers rooms: living_room, bedroom, bathroom" in line
    assert [_is_plan(r) for r in requests] == [True]  # nothing flown
    assert not out.exists()  # nothing recorded


def test_vln_pilot_plan_prints_the_plan_and_flies_nothing(monkeypatch, capsys):
    code, out, _ = run_main(monkeypatch, capsys, "plan", "Go to the bedroom and then find the sink in the bathroom")
    assert code == 0 and "1. go to bedroom" in out and "2. find sink in bathroom" in out
    code, _, err = run_main(monkeypatch, capsys, "plan", "Go to the bedroom or the bathroom")
    assert code == 2 and "names 2 rooms" in err


def test_a_person_plans_through_stdin_with_one_json_line():
    import io

    from vlnpilot.scene import load_scene

    sink = {"kind": "object", "room": "bathroom", "target": "sink"}
    lines = [json.dumps({"stages": [sink], "avoid": ["bedroom"], "refusal": None}),  # unreachable: re-asked
             json.dumps({"stages": [sink], "avoid": [], "refusal": None})]
    out = io.StringIO()
    pilot = make_pilot("stdin", input=io.StringIO("\n".join(lines) + "\n"), output=out)
    mission, planning = plan_instruction("Find the sink, quickly please", load_scene("cabin"), "living_room", pilot)
    shown = out.getvalue()
    assert "PLAN (before take-off)" in shown and "JSON schema of the answer" in shown and '"enum"' in shown
    assert "answer with ONE line of JSON: stages, avoid, refusal" in shown
    assert "cannot be reached from living_room without entering bedroom" in planning.calls[0]["error"]
    assert "Your previous plan was rejected" in shown and mission.plan() == {"stages": [{"object": "sink"}]}


def test_an_agent_plans_through_files_as_call_001(tmp_path):
    from vlnpilot.scene import load_scene

    pilot = make_pilot(f"files:{tmp_path / 'ep'}", clock=lambda: 0.0, sleep=lambda s: None)
    (tmp_path / "ep" / "001.answer.json").write_text(json.dumps(VALID))
    mission, planning = plan_instruction(QUERY, load_scene("cabin"), "living_room", pilot, planner="pilot")
    prompt = (tmp_path / "ep" / "001.prompt.md").read_text()
    assert prompt.startswith("# Plan before take-off") and "`001.answer.json`" in prompt and QUERY in prompt
    assert not (tmp_path / "ep" / "001.png").exists()
    assert mission.source == "files" and mission.plan()["stages"][1] == {"return": "living_room"}
