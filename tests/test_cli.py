"""The `vln-pilot` command line: a run with the oracle, bad input as one clear line with exit code 2, scene info."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli_support import PROVIDER_ENV, run_main
from vlnpilot import cli
from vlnpilot.core.rundir import load_run

NO_KEYS = dict.fromkeys(PROVIDER_ENV)  # for the runs in a CliRunner or a subprocess
FAKE_KEY = "not-a-real-key-0000"  # never a real key


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


# -- a real run ----------------------------------------------------------------------------------------------
def test_run_with_the_default_oracle_succeeds_and_prints_the_run_dir(runner: CliRunner, tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(cli.app, ["run", "Find the sink in the bathroom", "--spawn", "bathroom", "--out", str(out)],
                           env=NO_KEYS)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("pilot: oracle (no OPENAI_API_KEY")  # which pilot, and why
    assert any("Recognize Room" in line for line in lines)  # live progress: step, state, move, room
    assert "success in" in result.stdout
    assert lines[-1] == f"run directory: {out}  (report: {out / 'report.html'})"
    assert (out / "report.html").is_file() and (out / "episode.mp4").is_file()
    summary, steps = load_run(out)
    assert summary["status"] == "finished" and summary["result"]["outcome"] == "success"
    assert summary["pilot"] == "oracle" and len(steps) == summary["result"]["steps"]
    assert sum(1 for line in lines if line.split()[:1] and line.split()[0].isdigit()) == len(steps)


def test_run_quiet_and_explicit_pilot(runner: CliRunner, tmp_path: Path) -> None:
    result = runner.invoke(cli.app, ["run", "Go to the bedroom", "--spawn", "bedroom", "--pilot", "oracle",
                                     "--max-steps", "3", "--seed", "1", "-q", "--out", str(tmp_path / "r")])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0].startswith("success in 1 steps")  # no pilot line, no progress lines
    assert load_run(tmp_path / "r")[0]["config"]["seed"] == 1


# -- bad input: one line, exit code 2, the valid choices, no traceback ---------------------------------------
BAD_INPUT = [
    (["run", "Go to the bedroom", "--spawn", "attic"], ["unknown spawn 'attic'", "valid spawns: bathroom, bedroom, "
                                                        "living_room"]),
    (["run", "Go to the garage", "--spawn", "bedroom"], ["no known room", "known rooms: living room / kitchen, "
                                                         "bedroom, bathroom"]),
    (["run", "Find the piano"], ["unknown object", "known objects: refrigerator (living room / kitchen), "
                                 "mirror (bedroom), sink (bathroom)"]),
    (["run", "Find the sink in the bedroom"], ["no sink in the bedroom", "the sink is in the bathroom"]),
    (["run", ""], ["the query is empty"]),
    (["run", "Go to the bedroom", "--pilot", "gpt"], ["unknown pilot 'gpt'", "valid pilots:", "oracle", "openai",
                                                      "replay", "stdin"]),
    (["run", "Go to the bedroom", "--pilot", "oracle", "--profile", "turbo"], ["valid profiles: paper, fast"]),
    (["run", "Go to the bedroom", "--scene", "castle"], ["unknown scene 'castle'", "valid scenes: cabin"]),
    (["scene", "info", "--scene", "castle"], ["unknown scene 'castle'", "valid scenes: cabin"]),
    (["run", "Go to the bedroom", "--pilot", "oracle", "--pilot-option", "detail=high"],
     ["--pilot-option 'detail' of the oracle pilot: unknown option", "valid keys: approach_m, cross_m, lateral_tol_m, "
      "view_m"]),
    (["run", "Go to the bedroom", "--pilot", "openai", "--pilot-option", "timeout=-1"],
     ["bad value for option 'timeout' of the openai pilot: Input should be greater than 0", "valid options: "]),
    (["run", "Go to the bedroom", "--pilot", "oracle", "--pilot-option", "approach_m"], ["takes KEY=VALUE"]),
    (["bench", "--pilots", "oracle", "--pilot-option", "detail=high"],
     ["--pilot-option 'detail' is taken by none of the pilots oracle", "valid keys: approach_m"]),
    (["bench", "--plugin", "no_such_module_here"], ["cannot import plugin module 'no_such_module_here'"]),
    (["bench", "--executor", "slurm"], ["unknown executor 'slurm'; valid executors: inline, local, ray"]),
]


@pytest.mark.parametrize(("args", "fragments"), BAD_INPUT, ids=[" ".join(a[:3]) for a, _ in BAD_INPUT])
def test_bad_input_is_one_clear_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                     tmp_path: Path, args: list[str], fragments: list[str]) -> None:
    out = tmp_path / "never"
    extra = ["--out", str(out)] if args[0] in ("run", "bench") else []
    code, _, err = run_main(monkeypatch, capsys, *args, *extra)
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for fragment in fragments:
        assert fragment in lines[0]
    assert not out.exists()  # validated before anything is created


def test_a_secret_pilot_option_is_refused_and_never_echoed(monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--pilot", "openai", "--pilot-option",
                            f"api_key={FAKE_KEY}", "--out", str(tmp_path / "never"))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "a secret does not go on the command line" in err and FAKE_KEY not in err


def test_pilot_option_reaches_the_pilot(runner: CliRunner, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from vlnpilot.pilots.oracle import OraclePilot

    seen: list[float] = []
    real_configure = OraclePilot._configure

    def spy(self, options):
        seen.append(options.approach_m)
        real_configure(self, options)

    monkeypatch.setattr(OraclePilot, "_configure", spy)
    result = runner.invoke(cli.app, ["run", "Go to the bedroom", "--spawn", "bedroom", "--pilot", "oracle", "-q",
                                     "--max-steps", "1", "--pilot-option", "approach_m=0.5", "--no-video",
                                     "--out", str(tmp_path / "r")])
    assert result.exit_code == 0, result.output
    assert seen == [0.5]  # coerced from the string by OracleOptions


@pytest.mark.parametrize("kind", ["under_a_file", "a_file"])
def test_unwritable_out_is_one_clear_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                          tmp_path: Path, kind: str) -> None:
    regular = tmp_path / "file.txt"
    regular.write_text("not a directory")
    out = regular / "run" if kind == "under_a_file" else regular
    code, stdout, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--out", str(out))
    assert code == 2 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(out) in lines[0]
    assert ("Not a directory" if kind == "under_a_file" else "is not a directory") in lines[0]
    assert regular.read_text() == "not a directory"


@pytest.mark.parametrize("value", ["0", "-5", "many"])
def test_bad_max_steps_is_a_usage_error(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                        value: str) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--max-steps", value)
    assert code == 2 and "Traceback" not in err
    assert "Invalid value for '--max-steps'" in err


def test_interrupt_exits_130_and_keeps_the_steps(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                                 tmp_path: Path) -> None:
    import vlnpilot.episode.run as episode_run  # the one place `vln-pilot run` and the bench fly an episode

    real = episode_run.run_episode

    def interrupted(*args, on_step=None, **kwargs):
        def step(rec):
            on_step(rec)
            if rec["step"] == 3:
                raise KeyboardInterrupt

        return real(*args, on_step=step, **kwargs)

    monkeypatch.setattr(episode_run, "run_episode", interrupted)
    out = tmp_path / "r"
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bathroom", "--pilot", "oracle", "--out", str(out))
    assert code == 130 and "Traceback" not in err  # (typer turns Ctrl-C into exit 130 before main() sees it)
    summary, steps = load_run(out)
    assert summary["status"] == "interrupted" and [s["step"] for s in steps] == [1, 2, 3]


def test_entry_point_exit_codes_in_a_subprocess(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in NO_KEYS}
    cmd = [sys.executable, "-c", "from vlnpilot.cli import main; main()"]
    bad = subprocess.run([*cmd, "run", "Go to the garage", "--spawn", "bedroom"], capture_output=True, text=True,
                         env=env, timeout=120)
    assert bad.returncode == 2
    assert bad.stderr.strip().startswith("error: no known room") and "Traceback" not in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    usage = subprocess.run([*cmd, "run", "Go to the bedroom", "--max-steps", "0"], capture_output=True, text=True,
                           env=env, timeout=120)
    assert usage.returncode == 2 and "--max-steps" in usage.stderr and "Traceback" not in usage.stderr


def test_error_message_with_brackets_is_printed_verbatim(monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Find the [red] cup [/b]", "--spawn", "bedroom")
    assert code == 2 and "Find the [red] cup [/b]" in err and "Traceback" not in err


# -- scene info ----------------------------------------------------------------------------------------------
def test_scene_info_json_parses(runner: CliRunner) -> None:
    result = runner.invoke(cli.app, ["scene", "info", "--json"])
    assert result.exit_code == 0
    info = json.loads(result.stdout)
    assert info["name"] == "cabin"
    assert {r["id"] for r in info["rooms"]} == {"living_room", "bedroom", "bathroom"}
    assert {s["id"] for s in info["spawns"]} == {"living_room", "bedroom", "bathroom"}
    assert {t["id"] for t in info["targets"]} == {"refrigerator", "mirror", "sink"}
    assert {e["via"] for e in info["topological_map"]["edges"]} == {"door_living_bedroom", "door_bedroom_bathroom"}


def test_scene_info_text(runner: CliRunner) -> None:
    result = runner.invoke(cli.app, ["scene", "info"])
    assert result.exit_code == 0
    assert "living_room" in result.stdout and "spawn" in result.stdout and "topological map" in result.stdout


# -- default pilot -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("env", "pilot", "why"), [
    ({}, "oracle", "no OPENAI_API_KEY, GEMINI_API_KEY or GOOGLE_API_KEY"),
    ({"OPENAI_API_KEY": ""}, "oracle", "oracle"),  # an empty variable is no key
    ({"OPENAI_API_KEY": FAKE_KEY}, "openai", "OPENAI_API_KEY is set"),
    ({"GEMINI_API_KEY": FAKE_KEY}, "gemini", "GEMINI_API_KEY"),
    ({"GOOGLE_API_KEY": FAKE_KEY}, "gemini", "GOOGLE_API_KEY"),
    ({"OPENAI_API_KEY": FAKE_KEY, "GEMINI_API_KEY": FAKE_KEY}, "openai", "OPENAI_API_KEY"),  # OpenAI first
    ({"ANTHROPIC_API_KEY": FAKE_KEY}, "oracle", "oracle"),
])
def test_default_pilot_spec(env: dict[str, str], pilot: str, why: str) -> None:
    name, reason = cli.default_pilot_spec(env)
    assert name == pilot and why in reason
    assert FAKE_KEY not in reason  # never echo a key


def test_default_pilot_spec_reads_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in NO_KEYS:
        monkeypatch.delenv(key, raising=False)
    assert cli.default_pilot_spec()[0] == "oracle"
    monkeypatch.setenv("GEMINI_API_KEY", FAKE_KEY)
    assert cli.default_pilot_spec()[0] == "gemini"


PLUGIN = """
from vlnpilot.bench import register_executor
from vlnpilot.bench.episode_job import Event, SimulatorCache, run_guarded


