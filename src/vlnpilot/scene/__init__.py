"""Scenes by name. `load_scene("cabin")`, `load_scene("house:7?rooms=4")`; a bad name lists the known ones."""

from __future__ import annotations

from collections.abc import Callable

from vlnpilot.errors import UnknownNameError
from vlnpilot.scene.cabin import cabin, cabin_v1
from vlnpilot.scene.houses import PREFIX as HOUSE_PREFIX
from vlnpilot.scene.houses import load_house
from vlnpilot.scene.model import Door, Room, Scene, Solid, Spawn, Target

SCENES: dict[str, Callable[[], Scene]] = {"cabin": cabin, "cabin-v1": cabin_v1}


def load_scene(name: str | Scene = "cabin") -> Scene:
    if isinstance(name, Scene):
        return name
    if str(name).strip().lower().startswith(HOUSE_PREFIX):  # procedural: house:SEED[?rooms=N&types=...]
        return load_house(str(name))
    try:
        return SCENES[str(name).strip().lower()]()
    except KeyError:
        raise UnknownNameError("scene", name, [*SCENES, "house:SEED"]) from None


__all__ = ["SCENES", "Door", "Room", "Scene", "Solid", "Spawn", "Target", "load_scene"]
