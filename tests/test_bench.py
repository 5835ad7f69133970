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

from vlnpilot.bench import (
    BenchError,
    BenchSettings,
    ResultsLog,
    SuiteError,
    bench_command,
    episode_seed,
    load_suite,
    percentile,
    render_tables,
    run_bench,
    summarize,
    wilson_interval,
)
from vlnpilot.bench.executors import split_workers
from vlnpilot.bench.manifest import MANIFEST
from vlnpilot.bench.runner import config_hash
from vlnpilot.bench.suite import suite_from_dict
from vlnpilot.errors import ConfigError, UnknownNameError
from vlnpilot.tasks import spl

TINY = """\
name: tiny
repetitions: 2
max_steps: 30
seed: 3
rows:
  - {id: to-bedroom, spawn: living_room, query: Go to the bedroom, goal: bedroom}
  - {id: stay, spawn: bathroom, query: Go to the bathroom}
"""


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
    with pytest.raises(SuiteError, match="repetitions must be an integer >= 1"):
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
    records = [_rec("p", "r", i + 1, o, steps=s, spl=v, latencies=lat) for i, (o, s, v, lat) in enumerate(
        [("success", 10, 0.75, [1.0, 2.0]), ("success", 20, 1.0, [3.0]), ("collision", 30, 0.0, [4.0, 5.0])])]
    s = summarize("p", records)
    assert (s.episodes, s.successes, s.collisions) == (3, 2, 1)
    assert math.isclose(s.spl, 1.75 / 3) and s.mean_steps == 20.0
    assert s.latency_p50_s == 3.0 and math.isclose(s.latency_p95_s, 4.8)  # linear between 4 and 5
    assert percentile([1, 2, 3, 4], 50) == 2.5 and percentile([], 50) is None


# ------------------------------------------------------------------------------------------- results log
def test_results_log_skips_a_torn_line_and_keeps_one_line_per_key(tmp_path: Path):
    path = tmp_path / "results.jsonl"
    a, b = _rec("p", "r", 1, "success"), _rec("p", "r", 2, "collision")
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
        run_bench(inline(tiny, out, reps=1, pilots=("oracle:other",), resume=True))
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
    with pytest.raises(ConfigError, match="unknown executor 'slurm'; valid executors: local, ray, inline"):
        run_bench(BenchSettings(suite=tiny, out=out, executor="slurm"))
    with pytest.raises(UnknownNameError, match="unknown pilot 'gpt'"):
        run_bench(inline(tiny, out, pilots=("gpt",)))
    with pytest.raises(ConfigError, match="pilot.s. given twice: oracle"):
        bench_command(suite=str(tiny), pilots="oracle,oracle", out=out)
    assert not out.exists()


# --------------------------------------------------------------------------------------------------- tables
PILOTS = ["oracle", "openai:gpt-4.1"]
GOLDEN_SUITE = {
    "name": "golden", "repetitions": 2, "max_steps": 20, "seed": 7,
    "spawn_labels": {"living_room": "Living Room and Kitchen"},
    "rows": [{"id": "lr-bath", "spawn": "living_room", "query": "Go to the bathroom"},
             {"id": "lr-fridge", "spawn": "living_room", "query": "Find the refrigerator"},
             {"id": "bed-mirror", "spawn": "bedroom", "query": "Find the mirror in the bedroom"}],
}


def _rec(pilot: str, row: str, rep: int, outcome: str, *, steps: int = 10, spl: float | None = None,
         model: str = "m", latencies: list[float] | None = None, tokens: tuple[int, int] = (0, 0),
         cost: float = 0.0, invalid: int = 0, osc: int = 0, shield: str = "off", interventions: int = 0) -> dict:
    return {
        "key": f"{pilot}|{row}|{rep}", "pilot": pilot, "model": model, "row": row, "rep": rep, "seed": 1,
        "result": {"outcome": outcome, "steps": steps, "spl": (1.0 if outcome == "success" else 0.0) if spl is None
                   else spl, "collisions": int(outcome == "collision"), "invalid_decisions": invalid,
                   "oscillations": osc, "input_tokens": tokens[0], "output_tokens": tokens[1], "cost_usd": cost,
                   "pilot_calls": len(latencies or []), "latency_s_total": sum(latencies or []), "shield": shield,
                   "interventions": interventions},
        "call_latencies_s": latencies or [], "run_dir": f"runs/{pilot}/{row}/{rep}",
        "provenance": {"prompt_hash": "abc123", "git_sha": "deadbeef"},
    }


