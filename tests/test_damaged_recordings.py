"""A damaged recording is never read as a shorter one: a torn last line is skipped (a crash mid-write), another
damaged line is refused by a replay (one line naming the file and the line, exit code 2) and skipped with a
visible warning by a report; damaged frames and files are named, never a traceback."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from cli_support import run_main
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.rundir import EPISODE, Recorder, load_run
from vlnpilot.core.steplog import read_steps
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

W, H = 96, 72
QUERY, SPAWN = "Go to the bathroom", "living_room"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An oracle run of several steps, with frames."""
    run_dir = tmp_path_factory.mktemp("recorded") / "run"
    with Simulator("cabin", SimConfig(width=W, height=H, rear_width=W, rear_height=H)) as sim:
        result = run_episode(sim, OraclePilot(), parse_query(QUERY, sim.scene), EpisodeConfig(max_steps=6),
                             spawn=SPAWN, recorder=Recorder(run_dir), pilot_spec="oracle")
    assert result.steps >= 4
    return run_dir


@pytest.fixture
def copy(recorded: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(recorded, tmp_path / "copy"))


def _replace_line(run_dir: Path, number: int, text: str) -> None:
    lines = (run_dir / EPISODE).read_text().splitlines()
    lines[number - 1] = text
    (run_dir / EPISODE).write_text("\n".join(lines) + "\n")


# -- episode.jsonl -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "problem"), [("garbage", "not valid JSON"),
                                               ("[1, 2]", "a JSON list, not a step"),
                                               ('{"step": "x"}', 'its step is "x", not a whole number')])
def test_a_damaged_middle_line_is_refused_naming_the_file_and_line(copy: Path, text: str, problem: str) -> None:
    _replace_line(copy, 2, text)
    with pytest.raises(ConfigError, match=f"episode.jsonl line 2: {problem}"):
        load_run(copy)


def test_a_torn_last_line_is_still_skipped(copy: Path) -> None:
    whole = len(load_run(copy)[1])
    with open(copy / EPISODE, "a") as fh:
        fh.write('{"step": 99, "sta')
    assert len(load_run(copy)[1]) == whole


def test_a_reader_that_skips_is_told_every_damaged_line(copy: Path) -> None:
    whole = len(load_run(copy)[1])
    _replace_line(copy, 2, "garbage")
    told: list[str] = []
    steps = read_steps(copy / EPISODE, told.append)
    assert len(steps) == whole - 1 and told == [f"{copy / EPISODE} line 2: not valid JSON; skipped"]


def test_replay_of_a_damaged_recording_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str], copy: Path,
                                                   tmp_path: Path) -> None:
    _replace_line(copy, 2, "garbage")
    code, _, err = run_main(monkeypatch, capsys, "run", QUERY, "--spawn", SPAWN, "--pilot", f"replay:{copy}",
                            "--no-video", "-q", "--out", str(tmp_path / "again"))
    assert code == 2 and "Traceback" not in err
    assert err.strip().splitlines() == [f"error: {copy / EPISODE} line 2: not valid JSON; the steps after it cannot "
                                        "be trusted: restore the file or fly the run again"]


def test_report_of_a_damaged_recording_shows_every_other_step_and_warns(monkeypatch: pytest.MonkeyPatch,
                                                                       capsys: pytest.CaptureFixture[str],
                                                                       copy: Path) -> None:
    whole = len(load_run(copy)[1])
    _replace_line(copy, 2, "[1]")
    code, _, err = run_main(monkeypatch, capsys, "report", str(copy), "--no-video")
    assert code == 0 and "Traceback" not in err
    assert f"warning: {copy / EPISODE} line 2: a JSON list, not a step (a JSON object); skipped" in err
    page = (copy / "report.html").read_text()
    assert "line 2: a JSON list, not a step" in page
    assert f"Step {whole}" in page  # the steps after the damaged line are all there
