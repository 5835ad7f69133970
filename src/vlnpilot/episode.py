"""One closed-loop episode: the paper's Python controller.

Each step: observe, ask the pilot, validate the decision against the FSM (is the movement allowed in this
state? is the transition allowed?), execute, update the FSM, check termination. An invalid decision is
never executed: the pilot is re-asked with the validation error (at most `max_reasks` times; a transient
provider failure, already retried by the SDK, is not re-asked and not told to the model), then the
drone hovers (E) and the step counts an invalid decision.

Between the validated decision and the drone sits the safety layer (`vlnpilot.safety`, `EpisodeConfig.shield`):
an oscillation guard, a door-crossing assist and a shield may change the command (and, when the guard commits to
a crossing, the next state); each change is recorded and told to the pilot in the next prompt's feedback.

A loop control (`LoopControl`, e.g. the live ground station, vlnpilot.live) may hold the loop before a step,
hand the step to a person (steps marked `human`) or end the episode `aborted` before anything more is executed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

from vlnpilot.commands import HOVER, Command, get_command
from vlnpilot.context import ContextConfig, PilotContext, confirmation_note, context_name, context_preset
from vlnpilot.decision import Decision, DecisionError, PilotInput, Usage, normalize_decision, validate_decision
from vlnpilot.environment import Environment, capabilities_of
from vlnpilot.errors import ConfigError, RobotHalt
from vlnpilot.fsm import FINAL_STATES, PROFILES, State, parse_state
from vlnpilot.overrides import override_reason
from vlnpilot.pilots._common import TRANSIENT_REASONS
from vlnpilot.pilots._gate import call_in_daemon_thread
from vlnpilot.pilots.base import Pilot, PilotError
from vlnpilot.pilots.keyboard import HUMAN
from vlnpilot.prompting import prompt_hash
from vlnpilot.record import Recorder, git_sha, package_versions
from vlnpilot.safety import (
    OVERLAYS,
    SHIELDS,
    SafetyConfig,
    SafetyLayer,
    SafetyVerdict,
    draw_corridor,
    make_safety,
)
from vlnpilot.scene.model import Spawn
from vlnpilot.tasks import Oscillations, PathLength, SuccessConfig, Task, judge, shortest_path_length, spl
from vlnpilot.types import GroundTruth, Observation, Pose

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
class EpisodeResult:
    outcome: str
    reason: str
    steps: int
    path_length_m: float
    shortest_path_m: float
    spl: float
    collisions: int
    invalid_decisions: int
    oscillations: int
    final_state: str
    final_room: str | None
    contact: str | None
    input_tokens: int
    cached_tokens: int
    output_tokens: int
    cost_usd: float
    latency_s_total: float
    pilot_calls: int
    wall_time_s: float
    interventions: int = 0  # commands changed by the safety layer (guard, door assist, shield)
    oscillation_events: int = 0  # oscillation stretches the guard detected (also with the shield off)
    shield: str = "off"
    judged_by: str = "ground_truth"  # ground_truth | operator (confirmed or not) | declared (nobody checked) | none

    @property
    def success(self) -> bool:
        return self.outcome == "success"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


StepCallback = Callable[[dict[str, Any]], None]


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
    gt = env.ground_truth() if hasattr(env, "ground_truth") else None
    if getattr(pilot, "privileged", False):
        if gt is None:
            raise ConfigError(f"pilot {pilot.name!r} needs ground truth, which this environment does not provide")
        pilot.attach(gt)
    return gt


@dataclass(frozen=True)
class _Answer:
    """One pilot call, parsed and validated. A rejected reply keeps its text and the tokens it cost."""

    decision: Decision | None
    error: str | None = None
    fatal: bool = False
    usage: Usage = field(default_factory=Usage)
    raw_text: str | None = None
    kind: str | None = None  # the pilot's short reason code (refusal, truncated, invalid_enum, ...)
    hint: str | None = None  # the pilot's own one-line advice for the re-ask, if it has one


def _ask(pilot: Pilot, pin: PilotInput, state: State, profile: str) -> _Answer:
    try:
        decision = pilot.decide(pin)
    except PilotError as exc:
        return _Answer(None, f"{exc.reason}: {exc}", exc.fatal, getattr(exc, "usage", None) or Usage(),
                       getattr(exc, "raw_text", None), exc.reason, getattr(exc, "feedback", None))
    except DecisionError as exc:
        return _Answer(None, f"malformed answer: {exc}", raw_text=exc.raw_text, kind="malformed")
    if getattr(pilot, "validates_decisions", False):  # a model pilot checked it against this very state: once
        return _Answer(decision, usage=decision.usage, raw_text=decision.raw_text)
    decision = normalize_decision(decision)
    error = validate_decision(decision, state, profile)
    return _Answer(decision, error, usage=decision.usage, raw_text=decision.raw_text,
                   kind="invalid_decision" if error else None)


class _Deadline:
    """Runs pilot calls in a helper (daemon) thread so that a step can stop waiting when its deadline passes.

    A call still running at the deadline is abandoned and cancelled (`cancel_pending`: its SDK sends no further
    request, retries included), and the next call gets a fresh thread, so a hung request never blocks the
    episode, never calls the provider after the episode, and never holds up the process's exit.
    """

    def __init__(self, seconds: float | None, pilot: Pilot | None = None):
        self.seconds = seconds
        self._pilot = pilot

    def ask(self, pilot: Pilot, pin: PilotInput, state: State, profile: str, remaining_s: float) -> _Answer:
        if self.seconds is None:
            return _ask(pilot, pin, state, profile)
        if remaining_s <= 0:
            return self.expired()
        finished, answer = call_in_daemon_thread(lambda: _ask(pilot, pin, state, profile), remaining_s)
        if not finished:
            self._cancel()
            return self.expired()
        return answer

    def _cancel(self) -> None:
        cancel = getattr(self._pilot, "cancel_pending", None)
        if callable(cancel):
            cancel()

    def expired(self) -> _Answer:
        return _Answer(None, f"step_deadline: no valid answer within the step deadline of {self.seconds:g} s",
                       kind="step_deadline")

    def close(self) -> None:
        self._cancel()  # the episode is over: nothing may call the provider for it any more


def _needs_confirmation(context: ContextConfig, decision: Decision | None, asked: dict[str, Any] | None) -> bool:
    """A valid answer that declares a final state, not yet confirmed, with the confirm_final context item on."""
    return (context.confirm_final and asked is None and decision is not None
            and parse_state(decision.state) in FINAL_STATES)


def _reseed(pilot: Pilot, seed: int | None) -> None:
    """Give a stochastic pilot the episode's seed (pilots with a `reseed(seed)` method, e.g. noisy-oracle)."""
    if seed is not None and callable(getattr(pilot, "reseed", None)):
        pilot.reseed(seed)


