"""The episode page (`write_episode_report`): a run directory as a step-by-step player with the floor plan."""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vlnpilot.fileio import write_atomic
from vlnpilot.report.page import (
    FLOORPLAN,
    REPORT,
    _command_text,
    _cost,
    _fact,
    _image_size,
    _int,
    _num,
    _page,
    _room_chip,
    _state_badge,
    esc,
    static_text,
)
from vlnpilot.report.timeline import Entry, Episode, load_episode

EPISODE_JS = static_text("episode.js")


def _episode_header(ep: Episode, colors: Mapping[str, str]) -> str:
    s, r, task, scene = ep.summary, ep.result, ep.task, ep.scene
    outcome = r.get("outcome") or s.get("status") or "running"
    cfg = s.get("config") or {}
    calls = r.get("pilot_calls") or 0
    latency = r.get("latency_s_total")
    mean_latency = latency / calls if isinstance(latency, int | float) and calls else None
    spawn = s.get("spawn")
    spawn_room = None
    if scene is not None and spawn:
        try:
            spawn_room = scene.spawn(spawn).room
        except Exception:  # noqa: BLE001 - an unknown spawn only loses the colour swatch
            spawn_room = None
    goal = _room_chip(scene, task.get("goal_room"))
    if task.get("goal_target"):
        goal = f"{esc(task['goal_target'])} <small>in</small> {goal}"
    facts = [
        _fact("Spawn", _room_chip(scene, spawn_room) if spawn_room else esc(spawn or "–"),
              esc(spawn) if spawn_room and spawn_room != spawn else ""),
        _fact("Goal", goal),
        _fact("Pilot", f"<code>{esc(s.get('pilot') or s.get('pilot_name') or '–')}</code>"),
        _fact("Model", esc(s.get("model") or "–")),
        _fact("Steps", f"{_int(r.get('steps', len(ep.steps)))}", f"of {_int(cfg.get('max_steps'))}"
              if cfg.get("max_steps") else ""),
        _fact("Path length", _num(r.get("path_length_m"), 2, " m"),
              f"shortest {_num(r.get('shortest_path_m'), 2, ' m')} · SPL {_num(r.get('spl'), 2)}"
              if "shortest_path_m" in r else ""),
        _fact("Collisions", _int(r.get("collisions", sum(1 for x in ep.steps if x.get("collided")))),
              esc(r.get("contact") or "")),
        _fact("Invalid decisions", _int(r.get("invalid_decisions")),
              f"{_int(r.get('oscillations'))} oscillations" if "oscillations" in r else ""),
        _fact("Tokens", f"{_int(r.get('input_tokens'))} in · {_int(r.get('output_tokens'))} out",
              f"{_int(r.get('cached_tokens'))} cached" if r.get("cached_tokens") else ""),
        _fact("Cost", _cost(r.get("cost_usd"))),
        _fact("Model latency", _num(latency, 1, " s"),
              f"{_num(mean_latency, 2, ' s')} per call, {_int(calls)} calls" if calls else ""),
        _fact("Wall time", _num(r.get("wall_time_s"), 1, " s")),
    ]
    safety = s.get("safety") or {}
    shield = r.get("shield") or safety.get("shield") or (s.get("config") or {}).get("shield")
    n_int = r.get("interventions", sum(len(e.interventions) for e in ep.entries))
    n_osc = r.get("oscillation_events", sum(1 for e in ep.entries if e.oscillation_event))
    if shield is not None or n_int or n_osc:
        facts.append(_fact("Safety layer", esc(shield or "–"),
                           f"{_int(n_int)} intervention{'s' if n_int != 1 else ''} · {_int(n_osc)} oscillation "
                           f"event{'s' if n_osc != 1 else ''}"))
    files = [f'<a href="{n}">{n}</a>' for n in ("episode.mp4", "episode.gif", "summary.json", "episode.jsonl",
                                                  FLOORPLAN) if (ep.run_dir / n).is_file()]
    return f"""<header class="card hero">
<div class="eyebrow">VLN-Pilot · episode report · scene {esc(s.get('scene') or '–')} · {esc(ep.run_dir.name)}</div>
<h1>“{esc(task.get('query') or '')}”</h1>
<div><span class="outcome {esc(outcome)}">{esc(outcome.replace('_', ' '))}</span>
<span class="reason">{esc(r.get('reason') or '')}</span></div>
<dl class="facts">{''.join(facts)}</dl>
<div class="files">Files: {' '.join(files)}</div>
</header>"""


