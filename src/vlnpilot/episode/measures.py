"""What an episode counts: the measures, and the `EpisodeResult` they lay out.

A measure (habitat-lab's Measure) is a small object with `reset(start)`, `update(step)` once per step and
`value(end)`, which returns the `EpisodeResult` fields it fills. It is also the one place that says what
becomes of those fields downstream, as three class attributes:

- `fields`: its `ResultField`s (name, type, default), in the order `result.to_dict()` writes them;
- `aggregates`: how a bench combines a field over a pilot's episodes (`Total`, `Mean`), each a field of the
  bench's `PilotSummary` (`bench/results.py` derives that class from them);
- `columns`: its `Column`s in Table 4's summary per pilot (table.md, table.tex, summary.csv; `bench/tables.py`
  places them by `rank` among the bench's own columns).

`MEASURES` lists them, and, as `FilledByTheEpisode` entries, the fields the episode decides itself (outcome,
reason, steps, final state and room, contact, wall time, who judged: `EPISODE_FIELDS`), each where the recorded
format has it. So a new metric is a class here and a line at the end of `MEASURES`: `run_episode`, the result,
the bench's summary and the tables follow, and its key comes after the existing ones in summary.json and
results.jsonl, which stay as they were.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, make_dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from vlnpilot.core.commands import Command
from vlnpilot.core.decision import Decision, Usage
from vlnpilot.core.fsm import FINAL_STATES, State
from vlnpilot.core.movers import FiredEvent, is_mover_contact
from vlnpilot.core.records import Pose
from vlnpilot.safety import SafetyLayer
from vlnpilot.scene.model import Scene
from vlnpilot.tasks.mission import Mission, as_mission, stage_shortest_paths
from vlnpilot.tasks.signs import Turn, obeyed, sign_instruction, signs, signs_seen
from vlnpilot.tasks.task import Oscillations, PathLength, SuccessConfig, Task, spl

# The states in which a pilot is judged to have ended the episode itself (a sign asking it to land, tasks/signs.py).
ENDING_STATES = tuple(s.value for s in FINAL_STATES)
Result = dict[str, Any]  # one episode's result as recorded (`EpisodeResult.to_dict()`, a line of results.jsonl)


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()  # the default of a field without one: every result must give it


@dataclass(frozen=True)
class ResultField:
    """One field of `EpisodeResult`: its name, its type, and its default (none: every result must give it)."""

    name: str
    type: Any
    default: Any = REQUIRED


@dataclass(frozen=True)
class Total:
    """A bench sums the field over a pilot's episodes (`PilotSummary.<field>`). `absent`: what a recorded
    result without the field counts as (a field newer than the records); None: such a record is an error."""

    field: str
    type: type = int
    absent: int | float | None = None

    @property
    def name(self) -> str:
        return self.field

    def over(self, results: Sequence[Result]) -> int | float:
        return sum(self.type(self._value(r)) for r in results)

    def _value(self, result: Result) -> Any:
        if self.absent is None:
            return result[self.field]
        value = result.get(self.field)
        return self.absent if value is None else value


@dataclass(frozen=True)
class Mean:
    """A bench averages the field over a pilot's episodes (0 without episodes) into `PilotSummary.<name>`."""

    field: str
    name: str = ""  # default: the field's name

    def __post_init__(self) -> None:
        if not self.name:
            object.__setattr__(self, "name", self.field)

    @property
    def type(self) -> type:
        return float

    def over(self, results: Sequence[Result]) -> float:
        return (sum(float(r[self.field]) for r in results) / len(results)) if results else 0.0


@dataclass(frozen=True)
class Counted:
    """A bench counts a pilot's episodes whose field is set (not None) into `PilotSummary.<name>`: e.g. the
    episodes in which something moved, which tell a 0 of mover collisions from a bench where nothing could."""

    field: str
    name: str

    @property
    def type(self) -> type:
        return int

    def over(self, results: Sequence[Result]) -> int:
        return sum(r.get(self.field) is not None for r in results)


class Aggregate(Protocol):
    """What a bench computes over a pilot's episodes into `PilotSummary.<name>` (Total, Mean, StageRate)."""

    @property
    def name(self) -> str: ...
    @property
    def type(self) -> type: ...
    def over(self, results: Sequence[Result]) -> int | float: ...

