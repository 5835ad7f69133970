"""Figures for the reports: the episode floor plan (with pixel positions of every step) and benchmark plots.

Matplotlib without pyplot (no global state, no display); every benchmark plot is saved as a PNG that can go
into a paper as it is.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib import rc_context, ticker  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.typing import RcKeyType  # noqa: E402

from vlnpilot.episode.config import OUTCOMES  # noqa: E402

OUTCOME_ORDER = OUTCOMES
OUTCOME_COLORS = {"success": "#2f9e63", "false_success": "#e5a50a", "collision": "#d1495b",
                  "max_steps": "#5b7fbf", "pilot_error": "#8e6bbf", "halted": "#b5651d",
                  "link_lost": "#7a2e2e", "aborted": "#555555", "unreachable": "#3a9fb5",
                  "declared": "#9a8c3c"}
OUTCOME_LABELS = {"success": "success", "false_success": "false success", "collision": "collision",
                  "max_steps": "steps exceeded", "pilot_error": "pilot error", "halted": "halted (robot safety)",
                  "link_lost": "link lost (landed)", "aborted": "aborted (e-stop)",
                  "unreachable": "unreachable (reported)", "declared": "declared (not judged)"}
HALF = (6.4, 4.0)  # figures shown side by side; FULL_W: figures shown across the page
FULL_W = 12.8
PILOT_COLORS = ("#3b6fb6", "#e07b39", "#4a9d5b", "#c2464f", "#7d5fb2", "#8c6d46", "#d36fb0", "#6f7780")

STYLE: dict[RcKeyType, Any] = {
    "font.size": 10, "axes.titlesize": 11, "axes.titleweight": "bold", "axes.labelsize": 10,
    "axes.spines.top": False, "axes.spines.right": False, "axes.edgecolor": "#555", "axes.grid": True,
    "grid.color": "#e3e5ea", "grid.linewidth": 0.8, "axes.axisbelow": True, "legend.frameon": False,
    "xtick.color": "#333", "ytick.color": "#333",
}


# -- statistics -----------------------------------------------------------------------------------------
def wilson_interval(successes: int, n: int) -> tuple[float, float]:
    """95% Wilson score interval of a success rate: the bench package's, so tables and plots agree."""
    from vlnpilot.bench.results import wilson_interval as wilson

    return wilson(successes, n)


# -- the episode floor plan -----------------------------------------------------------------------------
@dataclass
class PlanImage:
    """A rendered floor plan and where things are on it, in pixels from the top-left corner."""

    rgb: np.ndarray  # H x W x 3 uint8
    positions: list[tuple[float, float] | None]  # one per requested pose
    meters_to_px: float
    state_colors: dict[str, str]  # state name -> hex colour of its markers
    origin_px: tuple[float, float] = (0.0, 0.0)  # where the world's (0, 0) is on the image (x right, y down)

    def to_px(self, x: float, y: float) -> tuple[float, float]:
        """A world point's pixel on the image (the plan is drawn at equal scale on both axes)."""
        return self.origin_px[0] + x * self.meters_to_px, self.origin_px[1] - y * self.meters_to_px

    @property
    def size(self) -> tuple[int, int]:
        return self.rgb.shape[1], self.rgb.shape[0]

    def png(self) -> bytes:
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(self.rgb).save(buf, format="PNG", compress_level=6)
        return buf.getvalue()


