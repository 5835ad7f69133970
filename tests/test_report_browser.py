"""Acceptance: both reports open from disk in headless Chromium (Debian's package, driven by Playwright).

Checks that a page logs no console error, that every image loaded, that the arrow keys move the episode
timeline, that the benchmark table matches results.jsonl and that every episode link opens; saves a screenshot
of each page under test-artifacts/ (gitignored). Skipped only when /usr/bin/chromium is missing.
"""

from __future__ import annotations

from pathlib import Path

from chromium import needs_chromium
from report_samples import expected_table, make_bench, make_run

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"

pytestmark = needs_chromium


class Page:
    """A page opened from disk, recording console errors and uncaught exceptions."""

    def __init__(self, browser, path: Path):  # noqa: ANN001
        self.context = browser.new_context(viewport={"width": 1440, "height": 900})
        self.page = self.context.new_page()
        self.errors: list[str] = []
        self.page.on("console", lambda m: self.errors.append(f"console.{m.type}: {m.text}") if m.type == "error"
                     else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"pageerror: {e}"))
        self.page.on("dialog", lambda d: (self.errors.append(f"dialog: {d.message}"), d.dismiss()))
        self.page.goto(path.resolve().as_uri(), wait_until="load")

    def broken_images(self) -> list[str]:
        return self.page.evaluate(
            "() => Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src)")

    def close(self) -> None:
        self.context.close()


def test_episode_report_in_chromium(browser, tmp_path: Path) -> None:  # noqa: ANN001
    from vlnpilot.report.html import write_episode_report

    run = make_run(tmp_path / "run", steps=8, outcome="collision", evil=True)
    p = Page(browser, write_episode_report(run))
    page = p.page
    try:
        assert page.evaluate("document.images.length") == 2 * 9 + 1  # both frames of 9 entries, the plan
        assert p.broken_images() == []
        assert page.evaluate("window.__pwned") is None  # model text stayed text
        current = page.locator("#player")

        def at() -> tuple[str, str, str]:
            visible = page.locator("article.step.current")
            assert visible.count() == 1 and visible.locator("img").first.is_visible()
            return (current.get_attribute("data-current"), visible.get_attribute("id"),
                    page.locator("#position").inner_text())

        assert at() == ("0", "step-1", "Step 1 of 9")
        cursor0 = page.locator("#cursor").get_attribute("style")
        for _ in range(3):
            page.keyboard.press("ArrowRight")
        assert at() == ("3", "step-4", "Step 4 of 9")
        assert page.locator("#cursor").get_attribute("style") != cursor0  # the plan's cursor moved with it
        assert "shield" in page.locator("article.step.current").inner_text()
        page.keyboard.press("ArrowLeft")
        assert at() == ("2", "step-3", "Step 3 of 9")
        page.keyboard.press("End")
        assert at() == ("8", "end", "End of 9")
        page.keyboard.press("ArrowRight")  # stays on the last entry
        assert at()[0] == "8"
        page.keyboard.press("Home")
        assert at()[0] == "0"
        page.locator(".steps tr[data-index='4']").click()
        assert at()[:2] == ("4", "step-5")
        page.keyboard.press("ArrowRight")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "episode-report.png"), full_page=True)
        assert p.errors == []
    finally:
        p.close()


def test_bench_report_in_chromium(browser, tmp_path: Path) -> None:  # noqa: ANN001
    from vlnpilot.report.html import write_bench_report

    bench = make_bench(tmp_path / "bench", rows=3, reps=1)
    p = Page(browser, write_bench_report(bench))
    page = p.page
    try:
        assert page.evaluate("document.images.length") == 4
        assert p.broken_images() == []
        pilots = page.locator("#table4 th.pilot[colspan]").all_text_contents()  # not upper-cased by CSS
        shown = {}
        for tr in page.locator("#table4 tbody tr").all():
            ach = tr.locator("td.ach").all_inner_texts()
            coll = tr.locator("td.coll").all_inner_texts()
            steps = tr.locator("td.steps").all_inner_texts()
            num = (lambda s: int(s) if s.strip().isdigit() else 0)  # noqa: E731 - '–' is none
            shown[tr.get_attribute("data-row")] = {
                pilot: (a, num(c), num(s)) for pilot, a, c, s in zip(pilots, ach, coll, steps, strict=True)}
        assert shown == expected_table(bench)
        links = page.locator("#episodes a")
        assert links.count() == len((bench / "results.jsonl").read_text().splitlines())
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "bench-report.png"), full_page=True)
        assert p.errors == []
        links.first.click()  # an episode report, opened from the bench page
        page.wait_for_load_state("load")
        assert page.url.endswith("/report.html") and page.locator("article.step.current").count() == 1
        assert p.broken_images() == []
        assert p.errors == []
    finally:
        p.close()
