"""The bench tables: the paper's Table 4 layout (Markdown, CSV, LaTeX with booktabs) and a per-pilot summary.

    Starting Room | Query | for each pilot: Ach. (successes/repetitions), Coll. (episodes ended by a
    collision), Steps (episodes that hit the step limit); '--' for zero, as in the paper.

Rows are grouped by starting room in suite order. Provenance (pilot and model, prompt hash, git SHA,
seeds, config hash) is a footnote in Markdown and LaTeX, and columns in the CSV files. Output depends only
on the suite, the pilots and the records (no clock), so a results file always renders to the same bytes.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Sequence
from itertools import groupby
from typing import Any

from vlnpilot.bench.results import CellStats, PilotSummary, cell_stats, summarize
from vlnpilot.bench.suite import Suite, SuiteRow, episode_seed
from vlnpilot.episode import measures as episode_measures
from vlnpilot.episode.measures import Column, column

TABLE_MD, TABLE_CSV, TABLE_TEX, SUMMARY_CSV = "table.md", "table.csv", "table.tex", "summary.csv"
LEGEND = ("Ach. = successes / repetitions finished; Coll. = episodes ended by a collision; Steps = episodes "
          "that reached the step limit; -- = none.")


def _dash(n: int) -> str:
    return str(n) if n else "--"


def _ach(c: CellStats) -> str:
    """Successes of the cell's episodes; goals rightly reported unreachable are named apart (issue 24)."""
    return f"{c.successes}/{c.episodes}" + (f" (+{c.unreachable} unreachable)" if c.unreachable else "")


def _fmt(x: float | None, digits: int = 3) -> str:
    return "--" if x is None else f"{x:.{digits}f}"


def _join(values: Iterable[str | None]) -> str:
    vals = sorted({str(v) for v in values if v is not None})
    return ", ".join(vals) if vals else "--"


class _Data:
    """Records indexed by (pilot, row), with the provenance of each pilot."""

    def __init__(self, suite: Suite, pilots: Sequence[str], records: Sequence[dict[str, Any]]):
        self.suite, self.pilots = suite, list(pilots)
        self.cells: dict[tuple[str, str], list[dict[str, Any]]] = {}
        for r in records:
            self.cells.setdefault((r["pilot"], r["row"]), []).append(r)
        self.by_pilot = {p: [r for r in records if r["pilot"] == p] for p in self.pilots}
        self.expected = len(suite.rows) * suite.repetitions * len(self.pilots)
        self.finished = sum(len(v) for v in self.by_pilot.values())

    def cell(self, pilot: str, row: SuiteRow) -> CellStats:
        return cell_stats(self.cells.get((pilot, row.id), []))

    def groups(self) -> list[tuple[str, list[SuiteRow]]]:
        return [(self.suite.spawn_label(spawn), list(rows))
                for spawn, rows in groupby(self.suite.rows, key=lambda r: r.spawn)]

    def seeds(self, row: SuiteRow) -> list[int]:
        return [episode_seed(self.suite.seed, row.id, rep) for rep in range(1, self.suite.repetitions + 1)]

    def provenance(self, pilot: str) -> dict[str, str]:
        rs = self.by_pilot[pilot]
        return {"model": _join([r.get("model") for r in rs]),
                "shield": _join([r["result"].get("shield") for r in rs]),
                "prompt_hash": _join([r.get("provenance", {}).get("prompt_hash") for r in rs]),
                "git_sha": _join([r.get("provenance", {}).get("git_sha") for r in rs])}

    def summaries(self) -> list[PilotSummary]:
        return [summarize(p, self.by_pilot[p]) for p in self.pilots]

    def notes(self, config_hash: str | None) -> list[str]:
        out = []
        for p in self.pilots:
            pv = self.provenance(p)
            shield = f", shield {pv['shield']}" if pv["shield"] != "--" else ""
            out.append(f"{p}: model {pv['model']}{shield}, prompt hash {pv['prompt_hash']}, git SHA {pv['git_sha']}")
        out.append(f"seeds: per repetition, sha256 of (base seed {self.suite.seed}, row, repetition); "
                   "listed per row in table.csv")
        tail = f"{self.finished}/{self.expected} episodes finished"
        if self.finished < self.expected:
            tail += " (incomplete: rerun the bench with --resume)"
        if config_hash:
            tail += f"; config hash {config_hash}"
        out.append(tail)
        return out


# ---------------------------------------------------------------------------------------------- Markdown
def _md_row(cells: Sequence[str]) -> str:
    return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"


def _rate(s: PilotSummary) -> str:
    return f"{s.successes}/{s.episodes} ({100 * s.success_rate:.1f}%)"


