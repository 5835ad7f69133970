"""HTML reports: one page per episode (`write_episode_report`) and one per benchmark (`write_bench_report`).

Both pages open from disk with no server and no network: CSS and JavaScript are inline, images are files
beside the page referenced by relative paths (the frames the recorder already wrote, `floorplan.png`,
`plots/*.png`). Relative paths keep a 50-step page at a few tens of kB instead of duplicating megabytes of
JPEG as base64, and the run directory stays the unit that is copied or archived. Everything a model wrote
(decisions, descriptions, raw answers, error messages) is untrusted and HTML-escaped; the page's script only
moves CSS classes and reads numbers from data attributes, it never parses model text.
"""

from __future__ import annotations

import html
import json
import math
import os
import time
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlnpilot.errors import ConfigError, VLNPilotError
from vlnpilot.fileio import write_atomic
from vlnpilot.report.timeline import Entry, Episode, load_episode, load_scene_or_none

REPORT = "report.html"
FLOORPLAN = "floorplan.png"
RESULTS = "results.jsonl"
PLOTS = "plots"


def esc(value: Any) -> str:
    """HTML-escape anything (None as an empty string), quotes included so it is safe in attributes too."""
    return "" if value is None else html.escape(str(value), quote=True)


# -- formatting -----------------------------------------------------------------------------------------
def _num(value: Any, digits: int = 2, unit: str = "") -> str:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return "–"
    return f"{value:,.{digits}f}{unit}"


def _int(value: Any) -> str:
    return f"{int(value):,}" if isinstance(value, int | float) and math.isfinite(value) else "–"


def _cost(value: Any) -> str:
    if not isinstance(value, int | float):
        return "–"
    return f"${value:.4f}" if value < 1 else f"${value:,.2f}"


