"""The benchmark page (`write_bench_report`): the paper's Table 4, per-pilot statistics, plots, every episode."""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vlnpilot.bench.reader import BenchData, load_bench
from vlnpilot.core.errors import VLNPilotError
from vlnpilot.core.fileio import write_atomic
from vlnpilot.report.episode_page import write_episode_report
from vlnpilot.report.page import PLOTS, REPORT, RESULTS, _cost, _css_rgb, _fact, _int, _num, _page, esc
from vlnpilot.report.timeline import load_scene_or_none


def _dash(v: int) -> str:
    return str(v) if v else '<span class="dash">–</span>'


def _outcome(record: Mapping[str, Any]) -> str:
    return str((record.get("result") or {}).get("outcome", "unknown"))


def _table4_html(data: BenchData) -> str:
    from vlnpilot.bench.results import cell_stats

    head1 = '<tr><th class="q" rowspan="2">Starting room</th><th class="q" rowspan="2">Query</th>' + "".join(
        f'<th class="pilot" colspan="3">{esc(p)}</th>' for p in data.pilots) + "</tr>"
    head2 = "<tr>" + "".join('<th class="pilot" title="successes / repetitions">Ach.</th>'
                             '<th title="episodes ended by a collision">Coll.</th>'
                             '<th title="episodes that reached the step limit">Steps</th>'
                             for _ in data.pilots) + "</tr>"
    body = []
    scene = load_scene_or_none(data.scene_name)
    for label, rows in data.groups():
        room = None
        if scene is not None:
            try:
                room = scene.spawn(rows[0].spawn).room
            except VLNPilotError:
                room = None
        chip = (f'<span class="room" style="--room:{_css_rgb(scene.room(room).color)}">{esc(label)}</span>'
                if room else esc(label))
        for i, row in enumerate(rows):
            tds = [f'<td class="start" rowspan="{len(rows)}">{chip}</td>'] if i == 0 else []
            tds.append(f'<td class="q">{esc(row.query)}</td>')
            for p in data.pilots:
                c = cell_stats(data.of(p, row.id))
                if not c.episodes:
                    tds.append('<td class="first ach"><span class="dash">0/0</span></td><td class="coll"></td>'
                               '<td class="steps"></td>')
                    continue
                tds.append(f'<td class="first ach">{c.successes}/{c.episodes}</td>'
                           f'<td class="coll">{_dash(c.collisions)}</td>'
                           f'<td class="steps">{_dash(c.steps_exceeded)}</td>')
            cls = ' class="group"' if i == 0 else ""
            body.append(f'<tr{cls} data-row="{esc(row.id)}">{"".join(tds)}</tr>')
    return (f'<div class="tablewrap" style="max-height:none"><table class="t4" id="table4"><thead>{head1}{head2}'
            f'</thead><tbody>{"".join(body)}</tbody></table></div>')


def _pilot_summary_html(data: BenchData) -> str:
    from vlnpilot.bench.results import summarize
    from vlnpilot.report.plots import pilot_color

    rows = []
    for i, p in enumerate(data.pilots):
        s = summarize(p, data.of(p))
        n = s.episodes
        rate = f"<strong>{s.successes}/{n}</strong> ({s.success_rate:.0%})" if n else "–"
        lat = (f"{_num(s.latency_p50_s, 2)} / {_num(s.latency_p95_s, 2)} s" if s.latency_p50_s is not None else "–")
        rows.append(
            f'<tr data-pilot="{esc(p)}"><td><span class="room" style="--room:{pilot_color(i)}"><code>{esc(p)}</code>'
            f'</span></td><td>{esc(", ".join(m for m in s.models if m != "None") or "–")}</td>'
            f'<td class="num">{n}</td><td class="num">{rate}</td>'
            f'<td class="num">{f"{s.ci_low:.0%} – {s.ci_high:.0%}" if n else "–"}</td>'
            f'<td class="num">{_num(s.spl, 2) if n else "–"}</td><td class="num">{_num(s.mean_steps, 1) if n else "–"}'
            f'</td><td class="num">{_dash(s.collisions)}</td><td class="num">{_dash(s.steps_exceeded)}</td>'
            f'<td class="num">{_dash(s.false_successes)}</td><td class="num">{_dash(s.pilot_errors)}</td>'
            f'<td class="num">{_dash(s.invalid_decisions)}</td><td class="num">{_dash(s.oscillations)}</td>'
            f'<td class="num">{_int(s.input_tokens)} / {_int(s.output_tokens)}</td>'
            f'<td class="num">{_cost(s.cost_usd)}</td><td class="num">{_cost(s.cost_usd / n) if n else "–"}</td>'
            f'<td class="num">{lat}</td></tr>')
    head = ('<tr><th>Pilot</th><th>Model</th><th class="num">Episodes</th><th class="num">Success</th>'
            '<th class="num">95% CI</th><th class="num">SPL</th><th class="num">Steps</th>'
            '<th class="num">Coll.</th><th class="num">Steps exc.</th><th class="num">False succ.</th>'
            '<th class="num">Pilot err.</th><th class="num">Invalid</th><th class="num">Osc.</th>'
            '<th class="num">Tokens in / out</th><th class="num">Cost</th><th class="num">Cost / ep.</th>'
            '<th class="num">Latency p50 / p95</th></tr>')
    return (f'<div class="tablewrap" style="max-height:none"><table id="pilots"><thead>{head}</thead>'
            f'<tbody>{"".join(rows)}</tbody></table></div>')


