"""What both report pages share: the Jinja2 environment (autoescape on), number formatting, the stylesheet.

The markup lives in `report/templates/` (`base.html.j2` is the page frame, `macros.html.j2` the small pieces);
Jinja2 escapes every value a template prints, so model text (untrusted) can only ever show as text. Python
code here and in the page modules computes values, never markup. The stylesheet and the scripts are package data
(`report/static/`), read once and inlined into every page so that a page opens from disk with no server and no
network.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from importlib.resources import files
from pathlib import Path
from typing import Any

from jinja2 import Environment, PackageLoader, StrictUndefined

REPORT = "report.html"
FLOORPLAN = "floorplan.png"
RESULTS = "results.jsonl"
PLOTS = "plots"


def static_text(name: str) -> str:
    """A file of `report/static/` as text (through importlib.resources, so it also works from a wheel or zip)."""
    return (files("vlnpilot.report") / "static" / name).read_text(encoding="utf-8")


CSS = static_text("report.css")


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
    from vlnpilot.core.commands import COMMANDS

    cmd = COMMANDS.get(str(code).strip().upper())
    return cmd.description if cmd is not None else "not a command"


def _image_size(path: Path) -> tuple[int, int] | None:
    from PIL import Image

    try:
        with Image.open(path) as im:
            return im.size
    except OSError:
        return None


def room_view(scene: Any, room_id: str | None) -> dict[str, str | None]:
    """A room as the `room_chip` macro shows it: its name and floor-plan colour (the paper's colours), or the raw
    id with no colour when the scene does not know it."""
    room = scene.find_room(room_id) if scene is not None and room_id else None
    if room is None:
        return {"name": room_id or "–", "color": None}
    return {"name": room.name, "color": _css_rgb(room.color)}


def _blank_none(value: Any) -> Any:
    return "" if value is None else value


def _environment() -> Environment:
    env = Environment(loader=PackageLoader("vlnpilot.report", "templates"), autoescape=True, finalize=_blank_none,
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters.update(num=_num, int=_int, cost=_cost, command_text=_command_text)
    env.globals.update(CSS=CSS)
    return env


TEMPLATES = _environment()


def render(template: str, **values: Any) -> str:
    """A page from `report/templates/`, every printed value escaped."""
    return TEMPLATES.get_template(template).render(**values)
