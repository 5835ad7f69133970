// The live ground station page: a view of the run's files (over Server-Sent Events) plus control messages.
// Control messages are sent once, never queued or retried: a page that lost its connection cannot act.
"use strict";
const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.hash.slice(1)).get("token");
const steps = new Map();  // step number -> record (a reconnect replays the run: keep each step once)
let meta = null, summary = null, status = null, connected = false, ended = false;

function dl(el, rows) {  // model text is untrusted: it only ever goes into textContent
  el.replaceChildren(...rows.filter(([, v]) => v !== undefined && v !== null && v !== "").flatMap(([k, v]) => {
    const dt = document.createElement("dt"), dd = document.createElement("dd");
    dt.textContent = k; dd.textContent = String(v);
    return [dt, dd];
  }));
}

function latest() { return steps.size ? steps.get(Math.max(...steps.keys())) : null; }

function why(rec) {
  const out = [];
  if (rec.failures && rec.failures.length) out.push(`re-asked ${rec.failures.length}x: ${rec.failures.map(f => f.reason).join(" | ")}`);
  for (const i of rec.interventions || []) out.push(`${i.kind || "safety"}: ${i.reason || JSON.stringify(i)}`);
  if (rec.override) out.push(`override: ${rec.override}`);
  if (!rec.decision) out.push("no valid decision: hover");
  return out.join("; ");
}

// At most one redraw per RENDER_MS: a fast pilot (the oracle flies ~20 steps/s) would otherwise make the page
// decode and paint every frame, taking CPU from the simulator on a small machine. Every step stays in the record.
const RENDER_MS = 200;
let lastRender = 0, pending = null;
function scheduleRender() {
  if (pending) return;
  const wait = Math.max(0, lastRender + RENDER_MS - performance.now());
  pending = setTimeout(() => { pending = null; lastRender = performance.now(); renderStep(); }, wait);
}

function renderStep() {
  const rec = latest();
  if (!rec) return;
  const frames = rec.frames || {};
  if (frames.front) $("front").src = "/" + frames.front;
  if (frames.rear) $("rear").src = "/" + frames.rear;
  $("frontcap").textContent = `front camera after step ${rec.step}: what the pilot sees next`;
  $("front").dataset.step = rec.step;
  const d = rec.decision || {};
  $("dstep").textContent = `(step ${rec.step}${rec.human ? ", human" : ""})`;
  dl($("decision"), [["by", rec.human ? "human" : (rec.model || "-")], ["room", d.room], ["movement", d.movement],
    ["next state", d.state], ["door", d.door_position], ["description", d.description]]);
  dl($("executed"), [["proposed", rec.proposed || "-"], ["executed", rec.executed || "-"], ["why it differed", why(rec)],
    ["collided", rec.collided ? `yes, ${rec.contact}` : ""], ["state", `${rec.state} → ${rec.next_state || "-"}`],
    ["events", (rec.events || []).map(e => `${e.kind.replace("_", " ")} ${e.name} (${e.trigger})`).join("; ")]]);
  let tin = 0, tout = 0, cost = 0, lat = 0;
  for (const r of steps.values()) {
    const u = r.usage || {};
    tin += u.input_tokens || 0; tout += u.output_tokens || 0; cost += u.cost_usd || 0; lat += u.latency_s || 0;
  }
  dl($("usage"), [["tokens in / out", `${tin} / ${tout}`], ["cost", `$${cost.toFixed(4)}`], ["pilot latency", `${lat.toFixed(2)} s`]]);
  $("fsm").textContent = rec.next_state || rec.state;
  renderHeader();
  renderPlan();
}

function renderHeader() {
  const max = summary && summary.config ? summary.config.max_steps : "?";
  const rec = latest();
  $("stepcount").textContent = `step ${rec ? rec.step : 0} / ${max}`;
  if (summary && summary.task) $("task").textContent = `“${summary.task.query}” · pilot ${summary.pilot} · scene ${summary.scene} · run ${meta ? meta.run : ""}`;
  if (summary && summary.result) {
    const r = summary.result;
    $("outcome").textContent = `${r.outcome} in ${r.steps} steps: ${r.reason}`;
    $("outcome").className = "badge " + (r.outcome === "success" ? "on" : "off");
  }
}

