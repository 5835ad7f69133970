"""Top-down floor plans of a scene, coloured as in the paper's room diagram, optionally with a flown trajectory.

The plan is a horizontal section at the drone's flight altitude: walls and door frames that the drone can hit
are dark grey, furniture is lighter (what stands at flight altitude darker than what stays below it), parts
wholly above flight altitude (door headers, wall cabinets, the ceiling) are left out, so doorways show as gaps.
Figures are built without pyplot (no global state, no display): Agg renders them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # no display; harmless when pyplot is never imported

from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Circle, Ellipse, FancyArrow, Patch, Polygon  # noqa: E402

from vlnpilot.core.errors import UnknownNameError  # noqa: E402
from vlnpilot.core.fsm import ASKED_STATES
from vlnpilot.scene.model import EXTERIOR, Door, Room, Scene, Solid  # noqa: E402

WALL_COLOR = "0.35"
WINDOW_COLOR = "lightskyblue"
TALL_FURNITURE_COLOR = "0.62"  # furniture that reaches flight altitude: an obstacle
LOW_FURNITURE_COLOR = "0.82"  # furniture below flight altitude
OPEN_DOOR_COLOR = "tab:green"
CLOSED_DOOR_COLOR = "red"
TARGET_COLOR = "gold"
SPAWN_COLOR, HEADING_COLOR = "limegreen", "red"  # the paper's Figure 6: a green sphere and a red bar
TRAJECTORY_COLOR = "0.15"
MOVER_COLORS = {"person": "#c2185b", "pet": "#6d4c41"}  # issue 24: people and pets, their paths and dots
EVENT_COLOR = "#ff8f00"  # issue 24: where an event of the scenario happened
_PALETTE = ("tab:blue", "tab:orange", "tab:purple", "tab:cyan", "tab:brown", "tab:pink", "tab:olive",
            "tab:gray", "tab:green", "tab:red")
# One fixed colour per FSM state, so that a state looks the same in every plan, report and video.
STATE_COLORS: dict[str, str] = {s.value: _PALETTE[i % len(_PALETTE)] for i, s in enumerate(ASKED_STATES)}

XY = tuple[float, float]


# -- geometry of solids seen from above ---------------------------------------------------------------
def _z_extent(s: Solid) -> tuple[float, float]:
    """Vertical extent of an upright solid (tilted ones are bounded by their largest half-size)."""
    half = {"box": s.size[2], "cylinder": s.size[1], "ellipsoid": s.size[2], "sphere": s.size[0],
            "capsule": s.size[0] + s.size[1]}.get(s.shape, max(s.size))
    if s.euler_deg is not None and (s.euler_deg[0] or s.euler_deg[1]):
        half = math.sqrt(sum(v * v for v in s.size))
    return s.pos[2] - half, s.pos[2] + half


def _rotation(s: Solid) -> list[list[float]]:
    """Rotation matrix of a solid (MuJoCo's default intrinsic x-y-z Euler angles, or a yaw)."""
    ax, ay, az = (math.radians(a) for a in (s.euler_deg or (0.0, 0.0, s.yaw_deg)))
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    # R = Rx(ax) @ Ry(ay) @ Rz(az)
    return [
        [cy * cz, -cy * sz, sy],
        [sx * sy * cz + cx * sz, -sx * sy * sz + cx * cz, -sx * cy],
        [-cx * sy * cz + sx * sz, cx * sy * sz + sx * cz, cx * cy],
    ]


def _convex_hull(points: Iterable[XY]) -> list[XY]:
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def half(seq: list[XY]) -> list[XY]:
        out: list[XY] = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]

    return half(pts) + half(pts[::-1])


def footprint(s: Solid, **style: Any):
    """A matplotlib patch for the solid's outline seen from above."""
    x, y = s.pos[0], s.pos[1]
    yaw = s.euler_deg[2] if s.euler_deg is not None else s.yaw_deg
    if s.shape in ("cylinder", "sphere", "capsule"):
        return Circle((x, y), s.size[0], **style)
    if s.shape == "ellipsoid":
        return Ellipse((x, y), 2 * s.size[0], 2 * s.size[1], angle=yaw, **style)
    r = _rotation(s)
    corners = []
    for dx in (-s.size[0], s.size[0]):
        for dy in (-s.size[1], s.size[1]):
            for dz in (-s.size[2], s.size[2]):
                corners.append((round(x + r[0][0] * dx + r[0][1] * dy + r[0][2] * dz, 9),
                                round(y + r[1][0] * dx + r[1][1] * dy + r[1][2] * dz, 9)))
    return Polygon(_convex_hull(corners), closed=True, **style)


