"""The episode page (`write_episode_report`): a run directory as a step-by-step player with the floor plan.

The markup is `templates/episode.html.j2`; this module gathers the values it shows."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from vlnpilot.core.fileio import write_atomic
from vlnpilot.report.page import (
    FLOORPLAN,
    REPORT,
    _cost,
    _image_size,
    _int,
    _num,
    render,
    room_view,
    static_text,
)
from vlnpilot.report.timeline import Entry, Episode, load_episode

EPISODE_JS = static_text("episode.js")
SOURCES = {"shield": "shield", "door_assist": "door assist", "oscillation_guard": "oscillation guard"}
SHORT_SOURCES = {"shield": "shield", "door_assist": "assist", "oscillation_guard": "guard"}
STATE_FALLBACK = ("#1f77b4", "#ff7f0e", "#9467bd", "#17becf", "#8c564b", "#e377c2", "#bcbd22", "#7f7f7f")


def _plural(n: Any, word: str) -> str:
    return f"{_int(n)} {word}{'s' if n != 1 else ''}"


def _facts(ep: Episode) -> list[tuple[str, str, str]]:
    """The header's plain facts (label, value, note), after Spawn, Goal and Pilot."""
    s, r = ep.summary, ep.result
    cfg = s.get("config") or {}
    calls = r.get("pilot_calls") or 0
    latency = r.get("latency_s_total")
    mean_latency = latency / calls if isinstance(latency, int | float) and calls else None
    facts = [
        ("Model", s.get("model") or "–", ""),
        ("Steps", _int(r.get("steps", len(ep.steps))), f"of {_int(cfg.get('max_steps'))}" if cfg.get("max_steps")
         else ""),
        ("Path length", _num(r.get("path_length_m"), 2, " m"),
         f"shortest {_num(r.get('shortest_path_m'), 2, ' m')} · SPL {_num(r.get('spl'), 2)}"
         if "shortest_path_m" in r else ""),
        ("Collisions", _int(r.get("collisions", sum(1 for x in ep.steps if x.get("collided")))),
         r.get("contact") or ""),
        ("Invalid decisions", _int(r.get("invalid_decisions")),
         f"{_int(r.get('oscillations'))} oscillations" if "oscillations" in r else ""),
        ("Tokens", f"{_int(r.get('input_tokens'))} in · {_int(r.get('output_tokens'))} out",
         f"{_int(r.get('cached_tokens'))} cached" if r.get("cached_tokens") else ""),
        ("Cost", _cost(r.get("cost_usd")), ""),
        ("Model latency", _num(latency, 1, " s"),
         f"{_num(mean_latency, 2, ' s')} per call, {_int(calls)} calls" if calls else ""),
        ("Wall time", _num(r.get("wall_time_s"), 1, " s"), ""),
    ]
    safety = s.get("safety") or {}
    shield = r.get("shield") or safety.get("shield") or cfg.get("shield")
    n_int = r.get("interventions", sum(len(e.interventions) for e in ep.entries))
    n_osc = r.get("oscillation_events", sum(1 for e in ep.entries if e.oscillation_event))
    if shield is not None or n_int or n_osc:
        facts.append(("Safety layer", shield or "–",
                      f"{_plural(n_int, 'intervention')} · {_plural(n_osc, 'oscillation event')}"))
    return facts


def _spawn(ep: Episode) -> dict[str, Any]:
    """The spawn as a room chip (its room's colour), with the spawn's own name as a note when it differs."""
    spawn = ep.summary.get("spawn")
    room = None
    if ep.scene is not None and spawn:
        try:
            room = ep.scene.spawn(spawn).room
        except Exception:  # noqa: BLE001 - an unknown spawn only loses the colour swatch
            room = None
    if room is None:
        return {"room": {"name": spawn or "–", "color": None}, "note": ""}
    return {"room": room_view(ep.scene, room), "note": spawn if room != spawn else ""}


def _frame(ep: Episode, entry: Entry, view: str, caption: str) -> dict[str, Any]:
    rel = entry.frames.get(view)
    if not rel and view == "rear" and (ep.summary.get("capabilities") or {}).get("rear_view") is False:
        return {"src": None, "missing": "this robot has no rear camera", "caption": caption}  # a real Tello
    if not rel:
        return {"src": None, "missing": f"no {view} frame recorded", "caption": caption}
    return {"src": rel, "alt": f"{view} camera, {entry.label.lower()}", "size": _image_size(ep.run_dir / rel),
            "caption": caption}


def _intervention(item: Any) -> dict[str, Any]:
    """One change the safety layer made: '[shield] A2 → A1 reason' (other shapes shown as key: value)."""
    if not isinstance(item, Mapping):
        return {"source": "safety", "proposed": None, "text": str(item)}
    source = SOURCES.get(str(item.get("source")), str(item.get("source") or "safety"))
    if "proposed" in item and "executed" in item:
        return {"source": source, "proposed": item["proposed"], "executed": item["executed"],
                "reason": item.get("reason")}
    text = " · ".join(f"{k}: {v}" for k, v in item.items() if k not in ("source", "step"))
    return {"source": source, "proposed": None, "text": text}


