"""One closed-loop episode: the paper's Python controller.

Each step, in the shape of dm_control's rl/control.py: observe, ask the pilot and validate its decision
against the FSM (is the movement allowed in this state? is the transition allowed?), filter it through the
safety layer, execute, measure, record, update the FSM, check termination. An invalid decision is never
executed: the pilot is re-asked with the validation error (`episode_ask`), then the drone hovers (E) and the
step counts an invalid decision. The measures live in `episode_measures`, the records in `episode_record`.

Between the validated decision and the drone sits the safety layer (`vlnpilot.safety`, `EpisodeConfig.shield`):
an oscillation guard, a door-crossing assist and a shield may change the command (and, when the guard commits to
a crossing, the next state); each change is recorded and told to the pilot in the next prompt's feedback.

A loop control (`LoopControl`, e.g. the live ground station, vlnpilot.live) may hold the loop before a step,
hand the step to a person (steps marked `human`) or end the episode `aborted` before anything more is executed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from vlnpilot.commands import HOVER, Command, get_command
from vlnpilot.context import ContextConfig, context_preset
from vlnpilot.environment import Environment, ground_truth_of
from vlnpilot.episode_ask import PilotAsker, StepAnswer
from vlnpilot.episode_measures import EpisodeEnd, EpisodeResult, EpisodeStart, Measures, StepFacts, result_type
from vlnpilot.episode_record import EpisodeRecording, StepCallback, StepRecord
from vlnpilot.errors import ConfigError, RobotHalt
from vlnpilot.fsm import FINAL_STATES, PROFILES, State, parse_state
from vlnpilot.overrides import override_reason
from vlnpilot.pilots.base import Pilot
from vlnpilot.record import Recorder
from vlnpilot.safety import OVERLAYS, SHIELDS, SafetyConfig, SafetyLayer, SafetyVerdict, make_safety
from vlnpilot.scene.model import Spawn
from vlnpilot.tasks import SuccessConfig, Task, judge
from vlnpilot.types import GroundTruth, Observation, Pose

__all__ = ["OUTCOMES", "EpisodeConfig", "EpisodeResult", "Gate", "LoopControl", "StepCallback", "run_episode"]

# halted: a real robot's safety rule ended the episode (battery, flight time, geofence, a lost reply to a move)
OUTCOMES = ("success", "false_success", "collision", "max_steps", "pilot_error", "halted", "aborted")
JudgeOutcome = Callable[[Task, State], tuple[bool, str]]  # the operator's word on a declared final state


@dataclass(frozen=True)
class EpisodeConfig:
    max_steps: int = 50
    profile: str = "paper"
    max_reasks: int = 2  # re-asks after an invalid or malformed answer, within one step
    max_failed_steps: int = 3  # consecutive steps without a valid decision before `pilot_error`
    success: SuccessConfig = field(default_factory=SuccessConfig)
    seed: int | None = None
    shield: str = "off"  # off | geometry | depth (the CLI defaults to safety.DEFAULT_SHIELD in the simulator)
    safety: SafetyConfig = field(default_factory=SafetyConfig)  # margin, door assist, oscillation guard, depth
    overlay: str | None = None  # None | "corridor": draw the propeller-tip corridor on the image the pilot sees
    # Wall-clock bound on one step's pilot calls, re-asks and provider retries included, for pilots that wait on
    # a network (`uses_step_deadline`); when it passes the drone hovers and the step counts an invalid decision.
    step_deadline_s: float | None = 120.0
    # What the pilot is told beyond the paper's five inputs (vlnpilot.context): a preset name or a ContextConfig.
    context: ContextConfig | str = "paper"

    @property
    def context_config(self) -> ContextConfig:
        """`context` as the ContextConfig that `__post_init__` made of it (a name given is looked up there)."""
        return context_preset(self.context)

    def __post_init__(self) -> None:
        object.__setattr__(self, "context", context_preset(self.context))
        if not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ConfigError(f"max_steps must be a positive integer, got {self.max_steps!r}")
        if self.profile not in PROFILES:
            raise ConfigError(f"unknown FSM profile {self.profile!r}; valid profiles: {', '.join(PROFILES)}")
        if self.max_reasks < 0:
            raise ConfigError("max_reasks must be >= 0")
        if str(self.shield).lower() not in SHIELDS:
            raise ConfigError(f"unknown shield {self.shield!r}; valid shields: {', '.join(SHIELDS)}")
        if self.step_deadline_s is not None and not self.step_deadline_s > 0:
            raise ConfigError(f"step_deadline_s must be positive or None, got {self.step_deadline_s!r}")
        if self.overlay is not None and self.overlay not in OVERLAYS:
            raise ConfigError(f"unknown overlay {self.overlay!r}; valid overlays: {', '.join(OVERLAYS)}")


@dataclass(frozen=True)
class Gate:
    """What a loop control (the live station, vlnpilot.live) says before a step: who flies it, or stop here."""

    pilot: Pilot | None = None  # flies this step instead of the episode's pilot (a person at the keyboard)
    abort: str | None = None  # the episode ends now, outcome `aborted`, for this reason


class LoopControl(Protocol):
    def before_step(self, step: int) -> Gate:
        """Called once per step before the pilot is asked; may wait (pause)."""

    def abort_reason(self) -> str | None:
        """Why the episode must end now (an emergency stop while the pilot thought), checked before executing."""


def _attach_ground_truth(env: Environment, pilot: Pilot) -> GroundTruth | None:
    gt = ground_truth_of(env)  # only if the environment declares it (a real drone does not)
    if getattr(pilot, "privileged", False):
        if gt is None:
            raise ConfigError(f"pilot {pilot.name!r} needs ground truth, which this environment does not declare; "
                              "use a model pilot")
        pilot.attach(gt)
    return gt


def _reseed(pilot: Pilot, seed: int | None) -> None:
    """Give a stochastic pilot the episode's seed (pilots with a `reseed(seed)` method, e.g. noisy-oracle)."""
    if seed is not None and callable(getattr(pilot, "reseed", None)):
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


