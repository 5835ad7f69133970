"""Chaos: bad values an outside audit found accepted or crashing, each refused in one line before anything is
written (exit code 2, no traceback)."""

from __future__ import annotations

import pytest

from cli_support import run_main
from vlnpilot.core.exits import BAD_INPUT

pytestmark = pytest.mark.chaos
FLY = ["--spawn", "bedroom", "--pilot", "oracle", "--max-steps", "2", "-q", "--no-video"]
Q = "Go to the bathroom"


def one_line(code: int, err: str) -> None:
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1 and err.startswith("error: "), (code, err)
    assert "Traceback" not in err


def refused(monkeypatch, capsys, *args: str) -> str:
    """The one error line of `vln-pilot ARGS`, asserting that it is one line and exit code 2."""
    code, _, err = run_main(monkeypatch, capsys, *args)
    one_line(code, err)
    return err


# -- seeds --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", [["run", Q, *FLY], ["bench", "--suite", "paper", "--reps", "1"]])
def test_a_negative_seed_is_refused_before_a_directory_is_made(monkeypatch, capsys, tmp_path, command) -> None:
    out = tmp_path / "seedneg"
    err = refused(monkeypatch, capsys, *command, "--seed", "-5", "--out", str(out))
    assert "--seed" in err and not out.exists()


def test_a_scenario_with_a_negative_seed_is_refused_before_a_directory_is_made(monkeypatch, capsys,
                                                                               tmp_path) -> None:
    events = tmp_path / "ev.yaml"
    events.write_text("scene: cabin\nseed: -1\nevents: [{kind: lights_out, room: bedroom, trigger: {step: 1}}]\n")
    out = tmp_path / "seedneg"
    err = refused(monkeypatch, capsys, "run", Q, *FLY, "--events", str(events), "--out", str(out))
    assert "seed" in err and not out.exists()


# -- files that cannot be read, names that cannot be made ---------------------------------------------------------
def test_an_events_file_that_is_not_utf8_is_one_line(monkeypatch, capsys, tmp_path) -> None:
    events = tmp_path / "ev_bin.yaml"
    events.write_bytes(b"\xff\xfe")
    err = refused(monkeypatch, capsys, "run", Q, *FLY, "--events", str(events), "--out", str(tmp_path / "r"))
    assert "ev_bin.yaml" in err and "UTF-8" in err


LONG = "x" * 300  # longer than a file name may be (255 bytes)


@pytest.mark.parametrize("command", [
    ["run", Q, *FLY, "--out", LONG], ["bench", "--reps", "1", "--out", LONG], ["scene", "render", "--out", LONG],
    ["report", LONG], ["watch", LONG], ["bench", "--suite", f"{LONG}.yaml"],
    ["run", Q, *FLY, "--events", f"{LONG}.yaml"],
    ["run", Q, *FLY, "--pilot", f"replay:{LONG}"], ["bench", "--pilots", f"replay:{LONG}"],
])
def test_a_path_too_long_is_one_line(monkeypatch, capsys, tmp_path, command) -> None:
    monkeypatch.chdir(tmp_path)
    err = refused(monkeypatch, capsys, *command)
    assert "too long" in err and LONG not in err  # named, shortened


# -- plan checks what run checks ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("options", "named"), [
    (["--planner", "nope"], "valid planners: auto, pilot, parser"),
    (["--pilot-option", "x"], "--pilot-option"),
    (["--base-url", "ftp://x"], "--base-url"),
    (["--pilot-option", "detail=high"], "without --pilot"),
])
def test_plan_checks_its_options_without_a_planning_pilot(monkeypatch, capsys, options, named) -> None:
    assert named in refused(monkeypatch, capsys, "plan", "Go to the bedroom", *options)


# -- bench --estimate checks what a bench that flies checks -------------------------------------------------------
@pytest.mark.parametrize(("option", "value"), [
    ("--shield", "nope"), ("--sensors", "nope"), ("--executor", "nope"), ("--rate-limit", "abc"), ("--camera", "nope"),
    ("--base-url", "ftp://x"), ("--pilot-option", "x"),
])
def test_an_estimate_refuses_what_a_bench_refuses(monkeypatch, capsys, option, value) -> None:
    assert option.lstrip("-") in refused(monkeypatch, capsys, "bench", "--estimate", "--reps", "1", option, value)


def test_an_estimate_of_a_model_pilot_still_needs_no_key(monkeypatch, capsys) -> None:
    code, out, err = run_main(monkeypatch, capsys, "bench", "--estimate", "--reps", "1", "--pilots", "openai:gpt-4.1")
    assert code == 0 and "gpt-4.1" in out, err


# -- upper limits ---------------------------------------------------------------------------------------------------
def test_reps_beyond_the_cap_are_refused_before_the_episodes_are_planned(monkeypatch, capsys, tmp_path) -> None:
    err = refused(monkeypatch, capsys, "bench", "--reps", "1000000000", "--out", str(tmp_path / "hr1"))
    assert "--reps" in err and "10000" in err and not (tmp_path / "hr1").exists()


# -- unknown commands and options name the valid ones -----------------------------------------------------------------
@pytest.mark.parametrize(("args", "lists"), [
    (["bogus"], "Valid commands: run, plan, watch, report, bench, tello-emulator, serve, scene"),
    (["scene", "bogus"], "Valid commands: info, render"),
    (["--bogus"], "the valid options: see vln-pilot --help"),
    (["scene", "info", "--bogus"], "the valid options: see vln-pilot scene info --help"),
    (["run", Q, "--pilto", "oracle"], "Possible options: --pilot"),
])
def test_an_unknown_command_or_option_names_where_the_valid_ones_are(monkeypatch, capsys, args, lists) -> None:
    assert lists in refused(monkeypatch, capsys, *args)


# -- options that would change nothing ------------------------------------------------------------------------------
@pytest.mark.parametrize(("args", "named"), [
    (["run", Q, *FLY, "--live-port", "9999"], "--live-port without --live"),
    (["run", Q, *FLY, "--live-host", "127.0.0.1"], "--live-host without --live"),
    (["run", Q, *FLY, "--judge", "none"], "--judge none applies to a robot without ground truth"),
    (["bench", "--reps", "1", "--ray-address", "127.0.0.1:1"], "--ray-address applies to --executor ray"),
    (["bench", "--estimate", "--ray-address", "127.0.0.1:1"], "--ray-address applies to --executor ray"),
])
def test_an_option_that_would_be_ignored_is_refused(monkeypatch, capsys, tmp_path, args, named) -> None:
    out = tmp_path / "ignored"
    assert named in refused(monkeypatch, capsys, *args, *([] if "--estimate" in args else ["--out", str(out)]))
    assert not out.exists()