function renderPlan() {
  if (!meta || !meta.plan || !summary || !summary.start_pose) return;
  const b = meta.plan, svg = $("traj"), W = 1000, H = 1000 * (b.ymax - b.ymin) / (b.xmax - b.xmin);
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  svg.setAttribute("preserveAspectRatio", "none");
  const px = (p) => [(p.x - b.xmin) / (b.xmax - b.xmin) * W, (b.ymax - p.y) / (b.ymax - b.ymin) * H];
  const ordered = [...steps.values()].sort((a, c) => a.step - c.step);
  const pts = [summary.start_pose, ...ordered.map(r => r.pose_after)].map(px);
  const ns = "http://www.w3.org/2000/svg";
  const line = document.createElementNS(ns, "polyline");
  line.setAttribute("points", pts.map(p => p.join(",")).join(" "));
  line.setAttribute("fill", "none"); line.setAttribute("stroke", "#222"); line.setAttribute("stroke-width", "3");
  const dots = ordered.map((r, i) => {
    const c = document.createElementNS(ns, "circle");
    c.setAttribute("cx", pts[i + 1][0]); c.setAttribute("cy", pts[i + 1][1]); c.setAttribute("r", r.human ? 9 : 7);
    c.setAttribute("fill", meta.state_colors[r.state] || "#777"); c.setAttribute("stroke", r.human ? "#000" : "#333");
    c.setAttribute("stroke-width", r.human ? 4 : 1);
    return c;
  });
  svg.replaceChildren(line, ...dots, ...moverMarks(ordered, px, ns), ...eventMarks(ordered, px, ns));
}

// Issue 24: each person's and pet's path so far (dashed) and where it is now (a dot), as in the episode report.
function moverMarks(ordered, px, ns) {
  const tracks = new Map(), colors = (meta.events || {}).mover_colors || {};
  for (const r of [summary, ...ordered]) {
    for (const m of r.movers || []) {
      if (!tracks.has(m.name)) tracks.set(m.name, {kind: m.kind, pts: []});
      tracks.get(m.name).pts.push(px(m));
    }
  }
  return [...tracks.entries()].flatMap(([name, t]) => {
    const color = colors[t.kind] || "#c2185b";
    const path = document.createElementNS(ns, "polyline");
    path.setAttribute("points", t.pts.map(p => p.join(",")).join(" "));
    path.setAttribute("fill", "none"); path.setAttribute("stroke", color); path.setAttribute("stroke-width", "3");
    path.setAttribute("stroke-dasharray", "10 6");
    const now = document.createElementNS(ns, "circle"), last = t.pts[t.pts.length - 1];
    now.setAttribute("cx", last[0]); now.setAttribute("cy", last[1]); now.setAttribute("r", t.kind === "pet" ? 9 : 13);
    now.setAttribute("fill", color); now.setAttribute("stroke", "#fff"); now.setAttribute("stroke-width", 3);
    now.classList.add("mover"); now.dataset.name = name;
    return [path, now];
  });
}

// Issue 24: a diamond where each fired event happened, labelled "step: kind" (where the scene cannot tell: the drone).
function eventMarks(ordered, px, ns) {
  const ev = meta.events || {}, points = ev.points || {}, out = [];
  const fired = [...(summary.events || []).map(e => [e, summary.start_pose]),
                 ...ordered.flatMap(r => (r.events || []).map(e => [e, r.pose_after]))];
  for (const [e, pose] of fired) {
    const first = [summary, ...ordered].map(r => (r.movers || []).find(m => m.name === e.name)).find(m => m);
    const at = points[e.name] ? {x: points[e.name][0], y: points[e.name][1]} : (first || pose);
    if (!at) continue;
    const [x, y] = px(at);
    const d = document.createElementNS(ns, "polygon");
    d.setAttribute("points", `${x},${y - 12} ${x + 12},${y} ${x},${y + 12} ${x - 12},${y}`);
    d.setAttribute("fill", ev.event_color || "#ff8f00"); d.setAttribute("stroke", "#000");
    d.classList.add("event");
    const label = document.createElementNS(ns, "text");
    label.setAttribute("x", x + 15); label.setAttribute("y", y + 5); label.setAttribute("font-size", "22");
    label.textContent = `${e.step}: ${String(e.kind).replace("_", " ")}`;
    out.push(d, label);
  }
  return out;
}