def _frame(ep: Episode, entry: Entry, view: str, caption: str) -> str:
    rel = entry.frames.get(view)
    if not rel and view == "rear" and (ep.summary.get("capabilities") or {}).get("rear_view") is False:
        return (f'<figure><div class="noframe">this robot has no rear camera</div>'  # a real Tello
                f'<figcaption>{caption}</figcaption></figure>')
    if not rel:
        return (f'<figure><div class="noframe">no {esc(view)} frame recorded</div>'
                f'<figcaption>{caption}</figcaption></figure>')
    size = _image_size(ep.run_dir / rel)
    dims = f' width="{size[0]}" height="{size[1]}"' if size else ""
    alt = f"{view} camera, {entry.label.lower()}"
    return (f'<figure><img src="{esc(rel)}" alt="{esc(alt)}"{dims} decoding="async">'
            f'<figcaption>{caption}</figcaption></figure>')


SOURCES = {"shield": "shield", "door_assist": "door assist", "oscillation_guard": "oscillation guard"}
SHORT_SOURCES = {"shield": "shield", "door_assist": "assist", "oscillation_guard": "guard"}


def _intervention_html(item: Any) -> str:
    """One change the safety layer made: '[shield] A2 → A1 reason' (other shapes shown as key: value)."""
    if not isinstance(item, Mapping):
        return f'<li class="shield"><span class="tag info">safety</span>{esc(item)}</li>'
    source = SOURCES.get(str(item.get("source")), str(item.get("source") or "safety"))
    if "proposed" in item and "executed" in item:
        text = (f"<code>{esc(item['proposed'])}</code> → <code>{esc(item['executed'])}</code> "
                f"{esc(_command_text(item.get('executed')))}")
        if item.get("reason"):
            text += f": {esc(item['reason'])}"
    else:
        text = " · ".join(f"{esc(k)}: {esc(v)}" for k, v in item.items() if k not in ("source", "step"))
    return f'<li class="shield"><span class="tag info">{esc(source)}</span>{text}</li>'


def _step_notes(entry: Entry) -> str:
    items = []
    for f in entry.failures:
        raw = f.get("raw_text")
        raw_html = (f"<details><summary>rejected answer</summary><pre>{esc(raw)}</pre></details>" if raw else "")
        items.append(f'<li class="fail"><span class="tag warn">re-ask {esc(int(f.get("attempt", 0)) + 1)}</span>'
                     f'{esc(f.get("reason"))}{raw_html}</li>')
    items += [_intervention_html(item) for item in entry.interventions]
    if (not entry.interventions and entry.step is not None and entry.proposed and entry.executed
            and entry.proposed != entry.executed):
        items.append(f'<li class="shield"><span class="tag info">changed</span>proposed <code>{esc(entry.proposed)}'
                     f'</code>, executed <code>{esc(entry.executed)}</code></li>')
    ev = entry.oscillation_event
    if ev:
        acted = "the guard acted" if ev.get("acted") else "detected only (safety layer off)"
        items.append(f'<li class="osc"><span class="tag">oscillation event</span>{esc(ev.get("reversals"))} '
                     f'reversals in {esc(ev.get("window"))} steps in {esc(ev.get("state"))}; {esc(acted)}'
                     f'{": " + esc(ev.get("action")) if ev.get("action") else ""}</li>')
    for note in entry.feedback:
        items.append(f'<li class="feedback"><span class="tag">to the pilot</span>{esc(note)}</li>')
    if entry.collided and entry.step is not None:
        items.append(f'<li class="collision"><span class="tag bad">collision</span>this move touched '
                     f'{esc(entry.contact or "an obstacle")}</li>')
    if entry.oscillation:
        items.append('<li class="osc"><span class="tag">reversal</span>this move reverses the previous one</li>')
    return f'<ul class="notes">{"".join(items)}</ul>' if items else ""


def _true_room_mark(scene: Any, said: str | None, true_room: str | None) -> str:
    if scene is None or not said or not true_room:
        return ""
    found = scene.find_room(said)
    if found is not None and found.id == true_room:
        return ' <span class="tag ok">matches</span>'
    return ' <span class="tag bad">differs</span>'


