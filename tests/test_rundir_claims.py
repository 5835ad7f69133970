"""Who may write a run directory: one run at a time (a lock), `--overwrite` clears every file a run wrote, and
runs, benches and scene pictures never share a directory."""

from __future__ import annotations

import fcntl
import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from cli_support import run_main
from vlnpilot.core.dirlock import RUN_LOCK
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.rundir import claim_run_dir

RUN = ["run", "Go to the bedroom", "--spawn", "bedroom", "--pilot", "oracle", "--max-steps", "2", "--no-video", "-q"]


@pytest.fixture
def held_by_another_run(tmp_path: Path) -> Iterator[Path]:
    """A run directory whose lock another run holds (a separate open file: flock treats it as another writer)."""
    out = tmp_path / "busy"
    out.mkdir()
    (out / "summary.json").write_text(json.dumps({"status": "running", "query": "the other run"}))
    with open(out / RUN_LOCK, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        fh.write("pid 4242\n")
        fh.flush()
        yield out


def test_a_run_dir_another_run_is_writing_is_refused(held_by_another_run: Path) -> None:
    with pytest.raises(ConfigError, match="being written by another run \\(pid 4242\\)"):
        claim_run_dir(held_by_another_run, overwrite=True)
    assert "the other run" in (held_by_another_run / "summary.json").read_text()


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_a_second_run_into_a_busy_out_is_one_line_and_deletes_nothing(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], held_by_another_run: Path,
        overwrite: list[str]) -> None:
    code, _, err = run_main(monkeypatch, capsys, *RUN, "--out", str(held_by_another_run), *overwrite)
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and "another run" in err
    assert json.loads((held_by_another_run / "summary.json").read_text())["query"] == "the other run"
    assert not (held_by_another_run / "episode.jsonl").exists()


def test_overwrite_removes_every_file_the_old_run_wrote(tmp_path: Path) -> None:
    out = tmp_path / "old"
    (out / "frames").mkdir(parents=True)
    for name in ("summary.json", "episode.jsonl", "robot_events.jsonl", "trial.json", "report.html",
                 "floorplan.png", "episode.mp4", "episode.gif", ".summary.json.tmp", "frames/front_000.jpg"):
        (out / name).write_text("old run")
    claim_run_dir(out, overwrite=True)
    assert sorted(p.name for p in out.iterdir()) == [RUN_LOCK]


def test_robot_events_mark_a_directory_as_holding_a_run(tmp_path: Path) -> None:
    (tmp_path / "robot_events.jsonl").write_text("{}\n")
    with pytest.raises(ConfigError, match="already holds a run \\(robot_events.jsonl\\)"):
        claim_run_dir(tmp_path)


@pytest.mark.parametrize("overwrite", [False, True])
def test_a_run_is_never_written_into_a_bench_directory(tmp_path: Path, overwrite: bool) -> None:
    (tmp_path / "bench.json").write_text("{}")
    (tmp_path / "report.html").write_text("the bench's report")
    with pytest.raises(ConfigError, match="holds a bench \\(bench.json\\).*choose another --out"):
        claim_run_dir(tmp_path, overwrite=overwrite)
    assert (tmp_path / "report.html").read_text() == "the bench's report"


def test_run_into_a_bench_dir_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                         tmp_path: Path) -> None:
    (tmp_path / "bench.json").write_text("{}")
    code, _, err = run_main(monkeypatch, capsys, *RUN, "--out", str(tmp_path), "--overwrite")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "holds a bench" in err
    assert not (tmp_path / "summary.json").exists()


def test_a_bench_is_never_written_into_a_run_directory(monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    (tmp_path / "summary.json").write_text(json.dumps({"status": "finished"}))
    suite = tmp_path.parent / f"{tmp_path.name}-suite.yaml"
    suite.write_text("name: tiny\nrows:\n  - {query: Go to the bedroom, spawn: bedroom}\n")
    code, _, err = run_main(monkeypatch, capsys, "bench", "--suite", str(suite), "--pilots", "oracle", "--no-report",
                            "--out", str(tmp_path))
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "holds a run (summary.json)" in err
    assert not (tmp_path / "bench.json").exists()


@pytest.mark.parametrize("mark", ["summary.json", "bench.json"])
def test_scene_render_refuses_a_run_or_bench_directory(monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                       mark: str) -> None:
    (tmp_path / mark).write_text("{}")
    code, _, err = run_main(monkeypatch, capsys, "scene", "render", "--spawn", "bedroom", "--width", "32",
                            "--height", "32", "--out", str(tmp_path))
    assert code == 2 and len(err.strip().splitlines()) == 1 and mark in err
    assert not (tmp_path / "front.png").exists()
