"""A whole episode flown by the `openai` pilot through the official SDK against a fake server on 127.0.0.1.

The fake server answers like the oracle (it runs an OraclePilot on the same simulator's ground truth), so
the episode must succeed exactly as the oracle does: proof that prompt, schema, SDK call, parsing,
validation and execution all fit together.
"""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from fakes import FakeOpenAI
from vlnpilot.cli import app
from vlnpilot.core.decision import PilotInput
from vlnpilot.core.fsm import parse_state
from vlnpilot.core.rundir import Recorder, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.tasks.task import parse_query

QUERY = "Go to the bedroom"


def test_openai_pilot_flies_a_whole_episode(geo_sim, tmp_path):
    oracle = OraclePilot()
    oracle.attach(geo_sim.ground_truth())

    def answer(request):
        state = parse_state(request.current_state)
        pin = PilotInput(image=np.zeros((2, 2, 3), np.uint8), query=QUERY, topological_map={}, state=state,
                         previous_movement=None)
        return oracle.decide(pin).core()

    with FakeOpenAI(oracle=answer) as fake:
        pilot = make_pilot("openai:gpt-4.1", base_url=fake.base_url, api_key="sk-test-not-a-key")
        task = parse_query(QUERY, geo_sim.scene)
        result = run_episode(geo_sim, pilot, task, EpisodeConfig(max_steps=50), spawn="living_room",
                             recorder=Recorder(tmp_path / "run"), pilot_spec="openai:gpt-4.1")
        requests = list(fake.requests)

    assert result.outcome == "success", result.reason
    assert result.collisions == 0 and result.invalid_decisions == 0
    assert len(requests) == result.steps == result.pilot_calls
    first = requests[0]
    assert first.model == "gpt-4.1"
    assert first.images, "the front image must travel with every request"
    assert first.schema is not None and "Search Open Door" in json.dumps(first.schema)
    assert result.input_tokens > 0 and result.output_tokens > 0
    summary, steps = load_run(tmp_path / "run")
    assert summary["result"]["outcome"] == "success"
    assert all(s["raw_text"] for s in steps), "the raw model text is recorded for every step"
    # the fake's prompt cache serves what a step shares with the step before (issue 27): each step records it
    assert steps[0]["usage"]["cached_tokens"] == 0 and "cache_write_tokens" in steps[0]["usage"]
    assert sum(s["usage"]["cached_tokens"] for s in steps) == result.cached_tokens > 0
    assert "sk-test-not-a-key" not in (tmp_path / "run" / "episode.jsonl").read_text()


def test_cli_run_with_openai_base_url(tmp_path, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    monkeypatch.setenv("OPENAI_API_KEY", "sk-test-cli")
    reply = {"room": "bedroom", "movement": "B1", "state": "Stay on Room",
             "description": "A bed with two pillows: this is the bedroom.", "door_position": "not_visible"}
    with FakeOpenAI(oracle=lambda request: reply) as fake:
        out = tmp_path / "cli-run"
        result = CliRunner().invoke(app, ["run", QUERY, "--spawn", "bedroom", "--pilot", "openai",
                                          "--base-url", fake.base_url, "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert "success" in result.output
    summary, steps = load_run(out)
    assert summary["pilot"] == "openai" and summary["model"] == "gpt-4.1"
    assert len(steps) == 1 and steps[0]["executed"] == "B1"
    assert "sk-test-cli" not in (out / "summary.json").read_text() + (out / "episode.jsonl").read_text()


def test_step_deadline_bounds_a_hanging_provider(geo_sim):
    """A provider that hangs longer than the step deadline: the step ends at the deadline, the drone hovers,
    the failure is recorded, and the next step flies normally."""
    reply = {"room": "bedroom", "movement": "B1", "state": "Stay on Room", "description": "bedroom",
             "door_position": "not_visible"}
    with FakeOpenAI(oracle=lambda request: reply) as fake:
        fake.push("hang", seconds=20)
        pilot = make_pilot("openai", base_url=fake.base_url, api_key="sk-test", timeout=30, max_retries=0)
        records = []
        result = run_episode(geo_sim, pilot, parse_query(QUERY, geo_sim.scene),
                             EpisodeConfig(max_steps=5, step_deadline_s=1.5), spawn="bedroom",
                             on_step=records.append)
    assert result.outcome == "success" and result.steps == 2
    assert result.invalid_decisions == 1
    # the provider hangs 20 s under a 30 s SDK timeout: only the 1.5 s step deadline can end step 1 like this
    assert records[0]["executed"] == "E" and records[0]["failures"][0]["kind"] == "step_deadline"
