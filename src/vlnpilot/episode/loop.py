"""One closed-loop episode: the paper's Python controller.

Each step, in the shape of dm_control's rl/control.py: observe, ask the pilot and validate its decision
against the FSM (is the movement allowed in this state? is the transition allowed?), filter it through the
safety layer, execute, measure, record, update the FSM, check termination. An invalid decision is never
executed: the pilot is re-asked with the validation error (`episode.ask`), then the drone hovers (E) and the
step counts an invalid decision. The measures live in `episode.measures`, the records in `episode.record`, the
configuration and the outcomes in `episode.config`.

Between the validated decision and the drone sits the safety layer (`vlnpilot.safety`, `EpisodeConfig.shield`):
an oscillation guard, a door-crossing assist and a shield may change the command (and, when the guard commits to
a crossing, the next state); each change is recorded and told to the pilot in the next prompt's feedback.

A loop control (`LoopControl`, e.g. the live ground station, vlnpilot.live) may hold the loop before a step,
hand the step to a person (steps marked `human`) or end the episode `aborted` before anything more is executed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

from vlnpilot.core.commands import HOVER, Command, get_command
from vlnpilot.core.environment import Environment, GroundTruth, capabilities_of, ground_truth_of, range_sensing_of
from vlnpilot.core.errors import ConfigError, RobotHalt
from vlnpilot.core.fsm import FINAL_STATES, State, parse_state
from vlnpilot.core.ranging import range_sensor
from vlnpilot.core.records import Observation, Pose
from vlnpilot.core.rundir import Recorder
from vlnpilot.episode.ask import PilotAsker, StepAnswer
from vlnpilot.episode.config import EpisodeConfig, Gate, JudgeOutcome, LoopControl
from vlnpilot.episode.measures import EpisodeEnd, EpisodeResult, EpisodeStart, Measures, StepFacts, result_type
from vlnpilot.episode.overrides import override_reason
from vlnpilot.episode.record import EpisodeRecording, StepCallback, StepRecord
from vlnpilot.pilots.base import BasePilot, Pilot, as_base_pilot
from vlnpilot.safety import SafetyLayer, SafetyVerdict, make_safety
from vlnpilot.scene.model import Spawn
from vlnpilot.tasks.mission import Mission, MissionProgress, as_mission, mission_budget
from vlnpilot.tasks.signs import legible_now, signs
from vlnpilot.tasks.success import SuccessConfig
from vlnpilot.tasks.task import Task

__all__ = ["run_episode"]


def _as_recorded(pilot: Pilot, config: EpisodeConfig) -> EpisodeConfig:
    """A replay flies under the rules its recording was flown with, the mover shield's height rule and the success
    monitor (and records them so): the same answers meet the same shield and the same end is the same outcome."""
    rule = getattr(pilot, "recorded_mover_clearance", None)
    if isinstance(rule, str) and rule != config.safety.mover_clearance:
        config = replace(config, safety=replace(config.safety, mover_clearance=rule))
    success = getattr(pilot, "recorded_success", None)
    if isinstance(success, SuccessConfig) and success != config.success:
        config = replace(config, success=success)
    return config


def _attach_ground_truth(env: Environment, pilot: BasePilot) -> GroundTruth | None:
    gt = ground_truth_of(env)  # only if the environment declares it (a real drone does not)
    if pilot.traits.privileged:
        if gt is None:
            raise ConfigError(f"pilot {pilot.name!r} needs ground truth, which this environment does not declare; "
                              "use a model pilot")
        pilot.attach(gt)
    return gt


def _reseed(pilot: BasePilot, seed: int | None) -> None:
    """Give a stochastic pilot (noisy-oracle) the episode's seed."""
    if seed is not None:
        pilot.reseed(seed)


class _NoControl:
    """No loop control: every step is the pilot's, nothing stops the episode early."""

    def before_step(self, step: int) -> Gate:
        return Gate()

    def abort_reason(self) -> str | None:
        return None


@dataclass(frozen=True)
class _End:
    outcome: str
    reason: str
    contact: str | None = None
    judged_by: str | None = None  # None: by ground truth if there is any, else nobody