def run_episode(env: Environment, pilot: Pilot, task: Task, config: EpisodeConfig | None = None, *,
                spawn: str | Spawn | None = None, recorder: Recorder | None = None,
                on_step: StepCallback | None = None, pilot_spec: str | None = None,
                judge_outcome: JudgeOutcome | None = None, control: LoopControl | None = None) -> EpisodeResult:
    """Fly one episode of `task` from `spawn` with `pilot`; record it if a recorder is given. Without ground
    truth (a real robot) a final state is a success as declared, unless `judge_outcome` (the operator) rules."""
    config, t_start, control = config or EpisodeConfig(), time.perf_counter(), control or _NoControl()
    obs: Observation = env.reset(spawn, seed=config.seed)
    gt = _attach_ground_truth(env, pilot)
    safety, measures, recording, asker = _start(env, pilot, task, config, obs, recorder, on_step, spawn, pilot_spec)
    state, steps, end = State.RECOGNIZE_ROOM, 0, None  # Start: the controller takes off, then Recognize Room
    for step in range(1, config.max_steps + 1):
        gate = control.before_step(step)
        if gate.abort is not None:
            end = _End("aborted", gate.abort)
            break
        steps = step
        answer = asker.ask(step, state, obs, person=gate.pilot)  # observe, ask, validate
        end = _not_to_execute(control, answer)
        if end is not None:  # recorded, never executed
            _unexecuted(step, state, answer, obs, measures, recording)
            break
        verdict = safety.filter(step, state, *_proposed(answer, state), obs.pose)  # the safety filter
        pose_before, (obs, halt) = obs.pose, _execute(env, safety, verdict.command, obs)
        measures.update(StepFacts(tuple(answer.usages), answer.valid, verdict.command, pose_before, obs.pose))
        recording.step(_flown(step, state, answer, verdict, pose_before, obs, gt, measures, config.profile))
        asker.flown(step, state, answer, verdict.command, verdict.next_state, verdict.feedback)
        end = _stopped(halt, obs, answer, asker.failed_streak, config.max_failed_steps)
        if end is None:  # the FSM moves on; a final state ends the episode, judged
            state = verdict.next_state
            end = _judged(task, state, gt, config, judge_outcome) if state in FINAL_STATES else None
        if end is not None:
            break
    asker.close()
    end = end or _End("max_steps", f"no final state within {config.max_steps} steps")
    result = _result(end, steps, state, gt, measures.values(EpisodeEnd(end.outcome, safety)), t_start)
    recording.finish(result, obs.pose, safety)
    _tell_pilot_the_outcome(pilot, result)
    return result