LAST = 1000  # the rank of a column that names none: after every other column


@dataclass(frozen=True)
class Column:
    """One column of Table 4's summary per pilot, read from a `PilotSummary` (`s`).

    `md` and `tex` are its headers in table.md and table.tex (None: not in that table), `csv` its headers in
    summary.csv (one or more; none: not there). `text(s)` is its Markdown cell, and its LaTeX cell unless
    `tex_text` says otherwise; `csv_cells(s)` gives one value per `csv` header. `rank` orders the columns, in
    tens from Pilot (0) to Latency p95 (180), the bench's own (bench/tables.py) and the measures' (SPL 50,
    Collisions 70, Invalid decisions 110 ... Pilot calls 160) interleaved; a new one takes a free rank where it
    belongs, or `LAST`.
    """

    rank: int
    md: str | None
    tex: str | None
    csv: tuple[str, ...]
    text: Callable[[Any], str]
    csv_cells: Callable[[Any], Sequence[Any]]
    tex_text: Callable[[Any], str] | None = None
    when: Callable[[Any], bool] | None = None  # shown only if true of some pilot's summary (None: always)

    def tex_cell(self, summary: Any) -> str:
        return (self.tex_text or self.text)(summary)


def column(name: str, *, md: str | None, tex: str | None, fmt: str = "", csv_fmt: str | None = None,
           rank: int = LAST) -> Column:
    """A column that shows one `PilotSummary` field: as `fmt` in Markdown and LaTeX, `csv_fmt` (else `fmt`) in
    summary.csv, under the header `name` there."""
    return Column(rank, md, tex, (name,), lambda s: format(getattr(s, name), fmt),
                  lambda s: (format(getattr(s, name), fmt if csv_fmt is None else csv_fmt),))


@dataclass(frozen=True)
class EpisodeStart:
    scene: Scene
    pose: Pose
    task: Task | Mission
    success: SuccessConfig
    fired: tuple[FiredEvent, ...] = ()  # the scenario's events that fired at the reset (issue 24)


@dataclass(frozen=True)
class StepFacts:
    """One step as the measures see it. `command` is None when nothing was executed (aborted, fatal)."""

    usages: tuple[Usage, ...]  # one per pilot call, in order
    valid: bool  # the pilot gave a decision to fly (else the drone hovered)
    command: Command | None
    pose_before: Pose
    pose_after: Pose
    decision: Decision | None = None  # the pilot's validated decision (None: none to fly)
    fired: tuple[FiredEvent, ...] = ()  # the scenario's events that fired during the step (issue 24)
    # the signs legible in the image the pilot decided from (tasks.signs.legible_now); None: not known (no signs, or
    # a ground truth that cannot tell: the in-view rule judges)
    legible: frozenset[str] | None = None


@dataclass(frozen=True)
class EpisodeEnd:
    outcome: str
    safety: SafetyLayer
    stages_reached: int | None = None  # stages judged a success in a row (None: counted from the outcome)
    stage_boundaries: tuple[int, ...] = ()  # the step at which each stage before the last was judged a success
    final_state: str | None = None  # the FSM state the episode ended in
    contact: str | None = None  # what the drone touched, if the episode ended in a collision


class Measure(Protocol):
    fields: ClassVar[tuple[ResultField, ...]]
    aggregates: ClassVar[tuple[Aggregate, ...]]
    columns: ClassVar[tuple[Column, ...]]

    def reset(self, start: EpisodeStart) -> None: ...
    def update(self, step: StepFacts) -> None: ...
    def value(self, end: EpisodeEnd) -> dict[str, Any]: ...