@register_executor("one-by-one")
class OneByOne:
    describe = "one by one (a plugin)"

    def __init__(self, options):
        pass

    def run(self, specs):
        sims = SimulatorCache()
        for spec in specs:
            yield Event("started", spec.key)
            record, error = run_guarded(spec, sims)
            yield Event("finished" if error is None else "failed", spec.key, record, error)
        sims.close_thread()

    def close(self):
        pass
"""


def test_a_plugin_registers_an_executor_the_command_line_can_use(monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str],
                                                                  tmp_path: Path) -> None:
    from bench_records import TINY

    (tmp_path / "my_executor_plugin.py").write_text(PLUGIN)
    (tmp_path / "tiny.yaml").write_text(TINY)
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "b"
    code, _, err = run_main(monkeypatch, capsys, "bench", "--suite", str(tmp_path / "tiny.yaml"), "--plugin",
                            "my_executor_plugin", "--executor", "one-by-one", "--out", str(out), "--no-report")
    assert code == 0, err
    assert "one by one (a plugin)" in " ".join(err.split())  # the console wraps long lines
    assert len((out / "results.jsonl").read_text().splitlines()) == 4


@pytest.mark.parametrize(("options", "frames"), [(("--no-report",), False), (("--no-report", "--frames"), True)])
def test_a_bench_without_a_report_records_no_frames_unless_asked(monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                                options: tuple[str, ...], frames: bool) -> None:
    """Nothing shows the frames of a bench without a report: they (and the chase camera's render) are skipped."""
    from bench_records import TINY

    (tmp_path / "tiny.yaml").write_text(TINY)
    out = tmp_path / "b"
    code, _, err = run_main(monkeypatch, capsys, "bench", "--suite", str(tmp_path / "tiny.yaml"), "--reps", "1",
                            "--executor", "inline", "--out", str(out), *options)
    assert code == 0, err
    assert json.loads((out / "bench.json").read_text())["config"]["save_frames"] is frames
    assert bool(list(out.glob("runs/*/*/*/frames/rear_*.jpg"))) is frames