function renderStatus() {
  const live = meta && meta.controls && !ended;
  $("controls").hidden = !live;
  const on = live && connected && status && !status.finished;
  for (const id of ["stop", "pause", "takeover"]) $(id).disabled = !on;
  let mode = ended ? "ended" : !connected ? "disconnected" : "flying";
  if (status && !ended) {
    if (status.stopped) mode = "emergency stop";
    else if (status.human) mode = "human at the controls";
    else if (status.paused) mode = status.holding ? "paused (holding)" : "pausing after this step";
  }
  $("mode").textContent = mode;
  $("mode").className = "badge " + (mode.startsWith("human") ? "human" : mode.startsWith("paus") ? "paused" : mode === "flying" ? "on" : "off");
  $("pause").textContent = status && status.paused ? "Resume (P)" : "Pause (P)";
  $("takeover").textContent = status && status.human ? "Hand back (T)" : "Take over (T)";
  const w = on && status.human ? status.waiting : null;
  $("human").hidden = !(on && status.human);
  $("hstep").textContent = w ? w.step : "-";
  $("hstate").textContent = w ? w.state : "waiting for the loop…";
  const select = $("nextstate");
  const states = w ? w.next_states : [];
  if ([...select.options].map(o => o.value).join() !== states.join()) {
    select.replaceChildren(...states.map(s => new Option(s, s)));
    if (w && states.includes(w.state)) select.value = w.state;
  }
  $("moves").replaceChildren(...(w ? w.moves : []).map(m => {
    const btn = document.createElement("button"); btn.textContent = m; btn.onclick = () => command(m); return btn;
  }));
  $("hfeedback").textContent = w && w.feedback.length ? w.feedback.join(" ") : "";
}

// The reply to a control message and the event stream both carry the status; whichever arrives last may be the
// older one (a pause's reply after the stream said the loop is now holding), so the newest version wins.
function applyStatus(next) {
  if (!status || next.version >= status.version) status = next;
  renderStatus();
}

async function control(action, extra = {}) {
  if (!connected || ended) { notice("not connected: nothing was sent"); return; }
  const headers = {"Content-Type": "application/json"};
  if (token) headers.Authorization = `Bearer ${token}`;
  try {
    const r = await fetch("/api/control", {method: "POST", headers, body: JSON.stringify({run: meta.run, action, ...extra})});
    const body = await r.json();
    if (!r.ok) { notice(`${action} refused (${r.status}): ${body.error}`); return; }
    applyStatus(body); notice("");
  } catch (e) { notice(`${action} not delivered: ${e}`); }  // never retried
}

function command(movement) {
  const w = status && status.waiting;
  if (!w) { notice("the loop is not waiting for a command yet"); return; }
  control("command", {step: w.step, movement, state: $("nextstate").value});
}

function notice(text) { $("notice").textContent = text; }

document.addEventListener("keydown", (ev) => {
  if (!meta || !meta.controls || ev.target.tagName === "SELECT") return;
  const key = ev.key.length === 1 ? ev.key.toLowerCase() : ev.key;
  if (key === " ") { ev.preventDefault(); control("stop"); return; }
  if (key === "p") { control(status && status.paused ? "resume" : "pause"); return; }
  if (key === "t") { control(status && status.human ? "hand_back" : "take_over"); return; }
  if (status && status.human && meta.keys[key]) { ev.preventDefault(); command(meta.keys[key]); }
});
$("stop").onclick = () => control("stop");
$("pause").onclick = () => control(status && status.paused ? "resume" : "pause");
$("takeover").onclick = () => control(status && status.human ? "hand_back" : "take_over");

async function start() {
  meta = await (await fetch("/api/meta")).json();
  if (meta.plan) { $("plan").src = "/plan.png"; $("plansec").hidden = false; }
  const es = new EventSource("/api/events");
  es.onopen = () => { connected = true; $("conn").textContent = "live"; $("conn").className = "badge on"; renderStatus(); };
  es.onerror = () => {
    connected = false;
    if (!ended) { $("conn").textContent = "disconnected"; $("conn").className = "badge off"; }
    renderStatus();
  };
  es.addEventListener("step", (ev) => { const r = JSON.parse(ev.data); steps.set(r.step, r); scheduleRender(); });
  es.addEventListener("summary", (ev) => { summary = JSON.parse(ev.data); renderHeader(); renderPlan(); });
  es.addEventListener("status", (ev) => applyStatus(JSON.parse(ev.data)));
  es.addEventListener("end", () => {
    ended = true; es.close(); $("conn").textContent = "run over"; $("conn").className = "badge"; renderStatus();
  });
  renderStatus();
}
start();
