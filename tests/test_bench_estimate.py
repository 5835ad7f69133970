"""`vln-pilot bench ... --estimate` (issue 27): the calls, tokens, cached share and cost of each pilot, counted
offline (o200k from the bpe-openai wheel: no download), printed before anything flies; then it exits."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli_support import run_main
from vlnpilot import cli
from vlnpilot.bench.estimate import (
    CALLS_PER_STEP,
    MIN_CACHED,
    OUTPUT_TOKENS,
    STATE_CHANGE_SHARE,
    RowCalls,
    episode_steps,
    estimate_pilot,
)
from vlnpilot.pilots import pricing


def test_the_estimate_prints_every_pilot_and_flies_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli.app, ["bench", "--suite", "paper", "--pilots", "oracle,openai:gpt-4.1,anthropic",
                                          "--reps", "1", "--estimate"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "nothing flown" in result.stdout
    rows = {line.split("│")[1].strip(): line for line in result.stdout.splitlines() if line.count("│") > 5}
    assert set(rows) >= {"oracle", "openai:gpt-4.1", "anthropic"}
    assert "claude" in rows["anthropic"] and "%" in rows["openai:gpt-4.1"]
    cells = [c.strip() for c in rows["openai:gpt-4.1"].split("│")[1:-1]]
    assert cells[2] == "10" and int(cells[3]) > 10  # ten rows, one repetition; calls
    assert float(cells[-1]) > 0
    assert not list(tmp_path.iterdir())  # no bench directory: nothing flew


def test_bad_input_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_main(monkeypatch, capsys, "bench", "--pilots", "nosuch", "--estimate")
    assert code == 2
    assert "unknown pilot 'nosuch'" in err and "valid pilots:" in err and len(err.strip().splitlines()) == 1


def test_a_call_is_served_from_the_cache_but_an_episodes_first_and_those_in_a_new_state() -> None:
    row = RowCalls(calls=11, text_tokens=2000.0, prefix_tokens=1800.0)
    e = estimate_pilot("openai:gpt-4.1", [(row, 3)])
    assert (e.episodes, e.calls) == (3, 33)
    assert e.input_tokens == (2000 + 85) * 33
    served = round(10 * (1 - STATE_CHANGE_SHARE))
    prefix = MIN_CACHED + (1800 - MIN_CACHED) // 128 * 128
    assert e.cached_tokens == prefix * served * 3
    assert e.output_tokens == OUTPUT_TOKENS * 33
    assert e.cost_usd == pricing.cost_usd("gpt-4.1", e.input_tokens, e.cached_tokens, e.output_tokens).usd
    short = estimate_pilot("gemini", [(RowCalls(calls=11, text_tokens=900.0, prefix_tokens=800.0), 1)])
    assert short.cached_tokens == 0  # under the 1,024 tokens any cache needs
    claude = estimate_pilot("anthropic", [(row, 1)])
    assert claude.cost_usd > pricing.cost_usd(claude.model, claude.input_tokens, claude.cached_tokens,
                                              claude.output_tokens).usd  # cache writes cost more than input


def test_steps_follow_the_shortest_path_up_to_the_limit() -> None:
    assert episode_steps(2.0, 50) == 28
    assert episode_steps(10.0, 50) == 50
    assert episode_steps(0.0, 50) == 1
    assert CALLS_PER_STEP >= 1
