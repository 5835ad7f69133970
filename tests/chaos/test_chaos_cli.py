"""Chaos: the command line under bad input and failing pilots (issue 16). One line, the right exit code."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from cli_support import PROVIDER_ENV, run_main
from fakes import FakeOpenAI
from vlnpilot import cli
from vlnpilot.bench.results import wilson_interval
from vlnpilot.core.exits import BAD_INPUT, INTERRUPTED, PILOT_ERROR
from vlnpilot.core.rundir import load_run

pytestmark = pytest.mark.chaos


@pytest.mark.parametrize(("args", "names"), [
    (["run", "Go to the bedroom", "--max-steps", "0"], "--max-steps"),
    (["bench", "--workers", "0"], "--workers"),
    (["run", "Go to the bedroom", "--seed", "abc"], "--seed"),
    (["run", "Go to the bedroom", "--base-url", "not a url"], "--base-url"),
    (["run", "Go to the bedroom", "--base-url", "ftp://example.org/v1"], "--base-url"),
    (["bench", "--base-url", "ftp://example.org/v1"], "--base-url"),
    (["nosuchcommand"], "nosuchcommand"),
])
def test_bad_input_is_one_line_naming_the_option_and_exit_2(monkeypatch, capsys, args, names) -> None:
    code, out, err = run_main(monkeypatch, capsys, *args)
    assert code == BAD_INPUT
    assert len(err.strip().splitlines()) == 1, err
    assert err.startswith("error: ") and names in err
    assert "Traceback" not in err and "╭" not in err  # no framework box


def test_a_huge_query_is_not_echoed_whole(monkeypatch, capsys) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "x" * 10_000)
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1
    assert len(err) < 600 and "10000 characters" in err


def test_a_malformed_suite_is_one_line_with_line_and_column(monkeypatch, capsys, tmp_path: Path) -> None:
    suite = tmp_path / "broken.yaml"
    suite.write_text("name: broken\nrows:\n  - id: a\n    query: [unclosed\n  - id: b\n")
    code, _, err = run_main(monkeypatch, capsys, "bench", "--suite", str(suite))
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1, err
    assert str(suite) in err and "line 5, column" in err


def test_remote_without_url_says_which_server_it_asks(monkeypatch, capsys, tmp_path: Path) -> None:
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("")  # the run stops at --out, after the pilot line and before any request
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--pilot", "remote", "--out",
                            str(not_a_dir))
    assert code == BAD_INPUT
    assert err.splitlines()[0] == "pilot server: http://127.0.0.1:8000 (VLN_PILOT_URL is not set)"


def test_a_rejected_key_exits_with_the_pilot_error_code(monkeypatch, capsys, tmp_path: Path) -> None:
    with FakeOpenAI() as fake:
        fake.push("bad_key", times=5)
        monkeypatch.setenv("OPENAI_API_KEY", "sk-not-a-real-key-0000")
        monkeypatch.setattr(sys, "argv", ["vln-pilot", "run", "Go to the bedroom", "--pilot", "openai",
                                          "--base-url", fake.base_url, "-q", "--no-video", "--out",
                                          str(tmp_path / "r")])
        with pytest.raises(SystemExit) as info:
            cli.main()
    assert info.value.code == PILOT_ERROR
    assert load_run(tmp_path / "r")[0]["result"]["outcome"] == "pilot_error"


def test_a_flown_episode_exits_0_whatever_its_outcome(monkeypatch, capsys, tmp_path: Path) -> None:
    code, out, _ = run_main(monkeypatch, capsys, "run", "Go to the bathroom", "--spawn", "bedroom", "--pilot",
                       "oracle", "--max-steps", "1", "-q", "--no-video", "--out", str(tmp_path / "r"))
    assert code == 0 and "max_steps" in out


def test_a_run_directory_that_holds_a_run_is_refused_unless_overwrite(monkeypatch, capsys, tmp_path: Path) -> None:
    args = ["run", "Go to the bedroom", "--spawn", "bedroom", "--pilot", "oracle", "-q", "--no-video"]
    out_dir = tmp_path / "r"
    assert run_main(monkeypatch, capsys, *args, "--max-steps", "3", "--out", str(out_dir))[0] == 0
    first = (out_dir / "episode.jsonl").read_text()
    code, _, err = run_main(monkeypatch, capsys, *args, "--max-steps", "2", "--out", str(out_dir))
    assert code == BAD_INPUT and "already holds a run" in err and "--overwrite" in err
    assert (out_dir / "episode.jsonl").read_text() == first  # untouched
    code, _, _ = run_main(monkeypatch, capsys, *args, "--max-steps", "1", "--seed", "7", "--out", str(out_dir),
                     "--overwrite")
    summary, steps = load_run(out_dir)
    assert code == 0 and summary["config"]["seed"] == 7 and len(steps) == summary["result"]["steps"]


def test_sigterm_ends_a_run_as_interrupted_with_code_130(tmp_path: Path) -> None:
    import os
    import signal
    import subprocess

    out_dir = tmp_path / "r"
    env = {k: v for k, v in os.environ.items() if k not in PROVIDER_ENV}
    proc = subprocess.Popen([sys.executable, "-m", "vlnpilot.cli", "run", "Go to the bedroom", "--pilot", "stdin",
                             "--no-video", "-q", "--out", str(out_dir)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    try:
        for line in proc.stderr:  # the stdin pilot prints its prompt, then waits for an answer: the event
            if line.startswith("image: "):
                break
        assert (out_dir / "summary.json").is_file()  # written first
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == INTERRUPTED, err
    summary, steps = load_run(out_dir)
    assert summary["status"] == "interrupted" and steps == []


def test_wilson_bounds_always_hold_the_rate_so_plots_never_get_negative_error_bars(tmp_path: Path) -> None:
    for n in range(1, 51):
        for k in range(n + 1):
            lo, hi = wilson_interval(k, n)
            assert 0.0 <= lo <= k / n <= hi <= 1.0, (k, n)
    from vlnpilot.report.plots import plot_success_rates

    path = plot_success_rates(["oracle", "noisy"], [10, 0], [10, 10], tmp_path / "rates.png")
    assert path.is_file() and path.stat().st_size > 0


def test_the_stdin_pilot_leaves_no_temporary_directory(tmp_path: Path) -> None:
    import os
    import subprocess

    env = {**{k: v for k, v in os.environ.items() if k not in PROVIDER_ENV}, "TMPDIR": str(tmp_path)}
    done = subprocess.run([sys.executable, "-m", "vlnpilot.cli", "run", "Go to the bedroom", "--pilot", "stdin",
                           "--no-video", "-q", "--out", str(tmp_path / "r")], stdin=subprocess.DEVNULL,
                          capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == PILOT_ERROR, done.stderr  # stdin closed at once: a pilot error
    assert "image: " + str(tmp_path) in done.stderr  # the images went to the temporary folder...
    assert not list(tmp_path.glob("vlnpilot-stdin-*"))  # ...and are gone at the end


SMALL_SUITE = """name: small
scene: cabin
repetitions: 1
max_steps: 2
seed: 0
rows:
  - id: bed
    spawn: living_room
    query: Go to the bedroom
    goal: {room: bedroom}
"""


@pytest.mark.parametrize(("pilot", "code"), [("oracle", 0), ("openai", PILOT_ERROR)])
def test_bench_exits_non_zero_when_an_episode_ended_in_pilot_error(monkeypatch, capsys, tmp_path, pilot,
                                                                    code) -> None:
    suite = tmp_path / "small.yaml"
    suite.write_text(SMALL_SUITE)
    with FakeOpenAI() as fake:
        fake.push("bad_key", times=5)
        monkeypatch.setattr(sys, "argv", ["vln-pilot", "bench", "--suite", str(suite), "--pilots", pilot,
                                          "--base-url", fake.base_url, "--no-report", "--out", str(tmp_path / "b")])
        monkeypatch.setenv("OPENAI_API_KEY", "sk-not-a-real-key-0000")
        with pytest.raises(SystemExit) as info:
            cli.main()
    assert info.value.code == code
