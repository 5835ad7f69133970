"""HTML reports: one page per episode (`write_episode_report`) and one per benchmark (`write_bench_report`).

Both pages open from disk with no server and no network: CSS and JavaScript are inline, images are files
beside the page referenced by relative paths (the frames the recorder already wrote, `floorplan.png`,
`plots/*.png`). Relative paths keep a 50-step page at a few tens of kB instead of duplicating megabytes of
JPEG as base64, and the run directory stays the unit that is copied or archived. Everything a model wrote
(decisions, descriptions, raw answers, error messages) is untrusted and HTML-escaped (the pages are Jinja2
templates with autoescape, `report/templates/`); the page's script only
moves CSS classes and reads numbers from data attributes, it never parses model text.

This module is the entry point the command line and the tests import; the work is split by job:
`page.py` (the shared frame, `static/` for its stylesheet and script), `episode_page.py`, `bench_page.py`,
and `bench/reader.py` (the bench directory read back).
"""

from __future__ import annotations

from vlnpilot.bench.reader import BenchData, BenchRow, load_bench
from vlnpilot.report.bench_page import bench_plots, render_bench_report, write_bench_report
from vlnpilot.report.episode_page import render_episode_report, write_episode_report
from vlnpilot.report.page import FLOORPLAN, PLOTS, REPORT, RESULTS

__all__ = [
    "FLOORPLAN", "PLOTS", "REPORT", "RESULTS", "BenchData", "BenchRow", "bench_plots", "load_bench",
    "render_bench_report", "render_episode_report", "write_bench_report", "write_episode_report",
]