class PathAndSpl:
    """Distance flown, the shortest path from the start, and SPL (a bench averages it: Anderson et al. 2018)."""

    fields: ClassVar[tuple[ResultField, ...]] = (
        ResultField("path_length_m", float), ResultField("shortest_path_m", float), ResultField("spl", float))
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Mean("spl"),)
    columns: ClassVar[tuple[Column, ...]] = (column("spl", md="SPL", tex="SPL", fmt=".3f", csv_fmt=".4f", rank=50),)

    def reset(self, start: EpisodeStart) -> None:
        self.path = PathLength()
        self.path.reset()
        # over the whole mission path: each stage from where the one before ends (one stage: as ever)
        self.shortest = sum(stage_shortest_paths(start.scene, start.pose, as_mission(start.task), start.success))

    def update(self, step: StepFacts) -> None:
        if step.command is not None:
            self.path.update(step.pose_before, step.pose_after)

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        taken = self.path.value()
        return {"path_length_m": round(taken, 4), "shortest_path_m": round(self.shortest, 4),
                "spl": round(spl(end.outcome == "success", self.shortest, taken), 4)}


class OscillationCount:
    """Direction reversals of executed moves; `reversed` says whether the last step was one (it is recorded)."""

    fields: ClassVar[tuple[ResultField, ...]] = (ResultField("oscillations", int),)
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("oscillations"),)
    columns: ClassVar[tuple[Column, ...]] = (column("oscillations", md="Oscillations", tex="Osc.", rank=120),)

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

    fields: ClassVar[tuple[ResultField, ...]] = (ResultField("invalid_decisions", int),)
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("invalid_decisions"),)
    columns: ClassVar[tuple[Column, ...]] = (
        column("invalid_decisions", md="Invalid decisions", tex="Invalid", rank=110),)

    def reset(self, start: EpisodeStart) -> None:
        self.count = 0

    def update(self, step: StepFacts) -> None:
        self.count += step.command is not None and not step.valid

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"invalid_decisions": self.count}


def _tokens(s: Any) -> str:
    return f"{s.input_tokens}/{s.output_tokens}"


def _cached_share(s: Any) -> str:
    """The share of the input tokens the providers served from their prompt caches (as each API reports it)."""
    return f"{s.cached_tokens / s.input_tokens:.1%}" if s.input_tokens else "--"


def _tokens_per_call(s: Any) -> str:
    """Input tokens per pilot call: what a step's prompt costs (the `history` option's earlier turns included)."""
    return f"{s.input_tokens / s.pilot_calls:.0f}" if s.pilot_calls else "--"


class PilotUsage:
    """Tokens, cost, latency and calls of every pilot call, re-asks and unexecuted steps included. (The bench's
    latency percentiles come from its workers' per-call timings, or from `latency_s_total` / `pilot_calls`.)"""

    fields: ClassVar[tuple[ResultField, ...]] = (
        ResultField("input_tokens", int), ResultField("cached_tokens", int), ResultField("output_tokens", int),
        ResultField("cost_usd", float), ResultField("latency_s_total", float), ResultField("pilot_calls", int))
    aggregates: ClassVar[tuple[Aggregate, ...]] = (
        Total("input_tokens"), Total("cached_tokens", absent=0), Total("output_tokens"), Total("cost_usd", float),
        Total("pilot_calls"))
    columns: ClassVar[tuple[Column, ...]] = (
        Column(140, "Tokens in/out", "Tokens in/out", ("input_tokens", "output_tokens"), _tokens,
               lambda s: (s.input_tokens, s.output_tokens)),
        # only where a pilot sent tokens (the oracle's tables stay as they were)
        Column(142, "Cached", None, ("cached_tokens",), _cached_share, lambda s: (s.cached_tokens,),
               when=lambda s: s.input_tokens > 0),
        Column(145, "Tokens in/call", None, (), _tokens_per_call, lambda s: ()),
        column("cost_usd", md="Cost (USD)", tex="Cost (\\$)", fmt=".4f", csv_fmt=".6f", rank=150),
        column("pilot_calls", md=None, tex=None, rank=160))

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
    fields: ClassVar[tuple[ResultField, ...]] = (ResultField("collisions", int),)
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("collisions"),)
    columns: ClassVar[tuple[Column, ...]] = (column("collisions", md="Collisions", tex="Coll.", rank=70),)

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"collisions": int(end.outcome == "collision")}