def run_episode(env: Environment, pilot: Pilot, task: Task | Mission, config: EpisodeConfig | None = None, *,
                spawn: str | Spawn | None = None, recorder: Recorder | None = None,
                on_step: StepCallback | None = None, pilot_spec: str | None = None,
                judge_outcome: JudgeOutcome | None = None, control: LoopControl | None = None) -> EpisodeResult:
    """Fly one episode of `task` (a Task, or a Mission of stages) from `spawn` with `pilot`; record it if a
    recorder is given. Without ground truth (a real robot) `judge_outcome` (the operator) judges a final state;
    without it too the episode ends `declared` (never a success: nobody judged it). A stage judged a success (or
    declared) hands over to the next one from Recognize Room; a stage judged a failure ends the mission.
    The budget is `config.max_steps` per stage, shared."""
    config, t_start, control = config or EpisodeConfig(), time.perf_counter(), control or _NoControl()
    config = _as_recorded(pilot, config)  # before the adapter: a wrapper (the bench's timer) delegates to the replay
    pilot = as_base_pilot(pilot)  # its traits and hooks, declared (a bare-protocol pilot is adapted once, here)
    safety = _preflight(env, pilot, config)  # on the ground: a real drone takes off in reset
    obs: Observation = env.reset(spawn, seed=config.seed)
    gt = _attach_ground_truth(env, pilot)
    progress = MissionProgress(_resolved(as_mission(task), env, obs, gt))
    max_steps = mission_budget(config.max_steps, progress.mission)
    measures, recording, asker = _start(env, pilot, progress.mission, config, obs, safety, recorder, on_step, spawn,
                                        pilot_spec, max_steps)
    state, steps, end = State.RECOGNIZE_ROOM, 0, None  # Start: the controller takes off, then Recognize Room
    unjudged = False  # a stage was declared and nobody judged it
    has_signs = bool(signs(env.scene))  # a sign is judged seen when legible (tasks/signs.py): read only where one is
    for step in range(1, max_steps + 1):
        gate = control.before_step(step)
        if gate.abort is not None:
            end = _End("aborted", gate.abort)
            break
        steps, started = step, time.monotonic()
        answer = asker.ask(step, state, obs, person=gate.pilot)  # observe, ask, validate
        end = _not_to_execute(control, answer)
        if end is not None:  # recorded, never executed
            _unexecuted(step, state, answer, obs, measures, recording, started)
            break
        legible = legible_now(gt) if has_signs else None  # in the image the pilot decided from, before it moves
        verdict = safety.filter(step, state, *_proposed(answer, state), obs.pose)  # the safety filter
        pose_before, (obs, flown, halt) = obs.pose, _execute(env, safety, verdict.command, obs)
        measures.update(StepFacts(tuple(answer.usages), answer.valid, flown, pose_before, obs.pose, answer.decision,
                                  obs.events, legible))
        progress.saw(gt.room() if gt is not None else None)
        recording.step(_timed(_flown(step, state, answer, verdict, flown, pose_before, obs, gt, measures,
                                     config.profile, None if progress.mission.is_single else progress.stage + 1),
                              answer, started))
        asker.flown(step, state, answer, flown or HOVER, verdict.next_state if flown else state, verdict.feedback)
        end = _stopped(halt, obs, answer, asker.failed_streak, config.max_failed_steps)
        if end is None and flown is not None:  # the FSM moves on; a final state ends the stage, judged
            state = verdict.next_state
            end = _judged(progress, state, gt, config, judge_outcome) if state in FINAL_STATES else None
            if end is not None and end.outcome in ("success", "declared") and not progress.last:  # next stage
                unjudged = unjudged or end.outcome == "declared"
                progress.advance(step)
                asker.stage, state, end = progress.stage, State.RECOGNIZE_ROOM, None
        if end is not None:
            break
    asker.close()
    end = end or _out_of_steps(progress, max_steps, steps, asker.failed_streak)
    # a stage counts as reached only when it was judged a success, as every one before it (a declared one was not)
    stages_reached = 0 if unjudged else len(progress.boundaries) + (end.outcome == "success")
    measured = measures.values(EpisodeEnd(end.outcome, safety, stages_reached, tuple(progress.boundaries),
                                          final_state=state.value, contact=end.contact))
    result = _result(end, steps, state, gt, measured, t_start)
    recording.finish(result, obs.pose, safety)
    _tell_pilot_the_outcome(pilot, result)
    return result


