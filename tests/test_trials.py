"""Every recorded real-VLM trial under trials/ replays to its recorded outcome: the regression test of every later
prompt, FSM or controller change. A change that makes a real pilot's recorded answers end differently fails here.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vlnpilot.bench.command import bench_command
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.rundir import load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.pilots.base import make_pilot
from vlnpilot.pilots.replay import camera_flown_with
from vlnpilot.scene.events import scene_with_recorded
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.mission import Mission
from vlnpilot.tasks.success import recorded_success
from vlnpilot.tasks.task import Task

TRIALS = Path(__file__).resolve().parents[1] / "trials"
ALL = sorted(p.parent for p in TRIALS.glob("*/*/trial.json"))


@pytest.fixture(scope="module")
def simulators():
    sims: dict[tuple[str, int | None, str], Simulator] = {}

    def simulator(scene: str, randomize: int | None = None, scenario: dict | None = None) -> Simulator:
        """A trial flown in a randomised world (docs/camera.md) replays in it: its camera height decides what is
        visible; one flown among events (docs/events.md) replays among the same events, as recorded."""
        key = (scene, randomize, json.dumps(scenario, sort_keys=True))
        if key not in sims:
            sims[key] = Simulator(scene_with_recorded(scene, scenario), SimConfig(render=False, randomize=randomize))
        return sims[key]

    yield simulator
    for sim in sims.values():
        sim.close()


def replay(sim: Simulator, trial_dir: Path, **overrides):
    summary, _ = load_run(trial_dir)
    cfg = summary["config"]
    recorded = {"max_steps": cfg["max_steps"], "profile": cfg["profile"], "seed": cfg["seed"], "shield": cfg["shield"],
                "overlay": cfg.get("overlay"), "context": (cfg.get("context") or {}).get("preset", "paper"),
                "success": recorded_success(cfg.get("success"))}  # judged by the monitor it was flown under
    config = EpisodeConfig(**{**recorded, **overrides})
    # a mission (docs/missions.md) replays the plan it flew, as recorded; a one-goal trial its task
    task = Mission.from_dict(summary["mission"]) if "mission" in summary else Task(**summary["task"])
    return run_episode(sim, make_pilot(f"replay:{trial_dir}"), task, config, spawn=summary["spawn"])


def test_trials_cover_the_paper_suite() -> None:
    """The baseline plus at least 24 later episodes, over all 10 rows of the paper suite."""
    sets = {p.parent.name for p in ALL}
    assert "baseline" in sets
    later = [p for p in ALL if p.parent.name in ("after-paper", "after-plus")]
    assert len(later) >= 24, len(later)
    rows = {p.name.rsplit("-", 1)[0] for p in later}
    assert len(rows) == 10, sorted(rows)
    for row in ("living-bathroom", "bathroom-living", "living-refrigerator", "bedroom-mirror", "bathroom-sink"):
        assert sum(p.name.startswith(row + "-") for p in later) >= 3, row  # two-door and object rows


@pytest.mark.parametrize("trial_dir", ALL, ids=[f"{p.parent.name}/{p.name}" for p in ALL])
def test_trial_replays_to_its_recorded_outcome(simulators, trial_dir: Path) -> None:
    trial = json.loads((trial_dir / "trial.json").read_text())
    summary = load_run(trial_dir)[0]
    sim = simulators(trial["scene"], camera_flown_with(summary["config"]).get("randomize"), summary.get("scenario"))
    assert sim.scene.fingerprint() == trial["scene_fingerprint"], "the scene this trial flew has changed"
    result = replay(sim, trial_dir)
    assert (result.outcome, result.steps) == (trial["outcome"], trial["steps"])


def test_replay_on_another_scene_is_refused(simulators) -> None:
    trial_dir = TRIALS / "baseline" / "living-bathroom"
    with pytest.raises(ConfigError, match="flown in scene 'cabin-v1'.*--scene cabin-v1"):
        replay(simulators("cabin"), trial_dir)


def test_replay_with_another_context_is_refused(simulators) -> None:
    trial_dir = next(p for p in ALL if p.parent.name == "after-plus")
    with pytest.raises(ConfigError, match="--context plus"):
        replay(simulators("cabin"), trial_dir, context="paper")


@pytest.mark.parametrize("name", ["baseline", "missions", "tello-cabin"])
def test_a_set_replays_through_the_bench(name: str, tmp_path: Path) -> None:
    """`vln-pilot bench --suite trials/SET/suite.yaml --pilots replay:trials/SET` reproduces the set, with no option:
    the suite pins what the set was flown with (its context, shield and camera; a mission's plan as its pilot
    planned it, even where the parser reads the instruction otherwise)."""
    set_dir = TRIALS / name
    out = bench_command(suite=str(set_dir / "suite.yaml"), pilots=f"replay:{set_dir}", out=tmp_path / "bench",
                        workers=1, progress=False, frames=False)
    records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    want = {p.name: json.loads((p / "trial.json").read_text())["outcome"] for p in set_dir.iterdir() if p.is_dir()}
    assert {r["row"]: r["result"]["outcome"] for r in records} == want
    flown = {json.loads((out / r["run_dir"] / "summary.json").read_text())["config"].get("camera", {}).get("model")
             for r in records}
    assert flown == ({"tello"} if name.startswith("tello") else {None})


def test_a_set_is_not_replayed_with_other_frames_than_it_was_flown_with(tmp_path: Path) -> None:
    """The same answers to other images are not the recording: refused in one line before anything runs, as
    `vln-pilot run --pilot replay:` refuses it."""
    for name, camera in (("tello-cabin", "ideal"), ("baseline", "tello")):
        set_dir = TRIALS / name
        with pytest.raises(ConfigError, match=f"was flown with other frames.*bench it with --camera "
                                              f"{'tello' if camera == 'ideal' else 'ideal'}"):
            bench_command(suite=str(set_dir / "suite.yaml"), pilots=f"replay:{set_dir}", out=tmp_path / name,
                          workers=1, progress=False, camera=camera)
        assert not (tmp_path / name).exists()


def test_a_replay_is_judged_by_the_monitor_its_recording_was_judged_by(simulators) -> None:
    """A trial judged before footprints (the point monitor) ends as it ended, flown with today's default config: the
    replay pilot brings its recording's monitor, as it brings the mover shield's height rule."""
    trial = TRIALS / "missions-houses" / "house10-hallway-desk-return"
    summary, _ = load_run(trial)
    assert "object_measured_to" not in summary["config"]["success"]
    config = EpisodeConfig(max_steps=summary["config"]["max_steps"], profile="paper", context="plus", shield="geometry")
    result = run_episode(simulators(summary["scene"]), make_pilot(f"replay:{trial}"),
                         Mission.from_dict(summary["mission"]), config, spawn=summary["spawn"])
    assert result.outcome == "false_success" == summary["result"]["outcome"]
    assert "56° off the heading" in result.reason and "middle of its front" in result.reason  # the point monitor


def test_readme_tables_come_from_the_trials() -> None:
    """The README's summary, docs/results.md's per-row table and trials/README.md's Outcomes are what
    scripts/trials_table.py prints from trials/*/*/trial.json, each table in one place only (no hand-kept copy)."""
    import runpy

    table = runpy.run_path(str(TRIALS.parent / "scripts" / "trials_table.py"))
    sets = table["load"](TRIALS)
    readme = (TRIALS.parent / "README.md").read_text()
    assert table["summary_table"](sets) in readme
    assert table["row_table"](sets) in (TRIALS.parent / "docs" / "results.md").read_text()
    trials_readme = (TRIALS / "README.md").read_text()
    assert table["trial_lines"](sets) in trials_readme
    assert trials_readme.count("\n| trials | row |") == 1 and "\n| row |" not in trials_readme


def test_run_replays_a_mission_on_the_plan_its_pilot_made(monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """`vln-pilot run --pilot replay:TRIAL` flies the recorded pilot's plan (a return), not the parser's reading of the
    same words (a room stage), and records no planning call it did not make."""
    from cli_support import run_main

    trial = TRIALS / "missions" / "cabin-living-bathroom-return"
    summary, _ = load_run(trial)
    code, out, _ = run_main(monkeypatch, capsys, "run", summary["task"]["query"], "--spawn", summary["spawn"],
                            "--pilot", f"replay:{trial}", "--no-video", "--out", str(tmp_path / "run"))
    again, _ = load_run(tmp_path / "run")
    assert code == 0 and "plan (stdin)" in out and "return to the start" in out
    assert [s["kind"] for s in again["mission"]["stages"]] == ["room", "return"]
    assert "planning" not in again["mission"]
    assert (again["result"]["outcome"], again["result"]["steps"]) == (summary["result"]["outcome"],
                                                                      summary["result"]["steps"])