def _start(env: Environment, pilot: Pilot, task: Task, config: EpisodeConfig, obs: Observation,
           recorder: Recorder | None, on_step: StepCallback | None, spawn: str | Spawn | None,
           pilot_spec: str | None) -> tuple[SafetyLayer, Measures, EpisodeRecording, PilotAsker]:
    """Before the first step: seed the pilot, reset the safety layer and the measures, write the run's header."""
    _reseed(pilot, config.seed)
    safety = make_safety(config.shield, env, env.scene, config.safety)
    safety.reset(obs)
    measures = Measures(EpisodeStart(env.scene, obs.pose, task, config.success))
    recording = EpisodeRecording(recorder, on_step)
    recording.start(env, pilot, task, config, spawn_id=spawn.id if isinstance(spawn, Spawn) else spawn,
                    pilot_spec=pilot_spec, safety=safety, obs=obs)
    _tell_pilot_the_episode(pilot, env.scene, config)
    return safety, measures, recording, PilotAsker(pilot, task, config, env.scene.topological_map())


def _unexecuted(step: int, state: State, answer: StepAnswer, obs: Observation, measures: Measures,
                recording: EpisodeRecording) -> None:
    """A step that ends the episode before anything is executed still costs its calls and is recorded."""
    measures.update(StepFacts(tuple(answer.usages), answer.valid, None, obs.pose, obs.pose))
    recording.step(StepRecord(step, state, answer.decision, answer.failures, obs.pose, obs,
                              confirmation=answer.confirmation))


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
             before: Observation) -> tuple[Observation, RobotHalt | None]:
    """Fly `command`. A real robot's safety rule (battery, geofence, lost reply) ends the episode: `halt`."""
    halt: RobotHalt | None = None
    try:
        obs = env.step(command)
    except RobotHalt as exc:
        halt = exc
        obs = exc.observation if isinstance(exc.observation, Observation) else before
    safety.observe(obs)
    return obs, halt


def _flown(step: int, state: State, answer: StepAnswer, verdict: SafetyVerdict, pose_before: Pose,
           obs: Observation, gt: GroundTruth | None, measures: Measures, profile: str) -> StepRecord:
    """The record of an executed step; `override` says why a command outside the state's moves ran."""
    override = override_reason(state, profile, verdict.command, not answer.valid, verdict.interventions,
                               verdict.next_state)
    return StepRecord(step, state, answer.decision, answer.failures, pose_before, obs, verdict.command,
                      verdict.next_state, gt.room() if gt is not None else None, measures.reversed(), verdict,
                      override, answer.confirmation)


def _stopped(halt: RobotHalt | None, obs: Observation, answer: StepAnswer, failed_streak: int,
             max_failed_steps: int) -> _End | None:
    """An end after an executed step that is not a final state: a robot's halt, a collision, a failing pilot."""
    if halt is not None:
        return _End("halted", str(halt))
    if obs.collided:
        return _End("collision", f"touched {obs.contact}", contact=obs.contact)
    if not answer.valid and failed_streak >= max_failed_steps:
        return _End("pilot_error", f"no valid decision in {failed_streak} consecutive steps")
    return None


def _judged(task: Task, state: State, gt: GroundTruth | None, config: EpisodeConfig,
            judge_outcome: JudgeOutcome | None) -> _End:
    """A declared final state: judged by ground truth, by the operator, or taken as declared."""
    if gt is None and judge_outcome is not None:
        ok, reason = judge_outcome(task, state)
        return _End("success" if ok else "false_success", reason, judged_by="operator")
    if gt is None:
        return _End("success", "final state declared (no ground truth to judge it)", judged_by="declared")
    ok, why = judge(task, state, gt, config.success)
    return _End("success" if ok else "false_success", why)


def _result(end: _End, steps: int, state: State, gt: GroundTruth | None, measured: dict[str, Any],
            t_start: float) -> EpisodeResult:
    final_room = gt.room() if gt is not None else None
    judged_by = end.judged_by or ("ground_truth" if gt is not None else "none")
    return result_type()(outcome=end.outcome, reason=end.reason, steps=steps, final_state=state.value,
                         final_room=final_room, contact=end.contact, judged_by=judged_by,
                         wall_time_s=round(time.perf_counter() - t_start, 3), **measured)


def _tell_pilot_the_episode(pilot: Pilot, scene: Any, config: EpisodeConfig) -> None:
    """A pilot with an `episode_started(scene, config)` method sees them first (the replay pilot checks them)."""
    started = getattr(pilot, "episode_started", None)
    if callable(started):
        started(scene, config)


def _tell_pilot_the_outcome(pilot: Pilot, result: EpisodeResult) -> None:
    """A pilot with an `episode_finished(result)` method learns the outcome (the files pilot writes done.txt)."""
    finished = getattr(pilot, "episode_finished", None)
    if callable(finished):
        finished(result)
