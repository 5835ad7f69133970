"""The `files` pilot: prompts and images in a directory, answers as files, flown end to end by a scripted answerer."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from vlnpilot import cli
from vlnpilot.core.decision import DecisionError, PilotInput
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import State
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import PilotError, make_pilot
from vlnpilot.pilots.files import FilesPilot
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.prompting.context import Travel, in_state_text
from vlnpilot.prompting.render import build_prompt, system_prompt
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

REPO = Path(__file__).resolve().parents[1]
QUERY, SPAWN = "Find the sink in the bathroom", "bathroom"
INVALID = {"room": "bathroom", "movement": "Z9", "state": "Recognize Room", "description": "?",
           "door_position": "left"}
ANSWER = {"room": "bedroom", "movement": "C2", "state": "Search Open Door", "description": "a bed",
          "door_position": "not_visible"}


class FakeTime:
    """An injected clock: `sleep` advances it and runs the hooks due at the new time (no real waiting)."""

    def __init__(self, hooks: dict[float, object] | None = None):
        self.now, self.sleeps = 0.0, 0
        self.hooks = dict(hooks or {})

    def clock(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds
        self.sleeps += 1
        for due in sorted(t for t in self.hooks if t <= self.now):
            self.hooks.pop(due)()


def pin(step: int = 1, feedback: tuple[str, ...] = (), state: State = State.RECOGNIZE_ROOM) -> PilotInput:
    image = np.full((48, 64, 3), 90, np.uint8)
    return PilotInput(image=image, query="Go to the bedroom", topological_map={"nodes": ["bedroom"]}, state=state,
                      previous_movement=None, step=step, feedback=feedback)


def fake_pilot(directory: Path, fake: FakeTime, **options: object) -> FilesPilot:
    return FilesPilot(directory=directory, poll_s=1.0, grace_s=3.0, clock=fake.clock, sleep=fake.sleep, **options)


# -- a whole episode, answered through files by the oracle -------------------------------------------------------
class OracleAnswerer(threading.Thread):
    """Waits for each NNN.prompt.md and writes NNN.answer.json: first an invalid and a malformed answer, then the
    oracle's (attached to the same simulator's ground truth, reading the state and step from the prompt)."""

    def __init__(self, directory: Path, sim: Simulator, topo: dict):
        super().__init__(daemon=True)
        self.directory, self.topo, self.stop = directory, topo, threading.Event()
        self.oracle = OraclePilot()
        self.oracle.attach(sim.ground_truth())
        self.scripted = {1: json.dumps(INVALID), 2: "I think we should go left"}

    def run(self) -> None:
        call = 1
        while not self.stop.is_set():
            prompt = self.directory / f"{call:03d}.prompt.md"
            if not prompt.exists():
                if (self.directory / "done.txt").exists():
                    return
                self.stop.wait(0.002)
                continue
            text = prompt.read_text()
            answer = self.scripted.get(call) or self.oracle_answer(text)
            tmp = self.directory / f".{call:03d}.answer.json.tmp"
            tmp.write_text(answer)
            os.replace(tmp, self.directory / f"{call:03d}.answer.json")
            call += 1

    def oracle_answer(self, prompt: str) -> str:
        state = State(re.search(r"## Current FSM state\n(.+)\n", prompt).group(1))
        step = int(re.search(r"## Step\n(\d+)\n", prompt).group(1))
        pilot_input = PilotInput(image=np.zeros((1, 1, 3), np.uint8), query=QUERY, topological_map=self.topo,
                                 state=state, previous_movement=None, step=step)
        return json.dumps(self.oracle.decide(pilot_input).core())


def test_a_whole_episode_flies_through_the_files_answered_by_a_scripted_oracle(sim: Simulator,
                                                                               tmp_path: Path) -> None:
    directory = tmp_path / "new" / "ep1"  # a missing DIR is created
    first_image = sim.reset(SPAWN).front_rgb.copy()
    pilot = make_pilot(f"files:{directory}", poll_s=0.002, grace_s=0.05, timeout_s=120)
    answerer = OracleAnswerer(directory, sim, sim.scene.topological_map())
    answerer.start()
    records: list[dict] = []
    try:
        result = run_episode(sim, pilot, parse_query(QUERY, sim.scene), EpisodeConfig(max_steps=50), spawn=SPAWN,
                             on_step=records.append)
    finally:
        answerer.stop.set()
        answerer.join(5)
    assert result.outcome == "success", result.reason
    calls = [f"{n:03d}" for n in range(1, result.pilot_calls + 1)]
    for call in calls:  # every call left its image, prompt and answer, and nothing else was numbered
        for suffix in (".png", ".prompt.md", ".answer.json"):
            assert (directory / f"{call}{suffix}").is_file(), f"{call}{suffix}"
    assert sorted(p.name for p in directory.glob("*.prompt.md")) == [f"{c}.prompt.md" for c in calls]
    assert (directory / "latest.txt").read_text().strip() == calls[-1]
    assert (directory / "done.txt").read_text() == f"success in {result.steps} steps: {result.reason}\n"
    assert (directory / "system.md").read_text() == system_prompt()
    assert np.array_equal(np.asarray(Image.open(directory / "001.png")), first_image)

    prompts = [(directory / f"{c}.prompt.md").read_text() for c in calls]
    first_input = PilotInput(image=first_image, query=QUERY, topological_map=sim.scene.topological_map(),
                             state=State.RECOGNIZE_ROOM, previous_movement=None, step=1,
                             in_state=in_state_text((), Travel()))
    assert prompts[0].startswith(build_prompt(first_input).user_text().rstrip())
    assert [("first prompt of the episode" in p) for p in prompts] == [True] + [False] * (len(prompts) - 1)
    assert all("`system.md`" in p for p in prompts)  # a fresh pilot per call finds the system prompt
    assert all(f"`{c}.answer.json`" in p and f"`{c}.png`" in p for c, p in zip(calls, prompts, strict=True))
    # the invalid answer (001) and the malformed one (002) were re-asked within step 1, with the reasons
    assert [f["kind"] for f in records[0]["failures"]] == ["invalid_decision", "malformed"]
    assert "Your previous answer was rejected: movement 'Z9' is not a movement command" in prompts[1]
    assert "Your previous answer was rejected: malformed answer: no JSON object" in prompts[2]
    assert records[0]["decision"] is not None and result.invalid_decisions == 0


# -- waiting: partial answers, grace, timeout (injected clock) -------------------------------------------------
def test_a_partially_written_answer_is_read_once_complete(tmp_path: Path) -> None:
    answer = tmp_path / "001.answer.json"
    fake = FakeTime({2.0: lambda: answer.write_text('{"room": "bedroom", "movem'),
                     4.0: lambda: answer.write_text(json.dumps(ANSWER))})
    decision = fake_pilot(tmp_path, fake).decide(pin())
    assert decision.core() == ANSWER
    assert decision.usage.latency_s == 4.0 and decision.model == "files"


def test_an_answer_that_stays_unparsable_past_the_grace_period_is_rejected(tmp_path: Path) -> None:
    fake = FakeTime({2.0: lambda: (tmp_path / "001.answer.json").write_text('{"room": "bedroom", "movem')})
    with pytest.raises(DecisionError, match="no JSON object"):
        fake_pilot(tmp_path, fake).decide(pin())
    assert fake.now == 5.0  # seen at 2 s, rejected once the 3 s grace had passed, long before the timeout


def test_no_answer_within_timeout_s_is_a_fatal_pilot_error(tmp_path: Path) -> None:
    fake = FakeTime()
    with pytest.raises(PilotError) as info:
        fake_pilot(tmp_path, fake, timeout_s=30).decide(pin())
    assert info.value.fatal and info.value.reason == "timeout"
    assert str(tmp_path / "001.answer.json") in str(info.value) and "30 s" in str(info.value)
    assert fake.now == 30.0 and fake.sleeps == 30


def test_a_timeout_ends_the_episode_as_pilot_error_and_writes_done(tmp_path: Path) -> None:
    fake = FakeTime()
    with Simulator("cabin", SimConfig(render=False)) as geo:
        result = run_episode(geo, fake_pilot(tmp_path, fake, timeout_s=10), parse_query(QUERY, geo.scene),
                             EpisodeConfig(max_steps=5), spawn=SPAWN)
    assert result.outcome == "pilot_error" and "timeout" in result.reason
    assert result.pilot_calls == 1  # fatal: no re-ask that would only wait again
    assert (tmp_path / "done.txt").read_text().startswith("pilot_error in 1 steps: timeout: no answer in ")


def test_a_directory_removed_mid_episode_ends_it_with_a_fatal_pilot_error(tmp_path: Path) -> None:
    pilot = fake_pilot(tmp_path / "ep", FakeTime())
    (tmp_path / "ep").rmdir()
    with pytest.raises(PilotError) as info:
        pilot.decide(pin())
    assert info.value.fatal and info.value.reason == "files_unwritable"
    assert f"cannot write call 001 in {tmp_path / 'ep'}" in str(info.value)
    pilot.episode_finished(type("R", (), {"outcome": "pilot_error", "steps": 1, "reason": "gone"})())  # no raise


# -- numbering, episodes, the directory ------------------------------------------------------------------------
def test_a_reask_is_a_new_call_and_a_new_episode_rewrites_the_system_prompt(tmp_path: Path) -> None:
    fake = FakeTime()
    pilot = fake_pilot(tmp_path, fake)

    def answer(call: str, payload: dict) -> None:
        fake.hooks[fake.now + 1] = lambda: (tmp_path / f"{call}.answer.json").write_text(json.dumps(payload))

    answer("001", ANSWER)
    pilot.decide(pin(step=1))
    answer("002", ANSWER)
    pilot.decide(pin(step=1, feedback=("Your previous answer was rejected: no",)))  # a re-ask: call 002
    answer("003", ANSWER)
    pilot.decide(pin(step=1))  # a second call of step 1 without feedback (a confirmation): same episode
    (tmp_path / "system.md").unlink()
    pilot.episode_finished(type("R", (), {"outcome": "success", "steps": 1, "reason": "ok"})())
    assert (tmp_path / "done.txt").read_text() == "success in 1 steps: ok\n"
    answer("004", ANSWER)
    pilot.decide(pin(step=1))  # after episode_finished: a new episode
    answer("005", ANSWER)
    pilot.decide(pin(step=2))
    answer("006", ANSWER)
    pilot.decide(pin(step=1))  # steps restart (a caller that does not report the end): a new episode
    assert "Your previous answer was rejected: no" in (tmp_path / "002.prompt.md").read_text()
    firsts = ["first prompt of the episode" in (tmp_path / f"00{n}.prompt.md").read_text() for n in range(1, 7)]
    assert firsts == [True, False, False, True, False, True]
    assert (tmp_path / "system.md").exists() and not (tmp_path / "done.txt").exists()
    assert (tmp_path / "latest.txt").read_text() == "006\n"


def test_each_file_appears_whole_and_the_prompt_after_the_image(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    published: list[tuple[str, str]] = []  # (temp name, final name) of every os.replace, in order
    real_replace = os.replace
    monkeypatch.setattr("vlnpilot.core.fileio.os.replace",
                        lambda src, dst: (published.append((Path(src).name, Path(dst).name)), real_replace(src, dst)))
    fake = FakeTime({1.0: lambda: (tmp_path / "001.answer.json").write_text(json.dumps(ANSWER))})
    fake_pilot(tmp_path, fake).decide(pin())
    assert published == [(".system.md.tmp", "system.md"), (".001.png.tmp", "001.png"),
                          (".001.prompt.md.tmp", "001.prompt.md"), (".latest.txt.tmp", "latest.txt")]


def test_a_directory_with_another_runs_files_is_refused_unless_overwrite(tmp_path: Path) -> None:
    (tmp_path / "004.prompt.md").write_text("old")
    (tmp_path / "004.answer.json").write_text("{}")
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match=f"{re.escape(str(tmp_path))} already holds .* fresh directory"):
        make_pilot(f"files:{tmp_path}")
    FilesPilot(directory=tmp_path, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # only the run's own files go


@pytest.mark.parametrize("spec", ["files", "files:", "files:  "])
def test_the_spec_needs_a_directory(spec: str) -> None:
    with pytest.raises(ConfigError, match="needs a directory: use --pilot files:DIR"):
        make_pilot(spec)


def test_the_spec_takes_everything_after_the_first_colon_as_the_directory(tmp_path: Path) -> None:
    pilot = make_pilot(f"Files:{tmp_path}/a:b")
    assert isinstance(pilot, FilesPilot) and pilot.directory == tmp_path / "a:b" and pilot.directory.is_dir()


@pytest.mark.parametrize("kind", ["under_a_file", "a_file", "old_run"])
def test_a_bad_directory_is_one_line_and_exit_2_from_the_cli(monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                             kind: str) -> None:
    regular = tmp_path / "file.txt"
    regular.write_text("not a directory")
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "001.prompt.md").write_text("old")
    directory = {"under_a_file": regular / "ep", "a_file": regular, "old_run": tmp_path / "old"}[kind]
    out = tmp_path / "run"
    monkeypatch.setattr(sys, "argv", ["vln-pilot", "run", "Go to the bedroom", "--pilot", f"files:{directory}",
                                      "--out", str(out), "-q"])
    with pytest.raises(SystemExit) as info:
        cli.main()
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert info.value.code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert str(directory) in lines[0]
    assert ("fresh directory" if kind == "old_run" else "cannot write in") in lines[0]
    assert not out.exists()


# -- scripts/files-answer.sh -----------------------------------------------------------------------------------
def test_the_answer_script_writes_the_answer_and_prints_the_next_prompt_then_done(tmp_path: Path) -> None:
    pilot = FilesPilot(directory=tmp_path, poll_s=0.002, timeout_s=60)
    decisions: list = []

    def fly() -> None:
        decisions.append(pilot.decide(pin(step=1)))
        decisions.append(pilot.decide(pin(step=2)))
        pilot.episode_finished(type("R", (), {"outcome": "success", "steps": 2, "reason": "reached"})())

    flier = threading.Thread(target=fly, daemon=True)
    flier.start()
    script = [str(REPO / "scripts" / "files-answer.sh"), str(tmp_path)]
    while not (tmp_path / "001.prompt.md").exists():
        threading.Event().wait(0.002)
    first = subprocess.run([*script, "001", json.dumps(ANSWER)], capture_output=True, text=True, timeout=60)
    assert first.returncode == 0, first.stderr
    assert first.stdout.startswith(f"{tmp_path}/002.prompt.md\n## User query\nGo to the bedroom")
    second = subprocess.run([*script, "002", json.dumps(ANSWER)], capture_output=True, text=True, timeout=60)
    flier.join(10)
    assert second.returncode == 0, second.stderr
    assert second.stdout == f"{tmp_path}/done.txt\nsuccess in 2 steps: reached\n"
    assert [d.core() for d in decisions] == [ANSWER, ANSWER]


def test_the_answer_script_times_out_cleanly(tmp_path: Path) -> None:
    done = subprocess.run([str(REPO / "scripts" / "files-answer.sh"), str(tmp_path), "007", "{}"],
                          capture_output=True, text=True, timeout=60, env={**os.environ, "FILES_ANSWER_WAIT_S": "0"})
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.strip() == f"no new prompt (008.prompt.md) nor done.txt in {tmp_path} within 0 s"
    assert json.loads((tmp_path / "007.answer.json").read_text()) == {}


def test_a_stateless_pilot_answers_one_call_and_stops(tmp_path: Path) -> None:
    """`--no-wait`: a fresh pilot per call writes its answer and is done; `files-wait.sh` finds the next call."""
    pilot = FilesPilot(directory=tmp_path, poll_s=0.002, timeout_s=60)
    decisions: list = []
    flier = threading.Thread(target=lambda: decisions.append(pilot.decide(pin(step=1))), daemon=True)
    flier.start()
    waited = subprocess.run([str(REPO / "scripts" / "files-wait.sh"), str(tmp_path), "001"], capture_output=True,
                            text=True, timeout=60)
    assert waited.returncode == 0 and waited.stdout.startswith(f"{tmp_path}/001.prompt.md\n## User query")
    answered = subprocess.run([str(REPO / "scripts" / "files-answer.sh"), "--no-wait", str(tmp_path), "001",
                               json.dumps(ANSWER)], capture_output=True, text=True, timeout=60,
                              env={**os.environ, "FILES_ANSWER_WAIT_S": "600"})
    flier.join(10)
    assert answered.returncode == 0 and answered.stdout == f"{tmp_path}/001.answer.json\n"
    assert [d.core() for d in decisions] == [ANSWER]
