"""Scenes by name. `load_scene("cabin")`, `load_scene("house:7?rooms=4")`; a bad name lists the known ones."""

from __future__ import annotations

from collections.abc import Callable

from vlnpilot.core.errors import UnknownNameError
from vlnpilot.core.registry import Registry
from vlnpilot.scene.cabin import cabin, cabin_v1
from vlnpilot.scene.houses import PREFIX as HOUSE_PREFIX
from vlnpilot.scene.houses import load_house
from vlnpilot.scene.model import Door, Room, Scene, Solid, Spawn, Target

# Scenes by name; a third party registers with `SCENES.register("NAME")` or the `vlnpilot.scenes` entry points.
SCENES: Registry[Callable[[], Scene]] = Registry("scene", group="vlnpilot.scenes")
SCENES.add("cabin", cabin)
SCENES.add("cabin-v1", cabin_v1)


def load_scene(name: str | Scene = "cabin") -> Scene:
    if isinstance(name, Scene):
        return name
    if str(name).strip().lower().startswith(HOUSE_PREFIX):  # procedural: house:SEED[?rooms=N&types=...]
        return load_house(str(name))
    key = str(name).strip().lower()
    if key not in SCENES:
        raise UnknownNameError("scene", name, [*SCENES, "house:SEED"])
    return SCENES.get(key)()


__all__ = ["SCENES", "Door", "Room", "Scene", "Solid", "Spawn", "Target", "load_scene"]
