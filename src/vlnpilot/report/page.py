"""The frame both report pages share: escaping, number formatting, the page skeleton and its stylesheet.

The stylesheet and the scripts are package data (`report/static/`), read once and inlined into every page so
that a page opens from disk with no server and no network.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Mapping
from importlib.resources import files
from pathlib import Path
from typing import Any

REPORT = "report.html"
FLOORPLAN = "floorplan.png"
RESULTS = "results.jsonl"
PLOTS = "plots"


def static_text(name: str) -> str:
    """A file of `report/static/` as text (through importlib.resources, so it also works from a wheel or zip)."""
    return (files("vlnpilot.report") / "static" / name).read_text(encoding="utf-8")


CSS = static_text("report.css")


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


def _room_chip(scene: Any, room_id: str | None) -> str:
    """A room name with a swatch of its floor-plan colour (the paper's colours); plain text when unknown."""
    room = scene.find_room(room_id) if scene is not None and room_id else None
    if room is None:
        return esc(room_id or "–")
    return f'<span class="room" style="--room:{_css_rgb(room.color)}">{esc(room.name)}</span>'


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
