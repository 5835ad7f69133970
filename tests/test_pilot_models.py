"""A pilot that has no model to choose (the oracle, its noisy and gullible kin, a person at stdin) refuses one in
its SPEC: a result is never labelled with a model that did not fly it."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_support import run_main
from vlnpilot.core.errors import ConfigError
from vlnpilot.pilots.base import make_pilot

TAKERS = {"anthropic", "files", "gemini", "openai", "remote", "replay"}


@pytest.mark.parametrize("name", ["oracle", "noisy-oracle", "gullible", "stdin"])
def test_a_pilot_without_a_model_refuses_one(name: str) -> None:
    with pytest.raises(ConfigError, match=f"the {name} pilot takes no model \\(got {name}:gpt-4.1\\); write {name}"):
        make_pilot(f"{name}:gpt-4.1")


def test_the_oracle_alone_still_flies_on_ground_truth() -> None:
    assert make_pilot("oracle").model == "ground-truth"


def test_run_with_a_model_for_the_oracle_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _, err = run_main(monkeypatch, capsys, "run", "Go to the bedroom", "--pilot", "oracle:xyz", "--no-video",
                            "--out", str(tmp_path / "r"))
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert lines[0].startswith("error: the oracle pilot takes no model (got oracle:xyz); write oracle. Pilots that "
                               "take a model or a path after ':': ")
    named = set(lines[0].split(": ")[-1].split(", "))  # with the pilots other tests register
    assert TAKERS <= named and not {"oracle", "noisy-oracle", "gullible", "stdin"} & named
    assert not (tmp_path / "r").exists()


def test_bench_with_a_model_for_the_oracle_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    suite = tmp_path / "tiny.yaml"
    suite.write_text("name: tiny\nrows:\n  - {query: Go to the bedroom, spawn: bedroom}\n")
    code, _, err = run_main(monkeypatch, capsys, "bench", "--suite", str(suite), "--pilots", "oracle:gpt-4.1",
                            "--no-report", "--out", str(tmp_path / "b"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "the oracle pilot takes no model" in err
    assert not (tmp_path / "b" / "results.jsonl").exists()
