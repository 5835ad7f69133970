"""A final state declared where nothing can judge it (no ground truth, `--judge none`) is its own outcome,
`declared`: recorded as declared, never counted or shown as a success."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from test_environment import BlindDrone
from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.exits import OK, exit_code_for
from vlnpilot.episode.config import OUTCOMES, EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.report.plots import OUTCOME_COLORS, OUTCOME_LABELS
from vlnpilot.scene import Scene, load_scene
from vlnpilot.tasks.task import parse_query


@dataclass
class DeclaresAtOnce:
    """Declares Stay on Room at its first step."""

    name: str = "declares"
    model: str | None = None

    def decide(self, pilot_input: PilotInput) -> Decision:
        return Decision(room="bathroom", movement="C1", state="Stay on Room", description="here")


def _fly_blind(judge: Any = None) -> Any:
    scene: Scene = load_scene("cabin")
    return run_episode(BlindDrone(scene), DeclaresAtOnce(), parse_query("Go to the bathroom", scene),
                       EpisodeConfig(shield="off", max_steps=3), judge_outcome=judge)


def test_an_unjudged_declaration_is_declared_never_a_success() -> None:
    result = _fly_blind()
    assert result.outcome == "declared" and not result.success
    assert result.judged_by == "declared" and "not judged" in result.reason
    assert result.spl == 0.0


def test_a_declared_stage_of_a_mission_counts_as_no_stage_reached() -> None:
    """Without ground truth or a judge, each stage is declared and handed on: none is counted reached (ISR, CSR)."""
    from vlnpilot.tasks.mission_parser import parse_mission

    scene: Scene = load_scene("cabin")
    mission = parse_mission("Go to the bathroom, then go to the bedroom", scene)
    result = run_episode(BlindDrone(scene), DeclaresAtOnce(), mission, EpisodeConfig(shield="off", max_steps=3))
    assert result.outcome == "declared" and not result.success
    assert result.stages == 2 and result.stages_reached == 0


def test_an_operator_still_judges_a_declaration() -> None:
    assert _fly_blind(lambda task, state: (True, "confirmed")).outcome == "success"
    assert _fly_blind(lambda task, state: (False, "no")).outcome == "false_success"


def test_declared_is_a_documented_outcome_with_its_own_label_and_colour() -> None:
    assert "declared" in OUTCOMES
    assert OUTCOME_LABELS["declared"] == "declared (not judged)"
    assert OUTCOME_COLORS["declared"] not in {c for k, c in OUTCOME_COLORS.items() if k != "declared"}
    assert exit_code_for(["declared"]) == OK  # an outcome, not a failure of the program (core/exits.py)


def test_an_old_record_of_an_unjudged_success_is_shown_as_declared(tmp_path: Path) -> None:
    """Recorded before `declared` was an outcome: outcome success, judged_by declared; the page never says success."""
    from report_samples import make_run
    from vlnpilot.report.html import write_episode_report

    run = make_run(tmp_path / "r", steps=2)
    summary = json.loads((run / "summary.json").read_text())
    summary["result"]["judged_by"] = "declared"
    (run / "summary.json").write_text(json.dumps(summary))
    page = write_episode_report(run).read_text()
    assert 'class="outcome declared"' in page and 'class="outcome success"' not in page