def _preflight(env: Environment, pilot: BasePilot, config: EpisodeConfig) -> SafetyLayer:
    """Every setting that can be checked on the ground, before `reset` (a real drone takes off there): a pilot
    that needs ground truth the environment does not declare, a shield it cannot serve, and what the pilot
    itself checks of the episode (a replay refuses another scene or other settings than its recording's)."""
    if pilot.traits.privileged and not capabilities_of(env).ground_truth:
        _attach_ground_truth(env, pilot)  # raises the one-line refusal
    safety = make_safety(config.shield, env, env.scene, config.safety)
    _tell_pilot_the_episode(pilot, env.scene, config)
    return safety


def _resolved(mission: Mission, env: Environment, obs: Observation, gt: GroundTruth | None) -> Mission:
    """A return stage points at the room the drone takes off in."""
    start_room = gt.room() if gt is not None else env.scene.room_at(obs.pose.x, obs.pose.y)
    return mission.resolved(start_room)


def _start(env: Environment, pilot: BasePilot, task: Mission, config: EpisodeConfig, obs: Observation,
           safety: SafetyLayer, recorder: Recorder | None, on_step: StepCallback | None, spawn: str | Spawn | None,
           pilot_spec: str | None, max_steps: int) -> tuple[Measures, EpisodeRecording, PilotAsker]:
    """Before the first step: seed the pilot, reset the safety layer and the measures, write the run's header."""
    _reseed(pilot, config.seed)
    safety.reset(obs)
    measures = Measures(EpisodeStart(env.scene, obs.pose, task, config.success, obs.events))
    recording = EpisodeRecording(recorder, on_step)
    recording.start(env, pilot, task, config, spawn_id=spawn.id if isinstance(spawn, Spawn) else spawn,
                    pilot_spec=pilot_spec, safety=safety, obs=obs)
    sensor = range_sensor(capabilities_of(env).range_sensor)
    return measures, recording, PilotAsker(pilot, task, config, env.scene.topological_map(), range_sensing_of(env),
                                           sensor, max_steps)


def _unexecuted(step: int, state: State, answer: StepAnswer, obs: Observation, measures: Measures,
                recording: EpisodeRecording, started: float) -> None:
    """A step that ends the episode before anything is executed still costs its calls and is recorded."""
    measures.update(StepFacts(tuple(answer.usages), answer.valid, None, obs.pose, obs.pose, answer.decision))
    recording.step(_timed(StepRecord(step, state, answer.decision, answer.failures, obs.pose, obs,
                                     confirmation=answer.confirmation, ranges=answer.ranges), answer, started))


def _timed(record: StepRecord, answer: StepAnswer, started: float) -> StepRecord:
    """The record with its calls (their HTTP attempts) and its wall time since `started` (time.monotonic)."""
    return replace(record, calls=tuple(answer.usages), wall_s=round(time.monotonic() - started, 4))


def _not_to_execute(control: LoopControl, answer: StepAnswer) -> _End | None:
    """Stopped while the pilot thought (its answer is recorded, never executed), or a fatal pilot error."""
    abort = control.abort_reason()
    if abort is not None:
        return _End("aborted", abort)
    if answer.fatal:
        return _End("pilot_error", answer.failures[-1]["reason"])
    return None


def _proposed(answer: StepAnswer, state: State) -> tuple[Command, State]:
    """The pilot's command and next state; without a valid decision the drone hovers and the state stays."""
    if answer.decision is None:
        return HOVER, state
    return get_command(answer.decision.movement), parse_state(answer.decision.state)


def _execute(env: Environment, safety: SafetyLayer, command: Command,
             before: Observation) -> tuple[Observation, Command | None, RobotHalt | None]:
    """Fly `command`: the observation, the command if it was executed (a real robot says when it was not: a
    rotation that did not happen, a move refused or unconfirmed), and the halt of a real robot's safety rule
    (battery, geofence, lost reply, lost link) that ends the episode."""
    halt: RobotHalt | None = None
    try:
        obs = env.step(command)
        executed = obs.executed
    except RobotHalt as exc:
        halt, executed = exc, exc.executed
        obs = exc.observation if isinstance(exc.observation, Observation) else before
    safety.observe(obs)
    return obs, command if executed else None, halt


