"""What an episode writes: the run's header, one `StepRecord` per step, and the summary at the end.

`StepRecord.to_dict` is the line of `episode.jsonl` (and what `on_step` receives); its keys and their order are
the recorded format, read by `report/` and the replay pilot. They are written once, in the tables
`ALWAYS_WRITTEN` and `WRITTEN_WHEN_SET` (key -> value), and listed, with `frames`, by `step_keys()`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from vlnpilot.core.commands import Command
from vlnpilot.core.decision import Decision
from vlnpilot.core.environment import Environment, camera_settings_of, capabilities_of
from vlnpilot.core.fsm import State
from vlnpilot.core.records import Observation, Pose
from vlnpilot.core.rundir import Recorder, git_sha, package_versions
from vlnpilot.pilots.base import Pilot
from vlnpilot.pilots.keyboard import HUMAN
from vlnpilot.prompting.context import context_name
from vlnpilot.prompting.render import prompt_hash
from vlnpilot.safety import SafetyLayer, SafetyVerdict
from vlnpilot.tasks.mission import Mission, mission_budget
from vlnpilot.tasks.task import Task

if TYPE_CHECKING:
    from vlnpilot.episode.config import EpisodeConfig
    from vlnpilot.episode.measures import EpisodeResult

StepCallback = Callable[[dict[str, Any]], None]


@dataclass(frozen=True)
class StepRecord:
    """One step. Without `command` nothing was executed (the episode was aborted, or the pilot failed fatally)."""

    step: int
    state: State
    decision: Decision | None
    failures: list[dict[str, Any]]
    pose_before: Pose
    obs: Observation  # after the step (the same as before when nothing was executed)
    command: Command | None = None
    next_state: State | None = None
    room_true: str | None = None
    oscillation: bool = False
    verdict: SafetyVerdict | None = None
    override: str | None = None  # why an executed command outside the state's allowed moves ran
    confirmation: dict[str, Any] | None = None  # the exchange before a final state (confirm_final)
    ranges: tuple[Any, ...] = ()  # the range readings the pilot was told (ranging.RangeReading), before the move
    stage: int | None = None  # the mission's stage (1-based) this step flew, for a mission of several stages
    calls: tuple[Any, ...] = ()  # the Usage of every pilot call of the step, in order (their HTTP attempts)
    wall_s: float | None = None  # the step's wall time: asking (re-asks and SDK retries included) and flying

    def to_dict(self) -> dict[str, Any]:
        record = {key: value(self) for key, value in ALWAYS_WRITTEN.items()}
        for key, value in WRITTEN_WHEN_SET.items():
            if (v := value(self)) is not None:
                record[key] = v
        return record


def _of_decision(read: Callable[[Decision], Any]) -> Callable[[StepRecord], Any]:
    return lambda r: read(r.decision) if r.decision else None


# The recorded format, one entry per key of an episode.jsonl line, in the order written: key -> its value.
ALWAYS_WRITTEN: dict[str, Callable[[StepRecord], Any]] = {
    "step": lambda r: r.step,
    "state": lambda r: r.state.value,
    "decision": _of_decision(Decision.core),
    "raw_text": _of_decision(lambda d: d.raw_text),
    "usage": _of_decision(lambda d: d.usage.model_dump()),
    "model": _of_decision(lambda d: d.model),
    "failures": lambda r: r.failures,
    "proposed": _of_decision(lambda d: d.movement),
    "executed": lambda r: r.command.code if r.command else None,
    "override": lambda r: r.override,
    "next_state": lambda r: r.next_state.value if r.next_state else None,
    "pose_before": lambda r: r.pose_before.as_dict(),
    "pose_after": lambda r: r.obs.pose.as_dict(),
    "collided": lambda r: r.obs.collided,
    "contact": lambda r: r.obs.contact,
    "contact_part": lambda r: r.obs.contact_part,
    "room_true": lambda r: r.room_true,
    "oscillation": lambda r: r.oscillation,
    "interventions": lambda r: [i.to_dict() for i in r.verdict.interventions] if r.verdict else [],
    "oscillation_event": lambda r: r.verdict.oscillation.to_dict() if r.verdict and r.verdict.oscillation else None,
    "safety_feedback": lambda r: list(r.verdict.feedback) if r.verdict else [],
}
# Written only when set (not None), so that the records of runs without them are unchanged.
WRITTEN_WHEN_SET: dict[str, Callable[[StepRecord], Any]] = {
    "confirmation": lambda r: r.confirmation,  # the exchange before a final state (confirm_final)
    "human": lambda r: True if r.decision is not None and r.decision.model == HUMAN else None,  # the live station
    "robot": lambda r: r.obs.info or None,  # a real robot's facts: frame age, battery, safety events
    "ranges": lambda r: {x.direction: x.as_dict() for x in r.ranges} or None,  # --sensors: metres, None beyond
    "stage": lambda r: r.stage,  # a mission of several stages: the stage flown (the report marks boundaries)
    # per pilot call, its HTTP attempts (pilots/attempts.py): status or error, wait_s, latency_s; SDK retries too
    "attempts": lambda r: [list(u.attempts) for u in r.calls] if any(u.attempts for u in r.calls) else None,
    "wall_s": lambda r: r.wall_s,
    # issue 24: the scenario's events that fired in this step, and the movers after it (ground truth, for reports)
    "events": lambda r: [e.as_dict() for e in r.obs.events] or None,
    "movers": lambda r: [m.as_dict() for m in r.obs.movers] or None,
}
FRAMES = "frames"  # added by `EpisodeRecording.step` when the run is recorded: the step's frame files


def step_keys() -> tuple[str, ...]:
    """Every key an episode.jsonl line may have (what `report/` reads back)."""
    return (*ALWAYS_WRITTEN, *WRITTEN_WHEN_SET, FRAMES)


class EpisodeRecording:
    """The recorder (run directory) and the `on_step` callback, either of which may be absent."""

    def __init__(self, recorder: Recorder | None, on_step: StepCallback | None):
        self.recorder, self.on_step = recorder, on_step

    def start(self, env: Environment, pilot: Pilot, task: Mission, config: EpisodeConfig, *, spawn_id: str | None,
              pilot_spec: str | None, safety: SafetyLayer, obs: Observation) -> None:
        if self.recorder is None:
            return
        scene = env.scene
        frames = self.recorder.save_observation(0, obs.front_rgb, obs.rear_rgb)
        self.recorder.start({
            "task": asdict(Task(task.query, task.goal_room, task.goal_target)), "spawn": spawn_id,
            "scene": scene.name, **({} if not task.recorded else {"mission": {
                **task.to_dict(), "max_steps": mission_budget(config.max_steps, task)}}),
            "pilot": pilot_spec or pilot.name, "pilot_name": pilot.name, "model": pilot.model,
            # a model pilot's conversation memory ('none', 'history=N'); a pilot without the option says nothing
            **({"pilot_memory": memory} if isinstance(memory := getattr(pilot, "memory", None), str) else {}),
            "config": {"max_steps": config.max_steps, "profile": config.profile, "max_reasks": config.max_reasks,
                       "context": {"preset": context_name(config.context_config), **config.context_config.to_dict()},
                       "seed": config.seed, "success": asdict(config.success), "shield": safety.name,
                       "overlay": config.overlay, "safety": config.safety.to_dict(),
                       **({"camera": camera} if (camera := camera_settings_of(env)) else {}),
                       **({"detail": config.detail} if config.detail != "plain" else {})},  # plain: as before
            "start_pose": obs.pose.as_dict(), "start_frames": frames,
            # issue 24: the scenario of events (replayed with it) and those that fired at take-off
            **({"scenario": scene.scenario.to_dict()} if scene.scenario is not None else {}),
            **({"events": [e.as_dict() for e in obs.events]} if obs.events else {}),
            "capabilities": capabilities_of(env).to_dict(), **({"robot": obs.info} if obs.info else {}),
            "provenance": {"git_sha": git_sha(), "prompt_hash": prompt_hash(config.profile),
                           "scene_fingerprint": scene.fingerprint(),
                           "versions": package_versions(), "started_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")},
        })

    def step(self, record: StepRecord) -> None:
        line = record.to_dict()
        if self.recorder is not None:
            line[FRAMES] = self.recorder.save_observation(record.step, record.obs.front_rgb, record.obs.rear_rgb)
            self.recorder.step(line)
        if self.on_step is not None:
            self.on_step(line)

    def finish(self, result: EpisodeResult, end_pose: Pose, safety: SafetyLayer) -> None:
        if self.recorder is None:
            return
        self.recorder.finish({"result": result.to_dict(), "end_pose": end_pose.as_dict(),
                              "safety": {"shield": safety.name,
                                         "interventions": [i.to_dict() for i in safety.interventions],
                                         "oscillation_events": [e.to_dict() for e in safety.events]}})