def run_episode(env: Environment, pilot: Pilot, task: Task, config: EpisodeConfig | None = None, *,
                spawn: str | Spawn | None = None, recorder: Recorder | None = None,
                on_step: StepCallback | None = None, pilot_spec: str | None = None,
                judge_outcome: JudgeOutcome | None = None, control: LoopControl | None = None) -> EpisodeResult:
    """Fly one episode of `task` from `spawn` with `pilot`; record it if a recorder is given.

    Without ground truth (a real robot) a declared final state is a success only as declared, unless
    `judge_outcome` (the operator) confirms or rejects it.
    """
    config = config or EpisodeConfig()
    t_start = time.perf_counter()
    obs: Observation = env.reset(spawn, seed=config.seed)
    gt = _attach_ground_truth(env, pilot)
    _reseed(pilot, config.seed)
    scene = env.scene
    safety: SafetyLayer = make_safety(config.shield, env, scene, config.safety)
    safety.reset(obs)
    notes: tuple[str, ...] = ()  # safety feedback for the next prompt
    spawn_id = spawn.id if isinstance(spawn, Spawn) else spawn
    topo = scene.topological_map()
    shortest = shortest_path_length(scene, obs.pose, task, config.success)
    path, osc = PathLength(), Oscillations()
    path.reset()
    osc.reset()
    usage = Usage()
    calls = invalid = failed_streak = 0
    state, previous = State.RECOGNIZE_ROOM, None  # Start: the controller takes off, then Recognize Room
    outcome, reason, contact = "max_steps", f"no final state within {config.max_steps} steps", None
    judged_by = "ground_truth" if gt is not None else "none"

    if recorder is not None:
        frames = recorder.save_observation(0, obs.front_rgb, obs.rear_rgb)
        recorder.start({
            "task": asdict(task), "spawn": spawn_id, "scene": scene.name,
            "pilot": pilot_spec or pilot.name, "pilot_name": pilot.name, "model": pilot.model,
            "config": {"max_steps": config.max_steps, "profile": config.profile, "max_reasks": config.max_reasks,
                       "context": {"preset": context_name(config.context), **config.context.to_dict()},
                       "seed": config.seed, "success": asdict(config.success), "shield": safety.name,
                       "overlay": config.overlay, "safety": config.safety.to_dict()},
            "start_pose": obs.pose.as_dict(), "start_frames": frames,
            "capabilities": capabilities_of(env).to_dict(), **({"robot": obs.info} if obs.info else {}),
            "provenance": {"git_sha": git_sha(), "prompt_hash": prompt_hash(config.profile),
                           "scene_fingerprint": scene.fingerprint(),
                           "versions": package_versions(), "started_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")},
        })

    _tell_pilot_the_episode(pilot, scene, config)
    pilot_context = PilotContext(config.context, config.max_steps)
    steps = 0
    bounded = getattr(pilot, "uses_step_deadline", False)  # network-bound pilots; never the local oracle
    deadline = _Deadline(config.step_deadline_s if bounded else None, pilot)
    for step in range(1, config.max_steps + 1):
        gate = control.before_step(step) if control is not None else Gate()
        if gate.abort is not None:
            outcome, reason = "aborted", gate.abort
            break
        steps = step
        flier = gate.pilot or pilot  # a person's decisions need no deadline: they wait for the keyboard
        ask = deadline.ask if gate.pilot is None else (lambda p, pin, s, prof, _left: _ask(p, pin, s, prof))
        feedback: list[str] = list(notes)
        failures: list[dict[str, Any]] = []
        decision: Decision | None = None
        fatal = False
        image = draw_corridor(obs.front_rgb) if config.overlay == "corridor" else obs.front_rgb
        step_end = time.monotonic() + (config.step_deadline_s or 0.0)
        context_lines = pilot_context.lines(step)
        confirmation: dict[str, Any] | None = None
        attempt, reasks = 0, 0
        while reasks <= config.max_reasks:
            pin = PilotInput(image=image, query=task.query, topological_map=topo, state=state,
                             previous_movement=previous, step=step, profile=config.profile, feedback=tuple(feedback),
                             context=context_lines)
            answer = ask(flier, pin, state, config.profile, step_end - time.monotonic())
            calls += 1
            attempt += 1
            usage = usage + answer.usage
            fatal = answer.fatal
            if answer.error is None and _needs_confirmation(config.context, answer.decision, confirmation):
                # A final state ends the episode for good: ask once more, with a warning (costs a call, not a step).
                first = parse_state(answer.decision.state)
                confirmation = {"attempt": attempt - 1, "first": answer.decision.core(),
                                "raw_text": answer.decision.raw_text}
                feedback = [*notes, confirmation_note(first)]
                continue
            if answer.error is None:
                decision = answer.decision
                if confirmation is not None:
                    confirmation["confirmed"] = decision.state == confirmation["first"]["state"]
                break
            reasks += 1
            failures.append({"attempt": attempt - 1, "reason": answer.error, "kind": answer.kind, "fatal": fatal,
                             "raw_text": answer.raw_text})
            if fatal or answer.kind == "step_deadline" or answer.kind in TRANSIENT_REASONS:
                break  # re-ask only an unusable answer; a transient failure is the transport's, not the model's
            why = answer.hint or f"{answer.error}. Answer again with valid values."
            feedback = [*notes, f"Your previous answer was rejected: {why}"]

        abort = control.abort_reason() if control is not None else None
        if abort is not None:  # stopped while the pilot thought: its answer is recorded, never executed
            outcome, reason = "aborted", abort
            _record(recorder, on_step, step, state, decision, failures, None, None, obs, obs.pose, None, None, None,
                    confirmation=confirmation)
            break
        if fatal:
            outcome, reason = "pilot_error", failures[-1]["reason"]
            _record(recorder, on_step, step, state, None, failures, None, None, obs, obs.pose, None, None, None,
                    confirmation=confirmation)
            break

        pose_before = obs.pose
        if decision is None:
            invalid += 1
            failed_streak += 1
            command, next_state = HOVER, state
        else:
            failed_streak = 0
            command, next_state = get_command(decision.movement), parse_state(decision.state)
        verdict = safety.filter(step, state, command, next_state, pose_before)
        command, next_state, notes = verdict.command, verdict.next_state, verdict.feedback
        halt: RobotHalt | None = None
        try:
            obs = env.step(command)
        except RobotHalt as exc:  # a real robot's safety rule (battery, geofence, lost reply) ends the episode
            halt = exc
            obs = exc.observation if isinstance(exc.observation, Observation) else obs
        safety.observe(obs)
        path.update(pose_before, obs.pose)
        reversal = osc.update(command)
        room_now = gt.room() if gt is not None else None
        override = override_reason(state, config.profile, command, decision is None, verdict.interventions,
                                   next_state)
        _record(recorder, on_step, step, state, decision, failures, command, next_state, obs, pose_before,
                room_now, reversal, verdict, override, confirmation)
        pilot_context.update(step, state, decision, command, next_state)
        previous = command.code

        if halt is not None:
            outcome, reason = "halted", str(halt)
            break
        if obs.collided:
            outcome, reason, contact = "collision", f"touched {obs.contact}", obs.contact
            break
        if decision is None and failed_streak >= config.max_failed_steps:
            outcome, reason = "pilot_error", f"no valid decision in {failed_streak} consecutive steps"
            break
        state = next_state
        if state in FINAL_STATES:
            if gt is None and judge_outcome is not None:
                ok, reason = judge_outcome(task, state)
                outcome, judged_by = ("success" if ok else "false_success"), "operator"
            elif gt is None:
                outcome, reason, judged_by = "success", "final state declared (no ground truth to judge it)", "declared"
            else:
                ok, why = judge(task, state, gt, config.success)
                outcome, reason = ("success" if ok else "false_success"), why
            break

    deadline.close()
    final_room = gt.room() if gt is not None else None
    result = EpisodeResult(
        outcome=outcome, reason=reason, steps=steps, path_length_m=round(path.value(), 4),
        shortest_path_m=round(shortest, 4), spl=round(spl(outcome == "success", shortest, path.value()), 4),
        collisions=int(outcome == "collision"), invalid_decisions=invalid, oscillations=osc.value(),
        final_state=state.value, final_room=final_room, contact=contact,
        input_tokens=usage.input_tokens, cached_tokens=usage.cached_tokens, output_tokens=usage.output_tokens,
        cost_usd=round(usage.cost_usd, 6), latency_s_total=round(usage.latency_s, 4), pilot_calls=calls,
        wall_time_s=round(time.perf_counter() - t_start, 3), interventions=len(safety.interventions),
        oscillation_events=len(safety.events), shield=safety.name, judged_by=judged_by,
    )
    if recorder is not None:
        recorder.finish({"result": result.to_dict(), "end_pose": obs.pose.as_dict(),
                         "safety": {"shield": safety.name,
                                    "interventions": [i.to_dict() for i in safety.interventions],
                                    "oscillation_events": [e.to_dict() for e in safety.events]}})
    _tell_pilot_the_outcome(pilot, result)
    return result


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


