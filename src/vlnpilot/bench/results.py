"""results.jsonl (one line per finished episode) and the statistics the tables print.

The log is append-only: the parent writes each line when its episode ends, then flushes and fsyncs it, so a
bench killed at any moment loses at most the line being written. Reading skips a torn last line and keeps the
first line of any key seen twice; `ResultsLog.open_for_append` cuts a torn tail off before appending.
"""

from __future__ import annotations

import functools
import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, make_dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vlnpilot.core.errors import ConfigError
from vlnpilot.episode import measures as episode_measures
from vlnpilot.episode.measures import Aggregate, Mean

RESULTS = "results.jsonl"
Z95 = 1.959963984540054  # two-sided 95% normal quantile

Key = tuple[str, str, int]  # (pilot spec, row id, repetition)


def episode_key(pilot: str, row: str, rep: int) -> str:
    """The printable key of an episode: 'pilot|row|rep'."""
    return f"{pilot}|{row}|{rep}"


def record_key(record: dict[str, Any]) -> Key:
    return str(record["pilot"]), str(record["row"]), int(record["rep"])


def _check_result(record: dict[str, Any], path: Path, number: int) -> None:
    """ConfigError naming the line of an episode's record that lacks its result (every table reads it)."""
    result = record.get("result")
    if not isinstance(result, dict) or not isinstance(result.get("outcome"), str):
        raise ConfigError(f"{path} line {number}: the record of {episode_key(*record_key(record))} has no result "
                          "(an object with an outcome); restore the file, or delete the line and --resume to fly "
                          "that episode again")


