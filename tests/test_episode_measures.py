"""The measures are made from the one list `episode_measures.MEASURES`: a measure added there is updated every
step and asked for its value once, and together the measures fill every `EpisodeResult` field the episode does
not decide itself."""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import pytest

import vlnpilot.episode_measures as episode_measures
from vlnpilot.episode import EpisodeConfig, EpisodeResult, run_episode
from vlnpilot.episode_measures import EPISODE_FIELDS, EpisodeEnd, EpisodeStart, Measures, StepFacts
from vlnpilot.pilots.oracle import OraclePilot
from vlnpilot.safety import make_safety
from vlnpilot.sim import SimConfig, Simulator
from vlnpilot.tasks import parse_query


@pytest.fixture(scope="module")
def geo() -> Simulator:
    return Simulator("cabin", SimConfig(render=False))


class StepCounter:
    """A measure that lives only in this test: counts the steps it sees."""

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
        filled += measure.value(EpisodeEnd("max_steps", make_safety("off", geo, geo.scene)))
    assert sorted(filled) == sorted(set(filled)), "two measures fill the same field"
    assert set(filled).isdisjoint(EPISODE_FIELDS)
    assert set(filled) | set(EPISODE_FIELDS) == {f.name for f in fields(EpisodeResult)}
