"""Synthetic run and bench directories for the report tests, in the exact formats the recorder and the bench write.

Synthetic (not flown) so that they are fast and hold every case a report must show: re-asks, a hover after
invalid answers, a shield intervention, a collision, untrusted model text, a pilot error. The pose path walks
from the living room through both doors of the cabin, so the floor plan has something to draw.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from vlnpilot.episode.measures import EpisodeResult

EVIL = '<script>window.__pwned=1</script><img src=x onerror="window.__pwned=2">&amp; "quoted" </pre>'

STATES = ["Recognize Room", "Search Open Door", "Oriented Towards Door", "Go Through Door",
          "Position in Center of Room", "Recognize Room", "Search Open Door", "Oriented Towards Door",
          "Go Through Door", "Position in Center of Room"]


def _frame(step: int, view: str, size: tuple[int, int]) -> np.ndarray:
    w, h = size
    y, x = np.mgrid[0:h, 0:w]
    img = np.zeros((h, w, 3), np.uint8)
    img[..., 0] = (x * 255 // max(1, w - 1)).astype(np.uint8)
    img[..., 1] = (y * 255 // max(1, h - 1)).astype(np.uint8)
    img[..., 2] = (step * 37 + (90 if view == "rear" else 0)) % 256
    return img


def _pose(i: int, n: int) -> dict[str, float]:
    """Point i of n on a path from the living-room spawn east through both doors (y = 1.0)."""
    t = i / max(1, n)
    x = 3.25 + t * (7.3 - 3.25)
    y = 0.75 + min(1.0, 4 * t) * 0.3
    return {"x": round(x, 4), "y": round(y, 4), "z": 1.0, "yaw_deg": round(135.0 - min(1.0, 3 * t) * 135.0, 1)}


def make_run(run_dir: Path, *, steps: int = 8, outcome: str = "success", query: str = "Go to the bathroom",
             spawn: str = "living_room", pilot: str = "openai:gpt-4.1", model: str = "gpt-4.1",
             frame_size: tuple[int, int] = (160, 120), evil: bool = False, finished: bool = True,
             seed: int | None = 7) -> Path:
    """Write a run directory of `steps` steps ending in `outcome` (collision: the last step collides)."""
    run_dir = Path(run_dir)
    frames = run_dir / "frames"
    frames.mkdir(parents=True, exist_ok=True)

    def save(step: int) -> dict[str, str]:
        out = {}
        for view in ("front", "rear"):
            rel = f"frames/{view}_{step:03d}.jpg"
            Image.fromarray(_frame(step, view, frame_size)).save(run_dir / rel, quality=80)
            out[view] = rel
        return out

    start = _pose(0, steps)
    summary: dict[str, Any] = {
        "status": "running", "task": {"query": query, "goal_room": "bathroom", "goal_target": None},
        "spawn": spawn, "scene": "cabin", "pilot": pilot, "pilot_name": pilot.split(":")[0], "model": model,
        "config": {"max_steps": 50, "profile": "paper", "max_reasks": 2, "seed": seed, "success": {}},
        "start_pose": start, "start_frames": save(0),
        "provenance": {"git_sha": "0123456789abcdef", "prompt_hash": "feedc0ffee12", "versions": {"python": "3"},
                       "started_at": "2026-01-01T00:00:00+0000"},
    }
    lines = []
    tokens_in = tokens_out = 0
    latency = cost = 0.0
    calls = invalid = 0
    for k in range(1, steps + 1):
        state, nxt = STATES[(k - 1) % len(STATES)], STATES[k % len(STATES)]
        if k == steps and outcome in ("success", "false_success"):
            nxt = "Stay on Room"
        usage = {"input_tokens": 1200 + 10 * k, "cached_tokens": 1024 if k > 1 else 0, "output_tokens": 60 + k,
                 "latency_s": round(1.5 + 0.1 * (k % 5), 3), "cost_usd": 0.0031}
        decision: dict[str, Any] | None = {
            "room": "living_room" if k < steps / 2 else "bedroom", "movement": "A1" if k % 3 else "B1",
            "state": nxt, "description": f"Step {k}: the door is ahead, slightly to the right.",
            "door_position": ["left", "center", "right", "not_visible"][k % 4]}
        failures: list[dict[str, Any]] = []
        if k == 2:  # one re-ask, then a valid answer
            failures = [{"attempt": 0, "reason": "movement C3 is not allowed in state Search Open Door",
                         "raw_text": '{"movement": "C3"}'}]
        if k == 3:  # three bad answers: the drone hovers and the step counts an invalid decision
            failures = [{"attempt": a, "reason": "malformed answer: no JSON object", "raw_text": "I think..."}
                        for a in range(3)]
            decision = None
            invalid += 1
        if evil and decision is not None and k == 1:
            decision["description"] = EVIL
            decision["room"] = EVIL
        collided = outcome == "collision" and k == steps
        before, after = _pose(k - 1, steps), _pose(k, steps)
        rec: dict[str, Any] = {
            "step": k, "state": state, "decision": decision,
            "raw_text": (EVIL if evil and k == 1 else json.dumps(decision)) if decision else None,
            "usage": usage if decision else None, "model": model if decision else None, "failures": failures,
            "proposed": decision["movement"] if decision else None,
            "executed": (decision["movement"] if decision else "E") if k != 4 else "E",
            "next_state": nxt if decision else state, "pose_before": before, "pose_after": after,
            "collided": collided, "contact": "wall_bedroom_east" if collided else None,
            "contact_part": "rotor_fl" if collided else None, "room_true": "living_room", "oscillation": k == 5,
            "frames": save(k),
        }
        rec.update(interventions=[], oscillation_event=None, safety_feedback=[])
        if k == 4:  # the shield replaced the move (safety.Intervention.to_dict())
            rec["interventions"] = [{"step": k, "source": "shield", "proposed": rec["proposed"], "executed": "E",
                                     "reason": "a propeller would come within 0.05 m of door_living_bedroom"}]
        if k == 5:  # the oscillation guard fired (safety.OscillationEvent.to_dict()) and told the pilot
            rec["oscillation_event"] = {"step": k, "state": state, "reversals": 3, "window": 6, "acted": True,
                                        "action": "vetoed the reversal: hover"}
            rec["safety_feedback"] = ["Your alignment is good enough: move forward or change state."]
        lines.append(json.dumps(rec))
        calls += 1 + len(failures)
        if decision:
            tokens_in += usage["input_tokens"]
            tokens_out += usage["output_tokens"]
            latency += usage["latency_s"]
            cost += usage["cost_usd"]
    (run_dir / "episode.jsonl").write_text("\n".join(lines) + "\n")
    if finished:
        result = EpisodeResult(
            outcome=outcome, reason={"success": "drone is in bathroom; goal room bathroom",
                                     "collision": "touched wall_bedroom_east"}.get(outcome, outcome),
            steps=steps, path_length_m=4.05, shortest_path_m=3.49, spl=0.86 if outcome == "success" else 0.0,
            collisions=int(outcome == "collision"), invalid_decisions=invalid, oscillations=1,
            final_state="Stay on Room", final_room="bathroom", contact=None, input_tokens=tokens_in,
            cached_tokens=1024 * (steps - 1), output_tokens=tokens_out, cost_usd=round(cost, 6),
            latency_s_total=round(latency, 3), pilot_calls=calls, wall_time_s=3.2,
            **_safety_counts(steps))
        summary.update(status="finished", result=result.to_dict(), end_pose=_pose(steps, steps),
                       safety={"shield": "geometry", "interventions": [], "oscillation_events": []})
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    return run_dir


def _safety_counts(steps: int) -> dict[str, Any]:
    """EpisodeResult's safety fields, when this version of it has them."""
    fields = EpisodeResult.__dataclass_fields__
    out: dict[str, Any] = {}
    if "interventions" in fields:
        out["interventions"] = int(steps >= 4)
    if "oscillation_events" in fields:
        out["oscillation_events"] = int(steps >= 5)
    if "shield" in fields:
        out["shield"] = "geometry"
    return out


