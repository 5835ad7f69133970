"""Issue 24 on the live page: the people's and pets' paths and where they are now, and a diamond per event, drawn on
the plan as the episode report draws them (headless Chromium over a synthetic run, watched read-only)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import httpx

from chromium import needs_chromium
from report_samples import make_run
from test_report_events import with_events
from vlnpilot.live.plan import event_marks
from vlnpilot.live.station import LiveStation
from vlnpilot.scene import load_scene
from vlnpilot.scene.events import load_scenario


def test_meta_places_the_scenarios_events() -> None:
    scene = replace(load_scene("cabin"), scenario=load_scenario("cabin-door"))  # what the simulator flies
    marks = event_marks(scene)
    (name, point), = marks["points"].items()
    door = scene.door(load_scenario("cabin-door").events[0].door).center
    assert name == "door-closes-1" and point == [round(door[0], 4), round(door[1], 4)]
    assert event_marks(load_scene("cabin"))["points"] == {}


@needs_chromium
def test_the_live_page_draws_movers_and_events(browser, tmp_path: Path) -> None:  # noqa: ANN001
    run = with_events(make_run(tmp_path / "run", steps=6))
    with LiveStation(run, scene=load_scene("cabin"), port=0) as station:
        assert httpx.get(f"{station.url}api/meta", timeout=10).json()["events"]["points"] == {}
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(station.page_url, wait_until="load")
        page.wait_for_function("() => document.querySelectorAll('#traj polygon.event').length === 2", timeout=15_000)
        assert page.locator("#traj circle.mover").count() == 1  # one person, where it is now
        assert page.locator("#traj text").all_text_contents() == ["0: person", "3: door closes"]
        assert errors == []
