"""A replay that cannot fly says why in one line, and the right fix; an episode page says how its record ended."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from report_samples import make_run
from vlnpilot.core.errors import ConfigError
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.pilots.base import make_pilot
from vlnpilot.report.html import write_episode_report
from vlnpilot.scene import load_scene


def _summary(run_dir: Path, summary: dict) -> Path:
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return run_dir


@pytest.mark.parametrize(("summary", "said"), [({}, "no status"), ({"status": "running"}, "running")])
def test_a_record_that_names_no_scene_is_not_a_set_of_trials(tmp_path: Path, summary: dict, said: str) -> None:
    run = _summary(tmp_path / "r", summary)
    with pytest.raises(ConfigError) as err:
        make_pilot(f"replay:{run}").episode_started(load_scene("cabin"), EpisodeConfig())
    message = str(err.value)
    assert message == (f"{run} holds no episode to replay: its summary.json names no scene ({said}); give a run "
                       "directory that was flown")
    assert "set of trials" not in message and "--scene" not in message


def test_a_changed_scene_of_the_same_name_is_not_told_to_pass_that_name(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", steps=2)
    summary = json.loads((run / "summary.json").read_text())
    summary["scene"] = "cabin"
    summary.setdefault("provenance", {})["scene_fingerprint"] = "deadbeef"
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(ConfigError, match="fingerprint deadbeef.*it cannot be replayed, fly it again") as err:
        make_pilot(f"replay:{run}").episode_started(load_scene("cabin"), EpisodeConfig())
    assert "--scene" not in str(err.value)


@pytest.mark.parametrize(("status", "shown"), [("interrupted", "interrupted"), ("failed", "failed"),
                                               (None, "unknown")])
def test_the_page_title_says_how_an_unfinished_record_ended(tmp_path: Path, status: str | None, shown: str) -> None:
    run = make_run(tmp_path / "r", steps=2, finished=False)
    summary = json.loads((run / "summary.json").read_text())
    if status is None:
        summary.pop("status")
    else:
        summary["status"] = status
    (run / "summary.json").write_text(json.dumps(summary))
    page = write_episode_report(run).read_text()
    title = re.search(r"<title>([^<]*)</title>", page)
    assert title is not None and f"· {shown} ·" in title.group(1)
    assert f'class="outcome {shown}"' in page and "running" not in title.group(1)
