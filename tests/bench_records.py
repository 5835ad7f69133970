"""Bench test material: a tiny two-row suite, and a results line as the runner writes it, with only the fields a
test cares about to choose."""

from __future__ import annotations

# Two rows of the cabin, two repetitions: the smallest bench that still has rows, repetitions and a goal.
TINY = """\
name: tiny
repetitions: 2
max_steps: 30
seed: 3
rows:
  - {id: to-bedroom, spawn: living_room, query: Go to the bedroom, goal: bedroom}
  - {id: stay, spawn: bathroom, query: Go to the bathroom}
"""


def bench_record(pilot: str, row: str, rep: int, outcome: str, *, steps: int = 10, spl: float | None = None,
                 model: str = "m", latencies: list[float] | None = None, tokens: tuple[int, int] = (0, 0),
                 cost: float = 0.0, invalid: int = 0, osc: int = 0, shield: str = "off",
                 interventions: int = 0, cached: int | None = None) -> dict:
    return {
        "key": f"{pilot}|{row}|{rep}", "pilot": pilot, "model": model, "row": row, "rep": rep, "seed": 1,
        "result": {"outcome": outcome, "steps": steps, "spl": (1.0 if outcome == "success" else 0.0) if spl is None
                   else spl, "collisions": int(outcome == "collision"), "invalid_decisions": invalid,
                   "oscillations": osc, "input_tokens": tokens[0], "output_tokens": tokens[1], "cost_usd": cost,
                   "pilot_calls": len(latencies or []), "latency_s_total": sum(latencies or []), "shield": shield,
                   "interventions": interventions, **({} if cached is None else {"cached_tokens": cached})},
        "call_latencies_s": latencies or [], "run_dir": f"runs/{pilot}/{row}/{rep}",
        "provenance": {"prompt_hash": "abc123", "git_sha": "deadbeef"},
    }
