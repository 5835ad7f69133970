"""The controller's own cost per step: everything in a step except the model call and the simulator.

Per step it times what the controller and a model pilot do around the model call, on real 640x480 frames:

    prompt     build_prompt: texts from the templates and tables, JPEG encoding of the front frame, schema
    encode     base64 of the JPEG and the user text, as a provider pilot sends them
    parse      parse_decision of a typical JSON reply (prose around a fenced JSON object)
    validate   normalize_decision + validate_decision against the FSM
    record     Recorder: both frames as JPEG (front, rear) and one episode.jsonl line, flushed

and prints the median and p90 per part and in total, with the machine. Budget: at most 30 ms per step.

    .venv/bin/python bench/controller_cost.py [--steps 200] [--warmup 10] [--out DIR] [--json] [--smoke]
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vlnpilot.core.decision import PilotInput, normalize_decision, parse_decision, validate_decision
from vlnpilot.core.fsm import State
from vlnpilot.core.rundir import Recorder
from vlnpilot.prompting.render import build_prompt
from vlnpilot.scene import load_scene

BUDGET_MS = 30.0
PARTS = ("prompt", "encode", "parse", "validate", "record")
REPLY = (
    "The image shows a wooden door frame slightly to the left, with the bedroom visible beyond it.\n"
    "```json\n"
    + json.dumps({"room": "living_room", "movement": "C1", "state": "Oriented Towards Door",
                  "description": "An open doorway is slightly left of centre; the bed is visible through it, so "
                                 "the bedroom is behind this door. Rotating left 15 degrees to face it.",
                  "door_position": "left"}, indent=2)
    + "\n```"
)


def machine() -> dict[str, object]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"cpu": cpu, "cores": os.cpu_count(), "usable_cores": usable, "python": platform.python_version(),
            "system": f"{platform.system()} {platform.release()}"}


def frames(count: int) -> tuple[list[tuple[np.ndarray, np.ndarray]], str]:
    """Real 640x480 front/rear frames from the simulator (rendering is not timed); synthetic ones without GL."""
    try:
        from vlnpilot.sim import Simulator

        out = []
        with Simulator("cabin") as sim:
            for spawn in sim.scene.spawns:
                obs = sim.reset(spawn.id)
                for _ in range(max(1, count // len(sim.scene.spawns))):
                    out.append((obs.front_rgb, obs.rear_rgb))
                    obs = sim.step("C2")
        return out, "simulator renders"
    except Exception as exc:  # no headless GL here: smooth synthetic images compress like renders
        print(f"(no simulator frames: {exc}; using synthetic images)", file=sys.stderr)
        y, x = np.mgrid[0:480, 0:640]
        img = np.stack([(x * 0.4) % 256, (y * 0.5) % 256, ((x + y) * 0.2) % 256], axis=-1).astype(np.uint8)
        return [(img, img[::-1].copy())], "synthetic"


def run(steps: int, warmup: int, out_dir: Path) -> tuple[dict[str, list[float]], str]:
    scene = load_scene("cabin")
    topo = scene.topological_map()
    shots, source = frames(12)
    recorder = Recorder(out_dir)
    times: dict[str, list[float]] = {p: [] for p in (*PARTS, "total")}
    states = [State.SEARCH_OPEN_DOOR, State.ORIENTED_TOWARDS_DOOR, State.RECOGNIZE_ROOM]
    pose = {"x": 3.25, "y": 0.75, "z": 1.0, "yaw_deg": 135.0}
    for i in range(warmup + steps):
        front, rear = shots[i % len(shots)]
        state = states[i % len(states)]
        pin = PilotInput(image=front, query="Go to the bathroom", topological_map=topo, state=state,
                         previous_movement="C1", step=i + 1)
        t0 = time.perf_counter()
        prompt = build_prompt(pin)
        t1 = time.perf_counter()
        payload = {"system": prompt.system, "text": prompt.user_text(),
                   "image": "data:image/jpeg;base64," + base64.b64encode(prompt.image_jpeg).decode("ascii"),
                   "schema": prompt.schema}
        t2 = time.perf_counter()
        decision = parse_decision(REPLY)
        t3 = time.perf_counter()
        decision = normalize_decision(decision)
        error = validate_decision(decision, State.SEARCH_OPEN_DOOR)
        t4 = time.perf_counter()
        record = {"step": i + 1, "state": state.value, "decision": decision.core(), "raw_text": decision.raw_text,
                  "usage": decision.usage.model_dump(), "model": "bench", "failures": [] if error is None else
                  [{"attempt": 0, "reason": error, "raw_text": decision.raw_text}], "proposed": decision.movement,
                  "executed": decision.movement, "next_state": decision.state, "pose_before": pose,
                  "pose_after": pose, "collided": False, "contact": None, "contact_part": None,
                  "room_true": "living_room", "oscillation": False}
        record["frames"] = recorder.save_observation(i + 1, front, rear)
        recorder.step(record)
        t5 = time.perf_counter()
        assert payload["image"] and decision.movement == "C1"
        if i >= warmup:
            for part, (a, b) in zip(PARTS, ((t0, t1), (t1, t2), (t2, t3), (t3, t4), (t4, t5)), strict=True):
                times[part].append((b - a) * 1000)
            times["total"].append((t5 - t0) * 1000)
    recorder.close()
    return times, source


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=200, help="timed steps (default 200)")
    ap.add_argument("--warmup", type=int, default=10, help="untimed steps first (default 10)")
    ap.add_argument("--out", type=Path, default=None, help="run directory to record into (default: a temp dir)")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    ap.add_argument("--smoke", action="store_true", help="3 steps, 1 warm-up (for the tests)")
    args = ap.parse_args()
    if args.smoke:
        args.steps, args.warmup = 3, 1
    if args.steps < 1 or args.warmup < 0:
        ap.error("--steps must be >= 1 and --warmup >= 0")
    with tempfile.TemporaryDirectory(prefix="vlnpilot-bench-") as tmp:
        out_dir = args.out or Path(tmp) / "run"
        times, source = run(args.steps, args.warmup, out_dir)
    stats = {p: {"median_ms": round(statistics.median(v), 3), "p90_ms": round(percentile(v, 90), 3)}
             for p, v in times.items()}
    info = {"machine": machine(), "steps": args.steps, "frames": f"640x480 front+rear, {source}",
            "per_step": stats, "budget_ms": BUDGET_MS, "within_budget": stats["total"]["median_ms"] <= BUDGET_MS}
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    m = info["machine"]
    print(f"controller cost per step (everything but the model call and the simulator), {args.steps} steps, "
          f"{info['frames']}")
    print(f"machine: {m['cpu']}, {m['cores']} cores ({m['usable_cores']} usable), Python {m['python']}, "
          f"{m['system']}")
    print(f"{'part':<10} {'median ms':>10} {'p90 ms':>10}")
    for part, s in stats.items():
        print(f"{part:<10} {s['median_ms']:>10.2f} {s['p90_ms']:>10.2f}")
    verdict = "within" if info["within_budget"] else "OVER"
    print(f"median total {stats['total']['median_ms']:.1f} ms: {verdict} the {BUDGET_MS:.0f} ms budget")
    return 0


if __name__ == "__main__":
    sys.exit(main())
