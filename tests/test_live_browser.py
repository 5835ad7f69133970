"""Acceptance of the live ground station (issue 15) in headless Chromium (Debian's, driven by Playwright).

A real simulator episode is flown by a gated oracle (tests/live_episode.py): the loop only moves when the test
releases the pilot, so every check knows where the loop is. Covers: step N's image and decision on the page
after the step ends; pause holding the loop; three keyboard commands recorded `human`; hand back; a
page closed and reopened mid-episode; the emergency stop (space) ending the episode `aborted` within one step.
Saves a screenshot to test-artifacts/live.png (and docs/img/live.png when VLN_UPDATE_SCREENSHOTS=1).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from chromium import needs_chromium
from live_episode import LiveEpisode
from vlnpilot.core.rundir import load_run
from vlnpilot.live.app import KEYS

ROOT = Path(__file__).resolve().parents[1]
KEY_FOR = {code: key for key, code in reversed(KEYS.items())}  # the arrow or letter key of each command
SHOW_TIMEOUT_MS = 15_000  # turns a page that never updates into a failure; a loaded machine is no failure
PREFERRED = ("B1", "C1", "A1", "D1", "D2")  # rotations first: a person turning in place never hits a wall

pytestmark = needs_chromium


def open_page(browser, url: str):  # noqa: ANN001, ANN201
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url, wait_until="load")
    page.wait_for_function("() => document.getElementById('conn').textContent === 'live'", timeout=10_000)
    return page, errors


def shows_step(page, ep: LiveEpisode, n: int) -> None:  # noqa: ANN001
    """The page shows step n's front image and decision (the wait is a failure bound, not a latency measure:
    the station checks for new steps every `live.app.POLL_S`, well within the 1 s the page has)."""
    record = ep.records[n - 1]
    page.wait_for_function(
        "([n, move]) => document.getElementById('front').dataset.step === String(n)"
        " && document.getElementById('front').complete && document.getElementById('front').naturalWidth > 0"
        " && document.getElementById('decision').textContent.includes(move)",
        arg=[n, (record["decision"] or {}).get("movement", "")], timeout=SHOW_TIMEOUT_MS)


def test_live_station_in_chromium(browser, tmp_path: Path) -> None:  # noqa: ANN001
    ep = LiveEpisode(tmp_path / "run")
    try:
        page, errors = open_page(browser, ep.station.page_url)
        # step N's image and decision within 1 s of the step ending
        for n in (1, 2):
            ep.pilot.release(1)
            ep.wait_steps(n)
            shows_step(page, ep, n)

        # pause holds the loop: it takes effect before the next pilot call
        page.keyboard.press("p")
        ep.pilot.release(1)  # step 3 was already asked for when the pause came
        ep.wait_status(lambda s: s["holding"])
        page.wait_for_function("() => document.getElementById('mode').textContent === 'paused (holding)'")
        # the pause's own reply may arrive after the stream's newer status: an older version never wins
        page.evaluate("() => applyStatus({...status, holding: false, version: status.version - 1})")
        assert page.locator("#mode").text_content() == "paused (holding)"
        ep.pilot.release(2)  # the pilot could answer twice, but the loop is held before asking it
        ep.wait_status(lambda s: s["holding"] and s["step"] == 4)
        assert ep.pilot.calls == 3 and len(ep.records) == 3
        page.keyboard.press("p")  # resume: the two released answers fly steps 4 and 5
        ep.wait_steps(5)
        shows_step(page, ep, 5)

        # take over: three keyboard commands, recorded `human`
        page.keyboard.press("t")
        ep.pilot.release(1)  # step 6 is the pilot's (it was being asked); step 7 waits for the person
        for n in (7, 8, 9):
            waiting = ep.wait_status(lambda s, n=n: (s["waiting"] or {}).get("step") == n)["waiting"]
            page.wait_for_function("n => document.getElementById('hstep').textContent === String(n)", arg=n)
            if n == 8:
                page.screenshot(path=str(screenshot_path()), full_page=True)
            move = next(m for m in PREFERRED if m in waiting["moves"])
            page.keyboard.press(KEY_FOR[move])
            ep.wait_steps(n)
            shows_step(page, ep, n)
        _, steps = load_run(tmp_path / "run")
        assert [s.get("human", False) for s in steps[6:9]] == [True, True, True]
        assert not any(s.get("human") for s in steps[:6]) and all(s["executed"] for s in steps[6:9])

        # hand back: the pilot flies again, from the state the person left
        page.keyboard.press("t")
        ep.pilot.release(1)
        ep.wait_steps(10)
        assert "human" not in ep.records[9] and ep.records[9]["model"] == "ground-truth"
        assert ep.records[9]["state"] == ep.records[8]["next_state"]

        # reconnect: close the page, let a step fly, reopen: the current state shows, the run is unaffected
        page.close()
        ep.pilot.release(1)
        ep.wait_steps(11)
        page, errors2 = open_page(browser, ep.station.page_url)
        shows_step(page, ep, 11)
        assert page.locator("#stepcount").text_content() == "step 11 / 40"
        assert page.locator("#traj circle").count() == 11
        errors += errors2

        # emergency stop (space) while the pilot thinks: its answer never flies, the episode ends `aborted`
        page.keyboard.press(" ")
        ep.wait_status(lambda s: s["stopped"])
        ep.pilot.release(1)
        ep.thread.join(30)
        page.wait_for_function("() => document.getElementById('outcome').textContent.startsWith('aborted')")
        assert ep.result is not None and ep.result.outcome == "aborted" and ep.result.steps == 12
        summary, steps = load_run(tmp_path / "run")
        assert len(steps) == 12 and steps[-1]["executed"] is None and summary["result"]["outcome"] == "aborted"
        assert [s["step"] for s in steps] == list(range(1, 13))  # nothing lost or mixed by the pages
        assert errors == []
    finally:
        ep.close()


def screenshot_path() -> Path:
    (ROOT / "test-artifacts").mkdir(exist_ok=True)
    return ROOT / "test-artifacts" / "live.png"


def teardown_module() -> None:
    shot = screenshot_path()
    if os.environ.get("VLN_UPDATE_SCREENSHOTS") == "1" and shot.is_file():
        shutil.copy(shot, ROOT / "docs" / "img" / "live.png")
