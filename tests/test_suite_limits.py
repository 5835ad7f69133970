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


@pytest.mark.parametrize(("key", "value", "named"), [
    ("max_steps", 999999999999, "max_steps must be an integer in 1..100000"),
    ("max_steps", 0, "max_steps must be an integer in 1..100000"),
    ("repetitions", 1_000_000_000, "repetitions must be an integer in 1..10000"),
])
def test_a_suite_has_the_command_line_caps(key, value, named) -> None:
    with pytest.raises(SuiteError, match=named):
        _suite(**{key: value})


def test_ctrl_c_advises_resume_only_where_there_is_a_bench_to_resume(tmp_path) -> None:
    from vlnpilot.bench.command import _interrupted
    from vlnpilot.bench.manifest import MANIFEST

    assert "--resume" not in _interrupted(tmp_path / "hr1")  # interrupted while the episodes were planned
    (tmp_path / MANIFEST).write_text("{}")
    assert f"--resume --out {tmp_path}" in _interrupted(tmp_path)


def test_a_bench_caps_its_reps_and_steps_as_the_command_line_does() -> None:
    from vlnpilot.bench.runner import BenchSettings, effective_suite
    from vlnpilot.core.errors import ConfigError

    with pytest.raises(ConfigError, match=r"--reps must be an integer in 1\.\.10000"):
        effective_suite(BenchSettings(suite="paper", reps=1_000_000_000))
    with pytest.raises(ConfigError, match=r"--max-steps must be an integer in 1\.\.100000"):
        effective_suite(BenchSettings(suite="paper", max_steps=999_999_999_999))