def _ci(s: PilotSummary, dash: str = "-", percent: str = "%") -> str:
    return f"{100 * s.ci_low:.1f}{dash}{100 * s.ci_high:.1f}{percent}" if s.episodes else "--"


def _latency(name: str, md: str, tex: str, rank: int) -> Column:
    return Column(rank, md, tex, (name,), lambda s: _fmt(getattr(s, name)),
                  lambda s: ("" if getattr(s, name) is None else f"{getattr(s, name):.4f}",))


# The bench's own columns of the summary per pilot. The measures' columns (`episode_measures.columns()`) go
# between them by rank: SPL 50, Collisions 70, Invalid decisions 110, ..., a new measure's last by default.
_OWN_COLUMNS = (
    Column(0, "Pilot", "Pilot", ("pilot",), lambda s: s.pilot, lambda s: (s.pilot,), lambda s: tex_escape(s.pilot)),
    Column(10, "Model", None, ("model",), lambda s: _join(s.models), lambda s: (_join(s.models),)),
    Column(20, None, None, ("episodes",), lambda s: str(s.episodes), lambda s: (s.episodes,)),
    Column(30, "Success", "Success", ("successes", "success_rate"), _rate,
           lambda s: (s.successes, f"{s.success_rate:.4f}"), lambda s: f"{s.successes}/{s.episodes}"),
    Column(40, "95% CI (Wilson)", "95\\% CI", ("ci95_low", "ci95_high"), _ci,
           lambda s: (f"{s.ci_low:.4f}", f"{s.ci_high:.4f}"), lambda s: _ci(s, "--", "\\%")),
    column("mean_steps", md="Mean steps", tex="Steps", fmt=".1f", csv_fmt=".2f", rank=60),
    column("steps_exceeded", md="Steps exceeded", tex="Exc.", rank=80),
    column("false_successes", md="False successes", tex="False", rank=90),
    column("pilot_errors", md="Pilot errors", tex=None, rank=100),
    _latency("latency_p50_s", "Latency p50 (s)", "p50 (s)", 170),
    _latency("latency_p95_s", "Latency p95 (s)", "p95 (s)", 180),
)


def summary_columns(summaries: Sequence[Any] | None = None) -> list[Column]:
    """The columns of the summary per pilot, the bench's own and the measures', in rank order; a column with a
    `when` only if it holds for one of `summaries` (the mission columns only in a bench with missions)."""
    cols = [c for c in (*_OWN_COLUMNS, *episode_measures.columns())
            if c.when is None or (summaries is not None and any(c.when(s) for s in summaries))]
    return sorted(cols, key=lambda c: c.rank)


def query_cell(row: SuiteRow) -> str:
    """A row's query as the tables show it; a row with events names them (issue 24): 'Go to the bathroom
    [events: person]'."""
    return f"{row.query} [events: {row.events_named}]" if row.events else row.query


def render_markdown(data: _Data, config_hash: str | None = None) -> str:
    head = ["Starting Room", "Query"] + [f"{p} {c}" for p in data.pilots for c in ("Ach.", "Coll.", "Steps")]
    lines = [f"# Bench: {data.suite.name}", "", _md_row(head), _md_row(["---"] * 2 + [":---:"] * (len(head) - 2))]
    for label, rows in data.groups():
        for i, row in enumerate(rows):
            cells = [label if i == 0 else "", query_cell(row)]
            for p in data.pilots:
                c = data.cell(p, row)
                cells += [_ach(c), _dash(c.collisions), _dash(c.steps_exceeded)]
            lines.append(_md_row(cells))
    cols = [c for c in summary_columns(data.summaries()) if c.md is not None]
    lines += ["", LEGEND, "", "## Summary per pilot", "", _md_row([str(c.md) for c in cols]),
              _md_row(["---"] * 2 + ["---:"] * (len(cols) - 2))]
    lines += [_md_row([c.text(s) for c in cols]) for s in data.summaries()]
    lines += ["", "SPL: mean over episodes of success weighted by path length; latency: per pilot call.", "",
              "Provenance:", ""]
    lines += [f"- {n}" for n in data.notes(config_hash)]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------------- CSV
def render_csv(data: _Data) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    head = ["Starting Room", "Query"] + [f"{p} {c}" for p in data.pilots for c in ("Ach.", "Coll.", "Steps")]
    head += ["Row", "Spawn", "Goal Room", "Goal Target", "Seeds"]
    head += [f"{p} {c}" for p in data.pilots for c in ("Model", "Shield", "Prompt Hash", "Git SHA")]
    w.writerow(head)
    prov = {p: data.provenance(p) for p in data.pilots}
    for label, rows in data.groups():
        for row in rows:
            cells: list[Any] = [label, query_cell(row)]
            for p in data.pilots:
                c = data.cell(p, row)
                cells += [_ach(c), c.collisions, c.steps_exceeded]
            cells += [row.id, row.spawn, row.goal_room, row.goal_target or "", " ".join(map(str, data.seeds(row)))]
            for p in data.pilots:
                cells += [prov[p]["model"], prov[p]["shield"], prov[p]["prompt_hash"], prov[p]["git_sha"]]
            w.writerow(cells)
    return buf.getvalue()


