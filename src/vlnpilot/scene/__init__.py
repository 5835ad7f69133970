"""Scenes by name. `load_scene("cabin")`; a bad name lists the known ones."""

from __future__ import annotations

from collections.abc import Callable

from vlnpilot.errors import UnknownNameError
from vlnpilot.scene.cabin import cabin, cabin_v1
from vlnpilot.scene.model import Door, Room, Scene, Solid, Spawn, Target

SCENES: dict[str, Callable[[], Scene]] = {"cabin": cabin, "cabin-v1": cabin_v1}


def load_scene(name: str | Scene = "cabin") -> Scene:
    if isinstance(name, Scene):
        return name
    try:
        return SCENES[str(name).strip().lower()]()
    except KeyError:
        raise UnknownNameError("scene", name, SCENES) from None


__all__ = ["SCENES", "Door", "Room", "Scene", "Solid", "Spawn", "Target", "load_scene"]