def _record(recorder: Recorder | None, on_step: StepCallback | None, step: int, state: State,
            decision: Decision | None, failures: list[dict[str, Any]], command: Command | None,
            next_state: State | None, obs: Observation, pose_before: Pose, room_now: str | None,
            reversal: bool | None, verdict: SafetyVerdict | None = None, override: str | None = None,
            confirmation: dict[str, Any] | None = None) -> None:
    record: dict[str, Any] = {
        "step": step,
        "state": state.value,
        "decision": decision.core() if decision else None,
        "raw_text": decision.raw_text if decision else None,
        "usage": decision.usage.model_dump() if decision else None,
        "model": decision.model if decision else None,
        "failures": failures,
        "proposed": decision.movement if decision else None,
        "executed": command.code if command else None,
        "override": override,  # why an executed command outside the state's allowed moves ran (vlnpilot.overrides)
        "next_state": next_state.value if next_state else None,
        "pose_before": pose_before.as_dict(),
        "pose_after": obs.pose.as_dict(),
        "collided": obs.collided,
        "contact": obs.contact,
        "contact_part": obs.contact_part,
        "room_true": room_now,
        "oscillation": bool(reversal),
        "interventions": [i.to_dict() for i in verdict.interventions] if verdict else [],
        "oscillation_event": verdict.oscillation.to_dict() if verdict and verdict.oscillation else None,
        "safety_feedback": list(verdict.feedback) if verdict else [],
    }
    if confirmation is not None:  # only with the confirm_final context item, so paper-context records are unchanged
        record["confirmation"] = confirmation
    if decision is not None and decision.model == HUMAN:  # a person flew this step from the live station
        record["human"] = True
    if obs.info:  # a real robot's facts: frame age, battery, safety events
        record["robot"] = obs.info
    if recorder is not None:
        record["frames"] = recorder.save_observation(step, obs.front_rgb, obs.rear_rgb)
        recorder.step(record)
    if on_step is not None:
        on_step(record)
