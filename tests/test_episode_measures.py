# ruff: noqa: E501 (a table line is long)
"""The measures are made from the one list `episode_measures.MEASURES`: a measure added there is updated every
step and asked for its value once, and together the measures fill every `EpisodeResult` field the episode does
not decide itself. A measure also declares its result fields, how a bench aggregates them and its columns in
the tables, so that a new metric touches one file: shown with a toy measure that lives only in this test."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import fields
from pathlib import Path
from typing import Any

import pytest

import vlnpilot.episode.measures as episode_measures
from bench_records import TINY
from vlnpilot.bench import BenchSettings, run_bench
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.episode.measures import (
    EPISODE_FIELDS,
    LAST,
    EpisodeEnd,
    EpisodeResult,
    EpisodeStart,
    Measures,
    ResultField,
    StepFacts,
    Total,
    column,
    measure_classes,
)
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.safety import make_safety
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks.task import parse_query

# The recorded result as main wrote it before the measures declared their fields: its keys, in this order.
RECORDED_KEYS = ["outcome", "reason", "steps", "path_length_m", "shortest_path_m", "spl", "collisions", "invalid_decisions", "oscillations", "final_state", "final_room", "contact", "input_tokens", "cached_tokens", "output_tokens", "cost_usd", "latency_s_total", "pilot_calls", "wall_time_s", "interventions", "oscillation_events", "shield", "judged_by", "stages", "stages_reached", "failed_stage", "stage_starts", "stage_paths_m", "unreachable", "unreachable_reported", "mover_collisions", "signs_obeyed", "sign_seen_step"]


@pytest.fixture(scope="module")
def geo() -> Simulator:
    return Simulator("cabin", SimConfig(render=False))


class StepCounter:
    """A measure that lives only in this test: counts the steps it sees, and fills no field."""

    fields = ()
    aggregates = ()
    columns = ()
    made: list[StepCounter] = []

    def __init__(self) -> None:
        StepCounter.made.append(self)
        self.steps, self.ends = 0, 0

    def reset(self, start: EpisodeStart) -> None:
        self.steps = 0

    def update(self, step: StepFacts) -> None:
        self.steps += 1

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        self.ends += 1
        return {}


class ForwardMoves:
    """A toy metric that lives only in this test: executed A1 commands (forward 10 cm), summed over a bench."""

    fields = (ResultField("a1_moves", int, 0),)
    aggregates = (Total("a1_moves", absent=0),)
    columns = (column("a1_moves", md="A1 moves", tex="A1", rank=LAST),)

    def reset(self, start: EpisodeStart) -> None:
        self.count = 0

    def update(self, step: StepFacts) -> None:
        self.count += step.command is not None and step.command.code == "A1"

    def value(self, end: EpisodeEnd) -> dict[str, Any]:
        return {"a1_moves": self.count}


def test_a_measure_in_the_list_is_picked_up(geo: Simulator, monkeypatch: pytest.MonkeyPatch) -> None:
    StepCounter.made.clear()
    monkeypatch.setattr(episode_measures, "MEASURES", (*episode_measures.MEASURES, StepCounter))
    result = run_episode(geo, OraclePilot(), parse_query("Find the sink", geo.scene), EpisodeConfig(max_steps=5),
                         spawn="bathroom")
    [counter] = StepCounter.made
    assert counter.steps == result.steps > 0 and counter.ends == 1


def test_the_measures_fill_the_result_once_each(geo: Simulator) -> None:
    obs = geo.reset("bedroom")
    task = parse_query("Go to the bathroom", geo.scene)
    measures = Measures(EpisodeStart(geo.scene, obs.pose, task, EpisodeConfig().success))
    filled: list[str] = []
    for measure in measures.all:
        value = measure.value(EpisodeEnd("max_steps", make_safety("off", geo, geo.scene)))
        assert list(value) == [f.name for f in measure.fields], f"{type(measure).__name__} fills other fields than it declares"
        filled += value
    assert sorted(filled) == sorted(set(filled)), "two measures fill the same field"
    assert set(filled).isdisjoint(EPISODE_FIELDS)
    assert set(filled) | set(EPISODE_FIELDS) == {f.name for f in fields(EpisodeResult)}


def test_the_result_keeps_its_recorded_layout_and_reads_back_from_its_dict() -> None:
    assert [f.name for f in fields(EpisodeResult)] == RECORDED_KEYS
    values = {name: i for i, name in enumerate(RECORDED_KEYS)} | {"outcome": "success"}
    result = EpisodeResult(**values)
    assert list(result.to_dict()) == RECORDED_KEYS and result.spl == values["spl"] and result.success
    assert EpisodeResult(**result.to_dict()) == result
    with pytest.raises(AttributeError):
        result.spl = 1.0  # type: ignore[misc]  # frozen


def test_a_new_metric_touches_one_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The toy measure, added to `MEASURES` only, is in every result, in the bench's summary and in its tables."""
    assert ForwardMoves not in measure_classes()
    monkeypatch.setattr(episode_measures, "MEASURES", (*episode_measures.MEASURES, ForwardMoves))
    suite = tmp_path / "tiny.yaml"
    suite.write_text(TINY)
    report = run_bench(BenchSettings(suite=suite, out=tmp_path / "bench", executor="inline", render=False,
                                     progress=False))
    records = [json.loads(line) for line in (report.out / "results.jsonl").read_text().splitlines()]
    assert [list(r["result"]) for r in records] == [[*RECORDED_KEYS, "a1_moves"]] * 4  # the new key comes last
    moves = sum(r["result"]["a1_moves"] for r in records)
    assert moves > 0  # the oracle flies forward in 10 cm steps on its way to the bedroom

    [summary] = report.summaries
    assert summary.a1_moves == moves

    md = (report.out / "table.md").read_text().splitlines()
    header = next(line for line in md if line.startswith("| Pilot |"))
    assert header.endswith("| Latency p95 (s) | A1 moves |")
    assert md[md.index(header) + 2].endswith(f" | {moves} |")
    [row] = csv.DictReader(io.StringIO((report.out / "summary.csv").read_text()))
    assert row["a1_moves"] == str(moves) and list(row)[-4:] == ["a1_moves", "shield", "prompt_hash", "git_sha"]
    tex = (report.out / "table.tex").read_text()
    assert r"p95 (s) & A1 \\" in tex and tex.count(f" & {moves} \\\\") == 1