class SafetyCounts(_ReadAtTheEnd):
    """What the safety layer did: commands it changed, oscillation stretches its guard saw, its name."""

    fields: ClassVar[tuple[ResultField, ...]] = (
        ResultField("interventions", int, 0),  # commands changed by the guard, the door assist, the shield
        ResultField("oscillation_events", int, 0),  # oscillation stretches the guard saw (shield off too)
        ResultField("shield", str, "off"))
    aggregates: ClassVar[tuple[Aggregate, ...]] = (
        Total("interventions", absent=0),)  # results recorded before the safety layer have none
    columns: ClassVar[tuple[Column, ...]] = (column("interventions", md="Interventions", tex="Interv.", rank=130),)

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        s = end.safety
        return {"interventions": len(s.interventions), "oscillation_events": len(s.events), "shield": s.name}


def _stages(r: Result) -> tuple[int, int, bool, list[float]]:
    """(stages, stages reached, whether a stage failed, the stages' shortest paths) of a result; a result
    recorded before missions is one stage, reached if it succeeded."""
    n = int(r.get("stages") or 1)
    reached = r.get("stages_reached")
    reached = int(r["outcome"] == "success") if reached is None else int(reached)
    paths = list(r.get("stage_paths_m") or [float(r.get("shortest_path_m") or 0.0)] * n)
    return n, reached, r["outcome"] != "success", paths


@dataclass(frozen=True)
class StageRate:
    """A bench's stage rate after LHPR-VLN (CVPR 2025), over a pilot's episodes:

    - `isr`: stages judged a success / stages flown (each stage on its own; a mission ends at its first failed
      stage, so the stages after it are not flown and not counted);
    - `csr`: stages reached in a row / all stages of the missions (a stage counts only if every earlier one
      succeeded);
    - `cgt`: `csr` weighted by each stage's shortest path (a long stage weighs more).
    """

    name: str

    @property
    def type(self) -> type:
        return float

    def over(self, results: Sequence[Result]) -> float:
        num = den = 0.0
        for r in results:
            n, reached, failed, paths = _stages(r)
            if self.name == "isr":
                num, den = num + reached, den + reached + (failed and reached < n)
            elif self.name == "csr":
                num, den = num + reached, den + n
            else:
                num, den = num + sum(paths[:reached]), den + sum(paths)
        return num / den if den else 0.0


def _when_missions(s: Any) -> bool:
    return s.stages > s.episodes  # a bench with a mission of several stages


class MissionStages:
    """A mission's stages: how many, how many were reached (judged a success in a row), the first that failed
    (1-based; None after a success), the step each later stage began at, and each stage's shortest path.
    A one-stage mission is today's episode: 1 stage, reached iff it succeeded."""

    fields: ClassVar[tuple[ResultField, ...]] = (
        ResultField("stages", int, 1), ResultField("stages_reached", int | None, None),
        ResultField("failed_stage", int | None, None), ResultField("stage_starts", list | None, None),
        ResultField("stage_paths_m", list | None, None))
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("stages", absent=1), StageRate("isr"), StageRate("csr"),
                                                   StageRate("cgt"))
    columns: ClassVar[tuple[Column, ...]] = tuple(
        replace(column(name, md=name.upper(), tex=name.upper(), fmt=".3f", csv_fmt=".4f", rank=rank),
                when=_when_missions)
        for name, rank in (("isr", 42), ("csr", 44), ("cgt", 46)))

    def reset(self, start: EpisodeStart) -> None:
        self.mission = as_mission(start.task)
        self.paths = stage_shortest_paths(start.scene, start.pose, self.mission, start.success)

    def update(self, step: StepFacts) -> None:
        pass

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        n = len(self.mission.stages)
        reached = end.stages_reached if end.stages_reached is not None else int(end.outcome == "success")
        if n == 1:  # today's episode: the fields say no more than the outcome
            return {"stages": 1, "stages_reached": reached, "failed_stage": None if reached else 1,
                    "stage_starts": None, "stage_paths_m": None}
        return {"stages": n, "stages_reached": reached, "failed_stage": None if reached == n else reached + 1,
                "stage_starts": [1, *(b + 1 for b in end.stage_boundaries)],
                "stage_paths_m": [round(p, 4) for p in self.paths]}


def _when_reported(s: Any) -> bool:
    return s.unreachable_reported > 0  # a bench in which some pilot reported a goal unreachable