def _episodes_html(data: BenchData) -> str:
    from vlnpilot.bench.results import call_latencies, percentile

    order = {row.id: i for i, row in enumerate(data.rows)}
    labels = {row.id: row for row in data.rows}
    rows = []
    for rec in sorted(data.records, key=lambda r: (order[r["row"]], data.pilots.index(r["pilot"]), int(r["rep"]))):
        res = rec.get("result") or {}
        row = labels[rec["row"]]
        run_dir = data.run_dir(rec)
        link = '<span class="dash">–</span>'
        if run_dir is not None and (run_dir / REPORT).is_file():
            href = Path(os.path.relpath(run_dir / REPORT, data.bench_dir)).as_posix()
            link = f'<a href="{esc(href)}">report</a>'
        outcome = _outcome(rec)
        rows.append(
            f'<tr data-key="{esc(rec.get("key") or "")}"><td><code>{esc(rec["pilot"])}</code></td>'
            f'<td>{esc(row.label)}</td><td>{esc(row.query)}</td><td class="num">{esc(rec.get("rep"))}</td>'
            f'<td class="num mono">{esc(rec.get("seed"))}</td>'
            f'<td><span class="outcome {esc(outcome)}" style="font-size:11px">{esc(outcome.replace("_", " "))}'
            f'</span></td><td class="num">{_int(res.get("steps"))}</td>'
            f'<td class="num">{_num(res.get("path_length_m"), 2)}</td><td class="num">{_num(res.get("spl"), 2)}</td>'
            f'<td class="num">{_cost(res.get("cost_usd"))}</td>'
            f'<td class="num">{_num(percentile(call_latencies(rec), 50), 2)}</td><td>{link}</td></tr>')
    head = ('<tr><th>Pilot</th><th>Starting room</th><th>Query</th><th class="num">Rep</th><th class="num">Seed</th>'
            '<th>Outcome</th><th class="num">Steps</th><th class="num">Path [m]</th><th class="num">SPL</th>'
            '<th class="num">Cost</th><th class="num">Latency p50 [s]</th><th>Episode</th></tr>')
    return (f'<div class="tablewrap"><table id="episodes"><thead>{head}</thead><tbody>{"".join(rows)}</tbody>'
            f'</table></div>')


def bench_plots(data: BenchData, out_dir: Path) -> list[tuple[str, str, Path]]:
    """Write the benchmark's plots as PNG into `out_dir`; returns (title, caption, path) for each."""
    from vlnpilot.bench.results import call_latencies, cell_stats
    from vlnpilot.report import plots

    pilots = data.pilots
    made = []
    per_pilot = [cell_stats(data.of(p)) for p in pilots]
    made.append(("Success rate per pilot", "Share of episodes that reached the goal; whiskers: 95% Wilson score "
                 "interval.", plots.plot_success_rates(pilots, [c.successes for c in per_pilot],
                                                       [c.episodes for c in per_pilot], out_dir / "success_rate.png")))
    made.append(("Outcomes per pilot", "How the episodes ended.",
                 plots.plot_outcomes(pilots, {p: Counter(_outcome(r) for r in data.of(p)) for p in pilots},
                                     out_dir / "outcomes.png")))
    labels = [f"{row.query}\n(from {row.label})" for row in data.rows]
    cells = {p: [cell_stats(data.of(p, row.id)) for row in data.rows] for p in pilots}
    made.append(("Collisions and steps exceeded per query", "Episodes that ended in a collision or reached the step "
                 "limit, per query and starting room.",
                 plots.plot_failures_per_query(labels, pilots, {p: [c.collisions for c in cells[p]] for p in pilots},
                                               {p: [c.steps_exceeded for c in cells[p]] for p in pilots},
                                               out_dir / "failures_per_query.png")))
    cost = {p: [float((r.get("result") or {}).get("cost_usd") or 0.0) for r in data.of(p)] for p in pilots}
    lat = {p: [x for r in data.of(p) for x in call_latencies(r)] for p in pilots}
    made.append(("Cost and latency per pilot", "Left: USD per episode (bar: mean; dots: episodes). Right: latency of "
                 "each model call.", plots.plot_cost_latency(pilots, cost, lat, out_dir / "cost_latency.png")))
    return made


