"""A suite's numbers are bounded where they are read: spawn jitter, step limit and repetitions."""

from __future__ import annotations

import pytest

from vlnpilot.bench.suite import SuiteError, suite_from_dict

ROWS = [{"id": "a", "spawn": "living_room", "query": "Go to the bathroom"}]


def _suite(**top):
    return suite_from_dict({"scene": "cabin", "rows": ROWS, **top}, source="t.yaml")


@pytest.mark.parametrize("jitter", [{"m": 4}, {"m": 1000, "deg": 1e300}, {"m": float("nan")}, {"deg": float("inf")},
                                    {"deg": 90}, {"m": -0.1}, {"m": "far"}])
def test_a_spawn_jitter_out_of_range_is_refused_naming_the_range(jitter) -> None:
    with pytest.raises(SuiteError, match=r"spawn_jitter must have m in 0\.\.0\.5 \(metres\) and deg in 0\.\.45"):
        _suite(spawn_jitter=jitter)


def test_a_spawn_jitter_in_range_is_kept() -> None:
    suite = _suite(spawn_jitter={"m": 0.5, "deg": 45})
    assert (suite.spawn_jitter_m, suite.spawn_jitter_deg) == (0.5, 45.0)