class Unreachable(_ReadAtTheEnd):
    """Issue 24: a goal the pilot reported unreachable (the Goal Unreachable state), and whether the report was
    true (outcome `unreachable`, a success of its own kind; a false report is a false_success). The column reads
    "true/reported"."""

    fields: ClassVar[tuple[ResultField, ...]] = (ResultField("unreachable", int, 0),
                                                 ResultField("unreachable_reported", int, 0))
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("unreachable", absent=0),
                                                   Total("unreachable_reported", absent=0))
    columns: ClassVar[tuple[Column, ...]] = (
        Column(35, "Unreachable (true/reported)", "Unreach.", ("unreachable", "unreachable_reported"),
               lambda s: f"{s.unreachable}/{s.unreachable_reported}",
               lambda s: (s.unreachable, s.unreachable_reported), when=_when_reported),)

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"unreachable": int(end.outcome == "unreachable"),
                "unreachable_reported": int(end.final_state == State.GOAL_UNREACHABLE.value)}
def _when_movers(s: Any) -> bool:
    return s.mover_episodes > 0


class MoverCollisions:
    """Issue 24: whether the episode ended touching a person or a pet (`Observation.contact` `mover:<name>`); None
    in a scene where nothing moves, so that a bench's 0 says something only where something could be touched."""

    fields: ClassVar[tuple[ResultField, ...]] = (ResultField("mover_collisions", int | None, None),)
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("mover_collisions", absent=0),
                                                   Counted("mover_collisions", "mover_episodes"))
    columns: ClassVar[tuple[Column, ...]] = (
        replace(column("mover_collisions", md="Mover collisions", tex="Mover coll.", rank=72), when=_when_movers),)

    def reset(self, start: EpisodeStart) -> None:
        scenario = start.scene.scenario
        self.movers = scenario is not None and bool(scenario.movers)

    def update(self, step: StepFacts) -> None:
        pass

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        if not self.movers:
            return {"mover_collisions": None}
        return {"mover_collisions": int(end.outcome == "collision" and is_mover_contact(end.contact))}


def _when_signs(s: Any) -> bool:
    return s.sign_episodes > 0


class SignsObeyed:
    """Issue 24: whether the pilot obeyed a redirecting sign (`tasks/signs.py` says what counts: it did what the
    sign asks within a few steps of first seeing it, in an episode not judged a success), and the step it first
    saw one; None without a redirecting sign that asks something."""

    fields: ClassVar[tuple[ResultField, ...]] = (ResultField("signs_obeyed", int | None, None),
                                                 ResultField("sign_seen_step", int | None, None))
    aggregates: ClassVar[tuple[Aggregate, ...]] = (Total("signs_obeyed", absent=0),
                                                   Counted("signs_obeyed", "sign_episodes"))
    columns: ClassVar[tuple[Column, ...]] = (
        Column(74, "Signs obeyed", "Signs obeyed", ("signs_obeyed", "sign_episodes"),
               lambda s: f"{s.signs_obeyed}/{s.sign_episodes}", lambda s: (s.signs_obeyed, s.sign_episodes),
               when=_when_signs),)

    def reset(self, start: EpisodeStart) -> None:
        self.scene, self.step = start.scene, 0
        self.redirects = {s.name for s in signs(start.scene) if s.redirect and sign_instruction(s.text)}
        self.present = {e.name for e in start.fired}
        self.seen: tuple[int, str] | None = None  # (step, what the sign asks)
        self.turns: list[Turn] = []

    def update(self, step: StepFacts) -> None:
        self.step += 1
        if self.redirects and self.seen is None:
            shown = signs_seen(self.scene, step.pose_before, self.present & self.redirects, step.legible)
            if shown:
                self.seen = (self.step, str(sign_instruction(shown[0].text)))
        if self.seen is not None:
            d = step.decision
            self.turns.append(Turn(d.movement, d.state) if d is not None else Turn(None, None))
        self.present |= {e.name for e in step.fired}

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        if not self.redirects:
            return {"signs_obeyed": None, "sign_seen_step": None}
        if self.seen is None:
            return {"signs_obeyed": 0, "sign_seen_step": None}
        done = obeyed(self.seen[1], self.turns, end.outcome == "success", ENDING_STATES)
        return {"signs_obeyed": int(done), "sign_seen_step": self.seen[0]}