def _is_structure(s: Solid, scene: Scene) -> bool:
    """Walls, door frames and leaves, windows: by the scene's naming convention."""
    return s.name.startswith("wall") or "window" in s.name or any(s.name.startswith(d.id) for d in scene.doors)


# -- the plan -----------------------------------------------------------------------------------------
def draw_floorplan(scene: Scene, ax: Axes | None = None, *, trajectory: Sequence[Any] | None = None,
                   states: Sequence[Any] | None = None, collision: Any | None = None,
                   goal: str | Iterable[str] | None = None, title: str | None = None,
                   movers: Mapping[str, Mapping[str, Any]] | None = None,
                   events: Sequence[Mapping[str, Any]] | None = None) -> Axes:
    """Draw the top-down plan of `scene` on `ax` (a new Figure's axes when None) and return the axes.

    `trajectory`: points as (x, y) pairs or objects with `.x`/`.y` (Poses), drawn as a line with markers;
    `states`: one FSM state (enum or str) per point, colouring the markers, with a legend;
    `collision`: a point (or Pose) marked with a red X; `goal`: room and/or target ids or aliases to highlight;
    `movers` (issue 24): each person's or pet's track, `{name: {"kind": ..., "points": [(x, y), ...]}}`, drawn as a
    dashed path with a dot per recorded step and its name at the start; `events`: the scenario's events that fired,
    each with `x`, `y`, `step` and `kind`, marked with a diamond and "step: kind".
    """
    if ax is None:
        (xmin, ymin), (xmax, ymax) = scene.bounds
        width = 10.0
        height = max(3.0, width * (ymax - ymin + 1.0) / (xmax - xmin + 0.6) + 1.2)
        ax = Figure(figsize=(width, height), dpi=100, layout="constrained").add_subplot()
    goals = _resolve_goals(scene, goal)

    for room in scene.rooms:
        highlighted = room.id in goals["rooms"]
        ax.add_patch(Polygon(room.polygon, closed=True, facecolor=(*room.color, 0.45), zorder=0,
                             edgecolor="darkgreen" if highlighted else "none", linewidth=4 if highlighted else 0,
                             hatch="//" if highlighted else None))
        cx, cy = _label_point(scene, room)
        ax.text(cx, cy, room.name + ("\n(goal)" if highlighted else ""), ha="center", va="center", fontsize=11,
                fontweight="bold", color="0.1", zorder=4.5,
                bbox={"boxstyle": "round,pad=0.25", "fc": (*room.color, 0.7), "ec": "0.3", "lw": 0.5})

    cut = scene.flight_altitude
    for s in scene.solids:
        if not s.collide:
            continue
        z0, z1 = _z_extent(s)
        if z1 <= 0.01 or z0 >= cut:  # the floor slab; anything wholly above flight altitude
            continue
        if "window" in s.name:
            color, z = WINDOW_COLOR, 3
        elif _is_structure(s, scene):
            color, z = WALL_COLOR, 3
        else:
            color, z = (TALL_FURNITURE_COLOR, 2) if z1 >= cut else (LOW_FURNITURE_COLOR, 2)
        ax.add_patch(footprint(s, facecolor=color, edgecolor="none", zorder=z))

    for door in scene.doors:
        _draw_door(ax, door)

    for t in scene.targets:
        big = t.id in goals["targets"]
        ax.plot(t.position[0], t.position[1], marker="*", markersize=20 if big else 15, color=TARGET_COLOR,
                markeredgecolor="darkgreen" if big else "black", markeredgewidth=2 if big else 0.8, zorder=6)
        ax.annotate(t.name, (t.position[0], t.position[1]), xytext=(0, -14), textcoords="offset points",
                    ha="center", va="top", fontsize=8, zorder=6,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7})

    for sp in scene.spawns:
        p = sp.pose
        c, s_ = math.cos(p.yaw_rad), math.sin(p.yaw_rad)
        ax.add_patch(FancyArrow(p.x, p.y, 0.35 * c, 0.35 * s_, width=0.04, head_width=0.12, head_length=0.1,
                                length_includes_head=True, color=HEADING_COLOR, zorder=7))
        ax.add_patch(Circle((p.x, p.y), 0.09, facecolor=SPAWN_COLOR, edgecolor="black", linewidth=0.8, zorder=8))
        ax.annotate(f"spawn: {sp.id}", (p.x, p.y), xytext=(0, 9), textcoords="offset points", ha="center",
                    va="bottom", fontsize=7, zorder=8)

    handles = [
        Patch(facecolor=WALL_COLOR, label="wall / door frame"),
        Patch(facecolor=WINDOW_COLOR, label="window"),
        Patch(facecolor=TALL_FURNITURE_COLOR, label="furniture (reaches flight altitude)"),
        Patch(facecolor=LOW_FURNITURE_COLOR, label="furniture (below flight altitude)"),
        Line2D([], [], color=OPEN_DOOR_COLOR, marker="o", linestyle="none", label="open door"),
        Line2D([], [], color=CLOSED_DOOR_COLOR, linewidth=4, label="closed door"),
        Line2D([], [], color=TARGET_COLOR, marker="*", markersize=12, markeredgecolor="black", linestyle="none",
               label="target"),
        Line2D([], [], color=SPAWN_COLOR, marker="o", markeredgecolor="black", linestyle="none", label="spawn"),
    ]
    if trajectory is not None:
        handles += _draw_trajectory(ax, [_xy(p) for p in trajectory], states)
    if movers:
        handles += _draw_movers(ax, movers)
    if events:
        handles += _draw_events(ax, events)
    if collision is not None:
        cx, cy = _xy(collision)
        ax.plot(cx, cy, marker="X", markersize=16, color="red", markeredgecolor="black", zorder=11)
        handles.append(Line2D([], [], color="red", marker="X", markeredgecolor="black", linestyle="none",
                              markersize=10, label="collision"))

    (xmin, ymin), (xmax, ymax) = scene.bounds
    ax.set_xlim(xmin - 0.3, xmax + 0.3)
    ax.set_ylim(ymin - 0.3, ymax + 0.3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title if title is not None else f"{scene.name}: floor plan")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=4, fontsize=8, frameon=False)
    return ax


