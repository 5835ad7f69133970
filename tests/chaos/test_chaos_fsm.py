"""Chaos: every executed command outside its state's allowed moves says which override put it there (issue 16)."""

from __future__ import annotations

import io
import json
from collections import Counter
from pathlib import Path

import pytest
from rich.console import Console

from vlnpilot.bench.command import bench_command
from vlnpilot.core.commands import get_command
from vlnpilot.core.fsm import state_spec
from vlnpilot.episode.overrides import OVERRIDE_REASONS, override_reason

pytestmark = pytest.mark.chaos


def test_no_command_outside_the_allowed_set_without_a_reason_over_a_noisy_oracle_bench(tmp_path: Path) -> None:
    out = bench_command(suite="paper", pilots="noisy-oracle", reps=2, executor="inline", out=tmp_path / "bench",
                        render=False, shield="geometry", progress=False, console=Console(file=io.StringIO()))
    steps = [json.loads(line) for path in sorted(out.rglob("episode.jsonl")) for line in path.read_text().splitlines()]
    assert len(steps) > 50
    reasons: Counter[str] = Counter()
    for s in steps:
        if s["executed"] is None:  # a fatal pilot error: nothing ran
            continue
        allowed = s["executed"] in state_spec(s["state"], "paper").moves
        assert (s["override"] is None) == allowed, s
        if not allowed:
            assert s["override"] in OVERRIDE_REASONS, s
            reasons[s["override"]] += 1
    assert reasons, "the noisy oracle and the shield must have forced some override, or this test proves nothing"


def test_the_reason_names_the_last_override_to_act() -> None:
    class Act:
        def __init__(self, source: str):
            self.source = source

    hover, d1 = get_command("E"), get_command("D1")
    # hover is allowed in every asked state (issue 24): the fallback's hover is no override any more
    assert override_reason("Recognize Room", "paper", hover, fallback=True) is None
    assert override_reason("Recognize Room", "paper", d1, fallback=True) == "fallback"
    assert override_reason("Go Through Door", "paper", d1, False, [Act("oscillation_guard"), Act("shield")]) \
        == "shield"
    assert override_reason("Go Through Door", "paper", get_command("A1"), False, [Act("door_assist")]) is None
