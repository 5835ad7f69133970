"""Model text holding markup shows as text on every page: the episode page, the bench page (Jinja2 templates with
autoescape) and the live page (its script puts model text into textContent only). The text goes where a model's
words land: a decision's description and room, and the query."""

from __future__ import annotations

import json
from html.parser import HTMLParser
from pathlib import Path

from chromium import needs_chromium
from report_samples import EVIL, make_bench, make_run
from vlnpilot.report.html import write_bench_report, write_episode_report

QUERY = f"Go to the bathroom {EVIL}"


class _Page(HTMLParser):
    def __init__(self, html: str) -> None:
        super().__init__()
        self.scripts, self.attrs, self.text = 0, [], []
        self.feed(html)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.scripts += tag == "script"
        self.attrs += [name for name, _ in attrs]

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def _evil_last_step(run: Path) -> None:
    """The last step's decision (the one the live page shows) carries the markup too."""
    lines = (run / "episode.jsonl").read_text().splitlines()
    last = json.loads(lines[-1])
    last["decision"].update(description=EVIL, room=EVIL)
    (run / "episode.jsonl").write_text("\n".join([*lines[:-1], json.dumps(last)]) + "\n")


def _shown_as_text(html: str, scripts: int) -> _Page:
    page = _Page(html)
    assert page.scripts == scripts and "onerror" not in page.attrs  # nothing the model wrote became markup
    return page


def test_episode_page_escapes_model_text(tmp_path: Path) -> None:
    run = make_run(tmp_path / "run", steps=6, evil=True, query=QUERY)
    page = _shown_as_text(write_episode_report(run).read_text(encoding="utf-8"), scripts=1)
    text = "".join(page.text)
    assert text.count(EVIL) >= 4  # the query (title and header), the description, the room, the raw answer


def test_bench_page_escapes_model_text(tmp_path: Path) -> None:
    bench = make_bench(tmp_path / "bench", rows=2, reps=1)
    manifest = json.loads((bench / "bench.json").read_text())
    manifest["suite"]["rows"][0]["query"] = QUERY
    manifest["suite"]["description"] = EVIL
    (bench / "bench.json").write_text(json.dumps(manifest))
    page = _shown_as_text(write_bench_report(bench, episode_reports=False).read_text(encoding="utf-8"), scripts=0)
    assert "".join(page.text).count(QUERY) >= 3  # Table 4 and each pilot's episode row


@needs_chromium
def test_live_page_escapes_model_text(browser, tmp_path: Path) -> None:  # noqa: ANN001
    from vlnpilot.live.station import LiveStation
    from vlnpilot.scene import load_scene

    run = make_run(tmp_path / "run", steps=2, evil=True, query=QUERY)
    _evil_last_step(run)
    with LiveStation(run, scene=load_scene("cabin"), port=0) as station:
        page = browser.new_page()
        try:
            page.goto(station.url, wait_until="load")
            page.wait_for_function("() => document.getElementById('conn').textContent === 'run over'",
                                   timeout=15_000)
            assert page.evaluate("window.__pwned") is None
            assert page.locator("script").count() == 1 and page.locator("[onerror]").count() == 0
            assert EVIL in page.locator("#task").inner_text()
            assert page.locator("#decision").inner_text().count(EVIL) == 2  # the room and the description
        finally:
            page.close()
