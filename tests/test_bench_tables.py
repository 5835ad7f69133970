# ruff: noqa: E501 (golden tables are long lines)
"""The bench tables (bench/tables.py): the paper's Table 4 in Markdown, CSV and LaTeX, and the per-pilot summary,
rendered from given results records (no episode runs here)."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import pytest

from bench_records import bench_record
from vlnpilot.bench import ResultsLog, render_tables
from vlnpilot.bench.suite import suite_from_dict

PILOTS = ["oracle", "openai:gpt-4.1"]
GOLDEN_SUITE = {
    "name": "golden", "repetitions": 2, "max_steps": 20, "seed": 7,
    "spawn_labels": {"living_room": "Living Room and Kitchen"},
    "rows": [{"id": "lr-bath", "spawn": "living_room", "query": "Go to the bathroom"},
             {"id": "lr-fridge", "spawn": "living_room", "query": "Find the refrigerator"},
             {"id": "bed-mirror", "spawn": "bedroom", "query": "Find the mirror in the bedroom"}],
}


def golden_records() -> list[dict]:
    o = dict(model="ground-truth", latencies=[0.001, 0.002])
    g = dict(model="gpt-4.1-2025-04-14", tokens=(1000, 100), cost=0.01, shield="geometry", cached=384)
    return [
        bench_record("oracle", "lr-bath", 1, "success", steps=40, spl=0.8, **o),
        bench_record("oracle", "lr-bath", 2, "success", steps=40, spl=0.8, **o),
        bench_record("oracle", "lr-fridge", 1, "success", steps=11, spl=0.9, **o),
        bench_record("oracle", "lr-fridge", 2, "success", steps=11, spl=0.9, **o),
        bench_record("oracle", "bed-mirror", 1, "success", steps=10, spl=1.0, **o),
        bench_record("oracle", "bed-mirror", 2, "success", steps=10, spl=1.0, **o),
        bench_record("openai:gpt-4.1", "lr-bath", 1, "collision", steps=12, latencies=[1.5, 2.5], invalid=1, **g),
        bench_record("openai:gpt-4.1", "lr-bath", 2, "max_steps", steps=20, latencies=[2.0, 2.0], osc=3, interventions=2,
             **g),
        bench_record("openai:gpt-4.1", "lr-fridge", 1, "success", steps=15, spl=0.5, latencies=[1.0], **g),
        bench_record("openai:gpt-4.1", "lr-fridge", 2, "false_success", steps=9, latencies=[3.0], **g),
        bench_record("openai:gpt-4.1", "bed-mirror", 1, "success", steps=8, spl=0.75, latencies=[1.2, 1.8], **g),
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

| Pilot | Model | Success | 95% CI (Wilson) | SPL | Mean steps | Collisions | Steps exceeded | False successes | Pilot errors | Invalid decisions | Oscillations | Interventions | Tokens in/out | Cached | Tokens in/call | Cost (USD) | Latency p50 (s) | Latency p95 (s) |
| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |
| oracle | ground-truth | 6/6 (100.0%) | 61.0-100.0% | 0.900 | 20.3 | 0 | 0 | 0 | 0 | 0 | 0 | 0 | 0/0 | -- | 0 | 0.0000 | 0.002 | 0.002 |
| openai:gpt-4.1 | gpt-4.1-2025-04-14 | 2/5 (40.0%) | 11.8-76.9% | 0.250 | 12.8 | 1 | 1 | 1 | 0 | 1 | 3 | 2 | 5000/500 | 38.4% | 625 | 0.0500 | 1.900 | 2.825 |

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
pilot,model,episodes,successes,success_rate,ci95_low,ci95_high,spl,mean_steps,collisions,steps_exceeded,false_successes,pilot_errors,invalid_decisions,oscillations,interventions,input_tokens,output_tokens,cached_tokens,cost_usd,pilot_calls,latency_p50_s,latency_p95_s,shield,prompt_hash,git_sha
oracle,ground-truth,6,6,1.0000,0.6097,1.0000,0.9000,20.33,0,0,0,0,0,0,0,0,0,0,0.000000,12,0.0015,0.0020,off,abc123,deadbeef
openai:gpt-4.1,gpt-4.1-2025-04-14,5,2,0.4000,0.1176,0.7693,0.2500,12.80,1,1,1,0,1,3,2,5000,500,1920,0.050000,8,1.9000,2.8250,geometry,abc123,deadbeef
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


# A suite whose names hold every character LaTeX treats specially, and Markdown's and CSV's separators (the
# comma in the label: a comma in the query would make it a two-clause mission).
QUERY = 'Find the mirror_1 (50% of $5 {box} #1 ~ ^ \\ a|b "x" & c)'
ODD_SUITE = {"name": "r&d_50%", "repetitions": 2, "spawn_labels": {"bedroom": "Bed, & Bath_1"},
             "rows": [{"id": "q", "spawn": "bedroom", "query": QUERY}]}
ODD_PILOTS = ["p_1", "idle"]  # 'idle' has no records yet


@pytest.fixture
def odd() -> dict[str, str]:
    return render_tables(suite_from_dict(ODD_SUITE), ODD_PILOTS, [bench_record("p_1", "q", 1, "collision")])


def _tex_rows(tex: str) -> list[str]:
    return [line for line in tex.splitlines() if line.endswith(r"\\") and "&" in line]


def test_latex_escapes_every_special_character(odd):
    tex = odd["table.tex"]
    escaped_query = (r"Find the mirror\_1 (50\% of \$5 \{box\} \#1 \textasciitilde{} \textasciicircum{} "
                     r'\textbackslash{} a|b "x" \& c)')
    row = next(line for line in _tex_rows(tex) if "mirror" in line)
    assert row.startswith(r"Bed, \& Bath\_1 & " + escaped_query + " & ")
    assert r"\caption{Bench r\&d\_50\%: achievements" in tex
    assert r"\multicolumn{3}{c}{\textbf{p\_1}}" in tex and "\np\\_1 & 0/1 & " in tex
    for line in _tex_rows(tex):  # no special character is left bare; the braces left are the commands' own
        body = re.sub(r"\\[&%$#_{}]|\\[A-Za-z]+|\\\\$", "", line)
        assert not set(body) & set("%$#_~^\\"), line
        assert body.count("{") == body.count("}"), line


def test_latex_labels_are_plain_keys(odd):
    """\\label{} takes a key, not text: an escape such as \\_ or \\& inside it breaks the document."""
    labels = re.findall(r"\\label\{([^}]*)\}", odd["table.tex"])
    assert labels == ["tab:bench-r-d-50-", "tab:bench-r-d-50--summary"]


def test_latex_columns_follow_the_pilots(odd):
    tex = odd["table.tex"]
    assert r"\begin{tabular}{lp{4.2cm}cccccc}" in tex  # Starting Room, Query, then Ach./Coll./Steps per pilot
    assert r"\cmidrule(lr){3-5}\cmidrule(lr){6-8}" in tex
    row = next(line for line in _tex_rows(tex) if "mirror" in line)
    assert row.endswith(" & 0/1 & 1 & -- & 0/0 & -- & -- \\\\")  # '--' for zero, as in the paper
    assert row.count("&") - row.count(r"\&") == 7  # 8 cells


def test_markdown_cells_line_up_and_escape_the_pipe(odd):
    md = odd["table.md"]
    table = [line for line in md.splitlines() if line.startswith("| ")]
    header = table[0]
    assert header == ("| Starting Room | Query | p_1 Ach. | p_1 Coll. | p_1 Steps | idle Ach. | idle Coll. "
                      "| idle Steps |")
    assert f"| Bed, & Bath_1 | {QUERY.replace('|', chr(92) + '|')} | 0/1 | 1 | -- | 0/0 | -- | -- |" in table
    for line in table[:3]:  # the Table 4 part: header, rule, one row
        assert len(re.split(r"(?<!\\)\|", line)) == len(re.split(r"(?<!\\)\|", header)), line


def test_csv_quotes_what_it_must_and_keeps_numbers(odd):
    rows = list(csv.reader(io.StringIO(odd["table.csv"])))
    head, row = rows
    assert len(row) == len(head)
    cells = dict(zip(head, row, strict=True))
    assert cells["Query"] == QUERY and cells["Starting Room"] == "Bed, & Bath_1"  # read back verbatim
    assert (cells["p_1 Ach."], cells["p_1 Coll."], cells["p_1 Steps"]) == ("0/1", "1", "0")  # numbers, not '--'
    assert (cells["Row"], cells["Spawn"], cells["Goal Room"], cells["Goal Target"]) == ("q", "bedroom", "bedroom",
                                                                                      "mirror")
    assert len(cells["Seeds"].split()) == 2  # one per repetition
    assert (cells["p_1 Model"], cells["p_1 Shield"], cells["idle Model"]) == ("m", "off", "--")


def test_a_pilot_without_records_gets_empty_cells_not_an_error(odd):
    md = odd["table.md"]
    assert "| idle | -- | 0/0 (0.0%) | -- | 0.000 | 0.0 | 0 |" in md  # no interval for no episodes
    assert "- idle: model --, prompt hash --, git SHA --" in md
    assert "- 1/4 episodes finished (incomplete: rerun the bench with --resume)" in md
    summary = {r["pilot"]: r for r in csv.DictReader(io.StringIO(odd["summary.csv"]))}
    assert summary["idle"]["episodes"] == "0" and summary["idle"]["latency_p50_s"] == ""
    assert summary["p_1"]["episodes"] == "1" and summary["p_1"]["collisions"] == "1"


def test_no_pilots_renders_the_rows_alone():
    tables = render_tables(suite_from_dict(ODD_SUITE), [], [])
    assert "| Starting Room | Query |\n| --- | --- |\n" in tables["table.md"]
    assert "0/0 episodes finished\n" in tables["table.md"]
    assert tables["table.csv"].splitlines()[0] == "Starting Room,Query,Row,Spawn,Goal Room,Goal Target,Seeds"
    assert len(tables["summary.csv"].splitlines()) == 1  # the header only
    assert r"\begin{tabular}{lp{4.2cm}}" in tables["table.tex"]


def test_a_finished_bench_says_so_with_its_config_hash():
    suite = suite_from_dict({**ODD_SUITE, "repetitions": 1})
    tables = render_tables(suite, ["p_1"], [bench_record("p_1", "q", 1, "success", latencies=[0.5])], "cafe")
    assert "- 1/1 episodes finished; config hash cafe\n" in tables["table.md"]
    assert "incomplete" not in tables["table.md"] + tables["table.tex"]
    assert "| p_1 | m | 1/1 (100.0%) |" in tables["table.md"]
