"""One episode into a run directory (`episode_run.run_recorded_episode`), shared by `vln-pilot run` and the bench:
the record is closed with a status that says how the episode ended, and the pilot is always closed."""

from __future__ import annotations

from pathlib import Path

import pytest

from vlnpilot.core.rundir import load_run
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.run import run_recorded_episode
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query


@pytest.fixture(scope="module")
def sim() -> Simulator:
    with Simulator("cabin", SimConfig(render=False)) as s:
        yield s


class ClosingOracle(OraclePilot):
    """The oracle, counting its `close` calls, and raising `fail_at` (an exception) at step `fail_step`."""

    def __init__(self, fail_step: int | None = None, fail_at: BaseException | None = None) -> None:
        super().__init__()
        self.closed = 0
        self.calls = 0
        self.fail_step, self.fail_at = fail_step, fail_at

    def decide(self, pilot_input):
        self.calls += 1
        if self.calls == self.fail_step and self.fail_at is not None:
            raise self.fail_at
        return super().decide(pilot_input)

    def close(self) -> None:
        self.closed += 1


def _fly(sim: Simulator, pilot: ClosingOracle, run_dir: Path):
    task = parse_query("Go to the bathroom", sim.scene)
    return run_recorded_episode(sim, pilot, task, EpisodeConfig(seed=0), run_dir=run_dir, spawn="living_room",
                                pilot_spec="oracle", save_frames=False)


def test_a_finished_episode_is_recorded_and_the_pilot_closed(sim: Simulator, tmp_path: Path) -> None:
    pilot = ClosingOracle()
    result = _fly(sim, pilot, tmp_path / "run")
    summary, steps = load_run(tmp_path / "run")
    assert result.outcome == "success" and summary["status"] == "finished" and len(steps) == result.steps
    assert summary["pilot"] == "oracle" and summary["spawn"] == "living_room"
    assert pilot.closed == 1


@pytest.mark.parametrize(("error", "status"), [(KeyboardInterrupt(), "interrupted"),
                                               (RuntimeError("the pilot's process died"), "failed")])
def test_an_episode_cut_short_keeps_its_steps_and_says_how_it_ended(sim: Simulator, tmp_path: Path,
                                                                     error: BaseException, status: str) -> None:
    pilot = ClosingOracle(fail_step=4, fail_at=error)
    with pytest.raises(type(error)):
        _fly(sim, pilot, tmp_path / "run")
    summary, steps = load_run(tmp_path / "run")
    assert summary["status"] == status and [s["step"] for s in steps] == [1, 2, 3]
    assert pilot.closed == 1


def test_a_used_run_directory_is_refused_unless_overwritten(sim: Simulator, tmp_path: Path) -> None:
    from vlnpilot.core.errors import ConfigError

    _fly(sim, ClosingOracle(), tmp_path / "run")
    with pytest.raises(ConfigError, match="--overwrite"):
        _fly(sim, ClosingOracle(), tmp_path / "run")
