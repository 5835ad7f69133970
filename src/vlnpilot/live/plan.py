"""The floor plan for the live page: the report's plan without legend or title, filling the whole image, so
that the page can place the trajectory with the plan's world bounds (x to the right, y up)."""

from __future__ import annotations

import io

from matplotlib.colors import to_hex
from matplotlib.figure import Figure

from vlnpilot.report.floorplan import EVENT_COLOR, MOVER_COLORS, STATE_COLORS, draw_floorplan
from vlnpilot.report.timeline import event_point
from vlnpilot.scene.model import Scene

WIDTH_IN, DPI = 6.0, 100


def plan_png(scene: Scene) -> tuple[bytes, dict[str, float]]:
    """The plan as PNG bytes and its bounds {xmin, xmax, ymin, ymax} in metres."""
    (x0, y0), (x1, y1) = scene.bounds
    height = WIDTH_IN * (y1 - y0 + 0.6) / (x1 - x0 + 0.6)
    fig = Figure(figsize=(WIDTH_IN, height), dpi=DPI)
    ax = fig.add_axes((0, 0, 1, 1))
    draw_floorplan(scene, ax)
    legend = ax.get_legend()
    if legend is not None:
        legend.remove()
    ax.set_title("")
    ax.set_axis_off()
    ax.set_aspect("auto")  # the figure already has the plan's proportions; the axes must fill it exactly
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    (xmin, xmax), (ymin, ymax) = ax.get_xlim(), ax.get_ylim()
    return buf.getvalue(), {"xmin": xmin, "xmax": xmax, "ymin": ymin, "ymax": ymax}


def state_colors() -> dict[str, str]:
    """The report's colour of each FSM state, as CSS colours."""
    return {state: to_hex(color) for state, color in STATE_COLORS.items()}



def event_marks(scene: Scene | None) -> dict[str, object]:
    """Issue 24: where each event of the scene's scenario happens ({name: [x, y]}; a mover's is where the page
    first sees it), and the report's colours of movers and events, for the page to draw them as the report does."""
    points: dict[str, list[float]] = {}
    for e in (scene.scenario.events if scene is not None and scene.scenario is not None else ()):
        at = event_point(scene, {"kind": e.kind, "name": e.name, "params": e.params()}, {})
        if at is not None:
            points[str(e.name)] = [round(at[0], 4), round(at[1], 4)]
    return {"points": points, "mover_colors": MOVER_COLORS, "event_color": EVENT_COLOR}