class FilledByTheEpisode:
    """`EpisodeResult` fields the episode decides itself and passes to it; in `MEASURES` only to lay them out."""

    aggregates: tuple[Aggregate, ...] = ()
    columns: tuple[Column, ...] = ()

    def __init__(self, *fields: ResultField):
        self.fields = fields


# `EpisodeResult`'s fields, in the order `to_dict()` writes them. A new measure goes at the end.
MEASURES: tuple[type[Measure] | FilledByTheEpisode, ...] = (
    FilledByTheEpisode(ResultField("outcome", str), ResultField("reason", str), ResultField("steps", int)),
    PathAndSpl, Collisions, InvalidDecisions, OscillationCount,
    FilledByTheEpisode(ResultField("final_state", str), ResultField("final_room", str | None),
                       ResultField("contact", str | None)),
    PilotUsage,
    FilledByTheEpisode(ResultField("wall_time_s", float)),
    SafetyCounts,
    # ground_truth | operator (confirmed or not) | declared (nobody checked) | none
    FilledByTheEpisode(ResultField("judged_by", str, "ground_truth")),
    MissionStages,
    Unreachable,
    MoverCollisions, SignsObeyed,
)


def measure_classes() -> tuple[type[Measure], ...]:
    """The measures in `MEASURES` (what `run_episode` resets, updates and reads)."""
    return tuple(m for m in MEASURES if not isinstance(m, FilledByTheEpisode))


def aggregates() -> tuple[Aggregate, ...]:
    """How a bench aggregates the results, measure by measure (bench/results.py)."""
    return tuple(a for m in MEASURES for a in m.aggregates)


def columns() -> tuple[Column, ...]:
    """The measures' columns in Table 4's summary per pilot (bench/tables.py)."""
    return tuple(c for m in MEASURES for c in m.columns)


class _ResultMethods:
    outcome: str  # a field of the derived dataclass (a bare annotation here makes no field)

    @property
    def success(self) -> bool:
        return self.outcome == "success"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)  # type: ignore[call-overload]  # a dataclass once derived


_RESULT_DOC = """One episode's result: a frozen dataclass whose fields are laid out by `MEASURES` (`result_type`).

Keyword-only, so `EpisodeResult(**result.to_dict())` rebuilds it from its recorded dict; `result.spl` and the
other fields read as attributes; `to_dict()` keeps the field order, the order of the recorded keys."""


@functools.cache
def _result_class(layout: tuple[type[Measure] | FilledByTheEpisode, ...]) -> type:
    spec = [(f.name, f.type) if f.default is REQUIRED else (f.name, f.type, field(default=f.default))
            for entry in layout for f in entry.fields]
    return make_dataclass("EpisodeResult", spec, bases=(_ResultMethods,), frozen=True, kw_only=True,
                          namespace={"__module__": __name__, "__doc__": _RESULT_DOC})


def result_type() -> type:
    """The `EpisodeResult` class of the current `MEASURES` (one class per list, made once).

    Derived rather than written out, so that a measure's fields are declared once, on the measure; looked up
    when a result is made, so that a measure added to `MEASURES` (a test's, say) is in the results at once.
    """
    return _result_class(MEASURES)


if TYPE_CHECKING:  # what a type checker sees; tests/test_typing.py keeps it equal to `result_type()`
    @dataclass(frozen=True, kw_only=True)
    class EpisodeResult(_ResultMethods):
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
        interventions: int = 0
        oscillation_events: int = 0
        shield: str = "off"
        judged_by: str = "ground_truth"
        stages: int = 1
        stages_reached: int | None = None
        failed_stage: int | None = None
        stage_starts: list | None = None
        stage_paths_m: list | None = None
        unreachable: int = 0
        unreachable_reported: int = 0
        mover_collisions: int | None = None
        signs_obeyed: int | None = None
        sign_seen_step: int | None = None
else:
    EpisodeResult = result_type()
EPISODE_FIELDS = tuple(f.name for m in MEASURES if isinstance(m, FilledByTheEpisode) for f in m.fields)


class Measures:
    """The episode's measures, made from `MEASURES`, updated together."""

    def __init__(self, start: EpisodeStart):
        self.all: list[Measure] = [make() for make in measure_classes()]
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

