"""The `stdin` pilot (a person or another program flies over text streams) and the `replay` pilot."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
from PIL import Image
from typer.testing import CliRunner

from vlnpilot import cli
from vlnpilot.core.decision import Decision, DecisionError, PilotInput, parse_decision
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import EpisodeResult
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.pilots.replay import ReplayPilot
from vlnpilot.pilots.stdin import StdinPilot
from vlnpilot.prompting.render import system_prompt
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

VOLATILE = {"frames", "wall_s"}  # fields that may differ between a run and its replay (wall_s: timing)
RESULT_VOLATILE = {"wall_time_s"}


@pytest.fixture(scope="module")
def geo() -> Simulator:
    with Simulator("cabin", SimConfig(render=False)) as sim:
        yield sim


def fly(sim: Simulator, pilot: Any, spawn: str, query: str, run_dir: Path | None = None,
        max_steps: int = 50) -> tuple[EpisodeResult, list[dict[str, Any]]]:
    records: list[dict[str, Any]] = []
    recorder = Recorder(run_dir) if run_dir is not None else None
    result = run_episode(sim, pilot, parse_query(query, sim.scene), EpisodeConfig(max_steps=max_steps), spawn=spawn,
                         recorder=recorder, on_step=records.append)
    return result, records


def strip(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in records]


def same_result(a: EpisodeResult, b: EpisodeResult) -> bool:
    da, db = a.to_dict(), b.to_dict()
    return all(da[k] == db[k] for k in da if k not in RESULT_VOLATILE)


# -- replay --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("spawn", "query"), [("living_room", "Go to the bathroom"),
                                              ("bedroom", "Find the mirror in the bedroom")])
def test_replay_of_an_oracle_run_flies_the_identical_episode(geo: Simulator, tmp_path: Path, spawn: str,
                                                             query: str) -> None:
    recorded, rec_steps = fly(geo, OraclePilot(), spawn, query, tmp_path / "rec")
    assert recorded.outcome == "success"
    pilot = make_pilot(f"replay:{tmp_path / 'rec'}")
    assert isinstance(pilot, ReplayPilot) and not getattr(pilot, "privileged", False)
    replayed, rep_steps = fly(geo, pilot, spawn, query, tmp_path / "rep")
    assert strip(rep_steps) == strip(rec_steps)
    assert same_result(replayed, recorded)
    # and the replay's own recording reads back the same
    assert strip(load_run(tmp_path / "rep")[1]) == strip(load_run(tmp_path / "rec")[1])


class Script:
    """A model-like pilot: answers from a list of raw replies (parsed like a model's) or exceptions."""

    name, model = "script", "script-1"

    def __init__(self, items: list[str | BaseException]):
        self.items = list(items)

    def decide(self, pilot_input: PilotInput) -> Decision:
        item = self.items.pop(0)
        if isinstance(item, BaseException):
            raise item
        return parse_decision(item)


def reply(movement: str, state: str, room: str = "bedroom") -> str:
    return "Here is my answer: " + json.dumps({"room": room, "movement": movement, "state": state,
                                               "description": "scripted", "door_position": "not_visible"})


def test_replay_reproduces_rejections_reasks_and_a_fatal_end(geo: Simulator, tmp_path: Path) -> None:
    items: list[str | BaseException] = [
        reply("A3", "Recognize Room"),  # step 1: not allowed (kept with its raw text), then valid
        reply("C1", "Recognize Room"),
        DecisionError("no JSON object found"),  # step 2: malformed, then valid
        reply("b1", "search open door"),
        PilotError("503 from the provider", reason="unavailable"),  # step 3: transient: hover, no re-ask
        reply("Z9", "Land"), reply("Z9", "Land"), reply("Z9", "Land"),  # step 4: three invalid -> hover
        PilotError("invalid API key", fatal=True, reason="auth"),  # step 5: fatal
    ]
    recorded, rec_steps = fly(geo, Script(items), "bedroom", "Go to the bathroom", tmp_path / "rec")
    assert recorded.outcome == "pilot_error" and recorded.steps == 5 and recorded.invalid_decisions == 2
    assert [len(r["failures"]) for r in rec_steps] == [1, 1, 1, 3, 1]
    replayed, rep_steps = fly(geo, ReplayPilot(run_dir=tmp_path / "rec"), "bedroom", "Go to the bathroom")
    assert strip(rep_steps) == strip(rec_steps)
    assert same_result(replayed, recorded)
    assert replayed.reason == "auth: invalid API key"


def test_replay_ends_with_a_fatal_error_when_the_recording_runs_out(geo: Simulator, tmp_path: Path) -> None:
    fly(geo, OraclePilot(), "living_room", "Go to the bathroom", tmp_path / "short", max_steps=5)
    result, steps = fly(geo, make_pilot("replay", run_dir=tmp_path / "short"), "living_room", "Go to the bathroom")
    assert result.outcome == "pilot_error" and result.steps == 6
    assert "recording exhausted at step 6" in result.reason
    assert [s["executed"] for s in steps[:5]] == [s["executed"] for s in load_run(tmp_path / "short")[1]]


def test_replay_of_an_interrupted_run(geo: Simulator, tmp_path: Path) -> None:
    fly(geo, OraclePilot(), "bedroom", "Go to the bathroom", tmp_path / "r", max_steps=4)
    episode = tmp_path / "r" / "episode.jsonl"
    episode.write_text(episode.read_text() + '{"step": 5, "sta')  # killed mid-write
    pilot = ReplayPilot(run_dir=tmp_path / "r")
    assert pilot.last_step == 4


def test_strict_replay_detects_divergence(geo: Simulator, tmp_path: Path) -> None:
    fly(geo, OraclePilot(), "bedroom", "Go to the bathroom", tmp_path / "r", max_steps=3)
    pin = PilotInput(image=None, query="Go to the bathroom", topological_map={}, state=State.REACH_OBJECT,
                     previous_movement=None, step=1)
    assert ReplayPilot(run_dir=tmp_path / "r").decide(pin).movement  # lenient by default
    with pytest.raises(PilotError, match="diverged at step 1") as info:
        ReplayPilot(run_dir=tmp_path / "r", strict=True).decide(pin)
    assert info.value.fatal


def test_replay_needs_a_run_directory(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="replay:RUN_DIR"):
        make_pilot("replay")
    with pytest.raises(ConfigError, match="summary.json is missing"):
        make_pilot(f"replay:{tmp_path}")


# -- stdin ---------------------------------------------------------------------------------------------------
def oracle_lines(sim: Simulator, spawn: str, query: str) -> tuple[EpisodeResult, list[dict[str, Any]], list[str]]:
    result, records = fly(sim, OraclePilot(), spawn, query)
    return result, records, [json.dumps(r["decision"]) + "\n" for r in records]


def test_stdin_pilot_flies_an_episode_from_a_scripted_stream(geo: Simulator, tmp_path: Path) -> None:
    expected, expected_steps, lines = oracle_lines(geo, "bathroom", "Find the sink in the bathroom")
    # a person's typing: a blank line, a malformed answer (re-asked), then the oracle's answers as JSON lines
    stream = io.StringIO("\n" + "well, go forward I guess\n" + "".join(lines))
    out = io.StringIO()
    pilot = make_pilot("stdin", input=stream, output=out, image_dir=tmp_path / "img")
    result, steps = fly(geo, pilot, "bathroom", "Find the sink in the bathroom")
    assert result.outcome == "success" and result.steps == expected.steps
    assert [s["executed"] for s in steps] == [s["executed"] for s in expected_steps]
    assert steps[0]["failures"][0]["reason"].startswith("malformed answer")
    assert stream.read() == ""  # every line consumed

    text = out.getvalue()
    assert text.count("SYSTEM PROMPT") == 1 and system_prompt().strip() in text
    assert text.count("## User query\nFind the sink in the bathroom") == result.steps + 1  # + the re-ask
    assert "## Controller feedback" in text and "re-ask 1" in text
    images = [line.split("image: ", 1)[1] for line in text.splitlines() if line.startswith("image: ")]
    assert len(images) == result.steps + 1 and len(set(images)) == len(images)
    for path in images:
        with Image.open(path) as img:
            assert img.format == "JPEG"
    assert all(s["model"] == "stdin" for s in steps)


def test_stdin_eof_ends_the_episode(geo: Simulator, tmp_path: Path) -> None:
    _, _, lines = oracle_lines(geo, "living_room", "Go to the bathroom")
    pilot = StdinPilot(input=io.StringIO("".join(lines[:3])), output=io.StringIO(), image_dir=tmp_path)
    result, steps = fly(geo, pilot, "living_room", "Go to the bathroom")
    assert result.outcome == "pilot_error" and result.steps == 4
    assert "stdin closed" in result.reason and result.pilot_calls == 4


def test_stdin_prints_the_system_prompt_once_per_episode(geo: Simulator, tmp_path: Path) -> None:
    line = json.dumps({"room": "bedroom", "movement": "C1", "state": "Stay on Room", "description": "",
                       "door_position": "not_visible"}) + "\n"
    out = io.StringIO()
    pilot = StdinPilot(input=io.StringIO(line * 2), output=out, image_dir=tmp_path)
    for _ in range(2):
        assert fly(geo, pilot, "bedroom", "Go to the bedroom")[0].outcome == "success"
    assert out.getvalue().count("SYSTEM PROMPT") == 2
    assert len(list(tmp_path.glob("*.jpg"))) == 2  # one image per step, never overwritten across episodes


def test_stdin_writes_the_front_image(tmp_path: Path) -> None:
    import numpy as np

    image = np.full((48, 64, 3), 200, np.uint8)
    pin = PilotInput(image=image, query="Go to the bedroom", topological_map={"nodes": ["bedroom"]},
                     state=State.RECOGNIZE_ROOM, previous_movement=None, step=1)
    out = io.StringIO()
    answer = '{"room": "bedroom", "movement": "C1", "state": "Stay on Room"}\n'
    decision = StdinPilot(input=io.StringIO(answer), output=out, image_dir=tmp_path).decide(pin)
    assert (decision.movement, decision.state, decision.model) == ("C1", "Stay on Room", "stdin")
    assert decision.raw_text == answer.strip()
    path = out.getvalue().split("image: ", 1)[1].splitlines()[0]
    with Image.open(path) as img:
        assert img.size == (64, 48)


def test_stdin_rejects_unknown_options(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="image_dir"):
        make_pilot("stdin", colour=True)


def test_stdin_pilot_through_the_cli(tmp_path: Path) -> None:
    answer = json.dumps({"room": "bedroom", "movement": "C1", "state": "Stay on Room",
                         "description": "A bed and a wardrobe.", "door_position": "not_visible"})
    result = CliRunner().invoke(cli.app, ["run", "Go to the bedroom", "--spawn", "bedroom", "--pilot", "stdin",
                                          "--out", str(tmp_path / "r")], input=answer + "\n" + answer + "\n")
    assert result.exit_code == 0, result.output
    assert "success in 1 steps" in result.stdout
    assert "Confirmation: you chose the final state 'Stay on Room'" in result.stderr  # the default context: plus
    assert "image: " in result.stderr and "## Current FSM state\nRecognize Room" in result.stderr


def test_cli_progress_survives_brackets_in_the_description(tmp_path: Path) -> None:
    answer = json.dumps({"room": "bedroom", "movement": "C1", "state": "Stay on Room",
                         "description": "a [/] sign and [bold] text", "door_position": "not_visible"})
    result = CliRunner().invoke(cli.app, ["run", "Go to the bedroom", "--spawn", "bedroom", "--pilot", "stdin",
                                          "--context", "paper", "--out", str(tmp_path / "r")], input=answer + "\n")
    assert result.exit_code == 0 and "a [/] sign" in result.stdout


def test_replay_flies_the_same_recording_twice(geo: Simulator, tmp_path: Path) -> None:
    recorded, rec_steps = fly(geo, OraclePilot(), "bedroom", "Go to the bedroom", tmp_path / "rec")
    assert recorded.steps == 1
    pilot = ReplayPilot(run_dir=tmp_path / "rec")
    for _ in range(2):  # a new episode at step 1 is not a re-ask of the last one
        replayed, steps = fly(geo, pilot, "bedroom", "Go to the bedroom")
        assert same_result(replayed, recorded) and strip(steps) == strip(rec_steps)


TRIALS = Path(__file__).resolve().parents[1] / "trials"


def test_run_replays_a_trial_with_the_settings_it_was_flown_with(tmp_path: Path) -> None:
    """`vln-pilot run --pilot replay:TRIAL` with no --context flies the trial's context (a paper-context trial under
    the plus default would be refused); an explicit option still wins, and is refused for naming another setting."""
    trial = TRIALS / "baseline" / "living-bedroom"
    args = ["run", "Go to the bedroom", "--scene", "cabin-v1", "--spawn", "living_room", "--pilot",
            f"replay:{trial}", "--no-video", "-q"]
    result = CliRunner().invoke(cli.app, [*args, "--out", str(tmp_path / "a")])
    assert result.exit_code == 0, result.output
    summary, _ = load_run(tmp_path / "a")
    assert summary["config"]["context"]["preset"] == "paper" and summary["result"]["outcome"] == "success"
    refused = CliRunner().invoke(cli.app, [*args, "--out", str(tmp_path / "b"), "--context", "plus"])
    assert isinstance(refused.exception, ConfigError) and "--context paper" in str(refused.exception)