def _notes(entry: Entry) -> dict[str, Any]:
    ev = entry.oscillation_event
    changed = (not entry.interventions and entry.step is not None and bool(entry.proposed and entry.executed)
               and entry.proposed != entry.executed)
    notes = {
        "failures": [{"attempt": int(f.get("attempt", 0)) + 1, "reason": f.get("reason"), "raw": f.get("raw_text")}
                     for f in entry.failures],
        "interventions": [_intervention(item) for item in entry.interventions],
        "changed": changed,
        "osc_event": ev and {**ev, "acted": "the guard acted" if ev.get("acted") else
                             "detected only (safety layer off)"},
        "collision": bool(entry.collided and entry.step is not None),
        "short_sources": [SHORT_SOURCES.get(str(src), src or "safety") for src in
                          (i.get("source") if isinstance(i, Mapping) else None for i in entry.interventions)],
    }
    notes["events"] = [_event_text(e) for e in entry.events]
    notes["any"] = bool(notes["failures"] or notes["interventions"] or changed or ev or entry.feedback
                        or notes["collision"] or entry.oscillation or notes["events"])
    return notes


def _event_text(event: Mapping[str, Any]) -> dict[str, str]:
    """Issue 24: an event that fired, as the page lists it: its kind, name, clock and what it is about."""
    params = event.get("params") or {}
    redirect = " (redirect)" if params.get("redirect") else ""
    about = {"door_closes": params.get("door"), "lights_out": params.get("room"),
             "sign": f"{params.get('room')}: \u201c{params.get('text')}\u201d{redirect}"}.get(str(event.get("kind")))
    if event.get("kind") in ("person", "pet"):
        about = " → ".join(str(p) for p in params.get("path") or ())
    clock = event.get("time_s")
    return {"kind": str(event.get("kind") or "event").replace("_", " "), "name": str(event.get("name") or ""),
            "when": f"{float(clock):.1f} s" if isinstance(clock, int | float) else "",
            "trigger": str(event.get("trigger") or ""), "about": str(about or "")}


def _movers_on_plan(entry: Entry, plan: Any) -> str:
    """Issue 24: where the people and pets were at this entry, in percent of the plan image (JSON for the page's
    script, which moves a dot per mover with the step)."""
    dots = []
    for m in entry.movers:
        x, y = plan.to_px(float(m["x"]), float(m["y"]))
        dots.append({"name": m.get("name"), "kind": m.get("kind"), "x": round(100 * x / plan.size[0], 3),
                     "y": round(100 * y / plan.size[1], 3)})
    return json.dumps(dots)


def _room_matches(scene: Any, said: str | None, true_room: str | None) -> bool | None:
    if scene is None or not said or not true_room:
        return None
    found = scene.find_room(said)
    return found is not None and found.id == true_room


def _entry(ep: Episode, entry: Entry, plan: Any | None) -> dict[str, Any]:
    seen = "seen by the pilot" if entry.step is not None else "final view"
    pose = entry.pose or {}
    view: dict[str, Any] = {
        "entry": entry, "notes": _notes(entry), "room_true": room_view(ep.scene, entry.room_true),
        "front": _frame(ep, entry, "front", f"Front camera · {seen}"), "rear": _frame(ep, entry, "rear", "Rear camera"),
        "pose": (f"x {_num(pose.get('x'))} m, y {_num(pose.get('y'))} m, yaw {_num(pose.get('yaw_deg'), 0)}°"
                 if pose else "–"),
        "room_matches": _room_matches(ep.scene, (entry.decision or {}).get("room"), entry.room_true),
        "extra_json": json.dumps(entry.extra, indent=2) if entry.extra else "", "plan": None,
        "stage_start": _stage_start(ep, entry),
    }
    at = plan.positions[entry.index] if plan is not None else None
    if plan is not None and at is not None:
        x, y = at
        view["plan"] = {"x": f"{100 * x / plan.size[0]:.3f}", "y": f"{100 * y / plan.size[1]:.3f}",
                        "yaw": f"{float(pose.get('yaw_deg', 0.0)):.1f}",
                        "movers": _movers_on_plan(entry, plan) if entry.movers else None}
    return view


def _chips(ep: Episode, colors: Mapping[str, str]) -> list[dict[str, str]]:
    chips = []
    for e in ep.entries:
        flags = ["stage-start"] if e.stage is not None and e.stage > 1 and e.index > 0 and \
            ep.entries[e.index - 1].stage != e.stage else []
        if e.failures or e.decision is None and e.step is not None:
            flags.append("flag-fail")
        if e.interventions or e.oscillation_event or (e.proposed and e.executed and e.proposed != e.executed):
            flags.append("flag-shield")
        if e.collided and e.step is not None:
            flags.append("flag-collision")
        if e.events:
            flags.append("flag-event")
        tip = f"{e.label}: {e.shown_state}" + (f" · {e.executed}" if e.executed else "") + "".join(
            f" · {ev.get('kind')}" for ev in e.events)
        chips.append({"cls": " ".join(flags + (["current"] if e.index == 0 else [])),
                      "color": colors.get(e.shown_state, "#c5cad3"), "tip": tip,
                      "text": str(e.step) if e.step is not None else "■"})
    return chips