def _entry_html(ep: Episode, entry: Entry, colors: Mapping[str, str], plan_pos: tuple[float, float] | None,
                plan_size: tuple[int, int] | None, total: int) -> str:
    scene = ep.scene
    attrs = [f'id="{"step-" + str(entry.step) if entry.step is not None else "end"}"',
             f'data-index="{entry.index}"', f'data-label="{esc(entry.label)}"']
    if plan_pos is not None and plan_size is not None:
        attrs += [f'data-x="{100 * plan_pos[0] / plan_size[0]:.3f}"',
                  f'data-y="{100 * plan_pos[1] / plan_size[1]:.3f}"',
                  f'data-yaw="{float((entry.pose or {}).get("yaw_deg", 0.0)):.1f}"']
    cls = "step current" if entry.index == 0 else "step"
    seen = "seen by the pilot" if entry.step is not None else "final view"
    frames = (f'<div class="frames">{_frame(ep, entry, "front", f"Front camera · {seen}")}'
              f'{_frame(ep, entry, "rear", "Rear camera")}</div>')
    pose = entry.pose or {}
    pose_txt = (f"x {_num(pose.get('x'))} m, y {_num(pose.get('y'))} m, yaw {_num(pose.get('yaw_deg'), 0)}°"
                if pose else "–")
    if entry.step is None:
        r = ep.result
        outcome = r.get("outcome") or ep.summary.get("status") or "running"
        title = (f'<div class="steptitle"><strong>End</strong><span class="outcome {esc(outcome)}">'
                 f'{esc(outcome.replace("_", " "))}</span> {_state_badge(entry.state, colors)}</div>')
        kv = [("Reason", esc(r.get("reason") or "–")), ("Final room", _room_chip(scene, entry.room_true)),
              ("Final pose", pose_txt)]
        body = "".join(f"<div><dt>{k}</dt><dd>{v}</dd></div>" for k, v in kv)
        return (f'<article class="{cls}" {" ".join(attrs)}>{title}{frames}<div class="details"><dl class="kv">'
                f'{body}</dl>{_step_notes(entry)}</div></article>')

    d = entry.decision or {}
    title = (f'<div class="steptitle"><strong>Step {entry.step}</strong><span class="hint">of {total}</span>'
             f'{_state_badge(entry.state, colors)}<span class="arrow">→</span>'
             f'{_state_badge(entry.next_state, colors)}</div>')
    if entry.decision is None:
        title += '<div><span class="tag warn">no valid decision: the drone hovered</span></div>' if entry.executed \
            else '<div><span class="tag bad">pilot error: the episode stopped</span></div>'
    move = "–"
    if entry.proposed or entry.executed:
        move = f"<code>{esc(entry.proposed or '–')}</code> {esc(_command_text(entry.proposed))}"
    executed = f"<code>{esc(entry.executed)}</code> {esc(_command_text(entry.executed))}" if entry.executed else "–"
    u = entry.usage
    tokens = (f"{_int(u.get('input_tokens'))} in · {_int(u.get('output_tokens'))} out"
              + (f" · {_int(u.get('cached_tokens'))} cached" if u.get("cached_tokens") else "")) if u else "–"
    kv = [
        ("Movement", move),
        ("Executed", executed),
        ("Room (model)", f"{esc(d.get('room') or '–')}{_true_room_mark(scene, d.get('room'), entry.room_true)}"),
        ("Room (true)", _room_chip(scene, entry.room_true)),
        ("Door position", esc(d.get("door_position") or "–")),
        ("Latency", _num(u.get("latency_s"), 2, " s") if u else "–"),
        ("Tokens", tokens),
        ("Cost", _cost(u.get("cost_usd")) if u else "–"),
        ("Pose", pose_txt),
    ]
    body = "".join(f"<div><dt>{k}</dt><dd>{v}</dd></div>" for k, v in kv)
    desc = f'<p class="desc">{esc(d.get("description"))}</p>' if d.get("description") else ""
    raw = (f"<details><summary>raw model answer</summary><pre>{esc(entry.raw_text)}</pre></details>"
           if entry.raw_text else "")
    extra = (f"<details><summary>other recorded fields</summary><pre>{esc(json.dumps(entry.extra, indent=2))}"
             f"</pre></details>" if entry.extra else "")
    return (f'<article class="{cls}" {" ".join(attrs)}>{title}{frames}<div class="details">{desc}<dl class="kv">'
            f'{body}</dl>{_step_notes(entry)}{raw}{extra}</div></article>')