def save_floorplan(scene: Scene, path: str | Path, *, dpi: int = 120, **kw: Any) -> Path:
    """Draw the plan (keyword arguments as for `draw_floorplan`) and write it to `path` (png, svg, pdf...)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ax = draw_floorplan(scene, **kw)
    fig = ax.get_figure(root=True)
    assert fig is not None  # draw_floorplan's axes always sit on a figure
    fig.savefig(path, dpi=dpi)
    return path


# -- helpers ------------------------------------------------------------------------------------------
def _xy(p: Any) -> XY:
    if hasattr(p, "x") and hasattr(p, "y"):
        return float(p.x), float(p.y)
    x, y = p[0], p[1]
    return float(x), float(y)


def _state_label(state: Any) -> str:
    return str(getattr(state, "value", state))


def _label_point(scene: Scene, room: Room) -> XY:
    """Where to write a room's name: near its centroid, but clear of its spawns and targets."""
    cx, cy = room.centroid
    ys = [p[1] for p in room.polygon]
    span = max(ys) - min(ys)
    marks = [(s.pose.x, s.pose.y) for s in scene.spawns if s.room == room.id]
    marks += [(t.position[0], t.position[1]) for t in scene.targets if t.room == room.id]
    candidates = [(cx, cy + f * span) for f in (0.0, 0.15, -0.15, 0.3, -0.3) if room.contains(cx, cy + f * span)]
    if not marks or not candidates:
        return cx, cy
    return max(candidates, key=lambda c: round(min(math.dist(c, m) for m in marks), 1))


def _resolve_goals(scene: Scene, goal: str | Iterable[str] | None) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {"rooms": set(), "targets": set()}
    if goal is None:
        return out
    for name in [goal] if isinstance(goal, str) else goal:
        if name is None:
            continue
        if (room := scene.find_room(name)) is not None:
            out["rooms"].add(room.id)
        elif (target := scene.find_target(name)) is not None:
            out["targets"].add(target.id)
        else:
            raise UnknownNameError("goal (room or target)", name,
                                   [r.id for r in scene.rooms] + [t.id for t in scene.targets])
    return out