def render_bench_report(data: BenchData, plot_files: list[tuple[str, str, Path]]) -> str:
    """The benchmark page as a string."""
    n_ok = sum(_outcome(r) == "success" for r in data.records)
    reps = {int(r["rep"]) for r in data.records}
    files = [f'<a href="{n}">{n}</a>' for n in (RESULTS, "table.md", "table.csv", "table.tex", "summary.csv",
                                                "bench.json") if (data.bench_dir / n).is_file()]
    finished = f"{len(data.records)}" + (f" <small>of {data.expected}</small>" if data.expected else "")
    cost = sum(float((r.get("result") or {}).get("cost_usd") or 0.0) for r in data.records)
    facts = [
        _fact("Episodes", finished),
        _fact("Pilots", _int(len(data.pilots))),
        _fact("Rows", _int(len(data.rows)), "starting room × query"),
        _fact("Repetitions", _int(len(reps)) if reps else "–"),
        _fact("Successes", f"{n_ok}/{len(data.records)}"),
        _fact("Total cost", _cost(cost)),
    ]
    m = data.manifest
    if m.get("config_hash"):
        facts.append(_fact("Config hash", f"<code>{esc(m['config_hash'])}</code>"))
    sessions = m.get("sessions") or []
    if sessions:
        facts.append(_fact("Git", f"<code>{esc(str(sessions[-1].get('git_sha', '–'))[:12])}</code>"))
    header = f"""<header class="card hero">
<div class="eyebrow">VLN-Pilot · benchmark report · scene {esc(data.scene_name)} ·
{esc(data.bench_dir.resolve().name)}</div>
<h1>Suite “{esc(data.name)}”: {esc(", ".join(data.pilots) or "no pilots")}</h1>
<div class="reason" style="margin-left:0">{esc(data.description)}</div>
<dl class="facts">{"".join(facts)}</dl>
<div class="files">Files: {" ".join(files)}</div>
</header>"""
    if not data.records:
        body = header + '<section class="card"><p>No finished episodes in results.jsonl yet.</p></section>'
        return _page(f"Bench {data.name} · VLN-Pilot", body)
    figs = []
    for title, caption, path in plot_files:
        rel = Path(os.path.relpath(path, data.bench_dir)).as_posix()
        figs.append(f'<figure class="card plot"><h2>{esc(title)}</h2><img src="{esc(rel)}" alt="{esc(title)}">'
                    f'<figcaption>{esc(caption)} <a href="{esc(rel)}">PNG</a></figcaption></figure>')
    body = (f"{header}\n"
            f'<section class="card"><h2>Results by starting room and query</h2>'
            f'<p class="hint" style="margin-top:-6px">The layout of the paper\'s Table 4. Ach. = successes / '
            f'repetitions finished; Coll. = episodes ended by a collision; Steps = episodes that reached the step '
            f'limit; – = none.</p>{_table4_html(data)}</section>\n'
            f'<section class="card"><h2>Per pilot</h2>{_pilot_summary_html(data)}</section>\n'
            f'<div class="grid2">{"".join(figs[:2])}</div>\n{"".join(figs[2:])}\n'
            f'<section class="card"><h2>Episodes</h2>{_episodes_html(data)}</section>\n'
            f'<footer>report written {time.strftime("%Y-%m-%d %H:%M:%S")} from {esc(RESULTS)}</footer>')
    return _page(f"Bench {data.name}: {', '.join(data.pilots)} · VLN-Pilot", body)


def write_bench_report(bench_dir: str | Path, *, episode_reports: bool = True) -> Path:
    """Write `report.html` and `plots/*.png` into a bench directory; returns the page's path.

    With `episode_reports` (the default), runs without a `report.html` get one first, so every link works.
    """
    data = load_bench(bench_dir)
    if episode_reports:
        for rec in data.records:
            run_dir = data.run_dir(rec)
            if run_dir is not None and (run_dir / "summary.json").is_file() and not (run_dir / REPORT).is_file():
                write_episode_report(run_dir)
    plot_files = bench_plots(data, data.bench_dir / PLOTS) if data.records else []
    page = render_bench_report(data, plot_files)
    path = data.bench_dir / REPORT
    return write_atomic(path, page)
