"""What an episode is configured with, and how it can end: `EpisodeConfig`, the outcomes, the loop control's `Gate`.

Apart from the loop (`episode.loop`) so that the loop's collaborators (`episode.ask`, `episode.record`) can read the
configuration without importing the loop that imports them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import PROFILES, State
from vlnpilot.pilots.base import Pilot
from vlnpilot.prompting.context import ContextConfig, context_preset
from vlnpilot.safety import OVERLAYS, SHIELD_REGISTRY, SafetyConfig
from vlnpilot.scene.detail import DEFAULT_DETAIL, check_detail
from vlnpilot.tasks.task import SuccessConfig, Task

__all__ = ["OUTCOMES", "EpisodeConfig", "Gate", "JudgeOutcome", "LoopControl"]

# halted: a real robot's safety rule ended the episode (battery, flight time, geofence, a lost reply to a move);
# link_lost: a real robot's link died in flight (its watchdog sent `land`; nothing after it counts as executed)
# unreachable (issue 24): the pilot reported Goal Unreachable and the goal is truly unreachable by the true map at
# that moment, a success of its own kind (a report for a reachable goal is a false_success)
# declared: without ground truth and without a judge (--judge none) the pilot declared a final state that nobody
# judged: never a success (the standard: nothing is reported a success that was not judged one)
OUTCOMES = ("success", "false_success", "collision", "max_steps", "pilot_error", "halted", "link_lost", "aborted",
            "unreachable", "declared")
JudgeOutcome = Callable[[Task, State], tuple[bool, str]]  # the operator's word on a declared final state


@dataclass(frozen=True)
class EpisodeConfig:
    max_steps: int = 50
    profile: str = "paper"
    max_reasks: int = 2  # re-asks after an invalid or malformed answer, within one step
    max_failed_steps: int = 3  # consecutive steps without a valid decision before `pilot_error`
    success: SuccessConfig = field(default_factory=SuccessConfig)
    seed: int | None = None
    # A name in safety.SHIELD_REGISTRY: off | geometry | depth | assist | a registered one (the CLI defaults to
    # safety.DEFAULT_SHIELD in the simulator)
    shield: str = "off"
    safety: SafetyConfig = field(default_factory=SafetyConfig)  # margin, door assist, oscillation guard, depth
    overlay: str | None = None  # None | "corridor": draw the propeller-tip corridor on the image the pilot sees
    # Wall-clock bound on one step's pilot calls, re-asks and provider retries included, for pilots that wait on
    # a network (`uses_step_deadline`); when it passes the drone hovers and the step counts an invalid decision.
    step_deadline_s: float | None = 120.0
    # What the pilot is told beyond the paper's five inputs (prompting.context): a preset name or a ContextConfig.
    context: ContextConfig | str = "paper"
    # The scene detail the simulator's cameras render (scene/detail.py): plain | rich. The run opens its simulator
    # with it, and it is recorded so that a replay renders the same images; it changes no geometry and no judgement.
    detail: str = DEFAULT_DETAIL

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
        if str(self.shield).strip().lower() not in SHIELD_REGISTRY:
            raise ConfigError(f"unknown shield {self.shield!r}; valid shields: {', '.join(SHIELD_REGISTRY)}")
        if self.step_deadline_s is not None and not self.step_deadline_s > 0:
            raise ConfigError(f"step_deadline_s must be positive or None, got {self.step_deadline_s!r}")
        check_detail(self.detail)
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