def golden_records() -> list[dict]:
    o = dict(model="ground-truth", latencies=[0.001, 0.002])
    g = dict(model="gpt-4.1-2025-04-14", tokens=(1000, 100), cost=0.01, shield="geometry")
    return [
        _rec("oracle", "lr-bath", 1, "success", steps=40, spl=0.8, **o),
        _rec("oracle", "lr-bath", 2, "success", steps=40, spl=0.8, **o),
        _rec("oracle", "lr-fridge", 1, "success", steps=11, spl=0.9, **o),
        _rec("oracle", "lr-fridge", 2, "success", steps=11, spl=0.9, **o),
        _rec("oracle", "bed-mirror", 1, "success", steps=10, spl=1.0, **o),
        _rec("oracle", "bed-mirror", 2, "success", steps=10, spl=1.0, **o),
        _rec("openai:gpt-4.1", "lr-bath", 1, "collision", steps=12, latencies=[1.5, 2.5], invalid=1, **g),
        _rec("openai:gpt-4.1", "lr-bath", 2, "max_steps", steps=20, latencies=[2.0, 2.0], osc=3, interventions=2,
             **g),
        _rec("openai:gpt-4.1", "lr-fridge", 1, "success", steps=15, spl=0.5, latencies=[1.0], **g),
        _rec("openai:gpt-4.1", "lr-fridge", 2, "false_success", steps=9, latencies=[3.0], **g),
        _rec("openai:gpt-4.1", "bed-mirror", 1, "success", steps=8, spl=0.75, latencies=[1.2, 1.8], **g),
        # bed-mirror repetition 2 has not finished: the table says 1/1 and the footnote says incomplete
    ]

GOLDEN_MD = """\
# Bench: golden

| Starting Room | Query | oracle Ach. | oracle Coll. | oracle Steps | openai:gpt-4.1 Ach. | openai:gpt-4.1 Coll. | openai:gpt-4.1 Steps |
| --- | --- | :---: | :---: | :---: | :---: | :---: | :---: |
| Living Room and Kitchen | Go to the bathroom | 2/2 | -- | -- | 0/2 | 1 | 1 |
|  | Find the refrigerator | 2/2 | -- | -- | 1/2 | -- | -- |
| Bedroom | Find the mirror in the bedroom | 2/2 | -- | -- | 1/1 | -- | -- |

Ach. = successes / repetitions finished; Coll. = episodes ended by a collision; Steps = episodes that reached the step limit; -- = none.

## Summary per pilot

| Pilot | Model | Success | 95% CI (Wilson) | SPL | Mean steps | Collisions | Steps exceeded | False successes | Pilot errors | Invalid decisions | Oscillations | Interventions | Tokens in/out | Cost (USD) | Latency p50 (s) | Latency p95 (s) |
| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |
| oracle | ground-truth | 6/6 (100.0%) | 61.0-100.0% | 0.900 | 20.3 | 0 | 0 | 0 | 0 | 0 | 0 | 0 | 0/0 | 0.0000 | 0.002 | 0.002 |
| openai:gpt-4.1 | gpt-4.1-2025-04-14 | 2/5 (40.0%) | 11.8-76.9% | 0.250 | 12.8 | 1 | 1 | 1 | 0 | 1 | 3 | 2 | 5000/500 | 0.0500 | 1.900 | 2.825 |

SPL: mean over episodes of success weighted by path length; latency: per pilot call.

Provenance:

- oracle: model ground-truth, shield off, prompt hash abc123, git SHA deadbeef
- openai:gpt-4.1: model gpt-4.1-2025-04-14, shield geometry, prompt hash abc123, git SHA deadbeef
- seeds: per repetition, sha256 of (base seed 7, row, repetition); listed per row in table.csv
- 11/12 episodes finished (incomplete: rerun the bench with --resume); config hash 0123456789abcdef
"""

GOLDEN_CSV = """\
Starting Room,Query,oracle Ach.,oracle Coll.,oracle Steps,openai:gpt-4.1 Ach.,openai:gpt-4.1 Coll.,openai:gpt-4.1 Steps,Row,Spawn,Goal Room,Goal Target,Seeds,oracle Model,oracle Shield,oracle Prompt Hash,oracle Git SHA,openai:gpt-4.1 Model,openai:gpt-4.1 Shield,openai:gpt-4.1 Prompt Hash,openai:gpt-4.1 Git SHA
Living Room and Kitchen,Go to the bathroom,2/2,0,0,0/2,1,1,lr-bath,living_room,bathroom,,137425804 154771838,ground-truth,off,abc123,deadbeef,gpt-4.1-2025-04-14,geometry,abc123,deadbeef
Living Room and Kitchen,Find the refrigerator,2/2,0,0,1/2,0,0,lr-fridge,living_room,living_room,refrigerator,532932306 744551649,ground-truth,off,abc123,deadbeef,gpt-4.1-2025-04-14,geometry,abc123,deadbeef
Bedroom,Find the mirror in the bedroom,2/2,0,0,1/1,0,0,bed-mirror,bedroom,bedroom,mirror,1414435921 998840480,ground-truth,off,abc123,deadbeef,gpt-4.1-2025-04-14,geometry,abc123,deadbeef
"""

