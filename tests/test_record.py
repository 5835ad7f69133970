"""Run directories: complete and parseable after a finished run, and after an interrupted one."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

from vlnpilot.core.decision import Decision, PilotInput
from vlnpilot.core.environment import GroundTruth
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.rundir import EPISODE, FRAMES, SUMMARY, Recorder, check_writable, default_run_dir, load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import EpisodeResult
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.prompting.render import prompt_hash
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

W, H = 160, 120
# The documented fields of an episode.jsonl line; later layers (e.g. safety) may add more.
STEP_FIELDS = {"step", "state", "decision", "raw_text", "usage", "model", "failures", "proposed", "executed",
               "next_state", "pose_before", "pose_after", "collided", "contact", "contact_part", "room_true",
               "oscillation", "frames"}
DECISION_FIELDS = {"room", "movement", "state", "description", "door_position"}
POSE_FIELDS = {"x", "y", "z", "yaw_deg"}
RESULT_FIELDS = set(EpisodeResult.__dataclass_fields__)
QUERY, SPAWN, SEED = "Find the mirror in the bedroom", "bedroom", 7


@pytest.fixture(scope="module")
def small_sim() -> Simulator:
    """A rendering simulator at a small resolution (frames must exist, but cheaply)."""
    with Simulator("cabin", SimConfig(width=W, height=H, rear_width=W, rear_height=H)) as sim:
        yield sim


@pytest.fixture(scope="module")
def finished_run(small_sim: Simulator, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, EpisodeResult]:
    run_dir = tmp_path_factory.mktemp("runs") / "oracle-mirror"
    recorder = Recorder(run_dir)
    result = run_episode(small_sim, OraclePilot(), parse_query(QUERY, small_sim.scene), EpisodeConfig(seed=SEED),
                         spawn=SPAWN, recorder=recorder, pilot_spec="oracle")
    return run_dir, result


def test_summary_is_complete(finished_run: tuple[Path, EpisodeResult]) -> None:
    run_dir, result = finished_run
    summary = json.loads((run_dir / SUMMARY).read_text())
    assert summary["status"] == "finished"
    assert set(summary["result"]) == RESULT_FIELDS  # every EpisodeResult field
    assert summary["result"] == json.loads(json.dumps(result.to_dict()))
    assert summary["result"]["outcome"] == "success"
    assert summary["task"] == {"query": QUERY, "goal_room": "bedroom", "goal_target": "mirror"}
    assert (summary["spawn"], summary["scene"], summary["pilot"], summary["model"]) == \
           (SPAWN, "cabin", "oracle", "ground-truth")
    assert summary["config"]["seed"] == SEED and summary["config"]["max_steps"] == 50
    assert summary["config"]["profile"] == "paper"
    prov = summary["provenance"]
    assert isinstance(prov["git_sha"], str) and prov["git_sha"]
    assert prov["prompt_hash"] == prompt_hash("paper")
    assert {"python", "mujoco", "numpy", "vln-pilot"} <= set(prov["versions"])
    assert prov["started_at"]
    assert set(summary["start_pose"]) == set(summary["end_pose"]) == POSE_FIELDS


def test_episode_jsonl_has_one_documented_line_per_step(finished_run: tuple[Path, EpisodeResult]) -> None:
    run_dir, result = finished_run
    lines = (run_dir / EPISODE).read_text().splitlines()
    assert len(lines) == result.steps
    steps = [json.loads(line) for line in lines]
    assert [s["step"] for s in steps] == list(range(1, result.steps + 1))
    for prev, rec in zip([None, *steps], steps, strict=False):
        assert STEP_FIELDS <= set(rec)
        assert set(rec["decision"]) == DECISION_FIELDS
        assert set(rec["pose_before"]) == set(rec["pose_after"]) == POSE_FIELDS
        assert rec["executed"] == rec["proposed"] == rec["decision"]["movement"]
        assert rec["next_state"] == rec["decision"]["state"]
        assert rec["collided"] is False and rec["failures"] == []
        assert set(rec["usage"]) >= {"input_tokens", "output_tokens", "latency_s"}
        if prev is not None:  # the trajectory is continuous, and the FSM walks as recorded
            assert rec["pose_before"] == prev["pose_after"]
            assert rec["state"] == prev["next_state"]
    assert steps[0]["state"] == "Recognize Room"
    assert steps[-1]["next_state"] == "Describe Object"


def test_frames_exist_for_every_step(finished_run: tuple[Path, EpisodeResult]) -> None:
    run_dir, result = finished_run
    summary, steps = load_run(run_dir)
    assert summary["start_frames"] == {"front": f"{FRAMES}/front_000.jpg", "rear": f"{FRAMES}/rear_000.jpg"}
    for k in range(result.steps + 1):
        for cam in ("front", "rear"):
            path = run_dir / FRAMES / f"{cam}_{k:03d}.jpg"
            with Image.open(path) as img:
                assert img.format == "JPEG" and img.size == (W, H)
    for rec in steps:
        assert all((run_dir / p).is_file() for p in rec["frames"].values())
    assert len(list((run_dir / FRAMES).iterdir())) == 2 * (result.steps + 1)


def test_load_run_reads_what_was_written(finished_run: tuple[Path, EpisodeResult]) -> None:
    run_dir, result = finished_run
    summary, steps = load_run(run_dir)
    assert summary["status"] == "finished" and len(steps) == result.steps


# -- interrupted runs ----------------------------------------------------------------------------------------
class InterruptedOracle(OraclePilot):
    """The oracle, until someone presses Ctrl-C while it thinks at step `at`."""

    def __init__(self, at: int):
        super().__init__()
        self.at = at

    def decide(self, pilot_input: PilotInput) -> Decision:
        if pilot_input.step == self.at:
            raise KeyboardInterrupt
        return super().decide(pilot_input)


def test_interrupted_run_keeps_every_step_so_far(small_sim: Simulator, tmp_path: Path) -> None:
    k = 4
    run_dir = tmp_path / "interrupted"
    recorder = Recorder(run_dir)
    with pytest.raises(KeyboardInterrupt):
        try:
            run_episode(small_sim, InterruptedOracle(at=k), parse_query("Go to the bathroom", small_sim.scene),
                        spawn="living_room", recorder=recorder)
        finally:
            recorder.close()  # what the CLI does
    summary, steps = load_run(run_dir)
    assert summary["status"] == "interrupted" and "result" not in summary
    assert summary["task"]["goal_room"] == "bathroom" and summary["provenance"]["prompt_hash"]
    assert [s["step"] for s in steps] == list(range(1, k))
    assert all(STEP_FIELDS <= set(s) for s in steps)
    assert {p.name for p in (run_dir / FRAMES).iterdir()} == {f"{c}_{i:03d}.jpg" for c in ("front", "rear")
                                                              for i in range(k)}


def test_steps_are_on_disk_before_the_run_ends(small_sim: Simulator, tmp_path: Path) -> None:
    """Each line is flushed as its step ends: a reader sees step n while the pilot thinks about step n+1."""
    run_dir = tmp_path / "live"
    seen: list[int] = []

    class Peeking(OraclePilot):
        def decide(self, pilot_input: PilotInput) -> Decision:
            seen.append(len(load_run(run_dir)[1]))
            return super().decide(pilot_input)

    recorder = Recorder(run_dir)
    run_episode(small_sim, Peeking(), parse_query("Find the sink", small_sim.scene), spawn="bathroom",
                recorder=recorder)
    assert seen == list(range(len(seen)))


def test_truncated_last_line_is_tolerated(finished_run: tuple[Path, EpisodeResult], tmp_path: Path) -> None:
    src, result = finished_run
    run_dir = tmp_path / "killed"
    run_dir.mkdir()
    (run_dir / SUMMARY).write_text((src / SUMMARY).read_text())
    text = (src / EPISODE).read_text()
    (run_dir / EPISODE).write_text(text + '{"step": 99, "state": "Reach Ob')  # killed mid-write
    summary, steps = load_run(run_dir)
    assert len(steps) == result.steps and steps[-1]["step"] == result.steps


def test_run_without_episode_file_has_no_steps(tmp_path: Path) -> None:
    (tmp_path / SUMMARY).write_text('{"status": "running"}')
    assert load_run(tmp_path) == ({"status": "running"}, [])


def test_load_run_of_a_non_run_directory_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="summary.json is missing"):
        load_run(tmp_path)


# -- output directories --------------------------------------------------------------------------------------
def test_check_writable(tmp_path: Path) -> None:
    assert check_writable(tmp_path / "a" / "b").is_dir()
    regular = tmp_path / "file.txt"
    regular.write_text("x")
    with pytest.raises(ConfigError, match="not a directory"):
        check_writable(regular)
    with pytest.raises(ConfigError, match="cannot write to --out"):
        check_writable(regular / "run")  # a path under a regular file
    assert not list(tmp_path.glob("a/b/.write-test-*"))  # the probe file is removed


def test_default_run_dir_is_a_safe_name() -> None:
    path = default_run_dir("runs", "living_room-Go to the ../../etc!")
    assert path.parent == Path("runs")
    assert "/" not in path.name and ".." not in path.name and " " not in path.name


def test_ground_truth_protocol_is_what_the_simulator_offers(small_sim: Simulator) -> None:
    assert isinstance(small_sim.ground_truth(), GroundTruth)



# -- provenance: the git commit ----------------------------------------------------------------------------------
ROOT = Path(__file__).resolve().parents[1]
GIT = ["git", "-c", "user.name=t", "-c", "user.email=t@example.org", "-c", "commit.gpgsign=false"]


def _committed_repository(root: Path) -> str:
    """`root` as a git repository with everything in it committed; its HEAD."""
    for args in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "the user's own work"]):
        subprocess.run([*GIT, "-C", str(root), *args], check=True, capture_output=True)
    return subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], check=True, capture_output=True,
                          text=True).stdout.strip()


def _recorded_sha(site_packages: Path) -> str:
    code = "from vlnpilot.core.rundir import git_sha; print(git_sha())"
    env = {**os.environ, "PYTHONPATH": str(site_packages)}
    return subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True,
                          text=True).stdout.strip()


def test_a_wheel_inside_the_users_own_repository_records_no_git_sha(tmp_path: Path) -> None:
    """The package installed in a virtual environment inside another repository: that repository's HEAD is not the
    code's commit (it was recorded as such)."""
    site_packages = tmp_path / ".venv" / "lib" / "site-packages"
    shutil.copytree(ROOT / "src" / "vlnpilot", site_packages / "vlnpilot",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "vln-pilot"\n')  # even a namesake
    users_head = _committed_repository(tmp_path)
    assert _recorded_sha(site_packages) == "unknown" != users_head


def test_a_checkout_records_its_head_and_whether_it_has_changes(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "src" / "vlnpilot", tmp_path / "src" / "vlnpilot",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    head = _committed_repository(tmp_path)
    assert _recorded_sha(tmp_path / "src") == head
    with (tmp_path / "src" / "vlnpilot" / "__init__.py").open("a") as changed:
        changed.write("# a local change\n")
    assert _recorded_sha(tmp_path / "src") == head + "+dirty"
