# ruff: noqa: E501 (golden tables are long lines)
"""The bench harness without worker processes: suites, statistics, results log, tables, resume rules.

Episodes here run `inline` on a render-free simulator, so the whole file takes a few seconds.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
from pathlib import Path

import pytest
from rich.console import Console

from bench_records import TINY, bench_record
from vlnpilot.bench import (
    BenchError,
    BenchSettings,
    ResultsLog,
    SuiteError,
    bench_command,
    episode_seed,
    load_suite,
    percentile,
    run_bench,
    summarize,
    wilson_interval,
)
from vlnpilot.bench.executors import split_workers
from vlnpilot.bench.manifest import MANIFEST
from vlnpilot.bench.runner import config_hash
from vlnpilot.bench.suite import suite_from_dict
from vlnpilot.core.errors import ConfigError, UnknownNameError
from vlnpilot.tasks.task import spl


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY)
    return path


def inline(suite: Path | str, out: Path, **kw) -> BenchSettings:
    return BenchSettings(suite=suite, out=out, executor="inline", render=False, progress=False, **kw)


# ------------------------------------------------------------------------------------------------ suites
def test_paper_suite_is_table_4():
    s = load_suite("paper")
    assert (s.repetitions, s.max_steps, s.profile, s.scene) == (5, 50, "paper", "cabin")
    assert [(r.spawn, r.query) for r in s.rows] == [
        ("living_room", "Go to the bathroom"), ("living_room", "Go to the bedroom"),
        ("living_room", "Go to the living room/kitchen"),
        ("living_room", "Find the refrigerator in the living room or kitchen"),
        ("bedroom", "Go to the bedroom"), ("bedroom", "Go to the living room/kitchen"),
        ("bedroom", "Find the mirror in the bedroom"),
        ("bathroom", "Go to the bathroom"), ("bathroom", "Go to the living room/kitchen"),
        ("bathroom", "Find the sink in the bathroom")]
    assert [r.goal_target for r in s.rows if r.goal_target] == ["refrigerator", "mirror", "sink"]
    assert [s.spawn_label(x) for x in ("living_room", "bedroom", "bathroom")] == [
        "Living Room and Kitchen", "Bedroom", "Bathroom"]


def test_invalid_suite_is_refused_before_anything_runs(tmp_path: Path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("repetitions: 2\nrows:\n"
                   "  - {spawn: garage, query: Go to the bedroom}\n"
                   "  - {spawn: bedroom, query: Go to the attic}\n"
                   "  - {spawn: bedroom, query: Find the piano}\n"
                   "  - {spawn: bedroom, query: Find the mirror, goal: {room: bathroom}}\n"
                   "  - {spawn: bedroom, query: Go to the bathroom, goal: {room: cellar}}\n")
    out = tmp_path / "out"
    with pytest.raises(SuiteError) as err:
        run_bench(inline(bad, out))
    msg = str(err.value)
    assert "row 1: unknown spawn 'garage'; valid spawns: living_room, bedroom, bathroom" in msg
    assert "row 2: no known room in 'Go to the attic'; known rooms: living room / kitchen, bedroom, bathroom" in msg
    assert "row 3: unknown object in 'Find the piano'; known objects: refrigerator" in msg
    assert "row 4: the goal says bathroom but the query 'Find the mirror' parses to bedroom / mirror" in msg
    assert "row 5: unknown goal room 'cellar'; valid rooms: living_room, bedroom, bathroom" in msg
    assert not out.exists()  # refused before the output directory was even created


def test_suite_keys_ids_and_numbers_are_checked():
    with pytest.raises(SuiteError, match=r"unknown key\(s\) 'repetition'; valid keys: name"):
        suite_from_dict({"repetition": 3, "rows": [{"spawn": "bedroom", "query": "Go to the bedroom"}]})
    with pytest.raises(SuiteError, match="repetitions must be an integer in 1..10000"):
        suite_from_dict({"repetitions": 0, "rows": [{"spawn": "bedroom", "query": "Go to the bedroom"}]})
    with pytest.raises(SuiteError, match="row 2 \\(a\\): the id is also used by row 1"):
        suite_from_dict({"rows": [{"id": "a", "spawn": "bedroom", "query": "Go to the bedroom"},
                                  {"id": "a", "spawn": "bathroom", "query": "Go to the bedroom"}]})
    with pytest.raises(SuiteError, match="unknown suite 'nope'"):
        load_suite("nope")


def test_seeds_are_per_repetition_stable_and_pilot_independent():
    seeds = {episode_seed(0, "row", rep) for rep in range(1, 6)}
    assert len(seeds) == 5 and all(0 <= s < 2**31 for s in seeds)
    assert episode_seed(0, "row", 1) == episode_seed(0, "row", 1) != episode_seed(1, "row", 1)
    assert episode_seed(0, "row", 1) == int(hashlib.sha256(b"0/row/1").hexdigest()[:8], 16) & 0x7FFFFFFF


def test_workers_split_into_processes_and_threads():
    assert split_workers(2, 2) == [1, 1]
    assert split_workers(16, 2) == [8, 8]
    assert split_workers(5, 2) == [3, 2]
    assert split_workers(1, 8) == [1]


# -------------------------------------------------------------------------------------------- statistics
def test_wilson_interval_matches_hand_computation():
    # 8/10: p=.8, z=1.96: centre (.8 + 1.9208/10) / 1.38415 = .71674, half 1.41601 * sqrt(.016 + .0096037) = .22658
    lo, hi = wilson_interval(8, 10)
    assert (round(lo, 4), round(hi, 4)) == (0.4902, 0.9433)
    assert tuple(round(x, 4) for x in wilson_interval(0, 10)) == (0.0, 0.2775)
    assert tuple(round(x, 4) for x in wilson_interval(10, 10)) == (0.7225, 1.0)
    assert tuple(round(x, 4) for x in wilson_interval(50, 50)) == (0.9287, 1.0)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_spl_and_summary_aggregate_as_by_hand():
    # success, shortest 3 m, flown 4 m -> .75; success on the shortest path -> 1; failure -> 0: mean .5833
    values = [spl(True, 3.0, 4.0), spl(True, 2.0, 2.0), spl(False, 2.0, 9.0)]
    assert values == [0.75, 1.0, 0.0]
    records = [bench_record("p", "r", i + 1, o, steps=s, spl=v, latencies=lat) for i, (o, s, v, lat) in enumerate(
        [("success", 10, 0.75, [1.0, 2.0]), ("success", 20, 1.0, [3.0]), ("collision", 30, 0.0, [4.0, 5.0])])]
    s = summarize("p", records)
    assert (s.episodes, s.successes, s.collisions) == (3, 2, 1)
    assert math.isclose(s.spl, 1.75 / 3) and s.mean_steps == 20.0
    assert s.latency_p50_s == 3.0 and math.isclose(s.latency_p95_s, 4.8)  # linear between 4 and 5
    assert percentile([1, 2, 3, 4], 50) == 2.5 and percentile([], 50) is None


# ------------------------------------------------------------------------------------------- results log
def test_results_log_skips_a_torn_line_and_keeps_one_line_per_key(tmp_path: Path):
    path = tmp_path / "results.jsonl"
    a, b = bench_record("p", "r", 1, "success"), bench_record("p", "r", 2, "collision")
    path.write_text(json.dumps(a) + "\n" + json.dumps({**a, "result": {"outcome": "max_steps"}}) + "\n"
                    + json.dumps(b)[:40])
    log = ResultsLog(path)
    assert [(r["rep"], r["result"]["outcome"]) for r in log.read()] == [(1, "success")]  # first line per key wins
    log.append(b)  # cuts the torn tail before appending
    log.close()
    lines = path.read_text().splitlines()
    assert len(lines) == 3 and json.loads(lines[-1])["rep"] == 2
    assert [r["rep"] for r in ResultsLog(path).read()] == [1, 2]


# ------------------------------------------------------------------------------------------- resume rules
def test_bench_writes_results_manifest_and_tables_then_resume_is_a_no_op(tiny: Path, tmp_path: Path):
    out = tmp_path / "bench"
    report = run_bench(inline(tiny, out))
    assert (report.episodes, report.finished, report.ran, report.failed) == (4, 4, 4, {})
    records = ResultsLog(out / "results.jsonl").read()
    assert sorted(r["key"] for r in records) == ["oracle|stay|1", "oracle|stay|2", "oracle|to-bedroom|1",
                                                 "oracle|to-bedroom|2"]
    r = next(r for r in records if r["key"] == "oracle|to-bedroom|2")
    assert r["seed"] == episode_seed(3, "to-bedroom", 2) and r["model"] == "ground-truth"
    assert r["result"]["outcome"] == "success" and r["run_dir"] == "runs/oracle/to-bedroom/2"
    assert set(r["provenance"]) >= {"prompt_hash", "git_sha", "config_hash", "finished_at", "worker"}
    assert len(r["call_latencies_s"]) == r["result"]["pilot_calls"]
    summary = json.loads((out / r["run_dir"] / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["config"]["seed"] == r["seed"]
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["config_hash"] == report.config_hash == config_hash(manifest["config"])
    assert {p.name for p in out.iterdir()} >= {"table.md", "table.csv", "table.tex", "summary.csv"}

    with pytest.raises(BenchError, match="already holds a bench .4 of 4 episodes finished.: pass --resume"):
        run_bench(inline(tiny, out))
    again = run_bench(inline(tiny, out, resume=True))
    assert (again.ran, again.finished) == (0, 4)
    assert len((out / "results.jsonl").read_text().splitlines()) == 4
    assert len(json.loads((out / MANIFEST).read_text())["sessions"]) == 2


def test_resume_with_a_changed_config_is_refused(tiny: Path, tmp_path: Path):
    out = tmp_path / "bench"
    run_bench(inline(tiny, out, reps=1))
    before = (out / "results.jsonl").read_bytes(), (out / MANIFEST).read_bytes()
    with pytest.raises(BenchError) as err:
        run_bench(inline(tiny, out, reps=2, resume=True))
    assert "cannot resume" in str(err.value) and "repetitions: recorded 1, now 2" in str(err.value)
    with pytest.raises(BenchError, match="max_steps: recorded 30, now 29"):
        run_bench(inline(tiny, out, reps=1, max_steps=29, resume=True))
    changed = tmp_path / "changed.yaml"
    changed.write_text(TINY.replace("Go to the bathroom", "Go to the bedroom"))
    with pytest.raises(BenchError, match="suite rows"):
        run_bench(inline(changed, out, reps=1, resume=True))
    with pytest.raises(BenchError, match="pilots: recorded"):
        run_bench(inline(tiny, out, reps=1, pilots=("noisy-oracle",), resume=True))
    assert ((out / "results.jsonl").read_bytes(), (out / MANIFEST).read_bytes()) == before  # untouched
    # Executor and workers are not part of the config: resuming with others is fine.
    assert run_bench(inline(tiny, out, reps=1, workers=3, resume=True)).finished == 2


def test_bench_command_runs_a_suite_with_a_shield_and_returns_its_directory(tiny: Path, tmp_path: Path):
    out = bench_command(suite=str(tiny), pilots="oracle", reps=1, out=tmp_path / "b", executor="inline",
                        progress=False, shield="geometry", render=False, console=Console(file=io.StringIO()))
    assert out == tmp_path / "b"
    records = ResultsLog(out / "results.jsonl").read()
    assert len(records) == 2 and {r["result"]["shield"] for r in records} == {"geometry"}
    config = json.loads((out / MANIFEST).read_text())["config"]
    assert config["episode_options"] == {"shield": "geometry"}
    assert "shield geometry" in (out / "table.md").read_text()


def test_bad_options_are_refused_before_anything_runs(tiny: Path, tmp_path: Path):
    out = tmp_path / "b"
    with pytest.raises(ConfigError, match="unknown shield 'laser'; valid shields: off, geometry, depth"):
        run_bench(inline(tiny, out, episode_options={"shield": "laser"}))
    with pytest.raises(ConfigError, match="unknown executor 'slurm'; valid executors: inline, local, ray"):
        run_bench(BenchSettings(suite=tiny, out=out, executor="slurm"))
    with pytest.raises(UnknownNameError, match="unknown pilot 'gpt'"):
        run_bench(inline(tiny, out, pilots=("gpt",)))
    with pytest.raises(ConfigError, match="pilot.s. given twice: oracle"):
        bench_command(suite=str(tiny), pilots="oracle,oracle", out=out)
    assert not out.exists()


# ------------------------------------------------------------------------------------------------ executors
def test_a_registered_executor_runs_the_bench(tiny: Path, tmp_path: Path) -> None:
    """An executor from outside the package: registered by name, it gets the options and every episode."""
    from vlnpilot.bench import register_executor
    from vlnpilot.bench.episode_job import Event, SimulatorCache, run_guarded
    from vlnpilot.bench.executors import EXECUTOR_REGISTRY, ExecutorOptions

    seen: dict[str, object] = {}

    class Backwards:  # the last episode first: results must not depend on the order episodes finish in
        describe = "backwards (test)"

        def __init__(self, options: ExecutorOptions) -> None:
            seen["options"] = options

        def run(self, specs):
            sims = SimulatorCache()
            for spec in reversed(specs):
                yield Event("started", spec.key)
                record, error = run_guarded(spec, sims)
                yield Event("finished" if error is None else "failed", spec.key, record, error)
            sims.close_thread()

        def close(self) -> None:
            seen["closed"] = True

    register_executor("backwards")(Backwards)
    try:
        report = run_bench(BenchSettings(suite=tiny, out=tmp_path / "b", executor="backwards", workers=3,
                                         render=False, progress=False))
    finally:
        EXECUTOR_REGISTRY.unregister("backwards")
    assert report.complete and report.executor == "backwards (test)" and seen["closed"] is True
    assert seen["options"] == ExecutorOptions(workers=3, ray_address=None, plugins=())
    reference = run_bench(inline(tiny, tmp_path / "i"))
    keys = [(s.pilot, s.episodes, s.successes, s.spl) for s in report.summaries]
    assert keys == [(s.pilot, s.episodes, s.successes, s.spl) for s in reference.summaries]
    with pytest.raises(ConfigError, match="unknown executor 'backwards'"):
        run_bench(BenchSettings(suite=tiny, out=tmp_path / "c", executor="backwards"))


def test_the_executor_is_closed_when_the_bench_fails(tiny: Path, tmp_path: Path) -> None:
    from vlnpilot.bench import register_executor
    from vlnpilot.bench.episode_job import Event
    from vlnpilot.bench.executors import EXECUTOR_REGISTRY

    closed = []

    class Failing:
        describe = "failing (test)"

        def __init__(self, options) -> None:
            pass

        def run(self, specs):
            for spec in specs:
                yield Event("started", spec.key)
                yield Event("failed", spec.key, error="RuntimeError: no GPU today")

        def close(self) -> None:
            closed.append(True)

    register_executor("failing")(Failing)
    try:
        with pytest.raises(BenchError, match="no GPU today"):
            run_bench(BenchSettings(suite=tiny, out=tmp_path / "b", executor="failing", progress=False))
    finally:
        EXECUTOR_REGISTRY.unregister("failing")
    assert closed == [True]
    assert (tmp_path / "b" / "table.md").is_file()  # the tables are written whatever happened


def test_a_bench_without_frames_renders_no_chase_view_and_a_resume_keeps_the_choice(tiny: Path, tmp_path: Path,
                                                                                    monkeypatch) -> None:
    import vlnpilot.sim

    built: list[bool] = []

    class Spy(vlnpilot.sim.Simulator):
        def __init__(self, scene, config):
            super().__init__(scene, config)
            built.append(config.rear_camera)

    monkeypatch.setattr(vlnpilot.sim, "Simulator", Spy)
    out, console = tmp_path / "b", Console(file=io.StringIO())
    bench_command(suite=str(tiny), pilots="oracle", reps=1, out=out, executor="inline", progress=False,
                  frames=False, console=console)
    assert built == [False] and not list(out.glob("runs/*/*/*/frames/*"))
    assert json.loads((out / MANIFEST).read_text())["config"]["save_frames"] is False
    bench_command(suite=str(tiny), pilots="oracle", reps=1, out=tmp_path / "c", executor="inline", progress=False,
                  console=console)  # the default: frames, with the chase view the report's episode pages show
    assert built == [False, True]
    assert {p.name.split("_")[0] for p in (tmp_path / "c/runs/oracle/to-bedroom/1/frames").iterdir()} == {"front",
                                                                                                         "rear"}
    # resuming without saying keeps what the bench started with (else the config hash would refuse it)
    results = out / "results.jsonl"
    results.write_text(results.read_text().splitlines(keepends=True)[0])  # one episode to fly again
    bench_command(suite=str(tiny), pilots="oracle", reps=1, out=out, executor="inline", progress=False, resume=True,
                  console=console)
    assert len(ResultsLog(results).read()) == 2
    assert built == [False, True, False]


@pytest.mark.parametrize("pilots", ["oracle,ORACLE", "Oracle, oracle", "openai:gpt-4.1,OpenAI:gpt-4.1"])
def test_a_pilot_given_twice_in_another_case_is_refused(pilots: str):
    from vlnpilot.bench.runner import parse_pilots

    with pytest.raises(ConfigError, match=r"pilot\(s\) given twice: .*not case-sensitive"):
        parse_pilots(pilots)


def test_models_that_differ_in_case_are_two_pilots():
    from vlnpilot.bench.runner import parse_pilots

    assert parse_pilots("files:A,files:a") == ("files:A", "files:a")  # a directory's case counts