def _css_rgb(color: Iterable[float] | None) -> str:
    if not color:
        return "#ccc"
    r, g, b = (int(round(255 * c)) for c in list(color)[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def _command_text(code: str | None) -> str:
    if not code:
        return ""
    from vlnpilot.commands import COMMANDS

    cmd = COMMANDS.get(str(code).strip().upper())
    return cmd.description if cmd is not None else "not a command"


def _image_size(path: Path) -> tuple[int, int] | None:
    from PIL import Image

    try:
        with Image.open(path) as im:
            return im.size
    except OSError:
        return None


def _room_chip(scene: Any, room_id: str | None) -> str:
    """A room name with a swatch of its floor-plan colour (the paper's colours); plain text when unknown."""
    room = scene.find_room(room_id) if scene is not None and room_id else None
    if room is None:
        return esc(room_id or "–")
    return f'<span class="room" style="--room:{_css_rgb(room.color)}">{esc(room.name)}</span>'


# -- shared page frame ----------------------------------------------------------------------------------
CSS = """
:root{--bg:#f5f6f8;--card:#fff;--ink:#1d2330;--muted:#5f6b7a;--line:#e2e5ea;--accent:#2b5fab;
--ok:#2f9e63;--warn:#e5a50a;--bad:#d1495b;--info:#5b7fbf;--err:#8e6bbf;--radius:10px;
--mono:ui-monospace,"SFMono-Regular","DejaVu Sans Mono","Liberation Mono",Menlo,monospace}
*{box-sizing:border-box}
html{-webkit-text-size-adjust:100%}
body{margin:0;background:var(--bg);color:var(--ink);font:15px/1.5 system-ui,-apple-system,"Segoe UI",Roboto,
"Helvetica Neue","Liberation Sans","DejaVu Sans",Arial,sans-serif}
main{max-width:1440px;margin:0 auto;padding:24px 28px 48px}
h1{font-size:26px;line-height:1.25;margin:2px 0 10px;font-weight:650;letter-spacing:-.01em}
h2{font-size:16px;margin:0 0 12px;font-weight:650}
h3{font-size:13px;margin:14px 0 6px;text-transform:uppercase;letter-spacing:.06em;color:var(--muted)}
a{color:var(--accent)}
code,.mono{font-family:var(--mono);font-size:.92em}
.eyebrow{font-size:12px;text-transform:uppercase;letter-spacing:.08em;color:var(--muted)}
.card{background:var(--card);border:1px solid var(--line);border-radius:var(--radius);padding:18px 20px;
margin:0 0 20px;box-shadow:0 1px 2px rgba(20,30,50,.04)}
.hero{padding:22px 24px}
.outcome{display:inline-block;padding:2px 10px;border-radius:999px;font-weight:650;font-size:13px;color:#fff;
vertical-align:middle;background:var(--muted)}
.outcome.success{background:var(--ok)}.outcome.false_success{background:var(--warn)}
.outcome.collision{background:var(--bad)}.outcome.max_steps{background:var(--info)}
.outcome.pilot_error{background:var(--err)}.outcome.aborted{background:#555}
.reason{color:var(--muted);margin-left:8px}
.facts{display:grid;grid-template-columns:repeat(auto-fill,minmax(170px,1fr));gap:10px 18px;margin:16px 0 0}
.facts div{border-left:3px solid var(--line);padding-left:10px}
.facts dt{font-size:12px;color:var(--muted);text-transform:uppercase;letter-spacing:.05em}
.facts dd{margin:0;font-weight:600;font-variant-numeric:tabular-nums}
.facts .room{white-space:normal}
.facts dd small{font-weight:400;color:var(--muted)}
.files{margin-top:14px;font-size:13px;color:var(--muted)}
.files a{margin-right:12px}
.room{white-space:nowrap}
.room::before{content:"";display:inline-block;width:.8em;height:.8em;border-radius:3px;background:var(--room);
margin-right:.35em;vertical-align:-.05em;border:1px solid rgba(0,0,0,.25)}
.state{display:inline-block;padding:1px 8px;border-radius:6px;font-size:13px;font-weight:600;white-space:nowrap;
background:color-mix(in srgb,var(--c,#999) 18%,white);border:1px solid color-mix(in srgb,var(--c,#999) 60%,white)}
.state::before{content:"";display:inline-block;width:.6em;height:.6em;border-radius:50%;background:var(--c,#999);
margin-right:.4em;vertical-align:.05em}
.toolbar{display:flex;align-items:center;gap:8px;flex-wrap:wrap;margin-bottom:10px}
.toolbar button{font:inherit;font-size:14px;border:1px solid var(--line);background:#fff;border-radius:7px;
padding:4px 11px;cursor:pointer;color:var(--ink)}
.toolbar button:hover{border-color:var(--accent);color:var(--accent)}
.toolbar .position{font-weight:650;min-width:120px;text-align:center;font-variant-numeric:tabular-nums}
.toolbar input[type=range]{flex:1;min-width:160px;accent-color:var(--accent)}
.hint{font-size:12px;color:var(--muted)}
kbd{font-family:var(--mono);font-size:11px;border:1px solid #ccd;border-bottom-width:2px;border-radius:4px;
padding:0 4px;background:#fafbfc}
.strip{display:flex;flex-wrap:wrap;gap:3px;margin:0 0 16px;padding:0;list-style:none}
.strip button{width:24px;height:22px;border-radius:4px;border:1px solid rgba(0,0,0,.12);background:var(--c,#bbb);
font:10px/1 var(--mono);color:#111;cursor:pointer;padding:0;position:relative;opacity:.8}
.strip button.flag-fail::after,.strip button.flag-shield::after{content:"";position:absolute;top:-3px;right:-3px;
width:7px;height:7px;border-radius:50%;background:var(--warn);border:1px solid #fff}
.strip button.flag-shield::after{background:var(--accent)}
.strip button.flag-collision{outline:2px solid var(--bad);outline-offset:1px}
.strip button.current{opacity:1;outline:2px solid var(--ink);outline-offset:1px;transform:translateY(-2px)}
.player{display:grid;grid-template-columns:minmax(0,1.5fr) minmax(0,1fr);column-gap:20px;align-items:start;
grid-template-areas:"title title" "frames plan" "details details"}
.player>aside{grid-area:plan}
.step>.steptitle{grid-area:title}.step>.frames{grid-area:frames}.step>.details{grid-area:details}
.no-js .player{display:block}
.frames{display:grid;grid-template-columns:1fr 1fr;gap:10px}
figure{margin:0}
figure img{width:100%;height:auto;display:block;border-radius:6px;background:#ddd}
figcaption{font-size:12px;color:var(--muted);margin-top:3px}
.noframe{aspect-ratio:4/3;display:flex;align-items:center;justify-content:center;background:#eceef2;
border-radius:6px;color:var(--muted);font-size:13px}
.js .step{display:none}
.js .step.current{display:contents}
.no-js .step{border-top:1px solid var(--line);padding-top:12px;margin-top:12px}
.steptitle{display:flex;align-items:center;gap:8px;flex-wrap:wrap;margin:0 0 10px}
.details{margin-top:14px;padding-top:14px;border-top:1px solid var(--line)}
.kv{display:grid;grid-template-columns:repeat(auto-fill,minmax(210px,1fr));gap:10px 18px;margin:0}
.kv div{min-width:0}
.kv dt{font-size:12px;color:var(--muted);text-transform:uppercase;letter-spacing:.05em}
.kv dd{margin:0;overflow-wrap:anywhere}
.steptitle strong{font-size:17px}
.arrow{color:var(--muted)}
.desc{margin:0 0 12px;padding:8px 12px;background:#f7f8fa;border-left:3px solid var(--accent);border-radius:4px;
font-style:italic;overflow-wrap:anywhere;white-space:pre-wrap}
.tag{display:inline-block;font-size:12px;font-weight:600;padding:0 7px;border-radius:5px;margin-right:4px;
background:#eef1f6;color:var(--ink);white-space:nowrap}
.tag.bad{background:#fbe4e7;color:#8f1d2c}.tag.warn{background:#fdf1d3;color:#7a5600}
.tag.ok{background:#e1f3e9;color:#1d6b41}.tag.info{background:#e4ebf7;color:#23467f}
.notes{margin:10px 0 0;padding:0;list-style:none;font-size:14px}
.notes li{padding:6px 10px;border-radius:6px;margin-bottom:6px;overflow-wrap:anywhere}
.notes li.fail{background:#fdf5e1}.notes li.shield{background:#e9effa}.notes li.collision{background:#fbe8ea}
.notes li.osc{background:#f1ecf8}.notes li.feedback{background:#f3f4f6}
details{margin-top:8px;font-size:13px}
summary{cursor:pointer;color:var(--accent)}
pre{white-space:pre-wrap;overflow-wrap:anywhere;background:#f7f8fa;border:1px solid var(--line);border-radius:6px;
padding:8px 10px;font:12px/1.45 var(--mono);max-height:320px;overflow:auto;margin:6px 0 0}
.planwrap{position:relative;line-height:0}
.planwrap img{width:100%;height:auto;border-radius:6px;border:1px solid var(--line)}
.cursor{position:absolute;width:22px;height:22px;border-radius:50%;border:3px solid #e11d48;
background:rgba(255,255,255,.55);box-shadow:0 0 0 3px rgba(255,255,255,.85);pointer-events:none;
transform:translate(-50%,-50%) rotate(var(--yaw,0deg));transition:left .15s,top .15s}
.cursor::after{content:"";position:absolute;left:50%;top:50%;width:22px;height:3px;background:#e11d48;
transform-origin:0 50%;transform:translateY(-50%)}
.legend{display:flex;flex-wrap:wrap;gap:6px 10px;margin-top:10px;font-size:12px;line-height:1.4}
.legend .state{font-size:12px}
.legend .mark{color:var(--muted)}
table{border-collapse:collapse;width:100%;font-size:13.5px;font-variant-numeric:tabular-nums}
th,td{padding:6px 8px;border-bottom:1px solid var(--line);text-align:left;vertical-align:top}
th{font-size:12px;text-transform:uppercase;letter-spacing:.04em;color:var(--muted);font-weight:600;
background:#fafbfc;position:sticky;top:0}
td.num,th.num{text-align:right}
td.num{white-space:nowrap}
td.c,th.c{text-align:center}
tbody tr:hover{background:#f6f8fb}
.steps tr{cursor:pointer}
.steps tr.current{background:#eaf1fb}
.steps td.text{max-width:300px;overflow:hidden;text-overflow:ellipsis;white-space:nowrap}
.steps td.short{max-width:150px}
.steps td.c,.steps td.num{white-space:nowrap}
.tablewrap{overflow:auto;max-height:520px;border:1px solid var(--line);border-radius:8px}
#episodes td{white-space:nowrap}#episodes td:nth-child(3){white-space:normal}
#pilots{font-size:13px}#pilots th,#pilots td{padding:6px 6px}#pilots td:nth-child(2){white-space:nowrap}
.grid2{display:grid;grid-template-columns:1fr 1fr;gap:20px}
.plot img{width:100%;height:auto;display:block}
.plot figcaption a{margin-left:6px}
.t4 th,.t4 td{text-align:center}
.t4 td.q,.t4 th.q{text-align:left}
.t4 td.start{font-weight:600;text-align:left;vertical-align:middle}
.t4 th.pilot{border-left:2px solid var(--line)}
.t4 td.first{border-left:2px solid var(--line)}
.t4 tbody tr.group td{border-top:2px solid #cfd4dc}
.dash{color:#aab}
footer{font-size:12px;color:var(--muted);margin-top:8px}
footer code{font-size:11px}
@media (max-width:980px){.player,.grid2{grid-template-columns:1fr}
.player{grid-template-areas:"title" "frames" "plan" "details"}main{padding:14px}}
@media print{.toolbar,.strip,.hint{display:none}.js .step{display:block}}
"""

EPISODE_JS = """
(function(){
  var root=document.documentElement; root.classList.remove('no-js'); root.classList.add('js');
  var steps=[].slice.call(document.querySelectorAll('.step'));
  if(!steps.length) return;
  var chips=[].slice.call(document.querySelectorAll('.strip button'));
  var rows=[].slice.call(document.querySelectorAll('.steps tr[data-index]'));
  var player=document.getElementById('player'), slider=document.getElementById('slider');
  var pos=document.getElementById('position'), cursor=document.getElementById('cursor');
  var cur=0;
  function mark(list,i,on){ if(list[i]) list[i].classList.toggle('current',on); }
  function show(i,updateHash){
    i=Math.max(0,Math.min(steps.length-1,i|0));
    [steps,chips,rows].forEach(function(l){mark(l,cur,false);mark(l,i,true);});
    cur=i; player.setAttribute('data-current',String(i)); slider.value=String(i);
    var s=steps[i]; pos.textContent=s.getAttribute('data-label')+' of '+steps.length;
    if(cursor){
      var x=s.getAttribute('data-x'), y=s.getAttribute('data-y');
      if(x!==null&&y!==null){ cursor.style.left=x+'%'; cursor.style.top=y+'%';
        cursor.style.setProperty('--yaw',(-parseFloat(s.getAttribute('data-yaw')||'0'))+'deg'); cursor.hidden=false; }
      else { cursor.hidden=true; }
    }
    if(updateHash){ try{ history.replaceState(null,'','#'+s.id); }catch(e){} }
  }
  document.addEventListener('keydown',function(e){
    if(e.altKey||e.ctrlKey||e.metaKey||e.shiftKey) return;
    var t=e.target, tag=t&&t.tagName;
    if(tag==='TEXTAREA'||tag==='SELECT'||(tag==='INPUT'&&t.type!=='range')||t===slider) return;
    var k=e.key, n=null;
    if(k==='ArrowRight') n=cur+1; else if(k==='ArrowLeft') n=cur-1;
    else if(k==='Home') n=0; else if(k==='End') n=steps.length-1;
    if(n===null) return;
    e.preventDefault(); show(n,true);
  });
  slider.addEventListener('input',function(){ show(parseInt(slider.value,10),true); });
  document.getElementById('prev').addEventListener('click',function(){ show(cur-1,true); });
  document.getElementById('next').addEventListener('click',function(){ show(cur+1,true); });
  document.getElementById('first').addEventListener('click',function(){ show(0,true); });
  document.getElementById('last').addEventListener('click',function(){ show(steps.length-1,true); });
  chips.forEach(function(c,i){ c.addEventListener('click',function(){ show(i,true); }); });
  rows.forEach(function(r){ r.addEventListener('click',function(){
    show(parseInt(r.getAttribute('data-index'),10),true);
    player.scrollIntoView({behavior:'smooth',block:'start'}); }); });
  var start=0, h=decodeURIComponent(location.hash.slice(1));
  steps.forEach(function(s,i){ if(s.id===h) start=i; });
  show(start,false);
})();
"""


def _page(title: str, body: str, script: str = "") -> str:
    js = f"<script>{script}</script>" if script else ""
    return (f'<!DOCTYPE html>\n<html lang="en" class="no-js">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f'<meta name="generator" content="vln-pilot">\n<title>{esc(title)}</title>\n'
            f'<link rel="icon" href="data:,">\n<style>{CSS}</style>\n</head>\n<body>\n<main>\n{body}\n</main>\n'
            f'{js}\n</body>\n</html>\n')


def _fact(label: str, value: str, note: str = "") -> str:
    small = f" <small>{note}</small>" if note else ""
    return f"<div><dt>{esc(label)}</dt><dd>{value}{small}</dd></div>"


def _state_badge(state: str | None, colors: Mapping[str, str]) -> str:
    if not state:
        return '<span class="dash">–</span>'
    color = colors.get(state, "#9aa3ad")
    return f'<span class="state" style="--c:{esc(color)}">{esc(state)}</span>'


# -- the episode page -----------------------------------------------------------------------------------
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
        flags = []
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
    for e in ep.entries:
        if e.step is None:
            continue
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


# -- the benchmark page ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class BenchRow:
    """A row of the paper's Table 4: a (starting room, query) pair of the suite."""

    id: str
    spawn: str
    label: str  # the starting room as the tables name it
    query: str


@dataclass
class BenchData:
    """A bench directory read back: the suite's rows and pilots (from bench.json) and the finished episodes."""

    bench_dir: Path
    name: str
    description: str
    scene_name: str
    pilots: list[str]
    rows: list[BenchRow]
    records: list[dict[str, Any]]
    expected: int | None
    manifest: dict[str, Any]

    def of(self, pilot: str, row: str | None = None) -> list[dict[str, Any]]:
        return [r for r in self.records if r["pilot"] == pilot and (row is None or r["row"] == row)]

    def run_dir(self, record: Mapping[str, Any]) -> Path | None:
        raw = record.get("run_dir")
        if not raw:
            return None
        path = Path(raw)
        return path if path.is_absolute() else self.bench_dir / path

    def groups(self) -> list[tuple[str, list[BenchRow]]]:
        """Rows grouped by consecutive starting room, as the bench tables group them."""
        out: list[tuple[str, list[BenchRow]]] = []
        for row in self.rows:
            if out and out[-1][1][0].spawn == row.spawn:
                out[-1][1].append(row)
            else:
                out.append((row.label, [row]))
        return out


def load_bench(bench_dir: str | Path) -> BenchData:
    """Read a bench directory (bench.json and results.jsonl, through the bench package's own readers)."""
    from vlnpilot.bench.results import ResultsLog
    from vlnpilot.bench.runner import read_manifest
    from vlnpilot.bench.suite import suite_from_dict

    bench_dir = Path(bench_dir)
    if not (bench_dir / RESULTS).is_file():
        raise ConfigError(f"{bench_dir} is not a bench directory: {RESULTS} is missing")
    records = ResultsLog(bench_dir / RESULTS).read()
    manifest = read_manifest(bench_dir) or {}
    if manifest.get("suite"):
        suite = suite_from_dict(manifest["suite"], source=str(bench_dir / "bench.json"))
        pilots = [str(p["spec"]) for p in manifest.get("pilots", [])] or list(dict.fromkeys(r["pilot"]
                                                                                              for r in records))
        rows = [BenchRow(r.id, r.spawn, suite.spawn_label(r.spawn), r.query) for r in suite.rows]
        name, description, scene_name = suite.name, suite.description, suite.scene
        expected = manifest.get("episodes")
    else:  # results without a manifest: rows and pilots in the order they appear
        pilots = list(dict.fromkeys(str(r["pilot"]) for r in records))
        scene_name = str(next((r["scene"] for r in records if r.get("scene")), "cabin"))
        scene = load_scene_or_none(scene_name)
        rows, seen = [], set()
        for r in records:
            if r["row"] in seen:
                continue
            seen.add(r["row"])
            spawn = str(r.get("spawn") or r["row"])
            label = spawn
            if scene is not None:
                try:
                    label = scene.room(scene.spawn(spawn).room).name.title()
                except VLNPilotError:
                    pass
            rows.append(BenchRow(str(r["row"]), spawn, label, str(r.get("query") or r["row"])))
        first = {spawn: i for i, spawn in reversed(list(enumerate(x.spawn for x in rows)))}
        rows.sort(key=lambda row: first[row.spawn])  # stable: grouped by the spawn's first appearance
        name, description, expected = bench_dir.resolve().name, "", None
    known_rows = {row.id for row in rows}
    records = [r for r in records if r["pilot"] in pilots and r["row"] in known_rows]
    return BenchData(bench_dir=bench_dir, name=name, description=description, scene_name=scene_name, pilots=pilots,
                     rows=rows, records=records, expected=expected, manifest=manifest)


def _dash(v: int) -> str:
    return str(v) if v else '<span class="dash">–</span>'


def _outcome(record: Mapping[str, Any]) -> str:
    return str((record.get("result") or {}).get("outcome", "unknown"))


def _table4_html(data: BenchData) -> str:
    from vlnpilot.bench.results import cell_stats

    head1 = '<tr><th class="q" rowspan="2">Starting room</th><th class="q" rowspan="2">Query</th>' + "".join(
        f'<th class="pilot" colspan="3">{esc(p)}</th>' for p in data.pilots) + "</tr>"
    head2 = "<tr>" + "".join('<th class="pilot" title="successes / repetitions">Ach.</th>'
                             '<th title="episodes ended by a collision">Coll.</th>'
                             '<th title="episodes that reached the step limit">Steps</th>'
                             for _ in data.pilots) + "</tr>"
    body = []
    scene = load_scene_or_none(data.scene_name)
    for label, rows in data.groups():
        room = None
        if scene is not None:
            try:
                room = scene.spawn(rows[0].spawn).room
            except VLNPilotError:
                room = None
        chip = (f'<span class="room" style="--room:{_css_rgb(scene.room(room).color)}">{esc(label)}</span>'
                if room else esc(label))
        for i, row in enumerate(rows):
            tds = [f'<td class="start" rowspan="{len(rows)}">{chip}</td>'] if i == 0 else []
            tds.append(f'<td class="q">{esc(row.query)}</td>')
            for p in data.pilots:
                c = cell_stats(data.of(p, row.id))
                if not c.episodes:
                    tds.append('<td class="first ach"><span class="dash">0/0</span></td><td class="coll"></td>'
                               '<td class="steps"></td>')
                    continue
                tds.append(f'<td class="first ach">{c.successes}/{c.episodes}</td>'
                           f'<td class="coll">{_dash(c.collisions)}</td>'
                           f'<td class="steps">{_dash(c.steps_exceeded)}</td>')
            cls = ' class="group"' if i == 0 else ""
            body.append(f'<tr{cls} data-row="{esc(row.id)}">{"".join(tds)}</tr>')
    return (f'<div class="tablewrap" style="max-height:none"><table class="t4" id="table4"><thead>{head1}{head2}'
            f'</thead><tbody>{"".join(body)}</tbody></table></div>')


def _pilot_summary_html(data: BenchData) -> str:
    from vlnpilot.bench.results import summarize
    from vlnpilot.report.plots import pilot_color

    rows = []
    for i, p in enumerate(data.pilots):
        s = summarize(p, data.of(p))
        n = s.episodes
        rate = f"<strong>{s.successes}/{n}</strong> ({s.success_rate:.0%})" if n else "–"
        lat = (f"{_num(s.latency_p50_s, 2)} / {_num(s.latency_p95_s, 2)} s" if s.latency_p50_s is not None else "–")
        rows.append(
            f'<tr data-pilot="{esc(p)}"><td><span class="room" style="--room:{pilot_color(i)}"><code>{esc(p)}</code>'
            f'</span></td><td>{esc(", ".join(m for m in s.models if m != "None") or "–")}</td>'
            f'<td class="num">{n}</td><td class="num">{rate}</td>'
            f'<td class="num">{f"{s.ci_low:.0%} – {s.ci_high:.0%}" if n else "–"}</td>'
            f'<td class="num">{_num(s.spl, 2) if n else "–"}</td><td class="num">{_num(s.mean_steps, 1) if n else "–"}'
            f'</td><td class="num">{_dash(s.collisions)}</td><td class="num">{_dash(s.steps_exceeded)}</td>'
            f'<td class="num">{_dash(s.false_successes)}</td><td class="num">{_dash(s.pilot_errors)}</td>'
            f'<td class="num">{_dash(s.invalid_decisions)}</td><td class="num">{_dash(s.oscillations)}</td>'
            f'<td class="num">{_int(s.input_tokens)} / {_int(s.output_tokens)}</td>'
            f'<td class="num">{_cost(s.cost_usd)}</td><td class="num">{_cost(s.cost_usd / n) if n else "–"}</td>'
            f'<td class="num">{lat}</td></tr>')
    head = ('<tr><th>Pilot</th><th>Model</th><th class="num">Episodes</th><th class="num">Success</th>'
            '<th class="num">95% CI</th><th class="num">SPL</th><th class="num">Steps</th>'
            '<th class="num">Coll.</th><th class="num">Steps exc.</th><th class="num">False succ.</th>'
            '<th class="num">Pilot err.</th><th class="num">Invalid</th><th class="num">Osc.</th>'
            '<th class="num">Tokens in / out</th><th class="num">Cost</th><th class="num">Cost / ep.</th>'
            '<th class="num">Latency p50 / p95</th></tr>')
    return (f'<div class="tablewrap" style="max-height:none"><table id="pilots"><thead>{head}</thead>'
            f'<tbody>{"".join(rows)}</tbody></table></div>')


def _episodes_html(data: BenchData) -> str:
    from vlnpilot.bench.results import call_latencies, percentile

    order = {row.id: i for i, row in enumerate(data.rows)}
    labels = {row.id: row for row in data.rows}
    rows = []
    for rec in sorted(data.records, key=lambda r: (order[r["row"]], data.pilots.index(r["pilot"]), int(r["rep"]))):
        res = rec.get("result") or {}
        row = labels[rec["row"]]
        run_dir = data.run_dir(rec)
        link = '<span class="dash">–</span>'
        if run_dir is not None and (run_dir / REPORT).is_file():
            href = Path(os.path.relpath(run_dir / REPORT, data.bench_dir)).as_posix()
            link = f'<a href="{esc(href)}">report</a>'
        outcome = _outcome(rec)
        rows.append(
            f'<tr data-key="{esc(rec.get("key") or "")}"><td><code>{esc(rec["pilot"])}</code></td>'
            f'<td>{esc(row.label)}</td><td>{esc(row.query)}</td><td class="num">{esc(rec.get("rep"))}</td>'
            f'<td class="num mono">{esc(rec.get("seed"))}</td>'
            f'<td><span class="outcome {esc(outcome)}" style="font-size:11px">{esc(outcome.replace("_", " "))}'
            f'</span></td><td class="num">{_int(res.get("steps"))}</td>'
            f'<td class="num">{_num(res.get("path_length_m"), 2)}</td><td class="num">{_num(res.get("spl"), 2)}</td>'
            f'<td class="num">{_cost(res.get("cost_usd"))}</td>'
            f'<td class="num">{_num(percentile(call_latencies(rec), 50), 2)}</td><td>{link}</td></tr>')
    head = ('<tr><th>Pilot</th><th>Starting room</th><th>Query</th><th class="num">Rep</th><th class="num">Seed</th>'
            '<th>Outcome</th><th class="num">Steps</th><th class="num">Path [m]</th><th class="num">SPL</th>'
            '<th class="num">Cost</th><th class="num">Latency p50 [s]</th><th>Episode</th></tr>')
    return (f'<div class="tablewrap"><table id="episodes"><thead>{head}</thead><tbody>{"".join(rows)}</tbody>'
            f'</table></div>')


def bench_plots(data: BenchData, out_dir: Path) -> list[tuple[str, str, Path]]:
    """Write the benchmark's plots as PNG into `out_dir`; returns (title, caption, path) for each."""
    from vlnpilot.bench.results import call_latencies, cell_stats
    from vlnpilot.report import plots

    pilots = data.pilots
    made = []
    per_pilot = [cell_stats(data.of(p)) for p in pilots]
    made.append(("Success rate per pilot", "Share of episodes that reached the goal; whiskers: 95% Wilson score "
                 "interval.", plots.plot_success_rates(pilots, [c.successes for c in per_pilot],
                                                       [c.episodes for c in per_pilot], out_dir / "success_rate.png")))
    made.append(("Outcomes per pilot", "How the episodes ended.",
                 plots.plot_outcomes(pilots, {p: Counter(_outcome(r) for r in data.of(p)) for p in pilots},
                                     out_dir / "outcomes.png")))
    labels = [f"{row.query}\n(from {row.label})" for row in data.rows]
    cells = {p: [cell_stats(data.of(p, row.id)) for row in data.rows] for p in pilots}
    made.append(("Collisions and steps exceeded per query", "Episodes that ended in a collision or reached the step "
                 "limit, per query and starting room.",
                 plots.plot_failures_per_query(labels, pilots, {p: [c.collisions for c in cells[p]] for p in pilots},
                                               {p: [c.steps_exceeded for c in cells[p]] for p in pilots},
                                               out_dir / "failures_per_query.png")))
    cost = {p: [float((r.get("result") or {}).get("cost_usd") or 0.0) for r in data.of(p)] for p in pilots}
    lat = {p: [x for r in data.of(p) for x in call_latencies(r)] for p in pilots}
    made.append(("Cost and latency per pilot", "Left: USD per episode (bar: mean; dots: episodes). Right: latency of "
                 "each model call.", plots.plot_cost_latency(pilots, cost, lat, out_dir / "cost_latency.png")))
    return made


def render_bench_report(data: BenchData, plot_files: list[tuple[str, str, Path]]) -> str:
    """The benchmark page as a string."""
    n_ok = sum(_outcome(r) == "success" for r in data.records)
    reps = {int(r["rep"]) for r in data.records}
    files = [f'<a href="{n}">{n}</a>' for n in (RESULTS, "table.md", "table.csv", "table.tex", "summary.csv",
                                                "bench.json") if (data.bench_dir / n).is_file()]
    finished = f"{len(data.records)}" + (f" <small>of {data.expected}</small>" if data.expected else "")
    cost = sum(float((r.get("result") or {}).get("cost_usd") or 0.0) for r in data.records)
    facts = [
        _fact("Episodes", finished),
        _fact("Pilots", _int(len(data.pilots))),
        _fact("Rows", _int(len(data.rows)), "starting room × query"),
        _fact("Repetitions", _int(len(reps)) if reps else "–"),
        _fact("Successes", f"{n_ok}/{len(data.records)}"),
        _fact("Total cost", _cost(cost)),
    ]
    m = data.manifest
    if m.get("config_hash"):
        facts.append(_fact("Config hash", f"<code>{esc(m['config_hash'])}</code>"))
    sessions = m.get("sessions") or []
    if sessions:
        facts.append(_fact("Git", f"<code>{esc(str(sessions[-1].get('git_sha', '–'))[:12])}</code>"))
    header = f"""<header class="card hero">
<div class="eyebrow">VLN-Pilot · benchmark report · scene {esc(data.scene_name)} ·
{esc(data.bench_dir.resolve().name)}</div>
<h1>Suite “{esc(data.name)}”: {esc(", ".join(data.pilots) or "no pilots")}</h1>
<div class="reason" style="margin-left:0">{esc(data.description)}</div>
<dl class="facts">{"".join(facts)}</dl>
<div class="files">Files: {" ".join(files)}</div>
</header>"""
    if not data.records:
        body = header + '<section class="card"><p>No finished episodes in results.jsonl yet.</p></section>'
        return _page(f"Bench {data.name} · VLN-Pilot", body)
    figs = []
    for title, caption, path in plot_files:
        rel = Path(os.path.relpath(path, data.bench_dir)).as_posix()
        figs.append(f'<figure class="card plot"><h2>{esc(title)}</h2><img src="{esc(rel)}" alt="{esc(title)}">'
                    f'<figcaption>{esc(caption)} <a href="{esc(rel)}">PNG</a></figcaption></figure>')
    body = (f"{header}\n"
            f'<section class="card"><h2>Results by starting room and query</h2>'
            f'<p class="hint" style="margin-top:-6px">The layout of the paper\'s Table 4. Ach. = successes / '
            f'repetitions finished; Coll. = episodes ended by a collision; Steps = episodes that reached the step '
            f'limit; – = none.</p>{_table4_html(data)}</section>\n'
            f'<section class="card"><h2>Per pilot</h2>{_pilot_summary_html(data)}</section>\n'
            f'<div class="grid2">{"".join(figs[:2])}</div>\n{"".join(figs[2:])}\n'
            f'<section class="card"><h2>Episodes</h2>{_episodes_html(data)}</section>\n'
            f'<footer>report written {time.strftime("%Y-%m-%d %H:%M:%S")} from {esc(RESULTS)}</footer>')
    return _page(f"Bench {data.name}: {', '.join(data.pilots)} · VLN-Pilot", body)


def write_bench_report(bench_dir: str | Path, *, episode_reports: bool = True) -> Path:
    """Write `report.html` and `plots/*.png` into a bench directory; returns the page's path.

    With `episode_reports` (the default), runs without a `report.html` get one first, so every link works.
    """
    data = load_bench(bench_dir)
    if episode_reports:
        for rec in data.records:
            run_dir = data.run_dir(rec)
            if run_dir is not None and (run_dir / "summary.json").is_file() and not (run_dir / REPORT).is_file():
                write_episode_report(run_dir)
    plot_files = bench_plots(data, data.bench_dir / PLOTS) if data.records else []
    page = render_bench_report(data, plot_files)
    path = data.bench_dir / REPORT
    return write_atomic(path, page)