def render_plan(scene: Any, *, trajectory: Sequence[Mapping[str, float]] = (), states: Sequence[str] | None = None,
                collision: Mapping[str, float] | None = None, goal: Sequence[str] = (),
                positions_of: Sequence[Mapping[str, float] | None] = (), width_px: int = 1200,
                movers: Mapping[str, Mapping[str, Any]] | None = None,
                events: Sequence[Mapping[str, Any]] | None = None) -> PlanImage:
    """Draw the scene's plan (via `floorplan.draw_floorplan`) tightly, without legend or axes.

    The figure has the aspect of the scene so the plan fills it; `positions_of` poses are mapped to pixels so
    that a page or a video can put a cursor on the plan without drawing it again.
    """
    from vlnpilot.report.floorplan import draw_floorplan

    (xmin, ymin), (xmax, ymax) = scene.bounds
    margin = 0.3  # draw_floorplan's limits
    span_x, span_y = xmax - xmin + 2 * margin, ymax - ymin + 2 * margin
    dpi = 100
    w_in = width_px / dpi
    fig = Figure(figsize=(w_in, w_in * span_y / span_x), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    pts = [(p["x"], p["y"]) for p in trajectory]
    col = (collision["x"], collision["y"]) if collision else None
    goals = [g for g in goal if g]
    draw_floorplan(scene, ax, trajectory=pts or None, states=list(states) if states is not None and pts else None,
                   collision=col, goal=goals or None, title="", movers=movers, events=events)
    state_colors: dict[str, str] = {}
    legend = ax.get_legend()
    if legend is not None:
        wanted = set(states or ())
        for handle, text in zip(legend.legend_handles, legend.get_texts(), strict=False):
            label = text.get_text()
            if label in wanted and handle is not None and hasattr(handle, "get_markerfacecolor"):
                state_colors[label] = to_hex(handle.get_markerfacecolor())
        legend.remove()
    ax.set_axis_off()
    ax.set_xlim(xmin - margin, xmax + margin)
    ax.set_ylim(ymin - margin, ymax + margin)
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    height = rgb.shape[0]
    positions: list[tuple[float, float] | None] = []
    for p in positions_of:
        if not p:
            positions.append(None)
            continue
        px, py = ax.transData.transform((p["x"], p["y"]))
        positions.append((float(px), float(height - py)))
    x0, y0 = ax.transData.transform((0.0, 0.0))
    x1 = ax.transData.transform((1.0, 0.0))[0]
    return PlanImage(rgb=rgb, positions=positions, meters_to_px=float(x1 - x0), state_colors=state_colors,
                     origin_px=(float(x0), float(height - y0)))


def episode_plan(episode: Any, width_px: int = 1200) -> PlanImage | None:
    """The plan of an `Episode` (from `timeline.load_episode`) with its trajectory, or None without a scene."""
    if episode.scene is None:
        return None
    try:
        import vlnpilot.report.floorplan  # noqa: F401
    except ImportError:
        return None
    task = episode.task
    return render_plan(episode.scene, trajectory=episode.trajectory(), states=episode.trajectory_states(),
                       collision=episode.collision_point(),
                       goal=[task.get("goal_room"), task.get("goal_target")],
                       positions_of=[e.pose for e in episode.entries], width_px=width_px,
                       movers=episode.mover_tracks(), events=episode.fired_events())


# -- benchmark plots ------------------------------------------------------------------------------------
def _save(fig: Figure, path: Path, dpi: int = 150) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi, facecolor="white")
    return path


def pilot_color(i: int) -> str:
    return PILOT_COLORS[i % len(PILOT_COLORS)]


def plot_success_rates(pilots: Sequence[str], successes: Sequence[int], totals: Sequence[int], path: Path) -> Path:
    """Bar chart of the success rate per pilot with its 95% Wilson interval."""
    with rc_context(STYLE):
        fig = Figure(figsize=HALF, layout="constrained")
        ax = fig.add_subplot()
        rates = [k / n if n else 0.0 for k, n in zip(successes, totals, strict=True)]
        ci = [wilson_interval(k, n) for k, n in zip(successes, totals, strict=True)]
        lo = [max(0.0, r - c[0]) for r, c in zip(rates, ci, strict=True)]  # never negative (matplotlib refuses)
        hi = [max(0.0, c[1] - r) for r, c in zip(rates, ci, strict=True)]
        x = np.arange(len(pilots))
        ax.bar(x, rates, width=0.6, color=[pilot_color(i) for i in range(len(pilots))], zorder=2)
        ax.errorbar(x, rates, yerr=[lo, hi], fmt="none", ecolor="#222", capsize=6, linewidth=1.2, zorder=3)
        for xi, r, k, n, c in zip(x, rates, successes, totals, ci, strict=True):
            ax.text(float(xi), c[1] + 0.03, f"{r:.0%}\n{k}/{n}", ha="center", va="bottom", fontsize=9)
        ax.set_xticks(x, pilots, rotation=0 if len(pilots) < 4 else 20, ha="center" if len(pilots) < 4 else "right")
        ax.set_ylim(0, 1.22)
        ax.set_yticks(np.linspace(0, 1, 6))
        ax.yaxis.set_major_formatter(ticker.PercentFormatter(1.0))
        ax.set_ylabel("success rate")
        ax.grid(axis="x", visible=False)
        return _save(fig, path)


