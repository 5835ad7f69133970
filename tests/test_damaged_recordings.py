"""A damaged recording is never read as a shorter one: a torn last line is skipped (a crash mid-write), another
damaged line is refused by a replay (one line naming the file and the line, exit code 2) and skipped with a
visible warning by a report; damaged frames and files are named, never a traceback."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

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


# -- frames ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("keep", [2000, 0])
def test_a_torn_or_empty_frame_is_a_placeholder_and_a_warning(monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str], copy: Path,
                                                              keep: int) -> None:
    frame = copy / "frames" / "front_003.jpg"
    frame.write_bytes(frame.read_bytes()[:keep])
    code, _, err = run_main(monkeypatch, capsys, "report", str(copy))  # the video draws every frame too
    assert code == 0 and "Traceback" not in err
    assert f"warning: {frame} is damaged (" in err and "drawn as a placeholder" in err
    assert (copy / "report.html").is_file() and (copy / "episode.mp4").is_file()
    assert '"frames/front_003.jpg"' not in (copy / "report.html").read_text()  # a placeholder, not the image


def test_frames_are_written_atomically(recorded: Path) -> None:
    assert not list((recorded / "frames").glob(".*"))  # no temporary file left behind
    assert sorted(p.name for p in (recorded / "frames").iterdir())[0] == "front_000.jpg"


def test_a_frame_is_written_through_a_temporary_file(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A kill mid-write leaves a hidden temporary file, never a torn front_NNN.jpg: the frame appears by rename."""
    import numpy as np

    from vlnpilot.core import fileio

    renamed: list[tuple[str, str]] = []
    replace = fileio.os.replace

    def spy(src: str, dst: str) -> None:
        renamed.append((Path(src).name, Path(dst).name))
        replace(src, dst)

    monkeypatch.setattr(fileio.os, "replace", spy)
    recorder = Recorder(tmp_path / "run")
    recorder.save_observation(1, np.zeros((8, 8, 3), np.uint8), np.zeros((8, 8, 3), np.uint8))
    recorder.close()
    assert (".front_001.jpg.tmp", "front_001.jpg") in renamed and (".rear_001.jpg.tmp", "rear_001.jpg") in renamed


# -- trial.json, results.jsonl, bench.json -------------------------------------------------------------------------
def test_a_corrupt_trial_json_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                          copy: Path, tmp_path: Path) -> None:
    (copy / "trial.json").write_text("{not json")
    code, _, err = run_main(monkeypatch, capsys, "run", QUERY, "--spawn", SPAWN, "--pilot", f"replay:{copy}",
                            "--no-video", "-q", "--out", str(tmp_path / "again"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and f"{copy / 'trial.json'} is not valid JSON" in err


@pytest.fixture
def bench_dir(tmp_path: Path) -> Path:
    from report_samples import make_bench

    return make_bench(tmp_path / "bench", rows=1, reps=1)


def test_a_results_line_without_a_result_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str], bench_dir: Path) -> None:
    lines = (bench_dir / "results.jsonl").read_text().splitlines()
    record = json.loads(lines[0])
    del record["result"]
    (bench_dir / "results.jsonl").write_text("\n".join([json.dumps(record), *lines[1:]]) + "\n")
    code, _, err = run_main(monkeypatch, capsys, "report", str(bench_dir))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"{bench_dir / 'results.jsonl'} line 1: the record of {record['key']} has no result" in err


@pytest.mark.parametrize(("change", "problem"), [
    (lambda m: [1, 2], "it holds a JSON list, not an object"),
    (lambda m: {k: v for k, v in m.items() if k != "suite"}, "its 'suite' is missing or not an object"),
    (lambda m: {**m, "pilots": "oracle"}, "its 'pilots' is missing or not a list of objects with a 'spec'")])
def test_a_misshapen_bench_json_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                            bench_dir: Path, change: Any, problem: str) -> None:
    manifest = json.loads((bench_dir / "bench.json").read_text())
    (bench_dir / "bench.json").write_text(json.dumps(change(manifest)))
    code, _, err = run_main(monkeypatch, capsys, "report", str(bench_dir))
    assert code == 2 and err.strip().splitlines() == [
        f"error: {bench_dir / 'bench.json'} is not a bench manifest: {problem}; restore it or choose another --out"]


# -- a directory where a file is written -------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["report.html", "episode.mp4"])
def test_report_refuses_a_directory_in_place_of_its_file(monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str], copy: Path,
                                                         name: str) -> None:
    (copy / name).mkdir()
    code, _, err = run_main(monkeypatch, capsys, "report", str(copy))
    assert code == 2 and err.strip().splitlines() == [
        f"error: {copy / name} is a directory where a file is written; remove or rename it"]


@pytest.mark.parametrize("name", ["table.md", "bench.json"])
def test_bench_refuses_a_directory_in_place_of_its_file_before_flying(monkeypatch: pytest.MonkeyPatch,
                                                                      capsys: pytest.CaptureFixture[str],
                                                                      tmp_path: Path, name: str) -> None:
    suite = tmp_path / "tiny.yaml"
    suite.write_text("name: tiny\nrows:\n  - {query: Go to the bedroom, spawn: bedroom}\n")
    out = tmp_path / "b"
    (out / name).mkdir(parents=True)
    code, _, err = run_main(monkeypatch, capsys, "bench", "--suite", str(suite), "--no-report", "--out", str(out))
    assert code == 2 and err.strip().splitlines() == [
        f"error: {out / name} is a directory where a file is written; remove or rename it"]
    assert not (out / "results.jsonl").exists()  # nothing flew
