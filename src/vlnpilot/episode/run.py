"""One episode into a run directory: the set-up that `vln-pilot run` and the bench's workers share.

`run_episode` flies and measures; this wraps it with the run directory's life cycle: the recorder opens the
directory (summary.json first), and whatever happens the record is closed with a status that says how it
ended (`finished`, `interrupted` by Ctrl-C or SIGTERM, `failed` by an exception), and the pilot is closed.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

from vlnpilot.core.environment import Environment
from vlnpilot.core.rundir import Recorder
from vlnpilot.episode.config import EpisodeConfig, JudgeOutcome, LoopControl
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import EpisodeResult
from vlnpilot.episode.record import StepCallback
from vlnpilot.pilots.base import Pilot, close_pilot
from vlnpilot.tasks.mission import Mission
from vlnpilot.tasks.task import Task


def run_recorded_episode(env: Environment, pilot: Pilot, task: Task | Mission, config: EpisodeConfig, *,
                         run_dir: str | Path, spawn: str | None = None, pilot_spec: str | None = None,
                         save_frames: bool = True, overwrite: bool = False, on_step: StepCallback | None = None,
                         judge_outcome: JudgeOutcome | None = None,
                         control: LoopControl | None = None) -> EpisodeResult:
    """Fly one episode recorded in `run_dir` (see `run_episode` for the hooks); the pilot is closed after it."""
    recorder = Recorder(run_dir, save_frames=save_frames, overwrite=overwrite)
    try:
        return run_episode(env, pilot, task, config, spawn=spawn, recorder=recorder, pilot_spec=pilot_spec,
                           on_step=on_step, judge_outcome=judge_outcome, control=control)
    except KeyboardInterrupt:
        recorder.close("interrupted")
        raise
    finally:
        recorder.close("failed")  # a no-op after a finished or interrupted episode
        with contextlib.suppress(Exception):  # the episode is recorded; a failing close must not hide it
            close_pilot(pilot)