GOLDEN_TEX = """\
% Generated by vln-pilot bench; needs \\usepackage{booktabs} and \\usepackage{multirow}.
\\begin{table}[ht]
\\centering
\\caption{Bench golden: achievements (successes/repetitions), collisions and episodes that reached the step limit, grouped by starting room.}
\\label{tab:bench-golden}
\\begin{tabular}{lp{4.2cm}cccccc}
\\toprule
\\textbf{Starting Room} & \\textbf{Query} & \\multicolumn{3}{c}{\\textbf{oracle}} & \\multicolumn{3}{c}{\\textbf{openai:gpt-4.1}} \\\\
\\cmidrule(lr){3-5}\\cmidrule(lr){6-8}
 & & \\textbf{Ach.} & \\textbf{Coll.} & \\textbf{Steps} & \\textbf{Ach.} & \\textbf{Coll.} & \\textbf{Steps} \\\\
\\midrule
\\multirow{2}{*}{Living Room and Kitchen} & Go to the bathroom & 2/2 & -- & -- & 0/2 & 1 & 1 \\\\
 & Find the refrigerator & 2/2 & -- & -- & 1/2 & -- & -- \\\\
\\midrule
Bedroom & Find the mirror in the bedroom & 2/2 & -- & -- & 1/1 & -- & -- \\\\
\\bottomrule
\\end{tabular}

\\smallskip
\\footnotesize Ach. = successes / repetitions finished; Coll. = episodes ended by a collision; Steps = episodes that reached the step limit; -- = none.\\\\
Provenance: oracle: model ground-truth, shield off, prompt hash abc123, git SHA deadbeef; openai:gpt-4.1: model gpt-4.1-2025-04-14, shield geometry, prompt hash abc123, git SHA deadbeef; seeds: per repetition, sha256 of (base seed 7, row, repetition); listed per row in table.csv; 11/12 episodes finished (incomplete: rerun the bench with --resume); config hash 0123456789abcdef.
\\end{table}

\\begin{table}[ht]
\\centering
\\caption{Bench golden: summary per pilot. Success rate with its 95\\% Wilson interval, SPL, mean steps, collisions, step limits reached, false successes, invalid decisions, oscillations, safety-layer interventions, tokens, cost and pilot-call latency.}
\\label{tab:bench-golden-summary}
\\small
\\begin{tabular}{lrrrrrrrrrrrrrr}
\\toprule
Pilot & Success & 95\\% CI & SPL & Steps & Coll. & Exc. & False & Invalid & Osc. & Interv. & Tokens in/out & Cost (\\$) & p50 (s) & p95 (s) \\\\
\\midrule
oracle & 6/6 & 61.0--100.0\\% & 0.900 & 20.3 & 0 & 0 & 0 & 0 & 0 & 0 & 0/0 & 0.0000 & 0.002 & 0.002 \\\\
openai:gpt-4.1 & 2/5 & 11.8--76.9\\% & 0.250 & 12.8 & 1 & 1 & 1 & 1 & 3 & 2 & 5000/500 & 0.0500 & 1.900 & 2.825 \\\\
\\bottomrule
\\end{tabular}
\\end{table}
"""

GOLDEN_SUMMARY_CSV = """\
pilot,model,episodes,successes,success_rate,ci95_low,ci95_high,spl,mean_steps,collisions,steps_exceeded,false_successes,pilot_errors,invalid_decisions,oscillations,interventions,input_tokens,output_tokens,cost_usd,pilot_calls,latency_p50_s,latency_p95_s,shield,prompt_hash,git_sha
oracle,ground-truth,6,6,1.0000,0.6097,1.0000,0.9000,20.33,0,0,0,0,0,0,0,0,0,0.000000,12,0.0015,0.0020,off,abc123,deadbeef
openai:gpt-4.1,gpt-4.1-2025-04-14,5,2,0.4000,0.1176,0.7693,0.2500,12.80,1,1,1,0,1,3,2,5000,500,0.050000,8,1.9000,2.8250,geometry,abc123,deadbeef
"""


def test_tables_render_from_a_fixed_results_file_exactly(tmp_path: Path):
    suite = suite_from_dict(GOLDEN_SUITE)
    results = tmp_path / "results.jsonl"
    results.write_text("".join(json.dumps(r) + "\n" for r in golden_records()))
    tables = render_tables(suite, PILOTS, ResultsLog(results).read(), "0123456789abcdef")
    assert tables["table.md"] == GOLDEN_MD
    assert tables["table.csv"] == GOLDEN_CSV
    assert tables["table.tex"] == GOLDEN_TEX
    assert tables["summary.csv"] == GOLDEN_SUMMARY_CSV


# ------------------------------------------------------------------------------------------------ executors
def test_a_registered_executor_runs_the_bench(tiny: Path, tmp_path: Path) -> None:
    """An executor from outside the package: registered by name, it gets the options and every episode."""
    from vlnpilot.bench import register_executor
    from vlnpilot.bench.episode_job import Event, SimulatorCache, run_guarded
    from vlnpilot.bench.executors import _EXECUTORS, ExecutorOptions

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
        del _EXECUTORS["backwards"]
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
    from vlnpilot.bench.executors import _EXECUTORS

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
        del _EXECUTORS["failing"]
    assert closed == [True]
    assert (tmp_path / "b" / "table.md").is_file()  # the tables are written whatever happened