def render_summary_csv(data: _Data) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = summary_columns(data.summaries())
    w.writerow([h for c in cols for h in c.csv] + ["shield", "prompt_hash", "git_sha"])
    for s in data.summaries():
        pv = data.provenance(s.pilot)
        w.writerow([v for c in cols for v in c.csv_cells(s)] + [pv["shield"], pv["prompt_hash"], pv["git_sha"]])
    return buf.getvalue()


# -------------------------------------------------------------------------------------------------- LaTeX
_TEX_ESCAPES = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
                "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}


def tex_escape(text: str) -> str:
    return "".join(_TEX_ESCAPES.get(ch, ch) for ch in str(text))


def _label(name: str) -> str:
    """A suite name as a LaTeX label key: escapes such as \\_ do not belong inside \\label{}, so other
    characters than letters, digits, '-', ':' and '.' become '-'."""
    return re.sub(r"[^A-Za-z0-9:.-]+", "-", name)


def render_tex(data: _Data, config_hash: str | None = None) -> str:
    """Two booktabs tables (needs \\usepackage{booktabs,multirow}): Table 4's layout, then the summary."""
    n = len(data.pilots)
    e = tex_escape
    lines = [
        "% Generated by vln-pilot bench; needs \\usepackage{booktabs} and \\usepackage{multirow}.",
        r"\begin{table}[ht]", r"\centering",
        r"\caption{Bench " + e(data.suite.name) + r": achievements (successes/repetitions), collisions and "
        r"episodes that reached the step limit, grouped by starting room.}",
        r"\label{tab:bench-" + _label(data.suite.name) + "}",
        r"\begin{tabular}{lp{4.2cm}" + "ccc" * n + "}", r"\toprule",
        r"\textbf{Starting Room} & \textbf{Query} & "
        + " & ".join(r"\multicolumn{3}{c}{\textbf{" + e(p) + "}}" for p in data.pilots) + r" \\",
        "".join(rf"\cmidrule(lr){{{3 + 3 * i}-{5 + 3 * i}}}" for i in range(n)),
        " & & " + " & ".join([r"\textbf{Ach.} & \textbf{Coll.} & \textbf{Steps}"] * n) + r" \\",
    ]
    for label, rows in data.groups():
        lines.append(r"\midrule")
        for i, row in enumerate(rows):
            first = (r"\multirow{" + str(len(rows)) + "}{*}{" + e(label) + "}") if i == 0 and len(rows) > 1 \
                else (e(label) if i == 0 else "")
            cells = [first, e(query_cell(row))]
            for p in data.pilots:
                c = data.cell(p, row)
                cells += [_ach(c), _dash(c.collisions), _dash(c.steps_exceeded)]
            lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", "", r"\smallskip", r"\footnotesize " + e(LEGEND) + r"\\",
              r"Provenance: " + "; ".join(e(x) for x in data.notes(config_hash)) + ".", r"\end{table}", ""]
    cols = [c for c in summary_columns(data.summaries()) if c.tex is not None]
    lines += [r"\begin{table}[ht]", r"\centering",
              r"\caption{Bench " + e(data.suite.name) + r": summary per pilot. Success rate with its 95\% Wilson "
              r"interval, SPL, mean steps, collisions, step limits reached, false successes, invalid decisions, "
              r"oscillations, safety-layer interventions, tokens, cost and pilot-call latency.}",
              r"\label{tab:bench-" + _label(data.suite.name) + "-summary}", r"\small",
              r"\begin{tabular}{l" + "r" * (len(cols) - 1) + "}", r"\toprule",
              " & ".join(str(c.tex) for c in cols) + r" \\", r"\midrule"]
    lines += [" & ".join(c.tex_cell(s) for c in cols) + r" \\" for s in data.summaries()]
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}", ""]
    return "\n".join(lines)


def render_tables(suite: Suite, pilots: Sequence[str], records: Sequence[dict[str, Any]],
                  config_hash: str | None = None) -> dict[str, str]:
    """{file name: content} for table.md, table.csv, table.tex and summary.csv."""
    data = _Data(suite, pilots, records)
    return {TABLE_MD: render_markdown(data, config_hash), TABLE_CSV: render_csv(data),
            TABLE_TEX: render_tex(data, config_hash), SUMMARY_CSV: render_summary_csv(data)}