def plot_failures_per_query(queries: Sequence[str], pilots: Sequence[str],
                            collisions: Mapping[str, Sequence[int]], exceeded: Mapping[str, Sequence[int]],
                            path: Path) -> Path:
    """Two panels of horizontal bars: collisions and steps exceeded per query (rows), one bar per pilot."""
    with rc_context(STYLE):
        height = max(3.2, 0.28 * len(queries) * max(1, len(pilots)) + 1.6)
        fig = Figure(figsize=(FULL_W, height), layout="constrained")
        axes = fig.subplots(1, 2, sharey=True)
        y = np.arange(len(queries))
        bar_h = 0.8 / max(1, len(pilots))
        for ax, data, title in ((axes[0], collisions, "Collisions"), (axes[1], exceeded, "Steps exceeded")):
            for i, pilot in enumerate(pilots):
                vals = list(data.get(pilot, [0] * len(queries)))
                ypos = y - 0.4 + bar_h * (i + 0.5)
                ax.barh(ypos, vals, height=bar_h * 0.9, color=pilot_color(i), label=pilot, zorder=2)
                for yp, v in zip(ypos, vals, strict=True):
                    if v:
                        ax.text(v + 0.05, yp, str(v), va="center", fontsize=8)
            top = max([1, *(v for vals in data.values() for v in vals)])
            ax.set_xlim(0, top + 0.8)
            ax.xaxis.set_major_locator(ticker.MaxNLocator(integer=True))
            ax.set_title(title)
            ax.set_xlabel("episodes")
            ax.grid(axis="y", visible=False)
        axes[0].set_yticks(y, queries)
        axes[0].invert_yaxis()
        axes[1].legend(loc="lower right", fontsize=8)
        return _save(fig, path)


def plot_cost_latency(pilots: Sequence[str], cost_per_episode: Mapping[str, Sequence[float]],
                      latency_per_call: Mapping[str, Sequence[float]], path: Path) -> Path:
    """Mean cost per episode (bars, with the spread as points) and model latency per call (box plots)."""
    with rc_context(STYLE):
        fig = Figure(figsize=(FULL_W, 4.0), layout="constrained")
        ax_cost, ax_lat = fig.subplots(1, 2)
        x = np.arange(len(pilots))
        rng = np.random.default_rng(0)
        for i, pilot in enumerate(pilots):
            costs = [c for c in cost_per_episode.get(pilot, []) if c is not None]
            mean = float(np.mean(costs)) if costs else 0.0
            ax_cost.bar(i, mean, width=0.6, color=pilot_color(i), alpha=0.85, zorder=2)
            if costs:
                ax_cost.scatter(i + rng.uniform(-0.15, 0.15, len(costs)), costs, s=10, color="#222", alpha=0.6,
                                zorder=3, linewidths=0)
            if mean:
                ax_cost.text(i, mean, f" ${mean:.4f}", ha="center", va="bottom", fontsize=8)
        ax_cost.set_xticks(x, pilots)
        ax_cost.set_ylim(bottom=0)
        if not any(c for vals in cost_per_episode.values() for c in vals):
            ax_cost.set_ylim(0, 1)
            ax_cost.text(0.5, 0.5, "no billed model calls", transform=ax_cost.transAxes, ha="center",
                         va="center", color="#666")
        ax_cost.set_ylabel("USD per episode")
        ax_cost.set_title("Cost per episode")
        ax_cost.grid(axis="x", visible=False)
        data = [[v for v in latency_per_call.get(p, []) if v is not None] or [0.0] for p in pilots]
        box = ax_lat.boxplot(data, positions=x, widths=0.5, patch_artist=True, showfliers=True,
                             medianprops={"color": "#222"})
        for i, patch in enumerate(box["boxes"]):
            patch.set_facecolor(pilot_color(i))
            patch.set_alpha(0.85)
        ax_lat.set_xticks(x, pilots)
        ax_lat.set_ylabel("seconds per model call")
        ax_lat.set_title("Latency per model call")
        ax_lat.grid(axis="x", visible=False)
        ax_lat.set_ylim(bottom=0)
        return _save(fig, path)


def plot_outcomes(pilots: Sequence[str], counts: Mapping[str, Mapping[str, int]], path: Path) -> Path:
    """Stacked horizontal bars: how each pilot's episodes ended."""
    with rc_context(STYLE):
        fig = Figure(figsize=HALF, layout="constrained")
        ax = fig.add_subplot()
        y = np.arange(len(pilots))
        left = np.zeros(len(pilots))
        for outcome in OUTCOME_ORDER:
            vals = np.array([counts.get(p, {}).get(outcome, 0) for p in pilots], dtype=float)
            if not vals.any():
                continue
            ax.barh(y, vals, left=left, color=OUTCOME_COLORS[outcome], label=OUTCOME_LABELS[outcome], height=0.6,
                    zorder=2)
            for yi, l, v in zip(y, left, vals, strict=True):
                if v:
                    ax.text(l + v / 2, float(yi), f"{int(v)}", ha="center", va="center", color="white", fontsize=9,
                            fontweight="bold")
            left += vals
        ax.set_yticks(y, pilots)
        ax.invert_yaxis()
        ax.set_xlabel("episodes")
        ax.xaxis.set_major_locator(ticker.MaxNLocator(integer=True))
        ax.grid(axis="y", visible=False)
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, fontsize=9)
        return _save(fig, path)