def _draw_door(ax: Axes, door: Door) -> None:
    nx, ny = door.normal
    lx, ly = -ny, nx
    a = (door.center[0] + lx * door.width / 2, door.center[1] + ly * door.width / 2)
    b = (door.center[0] - lx * door.width / 2, door.center[1] - ly * door.width / 2)
    if door.open and EXTERIOR not in door.rooms:
        ax.plot(*door.center, marker="o", markersize=9, color=OPEN_DOOR_COLOR, markeredgecolor="black", zorder=5)
        ax.plot([a[0], b[0]], [a[1], b[1]], color=OPEN_DOOR_COLOR, linestyle=":", linewidth=1.5, zorder=4)
    else:
        ax.plot([a[0], b[0]], [a[1], b[1]], color=CLOSED_DOOR_COLOR, linewidth=5, solid_capstyle="butt", zorder=5)
    # the name on the side of rooms[0], written along the wall
    ax.text(door.center[0] - 0.3 * nx, door.center[1] - 0.3 * ny, door.id, ha="center", va="center", fontsize=6,
            color="0.2", zorder=5, rotation=90 if abs(nx) > abs(ny) else 0)


def _draw_trajectory(ax: Axes, points: list[XY], states: Sequence[Any] | None) -> list[Any]:
    if not points:
        return []
    if states is not None and len(states) != len(points):
        raise ValueError(f"states has {len(states)} entries for {len(points)} trajectory points")
    xs, ys = zip(*points, strict=True)
    ax.plot(xs, ys, color=TRAJECTORY_COLOR, linewidth=1.2, alpha=0.8, zorder=9)
    handles: list[Any] = []
    if states is None:
        ax.scatter(xs, ys, s=14, color="tab:blue", edgecolors="black", linewidths=0.3, zorder=10)
        handles.append(Line2D([], [], color="tab:blue", marker="o", linestyle="none", label="trajectory"))
    else:
        labels = [_state_label(s) for s in states]
        order = list(dict.fromkeys(labels))
        extra = [lab for lab in order if lab not in STATE_COLORS]  # names outside the FSM keep a stable order too
        colors = {lab: STATE_COLORS.get(lab) or _PALETTE[-1 - extra.index(lab) % len(_PALETTE)] for lab in order}
        for lab in order:
            pts = [p for p, l in zip(points, labels, strict=True) if l == lab]
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=30, color=colors[lab], edgecolors="black",
                       linewidths=0.3, zorder=10)
            handles.append(Line2D([], [], color=colors[lab], marker="o", markeredgecolor="black", linestyle="none",
                                  label=lab))
    ax.plot(xs[0], ys[0], marker="s", markersize=8, color="white", markeredgecolor="black", zorder=10)
    handles.append(Line2D([], [], color="white", marker="s", markeredgecolor="black", linestyle="none",
                          label="start"))
    return handles


def _draw_movers(ax: Axes, movers: Mapping[str, Mapping[str, Any]]) -> list[Any]:
    """Issue 24: each mover's path (dashed), a dot per recorded step, its name where it started."""
    kinds: list[str] = []
    for name, track in movers.items():
        points = [_xy(p) for p in track.get("points") or ()]
        if not points:
            continue
        kind = str(track.get("kind") or "person")
        color = MOVER_COLORS.get(kind, MOVER_COLORS["person"])
        xs, ys = zip(*points, strict=True)
        ax.plot(xs, ys, color=color, linestyle="--", linewidth=1.4, alpha=0.85, zorder=9)
        ax.scatter(xs, ys, s=10, color=color, zorder=9)
        ax.annotate(name, points[0], xytext=(0, 8), textcoords="offset points", ha="center", fontsize=7,
                    color=color, zorder=9)
        kinds += [kind] if kind not in kinds else []
    return [Line2D([], [], color=MOVER_COLORS.get(k, MOVER_COLORS["person"]), linestyle="--", marker="o",
                   markersize=4, label=f"{k} path") for k in kinds]


def _draw_events(ax: Axes, events: Sequence[Mapping[str, Any]]) -> list[Any]:
    """Issue 24: a diamond where each event happened, labelled with its step and kind."""
    shown = [e for e in events if e.get("x") is not None and e.get("y") is not None]
    for e in shown:
        x, y = float(e["x"]), float(e["y"])
        ax.plot(x, y, marker="D", markersize=9, color=EVENT_COLOR, markeredgecolor="black", zorder=11)
        ax.annotate(f"{e.get('step')}: {str(e.get('kind')).replace('_', ' ')}", (x, y), xytext=(6, -10),
                    textcoords="offset points", fontsize=7, zorder=11,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": EVENT_COLOR, "alpha": 0.85})
    return [Line2D([], [], color=EVENT_COLOR, marker="D", markeredgecolor="black", linestyle="none",
                   label="event (step: kind)")] if shown else []
