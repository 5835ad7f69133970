"""Suites over procedural houses: `houses` (20 houses x 5 queries) and `houses:SEEDS` (any seeds).

SEEDS is a comma-separated list of seeds and ranges: `houses:0-99`, `houses:3,5,10-12`. Each row names its
house (`scene: house:SEED`), so a bench stays reproducible. Per house, five queries drawn by the house
seed mix room goals and object goals, and one-door and two-or-more-door routes where the house has both.
"""

from __future__ import annotations

import random
import re
from typing import Any

from vlnpilot.core.errors import ConfigError
from vlnpilot.scene import load_scene
from vlnpilot.scene.model import Scene

DEFAULT_SEEDS = tuple(range(20))
QUERIES_PER_HOUSE = 5
MAX_SEEDS = 1000
MAX_STEPS = 200  # the oracle's longest route in the default suite takes 121 steps of the paper profile
_NAME_RE = re.compile(r"^houses(?::(.*))?$", re.IGNORECASE)


def is_house_suite(name: str) -> bool:
    return bool(_NAME_RE.match(str(name).strip()))


def parse_seeds(text: str) -> tuple[int, ...]:
    """'0-19' or '3,5,10-12' -> seeds, in order, without repeats; bad text raises ConfigError."""
    seeds: list[int] = []
    for part in text.split(","):
        m = re.fullmatch(r"\s*(\d{1,9})\s*(?:-\s*(\d{1,9})\s*)?", part)
        if not m or (m.group(2) and int(m.group(2)) < int(m.group(1))):
            raise ConfigError(f"bad house seeds {text!r}: give seeds and ranges such as houses:0-19 or houses:3,5,8-9")
        lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
        seeds += [s for s in range(lo, hi + 1) if s not in seeds]
        if len(seeds) > MAX_SEEDS:
            raise ConfigError(f"houses:{text} asks for more than {MAX_SEEDS} houses")
    return tuple(seeds)


def house_suite_dict(name: str) -> dict[str, Any]:
    """The suite `houses[:SEEDS]` as plain data (what a suite YAML file would hold)."""
    m = _NAME_RE.match(name.strip())
    seeds = parse_seeds(m.group(1)) if m and m.group(1) else DEFAULT_SEEDS
    rows = [row for seed in seeds for row in house_rows(seed)]
    return {"name": name.strip().lower().replace(":", "-"),
            "description": f"{len(seeds)} procedural houses x {QUERIES_PER_HOUSE} queries (room and object goals, "
                           "one-door and multi-door routes)",
            "scene": f"house:{seeds[0]}", "repetitions": 1, "max_steps": MAX_STEPS, "seed": 0, "profile": "paper",
            "rows": rows}


def house_rows(seed: int) -> list[dict[str, Any]]:
    scene = load_scene(f"house:{seed}")
    rng = random.Random(f"vln-pilot-house-suite/{seed}")
    routes = _routes(scene)
    one = [r for r in routes if r[3] == 1]
    many = [r for r in routes if r[3] >= 2]
    rooms_, objects = [r for r in routes if r[2] is None], [r for r in routes if r[2] is not None]
    picked: list[tuple[str, str, str | None, int]] = []
    for pool in (many, one, objects, rooms_, objects, rooms_, routes):  # cover each kind first, then fill
        options = [r for r in pool if r not in picked and r[0] not in {p[0] for p in picked[-1:]}] or \
            [r for r in pool if r not in picked]
        if options and len(picked) < QUERIES_PER_HOUSE:
            picked.append(options[rng.randrange(len(options))])
    while len(picked) < QUERIES_PER_HOUSE:  # a two-room house has few routes: repeat from another spawn
        picked.append(routes[rng.randrange(len(routes))])
    out = []
    for i, (spawn, goal_room, target, _) in enumerate(picked):
        room = scene.room(goal_room)
        query = f"Find the {scene.target(target).name} in the {room.name}" if target else f"Go to the {room.name}"
        out.append({"id": f"h{seed}-{i + 1}-{spawn}-{target or goal_room}", "scene": f"house:{seed}",
                    "spawn": spawn, "query": query,
                    "goal": {"room": goal_room, **({"target": target} if target else {})}})
    return out


def _routes(scene: Scene) -> list[tuple[str, str, str | None, int]]:
    """(spawn, goal room, target or None, doors crossed) for every spawn and every other room."""
    out: list[tuple[str, str, str | None, int]] = []
    for s in scene.spawns:
        for r in scene.rooms:
            if r.id == s.room:
                continue
            doors = len(scene.room_path(s.room, r.id)) - 1
            out.append((s.id, r.id, None, doors))
            out += [(s.id, r.id, t.id, doors) for t in scene.targets if t.room == r.id]
    return out
