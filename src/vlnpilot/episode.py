"""One closed-loop episode: the paper's Python controller.

Each step: observe, ask the pilot, validate the decision against the FSM (is the movement allowed in this
state? is the transition allowed?), execute, update the FSM, check termination. An invalid decision is
never executed: the pilot is re-asked with the validation error (at most `max_reasks` times), then the
drone hovers (E) and the step counts an invalid decision.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

from vlnpilot.commands import HOVER, Command, get_command
from vlnpilot.environment import Environment
from vlnpilot.errors import ConfigError
from vlnpilot.fsm import FINAL_STATES, PROFILES, State, parse_state
from vlnpilot.pilots.base import Decision, Pilot, PilotError, PilotInput, Usage
from vlnpilot.prompting import DecisionError, normalize_decision, prompt_hash, validate_decision
from vlnpilot.record import Recorder, git_sha, package_versions
from vlnpilot.scene.model import Spawn
from vlnpilot.tasks import Oscillations, PathLength, SuccessConfig, Task, judge, shortest_path_length, spl
from vlnpilot.types import GroundTruth, Observation

OUTCOMES = ("success", "false_success", "collision", "max_steps", "pilot_error")


@dataclass(frozen=True)
class EpisodeConfig:
    max_steps: int = 50
    profile: str = "paper"
    max_reasks: int = 2  # re-asks after an invalid or malformed answer, within one step
    max_failed_steps: int = 3  # consecutive steps without a valid decision before `pilot_error`
    success: SuccessConfig = field(default_factory=SuccessConfig)
    seed: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ConfigError(f"max_steps must be a positive integer, got {self.max_steps!r}")
        if self.profile not in PROFILES:
            raise ConfigError(f"unknown FSM profile {self.profile!r}; valid profiles: {', '.join(PROFILES)}")
        if self.max_reasks < 0:
            raise ConfigError("max_reasks must be >= 0")


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

    @property
    def success(self) -> bool:
        return self.outcome == "success"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


StepCallback = Callable[[dict[str, Any]], None]


def _attach_ground_truth(env: Environment, pilot: Pilot) -> GroundTruth | None:
    gt = env.ground_truth() if hasattr(env, "ground_truth") else None
    if getattr(pilot, "privileged", False):
        if gt is None:
            raise ConfigError(f"pilot {pilot.name!r} needs ground truth, which this environment does not provide")
        pilot.attach(gt)
    return gt


def _ask(pilot: Pilot, pin: PilotInput, state: State, profile: str) -> tuple[Decision | None, str | None, bool]:
    """One pilot call, parsed and validated: (decision, error reason, fatal)."""
    try:
        decision = normalize_decision(pilot.decide(pin))
    except PilotError as exc:
        return None, f"{exc.reason}: {exc}", exc.fatal
    except DecisionError as exc:
        return None, f"malformed answer: {exc}", False
    error = validate_decision(decision, state, profile)
    return decision, error, False


def run_episode(env: Environment, pilot: Pilot, task: Task, config: EpisodeConfig | None = None, *,
                spawn: str | Spawn | None = None, recorder: Recorder | None = None,
                on_step: StepCallback | None = None, pilot_spec: str | None = None) -> EpisodeResult:
    """Fly one episode of `task` from `spawn` with `pilot`; record it if a recorder is given."""
    config = config or EpisodeConfig()
    t_start = time.perf_counter()
    obs: Observation = env.reset(spawn, seed=config.seed)
    gt = _attach_ground_truth(env, pilot)
    scene = env.scene
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

    if recorder is not None:
        frames = recorder.save_observation(0, obs.front_rgb, obs.rear_rgb)
        recorder.start({
            "task": asdict(task), "spawn": spawn_id, "scene": scene.name,
            "pilot": pilot_spec or pilot.name, "pilot_name": pilot.name, "model": pilot.model,
            "config": {"max_steps": config.max_steps, "profile": config.profile, "max_reasks": config.max_reasks,
                       "seed": config.seed, "success": asdict(config.success)},
            "start_pose": obs.pose.as_dict(), "start_frames": frames,
            "provenance": {"git_sha": git_sha(), "prompt_hash": prompt_hash(config.profile),
                           "versions": package_versions(), "started_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")},
        })

    steps = 0
    for step in range(1, config.max_steps + 1):
        steps = step
        feedback: list[str] = []
        failures: list[dict[str, Any]] = []
        decision: Decision | None = None
        fatal = False
        for attempt in range(1 + config.max_reasks):
            pin = PilotInput(image=obs.front_rgb, query=task.query, topological_map=topo, state=state,
                             previous_movement=previous, step=step, profile=config.profile, feedback=tuple(feedback))
            candidate, error, fatal = _ask(pilot, pin, state, config.profile)
            calls += 1
            if candidate is not None:
                usage = usage + candidate.usage
            if error is None:
                decision = candidate
                break
            failures.append({"attempt": attempt, "reason": error,
                             "raw_text": candidate.raw_text if candidate is not None else None})
            if fatal:
                break
            feedback = [f"Your previous answer was rejected: {error}. Answer again with valid values."]

        if fatal:
            outcome, reason = "pilot_error", failures[-1]["reason"]
            _record(recorder, on_step, step, state, None, failures, None, None, obs, obs, None, None)
            break

        pose_before = obs.pose
        if decision is None:
            invalid += 1
            failed_streak += 1
            command, next_state = HOVER, state
        else:
            failed_streak = 0
            command, next_state = get_command(decision.movement), parse_state(decision.state)
        obs = env.step(command)
        path.update(pose_before, obs.pose)
        reversal = osc.update(command)
        room_now = gt.room() if gt is not None else None
        _record(recorder, on_step, step, state, decision, failures, command, next_state, obs, pose_before,
                room_now, reversal)
        previous = command.code

        if obs.collided:
            outcome, reason, contact = "collision", f"touched {obs.contact}", obs.contact
            break
        if decision is None and failed_streak >= config.max_failed_steps:
            outcome, reason = "pilot_error", f"no valid decision in {failed_streak} consecutive steps"
            break
        state = next_state
        if state in FINAL_STATES:
            if gt is None:
                outcome, reason = "success", "final state declared (no ground truth to judge it)"
            else:
                ok, why = judge(task, state, gt, config.success)
                outcome, reason = ("success" if ok else "false_success"), why
            break

    final_room = gt.room() if gt is not None else None
    result = EpisodeResult(
        outcome=outcome, reason=reason, steps=steps, path_length_m=round(path.value(), 4),
        shortest_path_m=round(shortest, 4), spl=round(spl(outcome == "success", shortest, path.value()), 4),
        collisions=int(outcome == "collision"), invalid_decisions=invalid, oscillations=osc.value(),
        final_state=state.value, final_room=final_room, contact=contact,
        input_tokens=usage.input_tokens, cached_tokens=usage.cached_tokens, output_tokens=usage.output_tokens,
        cost_usd=round(usage.cost_usd, 6), latency_s_total=round(usage.latency_s, 4), pilot_calls=calls,
        wall_time_s=round(time.perf_counter() - t_start, 3),
    )
    if recorder is not None:
        recorder.finish({"result": result.to_dict(), "end_pose": obs.pose.as_dict()})
    return result


def _record(recorder: Recorder | None, on_step: StepCallback | None, step: int, state: State,
            decision: Decision | None, failures: list[dict[str, Any]], command: Command | None,
            next_state: State | None, obs: Observation, pose_before_obs: Any, room_now: str | None,
            reversal: bool | None) -> None:
    pose_before = pose_before_obs.pose if isinstance(pose_before_obs, Observation) else pose_before_obs
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
        "next_state": next_state.value if next_state else None,
        "pose_before": pose_before.as_dict(),
        "pose_after": obs.pose.as_dict(),
        "collided": obs.collided,
        "contact": obs.contact,
        "contact_part": obs.contact_part,
        "room_true": room_now,
        "oscillation": bool(reversal),
    }
    if recorder is not None:
        record["frames"] = recorder.save_observation(step, obs.front_rgb, obs.rear_rgb)
        recorder.step(record)
    if on_step is not None:
        on_step(record)