def _strip(ep: Episode, colors: Mapping[str, str]) -> str:
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
        cls = " ".join(flags + (["current"] if e.index == 0 else []))
        color = colors.get(e.shown_state, "#c5cad3")
        tip = f"{e.label}: {e.shown_state}" + (f" · {e.executed}" if e.executed else "")
        text = str(e.step) if e.step is not None else "■"
        chips.append(f'<li><button type="button" class="{cls}" style="--c:{esc(color)}" title="{esc(tip)}" '
                     f'aria-label="{esc(tip)}">{text}</button></li>')
    return f'<ol class="strip" aria-label="steps">{"".join(chips)}</ol>'


def _steps_table(ep: Episode, colors: Mapping[str, str]) -> str:
    rows = []
    stage = None
    for e in ep.entries:
        if e.step is None:
            continue
        if e.stage is not None and e.stage != stage:  # a mission's stage boundary
            stage = e.stage
            goal = _stage_goal(ep, stage)
            rows.append(f'<tr class="stage-start"><td colspan="10"><strong>Stage {stage}</strong>{goal}</td></tr>')
        d = e.decision or {}
        notes = []
        if e.failures:
            notes.append(f'<span class="tag warn">{len(e.failures)} re-ask{"s" if len(e.failures) > 1 else ""}</span>')
        if e.decision is None:
            notes.append('<span class="tag warn">no decision</span>')
        for item in e.interventions:
            src = item.get("source") if isinstance(item, Mapping) else None
            notes.append(f'<span class="tag info">{esc(SHORT_SOURCES.get(str(src), src or "safety"))}</span>')
        if e.oscillation_event:
            notes.append('<span class="tag" title="oscillation event">osc. event</span>')
        if e.collided:
            notes.append('<span class="tag bad">collision</span>')
        if e.oscillation:
            notes.append('<span class="tag" title="this move reverses the previous one">reversal</span>')
        u = e.usage or {}
        move = esc(e.proposed or "–")
        if e.executed and e.executed != e.proposed:
            move += f" → {esc(e.executed)}"
        rows.append(
            f'<tr data-index="{e.index}"{" class=current" if e.index == 0 else ""}><td class="num">{e.step}</td>'
            f'<td>{_state_badge(e.state, colors)}</td><td>{_state_badge(e.next_state, colors)}</td>'
            f'<td class="c"><code>{move}</code></td>'
            f'<td class="text short" title="{esc(d.get("room"))}">{esc(d.get("room") or "–")}</td>'
            f'<td>{esc(d.get("door_position") or "–")}</td>'
            f'<td class="text" title="{esc(d.get("description"))}">{esc(d.get("description") or "")}</td>'
            f'<td class="num">{_num(u.get("latency_s"), 2)}</td>'
            f'<td class="num">{_int(u.get("input_tokens", 0) + u.get("output_tokens", 0)) if u else "–"}</td>'
            f'<td>{"".join(notes)}</td></tr>')
    head = ('<tr><th class="num">#</th><th>State</th><th>Next state</th><th class="c">Move</th><th>Room (model)</th>'
            '<th>Door</th><th>Description</th><th class="num">Latency [s]</th><th class="num">Tokens</th>'
            '<th>Notes</th></tr>')
    return (f'<section class="card"><h2>All steps</h2><div class="tablewrap"><table class="steps">'
            f'<thead>{head}</thead><tbody>{"".join(rows)}</tbody></table></div></section>')


def _stage_goal(ep: Episode, stage: int) -> str:
    """': find sink in bathroom' for stage `stage` of the run's recorded mission, or nothing."""
    stages = (ep.summary.get("mission") or {}).get("stages") or []
    if not 1 <= stage <= len(stages):
        return ""
    s = stages[stage - 1]
    goal = f"find {s.get('target')} in {s.get('room')}" if s.get("kind") == "object" else (
        f"return to {s.get('room')}" if s.get("kind") == "return" else f"go to {s.get('room')}")
    return f": {esc(goal)}"


def _plan_legend(colors: Mapping[str, str], has_collision: bool) -> str:
    items = [_state_badge(s, colors) for s in colors]
    items.append('<span class="mark">□ start</span>')
    items.append('<span class="mark">◎ current position and heading</span>')
    if has_collision:
        items.append('<span class="mark" style="color:#c0392b">✖ collision</span>')
    items.append('<span class="mark">hatched: goal room · ★ targets</span>')
    return f'<div class="legend">{"".join(items)}</div>'