class ResultsLog:
    """The append-only results file of a bench directory."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fh: Any = None

    def read(self) -> list[dict[str, Any]]:
        """Every complete record, first occurrence per key, in file order (torn or foreign lines skipped)."""
        if not self.path.is_file():
            return []
        out: list[dict[str, Any]] = []
        seen: set[Key] = set()
        with open(self.path, "rb") as fh:
            for number, raw in enumerate(fh, 1):
                if not raw.endswith(b"\n"):  # torn last line: the writer died mid-write
                    break
                try:
                    record = json.loads(raw)
                    key = record_key(record)
                except (ValueError, KeyError, TypeError):
                    continue
                _check_result(record, self.path, number)
                if key not in seen:
                    seen.add(key)
                    out.append(record)
        return out

    def repair(self) -> int:
        """Cut an unterminated last line off (left by a kill mid-write); returns the bytes removed."""
        if not self.path.is_file():
            return 0
        with open(self.path, "rb+") as fh:
            size = fh.seek(0, os.SEEK_END)
            if size == 0:
                return 0
            pos, chunk = size, 4096
            while pos > 0:
                start = max(0, pos - chunk)
                fh.seek(start)
                data = fh.read(pos - start)
                nl = data.rfind(b"\n")
                if nl >= 0:
                    keep = start + nl + 1
                    break
                pos = start
            else:
                keep = 0
            if keep < size:
                fh.truncate(keep)
                fh.flush()
                os.fsync(fh.fileno())
            return size - keep

    def append(self, record: dict[str, Any]) -> None:
        """Write one record as one line, then flush and fsync: it survives a kill or a power cut."""
        if self._fh is None:
            self.repair()
            self._fh = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self._fh.write(json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> ResultsLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ----------------------------------------------------------------------------------------------- statistics
def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95% by default); (0, 1) when n is 0."""
    if n <= 0:
        return 0.0, 1.0
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in 0..{n}, got {successes}")
    p = successes / n
    z2 = z * z
    denom = 1 + z2 / n
    center = (p + z2 / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    # clamped around p: rounding may put a bound a hair on the wrong side of p (0/n, n/n)
    return max(0.0, min(p, center - half)), min(1.0, max(p, center + half))


def percentile(values: Sequence[float], q: float) -> float | None:
    """The q-th percentile (0..100) with linear interpolation between order statistics (numpy's default)."""
    if not values:
        return None
    xs = sorted(values)
    pos = (len(xs) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


@dataclass(frozen=True)
class CellStats:
    """One (row, pilot) cell of the paper's table."""

    episodes: int
    successes: int
    collisions: int
    steps_exceeded: int
    unreachable: int = 0  # goals rightly reported unreachable (issue 24): a success of their own kind


class _Rates:
    successes: int  # fields of the derived dataclass (bare annotations here make no fields)
    episodes: int

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0


# The summary's own fields (the measures' aggregates follow): from the outcomes, the steps and the call timings.
_OWN_FIELDS: tuple[tuple[str, Any], ...] = (
    ("pilot", str), ("models", tuple[str, ...]), ("episodes", int), ("successes", int), ("ci_low", float),
    ("ci_high", float), ("mean_steps", float), ("steps_exceeded", int), ("false_successes", int),
    ("pilot_errors", int), ("latency_p50_s", float | None), ("latency_p95_s", float | None))
_MEAN_STEPS = Mean("steps", "mean_steps")


_SUMMARY_DOC = """The per-pilot summary under the table: the bench's own statistics (success, its Wilson interval,
mean steps, outcome counts, call latency) and one field per aggregate of the measures
(`episode_measures.aggregates()`: SPL, collisions, invalid decisions, oscillations, interventions, tokens, cost,
pilot calls, and whatever a new measure adds). Keyword-only and frozen, like `EpisodeResult`."""


@functools.cache
def _summary_class(aggregates: tuple[Aggregate, ...]) -> type:
    spec = [*_OWN_FIELDS, *((a.name, a.type) for a in aggregates)]
    return make_dataclass("PilotSummary", spec, bases=(_Rates,), frozen=True, kw_only=True,
                          namespace={"__module__": __name__, "__doc__": _SUMMARY_DOC})


def summary_type() -> type:
    """The `PilotSummary` class of the current measures (one class per set of aggregates, made once)."""
    return _summary_class(episode_measures.aggregates())


if TYPE_CHECKING:  # what a type checker sees; tests/test_typing.py keeps it equal to `summary_type()`
    @dataclass(frozen=True, kw_only=True)
    class PilotSummary(_Rates):
        pilot: str
        models: tuple[str, ...]
        episodes: int
        successes: int
        ci_low: float
        ci_high: float
        mean_steps: float
        steps_exceeded: int
        false_successes: int
        pilot_errors: int
        latency_p50_s: float | None
        latency_p95_s: float | None
        spl: float
        collisions: int
        invalid_decisions: int
        oscillations: int
        input_tokens: int
        cached_tokens: int
        output_tokens: int
        cost_usd: float
        pilot_calls: int
        interventions: int
        stages: int
        isr: float
        csr: float
        cgt: float
        unreachable: int
        unreachable_reported: int
        mover_collisions: int
        mover_episodes: int
        signs_obeyed: int
        sign_episodes: int
else:
    PilotSummary = summary_type()


def cell_stats(records: Iterable[dict[str, Any]]) -> CellStats:
    outcomes = [r["result"]["outcome"] for r in records]
    return CellStats(episodes=len(outcomes), successes=outcomes.count("success"),
                     collisions=outcomes.count("collision"), steps_exceeded=outcomes.count("max_steps"),
                     unreachable=outcomes.count("unreachable"))


def call_latencies(record: dict[str, Any]) -> list[float]:
    """Per-call pilot latencies of an episode (the worker's timings; else the mean from the episode totals)."""
    lat = record.get("call_latencies_s")
    if lat is not None:
        return [float(x) for x in lat]
    res = record["result"]
    calls = int(res.get("pilot_calls") or 0)
    return [float(res.get("latency_s_total") or 0.0) / calls] * calls if calls else []


def summarize(pilot: str, records: Sequence[dict[str, Any]]) -> PilotSummary:
    """Aggregate one pilot's episodes into a `PilotSummary` (SPL: the mean of the per-episode SPL)."""
    res = [r["result"] for r in records]
    n = len(res)
    outcomes = [x["outcome"] for x in res]
    k = outcomes.count("success")
    lo, hi = wilson_interval(k, n)
    lat = [x for r in records for x in call_latencies(r)]
    measured = {a.name: a.over(res) for a in episode_measures.aggregates()}
    return summary_type()(
        pilot=pilot, models=tuple(sorted({str(r.get("model")) for r in records})), episodes=n, successes=k,
        ci_low=lo, ci_high=hi, mean_steps=_MEAN_STEPS.over(res), steps_exceeded=outcomes.count("max_steps"),
        false_successes=outcomes.count("false_success"), pilot_errors=outcomes.count("pilot_error"),
        latency_p50_s=percentile(lat, 50), latency_p95_s=percentile(lat, 95), **measured)
