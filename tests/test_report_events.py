"""Issue 24 in the reports: the episode report shows the people's and pets' paths and the events on the floor plan,
the events in the timeline, and a dot per mover that follows the step (the live page likewise)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from report_samples import make_run
from vlnpilot.report.floorplan import EVENT_COLOR, MOVER_COLORS
from vlnpilot.report.html import write_episode_report
from vlnpilot.report.timeline import load_episode

DOOR_EVENT = {"name": "door-closes-1", "kind": "door_closes", "step": 3, "time_s": 2.4, "trigger": "step 3",
              "params": {"door": "door_bedroom_bathroom", "swing_s": 1.0}}
PERSON_EVENT = {"name": "person-1", "kind": "person", "step": 0, "time_s": 0.0, "trigger": "step 0",
                "params": {"path": ["bedroom", "living_room"], "speed_mps": 1.2}}


def _person(step: int) -> dict:
    return {"name": "person-1", "kind": "person", "x": round(4.5 - 0.3 * step, 4), "y": 2.0, "vx": -0.3, "vy": 0.0,
            "radius": 0.25, "height": 1.75}


def with_events(run_dir: Path) -> Path:
    """A synthetic run (report_samples) with a person walking and a door closing, as the recorder writes them."""
    summary = json.loads((run_dir / "summary.json").read_text())
    summary["events"] = [PERSON_EVENT]
    (run_dir / "summary.json").write_text(json.dumps(summary))
    lines = []
    for line in (run_dir / "episode.jsonl").read_text().splitlines():
        rec = json.loads(line)
        rec["movers"] = [_person(rec["step"])]
        if rec["step"] == 3:
            rec["events"] = [DOOR_EVENT]
        lines.append(json.dumps(rec))
    (run_dir / "episode.jsonl").write_text("\n".join(lines) + "\n")
    return run_dir


@pytest.fixture()
def run(tmp_path: Path) -> Path:
    return with_events(make_run(tmp_path / "run", steps=6))


def test_the_timeline_reads_movers_and_events(run: Path) -> None:
    ep = load_episode(run)
    tracks = ep.mover_tracks()
    assert list(tracks) == ["person-1"] and tracks["person-1"]["kind"] == "person"
    assert tracks["person-1"]["points"][0] == (4.2, 2.0) and len(tracks["person-1"]["points"]) == 6
    fired = ep.fired_events()
    assert [(e["step"], e["kind"]) for e in fired] == [(0, "person"), (3, "door_closes")]
    door = ep.scene.door("door_bedroom_bathroom").center
    assert (fired[1]["x"], fired[1]["y"]) == (door[0], door[1])  # a closing door is marked where it is
    assert (fired[0]["x"], fired[0]["y"]) == (4.2, 2.0)  # a mover where it was first recorded
    assert ep.entries[2].events == [DOOR_EVENT] and ep.entries[1].events == []
    # entry k shows the movers where they were when the pilot decided: after step k-1
    assert ep.entries[3].movers == [_person(3)] and ep.entries[0].movers == []


def _colour_pixels(png: Path, colour: str) -> int:
    rgb = np.asarray(Image.open(png).convert("RGB")).astype(int)
    target = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(rgb - target).sum(axis=2) < 30).sum())


def test_the_report_draws_movers_and_events_on_the_plan_and_lists_them(run: Path, tmp_path: Path) -> None:
    still = make_run(tmp_path / "still", steps=6)
    write_episode_report(still)
    page = write_episode_report(run).read_text()
    for colour in (MOVER_COLORS["person"], EVENT_COLOR):
        assert _colour_pixels(run / "floorplan.png", colour) > 20 * max(1, _colour_pixels(still / "floorplan.png",
                                                                                          colour))
    assert "door-closes-1" in page and "door_bedroom_bathroom" in page and "flag-event" in page
    assert 'id="movers"' in page and "◆ event (step: kind)" in page
    dots = [json.loads(m.replace("&#34;", '"').replace("&quot;", '"'))
            for m in re.findall(r'data-movers="([^"]*)"', page)]
    assert len(dots) == 6 and all(d[0]["kind"] == "person" for d in dots)
    assert dots[1][0]["x"] < dots[-1][0]["x"] or dots[1][0]["x"] > dots[-1][0]["x"]  # the dot moves with the step
    assert 0 < dots[1][0]["x"] < 100 and 0 < dots[1][0]["y"] < 100
