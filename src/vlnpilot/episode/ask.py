"""Asking the pilot for one step's decision: re-asks, the step deadline and the confirmation of a final state.

An invalid decision is never executed: the pilot is re-asked with the validation error (at most `max_reasks`
times; a transient provider failure, already retried by the SDK, is not re-asked and not told to the model).
A valid answer that declares a final state with the `confirm_final` context item on is asked once more, with a
warning (a call, not a step). `PilotAsker` also keeps what the next prompt needs from the steps before: the
previous movement, the safety layer's feedback and the pilot context (odometry, budget, memory).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from vlnpilot.core.commands import Command
from vlnpilot.core.decision import (
    Decision,
    DecisionError,
    PilotInput,
    Usage,
    normalize_decision,
    traits_of,
    validate_decision,
)
from vlnpilot.core.environment import RangeSensing
from vlnpilot.core.fsm import FINAL_STATES, State, parse_state, state_spec
from vlnpilot.core.ranging import RangeReading, RangeSensor
from vlnpilot.core.records import Observation
from vlnpilot.pilots._gate import call_in_daemon_thread
from vlnpilot.pilots.base import Pilot, PilotError, as_base_pilot
from vlnpilot.pilots.transport import TRANSIENT_REASONS
from vlnpilot.prompting.context import ContextConfig, PilotContext, confirmation_note
from vlnpilot.safety import draw_corridor
from vlnpilot.tasks.mission import Mission, as_mission
from vlnpilot.tasks.task import Task

if TYPE_CHECKING:
    from vlnpilot.episode.config import EpisodeConfig


RATE_LIMITED = "rate_limited"
# A 429 the SDK's retries did not get past is asked again within the same step, with a fresh deadline (the provider
# answers: it is not hung), up to this many times; the shared rate budget (pilots/ratelimit.py) has by then slowed
# every worker down. It is recorded with the step's calls, and is neither a step nor a re-ask.
MAX_RATE_LIMITED_CALLS = 50


@dataclass(frozen=True)
class Answer:
    """One pilot call, parsed and validated. A rejected reply keeps its text and the tokens it cost."""

    decision: Decision | None
    error: str | None = None
    fatal: bool = False
    usage: Usage = field(default_factory=Usage)
    raw_text: str | None = None
    kind: str | None = None  # the pilot's short reason code (refusal, truncated, invalid_enum, ...)
    hint: str | None = None  # the pilot's own one-line advice for the re-ask, if it has one


def ask_once(pilot: Pilot, pin: PilotInput, state: State, profile: str) -> Answer:
    try:
        decision = pilot.decide(pin)
    except PilotError as exc:
        return Answer(None, f"{exc.reason}: {exc}", exc.fatal, getattr(exc, "usage", None) or Usage(),
                      getattr(exc, "raw_text", None), exc.reason, getattr(exc, "feedback", None))
    except DecisionError as exc:
        return Answer(None, f"malformed answer: {exc}", raw_text=exc.raw_text, kind="malformed")
    if traits_of(pilot).validates_decisions:  # a model pilot checked it against this very state: once
        return Answer(decision, usage=decision.usage, raw_text=decision.raw_text)
    decision = normalize_decision(decision)
    error = validate_decision(decision, state, profile)
    return Answer(decision, error, usage=decision.usage, raw_text=decision.raw_text,
                  kind="invalid_decision" if error else None)


class Deadline:
    """Runs pilot calls in a helper (daemon) thread so that a step can stop waiting when its deadline passes.

    A call still running at the deadline is abandoned and cancelled (`cancel_pending`: its SDK sends no further
    request, retries included), and the next call gets a fresh thread, so a hung request never blocks the
    episode, never calls the provider after the episode, and never holds up the process's exit.
    """

    def __init__(self, seconds: float | None, pilot: Pilot | None = None):
        self.seconds = seconds
        self._pilot = as_base_pilot(pilot) if pilot is not None else None

    def ask(self, pilot: Pilot, pin: PilotInput, state: State, profile: str, remaining_s: float) -> Answer:
        if self.seconds is None:
            return ask_once(pilot, pin, state, profile)
        if remaining_s <= 0:
            return self.expired()
        finished, answer = call_in_daemon_thread(lambda: ask_once(pilot, pin, state, profile), remaining_s)
        if not finished:
            self._cancel()
            abandoned = getattr(pilot, "abandoned_attempts", None)  # a model pilot's HTTP attempts so far
            return self.expired(abandoned() if callable(abandoned) else ())
        return answer

    def _cancel(self) -> None:
        if self._pilot is not None:
            self._pilot.cancel_pending()

    def expired(self, attempts: tuple[dict[str, Any], ...] = ()) -> Answer:
        return Answer(None, f"step_deadline: no valid answer within the step deadline of {self.seconds:g} s",
                      usage=Usage(attempts=attempts), kind="step_deadline")

    def close(self) -> None:
        self._cancel()  # the episode is over: nothing may call the provider for it any more


@dataclass
class StepAnswer:
    """Everything the pilot said in one step: the decision to fly (None: hover), the rejected answers, the
    confirmation exchange, and the usage of every call in order (the measures add them one by one)."""

    decision: Decision | None = None
    failures: list[dict[str, Any]] = field(default_factory=list)
    confirmation: dict[str, Any] | None = None
    fatal: bool = False
    usages: list[Usage] = field(default_factory=list)
    ranges: tuple[RangeReading, ...] = ()  # the range readings the pilot was told this step (before the move)

    @property
    def valid(self) -> bool:
        return self.decision is not None


def needs_confirmation(context: ContextConfig, decision: Decision | None, asked: dict[str, Any] | None) -> bool:
    """A valid answer that declares a final state, not yet confirmed, with the confirm_final context item on."""
    return (context.confirm_final and asked is None and decision is not None
            and parse_state(decision.state) in FINAL_STATES)


class PilotAsker:
    """Asks the episode's pilot (or a person taking a step over) and remembers what the next prompt needs."""

    def __init__(self, pilot: Pilot, task: Task | Mission, config: EpisodeConfig, topological_map: Any,
                 sensing: RangeSensing | None = None, sensor: RangeSensor | None = None,
                 max_steps: int | None = None):
        self.pilot, self.task, self.config, self.topo = pilot, task, config, topological_map
        self._mission = as_mission(task)
        self.mission = None if self._mission.is_single else self._mission.to_dict()  # one stage: the paper's prompt
        bounded = traits_of(pilot).uses_step_deadline  # network-bound pilots; never the local oracle
        self.deadline = Deadline(config.step_deadline_s if bounded else None, pilot)
        self.sensing = sensing  # the drone's range sensors, read once per step
        longer = "A2" in state_spec(State.REACH_OBJECT, config.profile).moves
        self.context = PilotContext(config.context_config, max_steps or config.max_steps, sensor, None, longer)
        self.stage = 0  # the mission's current stage (the episode moves it on)
        self.previous: str | None = None  # the movement executed last step
        self.notes: tuple[str, ...] = ()  # the safety layer's feedback for the next prompt
        self.failed_streak = 0  # consecutive steps without a valid decision (too many end the episode)

    @property
    def stage(self) -> int:
        return self._stage

    @stage.setter
    def stage(self, index: int) -> None:
        """The mission moves on: the range stop rule names the new stage's object (None for a room stage)."""
        self._stage = index
        self.context.goal_target = self._mission.task(index).goal_target

    def _stages_left(self) -> int:
        return len(self._mission.stages) - 1 - self._stage

    def ask(self, step: int, state: State, obs: Observation, person: Pilot | None = None) -> StepAnswer:
        """Ask until a valid decision, a fatal or transient failure, or `max_reasks` rejected answers."""
        config, out = self.config, StepAnswer()
        flier = person or self.pilot  # a person's decisions need no deadline: they wait for the keyboard
        ask: Callable[..., Answer] = (self.deadline.ask if person is None
                                      else (lambda p, pin, s, prof, _left: ask_once(p, pin, s, prof)))
        feedback = list(self.notes)
        image = draw_corridor(obs.front_rgb) if config.overlay == "corridor" else obs.front_rgb
        step_end = time.monotonic() + (config.step_deadline_s or 0.0)
        out.ranges = self.sensing.ranges() if self.sensing is not None else ()
        context_lines, in_state = self.context.lines(step, state, out.ranges), self.context.in_state()
        attempt, reasks, throttled = 0, 0, 0
        while reasks <= config.max_reasks:
            pin = PilotInput(image=image, query=self.task.query, topological_map=self.topo, state=state,
                             previous_movement=self.previous, step=step, profile=config.profile,
                             feedback=tuple(feedback), context=context_lines, in_state=in_state,
                             mission=self.mission, stage=self.stage)
            answer = ask(flier, pin, state, config.profile, step_end - time.monotonic())
            attempt += 1
            out.usages.append(answer.usage)
            out.fatal = answer.fatal
            decision = answer.decision if answer.error is None else None
            if decision is not None and needs_confirmation(config.context_config, decision, out.confirmation):
                # A final state ends the episode for good: ask once more, with a warning (costs a call, not a step).
                out.confirmation = {"attempt": attempt - 1, "first": decision.core(), "raw_text": decision.raw_text}
                feedback = [*self.notes, confirmation_note(parse_state(decision.state), self._stages_left())]
                continue
            if answer.error is None:
                out.decision = decision
                if out.confirmation is not None and decision is not None:
                    out.confirmation["confirmed"] = decision.state == out.confirmation["first"]["state"]
                return out
            out.failures.append({"attempt": attempt - 1, "reason": answer.error, "kind": answer.kind,
                                 "fatal": answer.fatal, "raw_text": answer.raw_text})
            if answer.kind == RATE_LIMITED and throttled < MAX_RATE_LIMITED_CALLS:
                throttled += 1  # the provider's limit, not the pilot's failure: ask again, the same step
                step_end = time.monotonic() + (config.step_deadline_s or 0.0)
                continue
            reasks += 1
            if answer.fatal or answer.kind == "step_deadline" or answer.kind in TRANSIENT_REASONS:
                break  # re-ask only an unusable answer; a transient failure is the transport's, not the model's
            why = answer.hint or f"{answer.error}. Answer again with valid values."
            feedback = [*self.notes, f"Your previous answer was rejected: {why}"]
        return out

    def flown(self, step: int, state: State, answer: StepAnswer, command: Command, next_state: State,
              notes: tuple[str, ...]) -> None:
        """After a step was executed: what the next prompt tells the pilot about it."""
        self.context.update(step, state, answer.decision, command, next_state)
        self.previous = command.code
        self.notes = notes
        self.failed_streak = 0 if answer.valid else self.failed_streak + 1

    def close(self) -> None:
        self.deadline.close()