def _state_colors(ep: Episode, plan: Any | None) -> dict[str, str]:
    colors = dict(plan.state_colors) if plan is not None else {}
    for e in ep.entries:  # states that never reached the plan (e.g. without a scene) still get a colour
        for st in (e.state, e.next_state):
            if st and st not in colors:
                colors[st] = STATE_FALLBACK[len(colors) % len(STATE_FALLBACK)]
    return colors


def _plan(ep: Episode, plan_file: str | None, plan: Any | None) -> dict[str, Any] | None:
    if plan is None or not plan_file:
        return None
    p0, size = plan.positions[0], plan.size
    cursor = (f"left:{100 * p0[0] / size[0]:.3f}%;top:{100 * p0[1] / size[1]:.3f}%;"
              f"--yaw:{-float((ep.entries[0].pose or {}).get('yaw_deg', 0.0)):.1f}deg") if p0 else ""
    return {"file": plan_file, "size": size, "cursor": cursor, "collision": ep.collision_point() is not None,
            "movers": bool(ep.mover_tracks()), "events": bool(ep.fired_events())}


def render_episode_report(ep: Episode, plan_file: str | None, plan: Any | None) -> str:
    """The episode page as a string (`plan` is a `plots.PlanImage` written to `plan_file`, or None)."""
    s, r = ep.summary, ep.result
    colors = _state_colors(ep, plan)
    prov = s.get("provenance") or {}
    files = [n for n in ("episode.mp4", "episode.gif", "summary.json", "episode.jsonl", FLOORPLAN)
             if (ep.run_dir / n).is_file()]
    query = ep.task.get("query") or "episode"
    return render(
        "episode.html.j2", title=f"{query} · {ep.shown_outcome} · VLN-Pilot", script=EPISODE_JS,
        summary=s, result=r, task=ep.task, run_name=ep.run_dir.name,
        outcome=ep.shown_outcome,
        spawn=_spawn(ep), goal_room=room_view(ep.scene, ep.task.get("goal_room")), facts=_facts(ep), files=files,
        colors=colors, chips=_chips(ep, colors), total=len(ep.entries) - 1,
        entries=[_entry(ep, e, plan) for e in ep.entries], plan=_plan(ep, plan_file, plan),
        prov=prov, cfg=s.get("config") or {}, versions=", ".join(f"{k} {v}" for k, v in
                                                                (prov.get("versions") or {}).items()),
        warnings=ep.warnings, written=time.strftime("%Y-%m-%d %H:%M:%S"))


def write_episode_report(run_dir: str | Path, *, out: str | Path | None = None,
                         warn: Callable[[str], None] | None = None) -> Path:
    """Write `report.html` (and `floorplan.png`) into a run directory; returns the page's path.

    Works on a finished run and on one still running or interrupted (the page shows the steps so far). What of
    the recording could not be read is shown on the page and told to `warn` (the command line prints it).
    """
    from vlnpilot.report.plots import episode_plan

    run_dir = Path(run_dir)
    ep = load_episode(run_dir)
    plan = episode_plan(ep)
    plan_file = None
    if plan is not None:
        plan_file = FLOORPLAN
        (run_dir / FLOORPLAN).write_bytes(plan.png())
    page = render_episode_report(ep, plan_file, plan)
    path = Path(out) if out is not None else run_dir / REPORT
    written = write_atomic(path, page)
    if warn is not None:
        for line in ep.warnings:
            warn(line)
    return written


def _stage_start(ep: Episode, entry: Entry) -> dict[str, Any] | None:
    """Stage 2 and ': find sink in bathroom' on the first step of each stage of a mission of several stages."""
    if entry.stage is None or entry.step is None:
        return None
    earlier = [e.stage for e in ep.entries[:entry.index] if e.step is not None]
    if earlier and earlier[-1] == entry.stage:
        return None
    return {"n": entry.stage, "goal": _stage_goal(ep, entry.stage)}


def _stage_goal(ep: Episode, stage: int) -> str:
    """': find sink in bathroom' for stage `stage` of the run's recorded mission, or nothing."""
    stages = (ep.summary.get("mission") or {}).get("stages") or []
    if not 1 <= stage <= len(stages):
        return ""
    s = stages[stage - 1]
    goal = f"find {s.get('target')} in {s.get('room')}" if s.get("kind") == "object" else (
        f"return to {s.get('room')}" if s.get("kind") == "return" else f"go to {s.get('room')}")
    return f": {goal}"