def _footer(ep: Episode) -> str:
    s = ep.summary
    prov = s.get("provenance") or {}
    cfg = s.get("config") or {}
    versions = ", ".join(f"{k} {v}" for k, v in (prov.get("versions") or {}).items())
    bits = [f"started {esc(prov.get('started_at') or '–')}", f"git <code>{esc(prov.get('git_sha') or '–')}</code>",
            f"prompt <code>{esc(prov.get('prompt_hash') or '–')}</code>",
            f"profile {esc(cfg.get('profile') or '–')}", f"seed {esc(cfg.get('seed'))}",
            f"max re-asks {esc(cfg.get('max_reasks'))}", esc(versions),
            f"report written {time.strftime('%Y-%m-%d %H:%M:%S')}"]
    return f"<footer>{' · '.join(b for b in bits if b)}</footer>"


def render_episode_report(ep: Episode, plan_file: str | None, plan: Any | None) -> str:
    """The episode page as a string (`plan` is a `plots.PlanImage` written to `plan_file`, or None)."""
    colors = dict(plan.state_colors) if plan is not None else {}
    fallback = ("#1f77b4", "#ff7f0e", "#9467bd", "#17becf", "#8c564b", "#e377c2", "#bcbd22", "#7f7f7f")
    for e in ep.entries:  # states that never reached the plan (e.g. without a scene) still get a colour
        for st in (e.state, e.next_state):
            if st and st not in colors:
                colors[st] = fallback[len(colors) % len(fallback)]
    total = len(ep.entries) - 1
    plan_size = plan.size if plan is not None else None
    entries = "".join(_entry_html(ep, e, colors, plan.positions[e.index] if plan is not None else None, plan_size,
                                  total) for e in ep.entries)
    if plan is not None and plan_file:
        first = ep.entries[0]
        p0 = plan.positions[0]
        style = (f"left:{100 * p0[0] / plan_size[0]:.3f}%;top:{100 * p0[1] / plan_size[1]:.3f}%;"
                 f"--yaw:{-float((first.pose or {}).get('yaw_deg', 0.0)):.1f}deg") if p0 else ""
        plan_html = (f'<div class="planwrap"><img src="{esc(plan_file)}" alt="floor plan with the trajectory" '
                     f'width="{plan_size[0]}" height="{plan_size[1]}"><div id="cursor" class="cursor" '
                     f'style="{style}"></div></div>{_plan_legend(colors, ep.collision_point() is not None)}')
    else:
        plan_html = ('<div class="noframe" style="aspect-ratio:2/1">no floor plan: the scene is not a built-in one'
                     '</div>')
    toolbar = (f'<div class="toolbar"><button type="button" id="first" title="first (Home)">«</button>'
               f'<button type="button" id="prev" title="previous (←)">◀</button>'
               f'<span class="position" id="position">{esc(ep.entries[0].label)} of {len(ep.entries)}</span>'
               f'<button type="button" id="next" title="next (→)">▶</button>'
               f'<button type="button" id="last" title="last (End)">»</button>'
               f'<input type="range" id="slider" min="0" max="{len(ep.entries) - 1}" value="0" '
               f'aria-label="step">'
               f'<span class="hint"><kbd>←</kbd> <kbd>→</kbd> step · <kbd>Home</kbd> <kbd>End</kbd></span></div>')
    body = (f"{_episode_header(ep, colors)}\n"
            f'<section class="card" id="player" data-current="0" data-count="{len(ep.entries)}">'
            f"<h2>Step by step</h2>{toolbar}{_strip(ep, colors)}"
            f'<div class="player">{entries}'
            f'<aside>{plan_html}</aside></div></section>\n'
            f"{_steps_table(ep, colors)}\n{_footer(ep)}")
    query = ep.task.get("query") or "episode"
    return _page(f"{query} · {ep.result.get('outcome', 'running')} · VLN-Pilot", body, EPISODE_JS)


def write_episode_report(run_dir: str | Path, *, out: str | Path | None = None) -> Path:
    """Write `report.html` (and `floorplan.png`) into a run directory; returns the page's path.

    Works on a finished run and on one still running or interrupted (the page shows the steps so far).
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
    return write_atomic(path, page)
