"""Chaos: the command line's error path and the inputs that used to fail after take-off (issue 26)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import typer

from cli_support import run_main
from vlnpilot.core.exits import BAD_INPUT, INTERRUPTED

pytestmark = pytest.mark.chaos
FLY = ["--spawn", "bedroom", "--pilot", "oracle", "--max-steps", "2", "-q", "--no-video"]


def one_line(code: int, err: str) -> None:
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1 and err.startswith("error: "), (code, err)
    assert "Traceback" not in err


@pytest.fixture(scope="module")
def flown(tmp_path_factory) -> Path:
    """A real run directory (2 steps), copied by the tests that corrupt it."""
    import subprocess
    import sys

    out = tmp_path_factory.mktemp("flown") / "r"
    subprocess.run([sys.executable, "-m", "vlnpilot.cli", "run", "Go to the bathroom", *FLY, "--out", str(out)],
                   check=True, capture_output=True)
    return out


@pytest.mark.parametrize("content", ['{"bad', "[1, 2]", "\xff\xfe"])
@pytest.mark.parametrize("command", [
    ["report", "{run}"], ["watch", "{run}", "--port", "0"],
    ["run", "Go to the bathroom", *FLY, "--pilot", "replay:{run}", "--out", "{out}"],
])
def test_a_corrupt_summary_is_one_line_under_every_command(monkeypatch, capsys, tmp_path, flown, content,
                                                           command) -> None:
    import shutil

    run = tmp_path / "corrupt"
    shutil.copytree(flown, run)
    (run / "summary.json").write_bytes(content.encode("latin-1"))
    args = [a.format(run=run, out=tmp_path / "out") for a in command]
    code, _, err = run_main(monkeypatch, capsys, *args)
    one_line(code, err)
    assert "summary.json" in err


def test_an_unexpected_error_keeps_its_one_traceback(monkeypatch, capsys) -> None:
    """The error path itself: a bug surfaces as itself, not as a second error raised while handling it."""
    def boom(*args, **kwargs) -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr("vlnpilot.live.station.watch_run", boom)
    with pytest.raises(RuntimeError, match="a bug"):  # was an AttributeError raised while handling it
        run_main(monkeypatch, capsys, "watch", ".")


def test_typer_abort_is_an_interruption(monkeypatch, capsys) -> None:
    def abort(*args, **kwargs) -> None:
        raise typer.Abort()

    monkeypatch.setattr("vlnpilot.live.station.watch_run", abort)
    code, _, err = run_main(monkeypatch, capsys, "watch", ".")
    assert code == INTERRUPTED and "interrupted" in err and "Traceback" not in err


def test_the_exceptions_main_relies_on_exist_in_the_pinned_typer() -> None:
    from typer._click.exceptions import ClickException, NoArgsIsHelpError

    assert issubclass(typer.BadParameter, ClickException) and NoArgsIsHelpError and typer.Abort
    assert "typer>=0.29,<0.30" in (Path(__file__).parents[2] / "pyproject.toml").read_text()


# ------------------------------------------------------------------------------------------ before take-off

LONG = "Go to the kitchen " * 160  # 2,880 characters; the server takes 2,000


SHORT = ["--max-steps", "2", "--no-video", "-q"]  # so that a build without the checks ends soon
BRIEF = ["--reps", "1", "--max-steps", "1", "--no-report", "--executor", "inline"]


@pytest.mark.parametrize(("args", "words"), [
    (["run", LONG, "--pilot", "remote", *SHORT], "2000"),
    (["run", "Go to the kitchen \udcff", "--pilot", "oracle", *SHORT], "UTF-8"),
    (["run", "Go to the kitchen", "--pilot", "oracle", *SHORT, "--out", "{tmp}/r\udcff"], "UTF-8"),
    (["bench", *BRIEF, "--out", "{tmp}/b\udcff"], "UTF-8"),
    (["run", "Go to the kitchen", "--pilot", "openai", *SHORT, "--base-url", "http://127.0.0.1:99999/v1"], "99999"),
    (["bench", *BRIEF, "--pilots", "openai", "--base-url", "http://127.0.0.1:99999/v1"], "99999"),
    (["run", "Go to the kitchen", "--pilot", "oracle", "--no-video", "--max-steps", "1" + "0" * 30], "--max-steps"),
    (["bench", "--reps", "1", "--executor", "inline", "--max-steps", "1" + "0" * 30], "--max-steps"),
    (["run", "Go to the kitchen", *SHORT, "--pilot", "openai:", "--base-url", "http://127.0.0.1:9/v1"],
     "nothing after ':'"),
    (["bench", *BRIEF, "--pilots", "openai:", "--base-url", "http://127.0.0.1:9/v1"], "nothing after ':'"),
    (["bench", *BRIEF, "--pilots", "oracle,,"], "empty SPEC"),
    (["bench", *BRIEF, "--pilots", ",oracle"], "empty SPEC"),
    (["bench", *BRIEF, "--resume", "--out", "{tmp}/nothing-here"], "--resume"),
])
def test_inputs_that_used_to_fail_after_take_off_are_refused_before(monkeypatch, capsys, tmp_path, args,
                                                                     words) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", "sk-not-a-real-key-0000")
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    monkeypatch.chdir(tmp_path)
    code, _, err = run_main(monkeypatch, capsys, *args)
    one_line(code, err.split("\n", 1)[1] if err.startswith("pilot server:") else err)
    assert words in err
    assert not list(tmp_path.rglob("episode.jsonl")) and not list(tmp_path.rglob("results.jsonl"))
    assert not (tmp_path / "nothing-here").exists()


# ------------------------------------------------------------------------------------------ the video

def test_interrupting_the_video_leaves_no_temporary_file(monkeypatch, flown, tmp_path) -> None:
    import shutil

    import av

    from vlnpilot.report.video import write_episode_video

    run = tmp_path / "r"
    shutil.copytree(flown, run)
    for name in ("episode.mp4", "episode.gif"):
        (run / name).unlink(missing_ok=True)
    real, calls = av.VideoFrame.from_ndarray, []

    def once_then_interrupt(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202 - the file exists after frame 1
        calls.append(1)
        if len(calls) > 1:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(av.VideoFrame, "from_ndarray", once_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_episode_video(run)
    assert calls and not [n for n in os.listdir(run) if "tmp" in n]  # was episode.mp4.tmp.mp4
    assert not (run / "episode.mp4").exists() and not (run / "episode.gif").exists()
