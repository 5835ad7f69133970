"""What an episode counts: the measures and the `EpisodeResult` they fill.

A measure (habitat-lab's Measure) is a small object with `reset(start)`, `update(step)` once per step and
`value(end)`, which returns the `EpisodeResult` fields it fills. `MEASURES` is the one list `run_episode`
creates them from, so a new measure is a class here, a line in `MEASURES` and its field in `EpisodeResult`.
The fields the episode decides itself (outcome, reason, steps, final state and room, contact, wall time, who
judged) are `EPISODE_FIELDS`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Protocol

from vlnpilot.commands import Command
from vlnpilot.decision import Usage
from vlnpilot.safety import SafetyLayer
from vlnpilot.scene.model import Scene
from vlnpilot.tasks import Oscillations, PathLength, SuccessConfig, Task, shortest_path_length, spl
from vlnpilot.types import Pose


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


EPISODE_FIELDS = ("outcome", "reason", "steps", "final_state", "final_room", "contact", "wall_time_s", "judged_by")


@dataclass(frozen=True)
class EpisodeStart:
    scene: Scene
    pose: Pose
    task: Task
    success: SuccessConfig


@dataclass(frozen=True)
class StepFacts:
    """One step as the measures see it. `command` is None when nothing was executed (aborted, fatal)."""

    usages: tuple[Usage, ...]  # one per pilot call, in order
    valid: bool  # the pilot gave a decision to fly (else the drone hovered)
    command: Command | None
    pose_before: Pose
    pose_after: Pose


@dataclass(frozen=True)
class EpisodeEnd:
    outcome: str
    safety: SafetyLayer


class Measure(Protocol):
    def reset(self, start: EpisodeStart) -> None: ...
    def update(self, step: StepFacts) -> None: ...
    def value(self, end: EpisodeEnd) -> dict[str, Any]: ...


class PathAndSpl:
    """Distance flown, the shortest path from the start, and SPL."""

    def reset(self, start: EpisodeStart) -> None:
        self.path = PathLength()
        self.path.reset()
        self.shortest = shortest_path_length(start.scene, start.pose, start.task, start.success)

    def update(self, step: StepFacts) -> None:
        if step.command is not None:
            self.path.update(step.pose_before, step.pose_after)

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        taken = self.path.value()
        return {"path_length_m": round(taken, 4), "shortest_path_m": round(self.shortest, 4),
                "spl": round(spl(end.outcome == "success", self.shortest, taken), 4)}


class OscillationCount:
    """Direction reversals of executed moves; `reversed` says whether the last step was one (it is recorded)."""

    def reset(self, start: EpisodeStart) -> None:
        self.osc = Oscillations()
        self.osc.reset()
        self.reversed = False

    def update(self, step: StepFacts) -> None:
        self.reversed = step.command is not None and self.osc.update(step.command)

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"oscillations": self.osc.value()}


class InvalidDecisions:
    """Executed steps without a valid decision (the drone hovered)."""

    def reset(self, start: EpisodeStart) -> None:
        self.count = 0

    def update(self, step: StepFacts) -> None:
        self.count += step.command is not None and not step.valid

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"invalid_decisions": self.count}


class PilotUsage:
    """Tokens, cost, latency and calls of every pilot call, re-asks and unexecuted steps included."""

    def reset(self, start: EpisodeStart) -> None:
        self.usage, self.calls = Usage(), 0

    def update(self, step: StepFacts) -> None:
        for usage in step.usages:  # one by one, in call order, so the float sums are the same as ever
            self.usage = self.usage + usage
            self.calls += 1

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        u = self.usage
        return {"input_tokens": u.input_tokens, "cached_tokens": u.cached_tokens, "output_tokens": u.output_tokens,
                "cost_usd": round(u.cost_usd, 6), "latency_s_total": round(u.latency_s, 4), "pilot_calls": self.calls}


class _ReadAtTheEnd:
    """A measure that needs nothing per step: everything it reports is known when the episode ends."""

    def reset(self, start: EpisodeStart) -> None:
        pass

    def update(self, step: StepFacts) -> None:
        pass


class Collisions(_ReadAtTheEnd):
    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"collisions": int(end.outcome == "collision")}


class SafetyCounts(_ReadAtTheEnd):
    """What the safety layer did: commands it changed, oscillation stretches its guard saw, its name."""

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        s = end.safety
        return {"interventions": len(s.interventions), "oscillation_events": len(s.events), "shield": s.name}


MEASURES: tuple[type[Measure], ...] = (PathAndSpl, OscillationCount, InvalidDecisions, PilotUsage, Collisions,
                                       SafetyCounts)


class Measures:
    """The episode's measures, made from `MEASURES`, updated together."""

    def __init__(self, start: EpisodeStart):
        self.all: list[Measure] = [make() for make in MEASURES]
        for measure in self.all:
            measure.reset(start)

    def update(self, step: StepFacts) -> None:
        for measure in self.all:
            measure.update(step)

    def reversed(self) -> bool:
        """Whether the step just measured reversed the move before it (the step record's `oscillation`)."""
        return any(m.reversed for m in self.all if isinstance(m, OscillationCount))

    def values(self, end: EpisodeEnd) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for measure in self.all:
            out.update(measure.value(end))
        return out
