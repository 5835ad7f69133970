"""A run directory read back as a timeline for the reports: one entry per decision, plus the end.

Entry k (k = 1..N) is step k as the pilot lived it: the frames it saw (the observation recorded after step
k-1, or the start frames), the pose it decided from, its decision, what the controller executed and what
happened. A last entry shows where the episode ended. The HTML page and the video both read this, so they
show the same thing for the same step.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vlnpilot.core.rundir import load_run
from vlnpilot.episode.record import step_keys

# Step-record keys of the safety layer (`vlnpilot.safety`): commands it changed, oscillation events, and the
# feedback it puts into the next prompt. Absent in runs recorded before it existed.
INTERVENTION_KEYS = ("interventions",)

# Recorded keys the page has no place for: shown raw ("other recorded fields"), as are keys the step record
# does not know (a newer or a foreign writer's).
SHOWN_RAW = ("override", "confirmation", "human", "robot", "ranges", "attempts", "wall_s")


def known_keys() -> set[str]:
    """The step-record keys the timeline reads into its own fields: the recorded format (`episode_record`)
    but those shown raw."""
    return set(step_keys()) - set(SHOWN_RAW)


@dataclass
class Entry:
    """One row of the timeline. `step` is None for the closing entry."""

    index: int
    step: int | None
    state: str | None
    next_state: str | None
    decision: dict[str, Any] | None
    proposed: str | None
    executed: str | None
    failures: list[dict[str, Any]]
    usage: dict[str, Any]
    raw_text: str | None
    pose: dict[str, float] | None  # where the pilot decided from (the final pose for the closing entry)
    pose_after: dict[str, float] | None
    collided: bool
    contact: str | None
    room_true: str | None  # ground-truth room at `pose`, when known
    oscillation: bool
    interventions: list[Any]  # safety.Intervention dicts: step, source, proposed, executed, reason
    frames: dict[str, str]  # view -> path relative to the run dir, only for frames that exist
    oscillation_event: dict[str, Any] | None = None  # safety.OscillationEvent dict
    feedback: list[str] = field(default_factory=list)  # what the controller tells the pilot in the next prompt
    extra: dict[str, Any] = field(default_factory=dict)  # unknown keys of the record, shown raw
    stage: int | None = None  # the mission's stage (1-based) this step flew; None: a one-stage episode
    events: list[dict[str, Any]] = field(default_factory=list)  # issue 24: the scenario's events fired in this step
    movers: list[dict[str, Any]] = field(default_factory=list)  # the people and pets where they were at `pose`

    @property
    def label(self) -> str:
        return f"Step {self.step}" if self.step is not None else "End"

    @property
    def shown_state(self) -> str:
        """The state that colours this entry: the state it decided in (the final state for the closing entry)."""
        return self.state or "?"


@dataclass
class Episode:
    run_dir: Path
    summary: dict[str, Any]
    steps: list[dict[str, Any]]
    entries: list[Entry]
    scene: Any | None  # vlnpilot.scene.Scene when the scene could be loaded
    warnings: list[str] = field(default_factory=list)  # what of the recording could not be read (shown on the page)

    @property
    def result(self) -> dict[str, Any]:
        return self.summary.get("result") or {}

    @property
    def task(self) -> dict[str, Any]:
        return self.summary.get("task") or {}

    @property
    def shown_outcome(self) -> str:
        """What the page's title, its header and the video's last frame call the end: the outcome, else the record's
        status (running, interrupted, failed), else "unknown" (a summary that says neither). A declaration nobody
        judged, recorded as a success before `declared` was an outcome of its own, is shown as `declared`."""
        outcome = self.result.get("outcome")
        if outcome in ("success", "unreachable") and self.result.get("judged_by") == "declared":
            return "declared"
        return str(outcome or self.summary.get("status") or "unknown")

    def trajectory(self) -> list[dict[str, float]]:
        """Start pose and the pose after every step."""
        pts = [self.summary["start_pose"]] if self.summary.get("start_pose") else []
        if not pts and self.steps and self.steps[0].get("pose_before"):
            pts = [self.steps[0]["pose_before"]]
        pts += [s["pose_after"] for s in self.steps if s.get("pose_after")]
        return pts

    def trajectory_states(self) -> list[str]:
        """One state per trajectory point: the state the pilot chose on arriving there (the start state first)."""
        first = (self.steps[0].get("state") if self.steps else None) or "Recognize Room"
        out = [first]
        for s in self.steps:
            if s.get("pose_after"):
                out.append(s.get("next_state") or s.get("state") or "?")
        return out[: len(self.trajectory())]

    def mover_tracks(self) -> dict[str, dict[str, Any]]:
        """Issue 24: each person's and pet's positions over the episode, one per step it was recorded at:
        {name: {"kind": ..., "points": [(x, y), ...]}} in the order they first appear."""
        tracks: dict[str, dict[str, Any]] = {}
        for movers in [self.summary.get("movers") or [], *(s.get("movers") or [] for s in self.steps)]:
            for m in movers:
                track = tracks.setdefault(str(m.get("name")), {"kind": m.get("kind"), "points": []})
                track["points"].append((float(m["x"]), float(m["y"])))
        return tracks

    def fired_events(self) -> list[dict[str, Any]]:
        """Issue 24: every event of the scenario that fired, in order (those at take-off first, at step 0), each
        with where it happened on the plan (`x`, `y`: see `event_point`)."""
        tracks = self.mover_tracks()
        out = []
        for step, events, pose in [(0, self.summary.get("events") or [], self.summary.get("start_pose")),
                                   *((s.get("step", i + 1), s.get("events") or [], s.get("pose_after"))
                                     for i, s in enumerate(self.steps))]:
            for e in events:
                at = event_point(self.scene, e, tracks) or ((pose["x"], pose["y"]) if pose else None)
                out.append({**e, "step": e.get("step", step), "x": at and at[0], "y": at and at[1]})
        return out

    def collision_point(self) -> dict[str, float] | None:
        for s in self.steps:
            if s.get("collided"):
                return s.get("pose_after") or s.get("pose_before")
        return None


def event_point(scene: Any, event: dict[str, Any], tracks: dict[str, dict[str, Any]]) -> tuple[float, float] | None:
    """Where an event happened: a mover where it was first recorded, a closing door's centre, a sign where it hangs,
    a dimmed room's centre; None when the scene cannot tell (the plan then marks the drone's position)."""
    kind, params = event.get("kind"), event.get("params") or {}
    track = tracks.get(str(event.get("name")))
    if kind in ("person", "pet") and track and track["points"]:
        return track["points"][0]
    if scene is None:
        return None
    try:
        if kind == "door_closes":
            center = scene.door(params["door"]).center
            return center[0], center[1]
        if kind == "lights_out":
            return scene.room(params["room"]).centroid
        if kind == "sign":
            from vlnpilot.scene.events import EventSpec
            from vlnpilot.sim.events import sign_placement

            fields = {k: v for k, v in params.items() if k in EventSpec.model_fields and v is not None}
            where = sign_placement(EventSpec(kind="sign", **fields), scene)
            return where.x, where.y
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    return None


class _FrameCheck:
    """Which recorded frames can be drawn: a frame that is missing, or damaged (torn, empty, not an image), is left
    out (the page and the video draw a placeholder), and a damaged one is said once in `warnings`."""

    def __init__(self, run_dir: Path, warnings: list[str]):
        self.run_dir, self.warnings = run_dir, warnings
        self._readable: dict[str, bool] = {}

    def existing(self, frames: dict[str, str] | None) -> dict[str, str]:
        return {view: rel for view, rel in (frames or {}).items() if isinstance(rel, str) and self._ok(rel)}

    def _ok(self, rel: str) -> bool:
        if rel not in self._readable:
            self._readable[rel] = self._decodes(self.run_dir / rel)
        return self._readable[rel]

    def _decodes(self, path: Path) -> bool:
        if not path.is_file():
            return False
        from PIL import Image

        try:
            with Image.open(path) as im:
                im.load()
        except (OSError, SyntaxError, ValueError) as exc:  # PIL's errors for a torn, empty or foreign file
            self.warnings.append(f"{path} is damaged ({exc}); drawn as a placeholder")
            return False
        return True


def _interventions(record: dict[str, Any]) -> list[Any]:
    out: list[Any] = []
    for key in INTERVENTION_KEYS:
        value = record.get(key)
        if value in (None, False, [], {}):
            continue
        out.extend(value if isinstance(value, list) else [value])
    return out


def _room_at(scene: Any, pose: dict[str, float] | None) -> str | None:
    if scene is None or not pose:
        return None
    try:
        return scene.room_at(pose["x"], pose["y"])
    except (KeyError, TypeError):
        return None


@functools.lru_cache(maxsize=8)
def load_scene_or_none(name: str | None) -> Any | None:
    """The scene a run flew in, or None when it is not a built-in scene (the report then omits the plan).

    Cached: scenes are immutable, and a benchmark report reads hundreds of runs of the same scene.
    """
    if not name:
        return None
    from vlnpilot.core.errors import VLNPilotError
    from vlnpilot.scene import load_scene

    try:
        return load_scene(name)
    except (VLNPilotError, KeyError, ValueError):
        return None


def load_episode(run_dir: str | Path, scene: Any | None = None) -> Episode:
    """Read a run directory into an `Episode` with its timeline (scene loaded by name unless given)."""
    run_dir = Path(run_dir)
    warnings: list[str] = []
    summary, steps = load_run(run_dir, on_damage=warnings.append)  # a damaged line is skipped, and said
    frames_ok = _FrameCheck(run_dir, warnings)
    if scene is None:
        scene = load_scene_or_none(summary.get("scene"))
    prev_frames = summary.get("start_frames") or {"front": "frames/front_000.jpg", "rear": "frames/rear_000.jpg"}
    prev_room = None
    prev_movers = list(summary.get("movers") or [])  # where the people and pets were when the pilot decided
    known = known_keys()
    entries: list[Entry] = []
    for i, rec in enumerate(steps):
        pose = rec.get("pose_before")
        room = _room_at(scene, pose) or prev_room
        entries.append(Entry(
            index=i, step=rec.get("step", i + 1), state=rec.get("state"), next_state=rec.get("next_state"),
            decision=rec.get("decision"), proposed=rec.get("proposed"), executed=rec.get("executed"),
            failures=list(rec.get("failures") or []), usage=dict(rec.get("usage") or {}),
            raw_text=rec.get("raw_text"), pose=pose, pose_after=rec.get("pose_after"),
            collided=bool(rec.get("collided")), contact=rec.get("contact"), room_true=room,
            oscillation=bool(rec.get("oscillation")), interventions=_interventions(rec),
            frames=frames_ok.existing(prev_frames),
            oscillation_event=rec.get("oscillation_event") or None,
            feedback=[str(f) for f in rec.get("safety_feedback") or []],
            extra={k: v for k, v in rec.items() if k not in known and v is not None},  # `override: null` says nothing
            stage=rec.get("stage"), events=list(rec.get("events") or []), movers=prev_movers,
        ))
        prev_movers = list(rec.get("movers") or prev_movers)
        prev_frames = rec.get("frames") or {}
        prev_room = rec.get("room_true")
    end_pose = summary.get("end_pose") or (steps[-1].get("pose_after") if steps else summary.get("start_pose"))
    result = summary.get("result") or {}
    last = steps[-1] if steps else {}
    final_state = result.get("final_state") or last.get("next_state") or last.get("state")
    entries.append(Entry(
        index=len(steps), step=None, state=final_state, next_state=None, decision=None, proposed=None,
        executed=None, failures=[], usage={}, raw_text=None, pose=end_pose, pose_after=None,
        collided=bool(last.get("collided")), contact=last.get("contact"),
        room_true=_room_at(scene, end_pose) or result.get("final_room") or last.get("room_true"),
        oscillation=False, interventions=[], frames=frames_ok.existing(prev_frames), movers=prev_movers,
    ))
    return Episode(run_dir=run_dir, summary=summary, steps=steps, entries=entries, scene=scene, warnings=warnings)


def finite(value: Any) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)