PILOTS = (("openai:gpt-4.1", "gpt-4.1"), ("gemini:gemini-2.5-flash", "gemini-2.5-flash"))


def _outcome(p: int, r: int, rep: int) -> str:
    cycle = ["success", "success", "collision", "max_steps", "success", "false_success", "success", "pilot_error"]
    return cycle[(3 * p + 2 * r + rep) % len(cycle)]


def make_bench(bench_dir: Path, *, rows: int = 3, reps: int = 2, steps: int = 4) -> Path:
    """A bench directory as `vln-pilot bench` writes it: bench.json, results.jsonl and runs/, two pilots."""
    from vlnpilot.bench.results import episode_key
    from vlnpilot.bench.suite import episode_seed, load_suite

    bench_dir = Path(bench_dir)
    bench_dir.mkdir(parents=True, exist_ok=True)
    paper = load_suite("paper")
    suite = replace(paper, rows=paper.rows[:rows], repetitions=reps)
    manifest = {"format": "vln-pilot-bench/1", "config_hash": "0f1e2d3c4b5a6978", "suite": suite.to_dict(),
                "pilots": [{"spec": s, "model": m, "dir": s.replace(":", "-")} for s, m in PILOTS],
                "episodes": rows * reps * len(PILOTS), "created_at": "2026-01-01T00:00:00+0000",
                "sessions": [{"git_sha": "0123456789abcdef", "prompt_hash": "feedc0ffee12"}]}
    (bench_dir / "bench.json").write_text(json.dumps(manifest, indent=2))
    lines = []
    for rep in range(1, reps + 1):
        for p, (spec, model) in enumerate(PILOTS):
            for r, row in enumerate(suite.rows):
                outcome = _outcome(p, r, rep)
                rel = f"runs/{spec.replace(':', '-')}/{row.id}/{rep}"
                n = steps + (2 if outcome == "max_steps" else 0)
                make_run(bench_dir / rel, steps=n, outcome=outcome, query=row.query, spawn=row.spawn, pilot=spec,
                         model=model, frame_size=(96, 72))
                summary = json.loads((bench_dir / rel / "summary.json").read_text())
                lat = [1.0 + 0.3 * p + 0.05 * i for i in range(summary["result"]["pilot_calls"])]
                lines.append(json.dumps({
                    "key": episode_key(spec, row.id, rep), "pilot": spec, "model": model, "row": row.id, "rep": rep,
                    "seed": episode_seed(suite.seed, row.id, rep), "spawn": row.spawn, "query": row.query,
                    "goal_room": row.goal_room, "goal_target": row.goal_target, "result": summary["result"],
                    "call_latencies_s": lat, "run_dir": rel,
                    "provenance": {"prompt_hash": "feedc0ffee12", "git_sha": "0123456789abcdef"}}))
    (bench_dir / "results.jsonl").write_text("\n".join(lines) + "\n")
    return bench_dir


def expected_table(bench_dir: Path) -> dict[str, dict[str, tuple[str, int, int]]]:
    """Table-4 cells computed straight from results.jsonl: row id -> pilot -> ('k/n', collisions, exceeded)."""
    cells: dict[str, dict[str, list[int]]] = {}
    for line in (Path(bench_dir) / "results.jsonl").read_text().splitlines():
        rec = json.loads(line)
        c = cells.setdefault(rec["row"], {}).setdefault(rec["pilot"], [0, 0, 0, 0])
        outcome = rec["result"]["outcome"]
        c[0] += outcome == "success"
        c[1] += 1
        c[2] += outcome == "collision"
        c[3] += outcome == "max_steps"
    return {row: {p: (f"{v[0]}/{v[1]}", v[2], v[3]) for p, v in by.items()} for row, by in cells.items()}
