"""The benchmark page (`write_bench_report`): the paper's Table 4, per-pilot statistics, plots, every episode.

The markup is `templates/bench.html.j2`; this module gathers the values it shows."""

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
from vlnpilot.report.page import PLOTS, REPORT, RESULTS, _cost, _css_rgb, _int, render
from vlnpilot.report.timeline import load_scene_or_none


def _outcome(record: Mapping[str, Any]) -> str:
    return str((record.get("result") or {}).get("outcome", "unknown"))


def _table4(data: BenchData) -> list[dict[str, Any]]:
    """The paper's Table 4 layout: per starting room, its rows, each with one cell per pilot."""
    from vlnpilot.bench.results import cell_stats

    scene = load_scene_or_none(data.scene_name)
    groups = []
    for label, rows in data.groups():
        start: dict[str, Any] = {"name": label, "color": None}
        if scene is not None:
            try:
                start["color"] = _css_rgb(scene.room(scene.spawn(rows[0].spawn).room).color)
            except VLNPilotError:
                pass
        groups.append({"start": start, "rows": [
            {"id": row.id, "query": row.query, "cells": [cell_stats(data.of(p, row.id)) for p in data.pilots]}
            for row in rows]})
    return groups


def _pilots(data: BenchData) -> list[dict[str, Any]]:
    from vlnpilot.bench.results import summarize
    from vlnpilot.report.plots import pilot_color

    out = []
    for i, p in enumerate(data.pilots):
        s = summarize(p, data.of(p))
        out.append({"name": p, "color": pilot_color(i), "summary": s,
                    "models": ", ".join(m for m in s.models if m != "None")})
    return out


def _episodes(data: BenchData) -> list[dict[str, Any]]:
    from vlnpilot.bench.results import call_latencies, percentile

    order = {row.id: i for i, row in enumerate(data.rows)}
    labels = {row.id: row for row in data.rows}
    out = []
    for rec in sorted(data.records, key=lambda r: (order[r["row"]], data.pilots.index(r["pilot"]), int(r["rep"]))):
        run_dir = data.run_dir(rec)
        report = None
        if run_dir is not None and (run_dir / REPORT).is_file():
            report = Path(os.path.relpath(run_dir / REPORT, data.bench_dir)).as_posix()
        out.append({"record": rec, "row": labels[rec["row"]], "outcome": _outcome(rec), "report": report,
                    "latency": percentile(call_latencies(rec), 50)})
    return out


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
    """The benchmark page as a string (the markup is `templates/bench.html.j2`)."""
    n_ok = sum(_outcome(r) == "success" for r in data.records)
    reps = {int(r["rep"]) for r in data.records}
    files = [n for n in (RESULTS, "table.md", "table.csv", "table.tex", "summary.csv", "bench.json")
             if (data.bench_dir / n).is_file()]
    cost = sum(float((r.get("result") or {}).get("cost_usd") or 0.0) for r in data.records)
    facts = [("Pilots", _int(len(data.pilots)), ""), ("Rows", _int(len(data.rows)), "starting room × query"),
             ("Repetitions", _int(len(reps)) if reps else "–", ""),
             ("Successes", f"{n_ok}/{len(data.records)}", ""), ("Total cost", _cost(cost), "")]
    sessions = data.manifest.get("sessions") or []
    figures = [{"title": title, "caption": caption, "src": Path(os.path.relpath(path, data.bench_dir)).as_posix()}
               for title, caption, path in plot_files]
    pilots = f": {', '.join(data.pilots)}" if data.records else ""
    title = f"Bench {data.name}{pilots} · VLN-Pilot"
    return render(
        "bench.html.j2", title=title, script="", data=data, bench_name=data.bench_dir.resolve().name, facts=facts,
        files=files, config_hash=data.manifest.get("config_hash"),
        git_sha=str(sessions[-1].get("git_sha", "–"))[:12] if sessions else None,
        table4=_table4(data) if data.records else [], pilots=_pilots(data) if data.records else [],
        figures=figures, episodes=_episodes(data) if data.records else [], results_file=RESULTS,
        written=time.strftime("%Y-%m-%d %H:%M:%S"))


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