def _flown(step: int, state: State, answer: StepAnswer, verdict: SafetyVerdict, flown: Command | None,
           pose_before: Pose, obs: Observation, gt: GroundTruth | None, measures: Measures,
           profile: str, stage: int | None = None) -> StepRecord:
    """The record of a step that went to the drone; `override` says why a command outside the state's moves ran.
    Without `flown` nothing was executed: the step keeps its decision and verdict, no command, no next state.
    `stage`: the mission's stage (1-based) the step flew, for a mission of several stages."""
    if flown is None:
        return StepRecord(step, state, answer.decision, answer.failures, pose_before, obs,
                          room_true=gt.room() if gt is not None else None, verdict=verdict,
                          confirmation=answer.confirmation, stage=stage)
    override = override_reason(state, profile, flown, not answer.valid, verdict.interventions, verdict.next_state)
    return StepRecord(step, state, answer.decision, answer.failures, pose_before, obs, flown,
                      verdict.next_state, gt.room() if gt is not None else None, measures.reversed(), verdict,
                      override, answer.confirmation, ranges=answer.ranges, stage=stage)


def _stopped(halt: RobotHalt | None, obs: Observation, answer: StepAnswer, failed_streak: int,
             max_failed_steps: int) -> _End | None:
    """An end after an executed step that is not a final state: a robot's halt, a collision, a failing pilot."""
    if halt is not None:
        return _End(halt.outcome, str(halt))  # halted, or link_lost
    if obs.collided:
        return _End("collision", f"touched {obs.contact}", contact=obs.contact)
    if not answer.valid and failed_streak >= max_failed_steps:
        return _End("pilot_error", f"no valid decision in {failed_streak} consecutive steps")
    return None


def _out_of_steps(progress: MissionProgress, max_steps: int, steps: int, failed_streak: int) -> _End:
    """The end at the step limit: `pilot_error` when not one step got a valid decision (an unreachable provider,
    whose every call failed, even when its failures were too few in a row to end the episode earlier: the pilot,
    not the flight, is what failed), else `max_steps`."""
    if steps and failed_streak >= steps:
        return _End("pilot_error", f"no valid decision in any of the {steps} steps")
    return _End("max_steps", progress.prefix(False, f"no final state within {max_steps} steps"))


def _judged(progress: MissionProgress, state: State, gt: GroundTruth | None, config: EpisodeConfig,
            judge_outcome: JudgeOutcome | None) -> _End:
    """A declared final state: the current stage judged by ground truth, by the operator, or taken as declared."""
    right = "unreachable" if state is State.GOAL_UNREACHABLE else "success"  # a true report is its own kind
    if gt is None and judge_outcome is not None:
        ok, reason = judge_outcome(progress.task, state)
        return _End(right if ok else "false_success", progress.prefix(ok, reason), judged_by="operator")
    if gt is None:  # nobody can judge it: recorded as declared, never as a success
        return _End("declared", progress.prefix(True, "final state declared; not judged (no ground truth, "
                                                      "no operator: --judge none)"), judged_by="declared")
    ok, why = progress.judge(state, gt, config.success)
    return _End(right if ok else "false_success", progress.prefix(ok, why))


def _result(end: _End, steps: int, state: State, gt: GroundTruth | None, measured: dict[str, Any],
            t_start: float) -> EpisodeResult:
    final_room = gt.room() if gt is not None else None
    judged_by = end.judged_by or ("ground_truth" if gt is not None else "none")
    return result_type()(outcome=end.outcome, reason=end.reason, steps=steps, final_state=state.value,
                         final_room=final_room, contact=end.contact, judged_by=judged_by,
                         wall_time_s=round(time.perf_counter() - t_start, 3), **measured)


def _tell_pilot_the_episode(pilot: BasePilot, scene: Any, config: EpisodeConfig) -> None:
    """The pilot sees the scene and the configuration first (the replay pilot checks them)."""
    pilot.episode_started(scene, config)


def _tell_pilot_the_outcome(pilot: BasePilot, result: EpisodeResult) -> None:
    """The pilot learns the outcome (the files pilot writes done.txt)."""
    pilot.episode_finished(result)
