"""Procedural houses: `generate_house(seed, rooms=..., types=...)` -> a furnished multi-room Scene.

Scene names: `house:SEED`, `house:SEED?rooms=4`, `house:SEED?rooms=5&types=study,kitchen`. The same name
gives a byte-identical MJCF on every machine: all randomness comes from `random.Random` seeded with a
string (SHA-512 based, independent of PYTHONHASHSEED) and every coordinate is rounded.

Pipeline: room programme (which rooms) -> floor plan (layout.py, the corridor-spine method) -> shell
(house_structure.py) -> furniture (furnish.py) -> targets and spawns -> validation (validate.py). A house
that fails validation is refused with its reason and rebuilt from the next sub-seed (at most MAX_ATTEMPTS).
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass
from functools import lru_cache

from vlnpilot.core.errors import ConfigError, VLNPilotError
from vlnpilot.scene.furnish import FurnishError, furnish_room, place_spawn
from vlnpilot.scene.house_structure import furniture_materials, lights, room_materials, shell, to_door
from vlnpilot.scene.layout import HALLWAY, Plan, plan_house
from vlnpilot.scene.model import Room, Scene
from vlnpilot.scene.parts import WALL_H
from vlnpilot.scene.validate import HouseInvalid, validate

PREFIX = "house:"
MIN_ROOMS, MAX_ROOMS = 2, 6
MAX_ATTEMPTS = 5
SEEDS = 10**9  # house:0 ... house:999999999 (nine digits in a scene name)
FLIGHT_Z = 1.0
ROOM_TYPES = ("living_room", "kitchen", "bedroom", "bathroom", "study", "hallway")
# room type -> (display name, aliases, floor-plan colour); a second bedroom is "second bedroom"
ROOM_INFO: dict[str, tuple[str, tuple[str, ...], tuple[float, float, float]]] = {
    "living_room": ("living room", ("lounge", "sitting room"), (0.45, 0.80, 0.45)),
    "kitchen": ("kitchen", ("cooking area",), (0.95, 0.60, 0.35)),
    "bedroom": ("bedroom", ("bed room",), (0.85, 0.40, 0.85)),
    "bedroom_2": ("second bedroom", ("guest bedroom", "guest room"), (0.60, 0.45, 0.90)),
    "bathroom": ("bathroom", ("bath room", "restroom", "washroom"), (0.95, 0.85, 0.30)),
    "study": ("study", ("office", "home office"), (0.45, 0.70, 0.90)),
    "hallway": ("hallway", ("hall", "corridor"), (0.75, 0.75, 0.75)),
}


class HouseSpecError(ConfigError):
    """A malformed house name or parameter; the message names the valid choices."""


class HouseGenerationError(VLNPilotError):
    """No valid house within MAX_ATTEMPTS sub-seeds; the message lists every refusal."""


@dataclass(frozen=True)
class HouseSpec:
    seed: int
    rooms: int | None = None  # None: drawn from the seed (2..6)
    types: tuple[str, ...] = ()  # room types the house must contain

    @property
    def name(self) -> str:
        params = ([f"rooms={self.rooms}"] if self.rooms is not None else []) + \
            ([f"types={','.join(self.types)}"] if self.types else [])
        return f"{PREFIX}{self.seed}" + ("?" + "&".join(params) if params else "")


def parse_house_name(name: str) -> HouseSpec:
    """`house:SEED[?rooms=N&types=a,b]` -> HouseSpec; anything else raises HouseSpecError."""
    body = name.strip()[len(PREFIX):] if name.strip().lower().startswith(PREFIX) else name.strip()
    seed_text, _, query = body.partition("?")
    if not re.fullmatch(r"\d{1,9}", seed_text.strip()):
        raise HouseSpecError(f"bad house seed {seed_text!r} in {name!r}: give a whole number 0..999999999, "
                             "e.g. house:7 or house:7?rooms=4")
    rooms: int | None = None
    types: tuple[str, ...] = ()
    for part in filter(None, query.split("&")):
        key, _, value = part.partition("=")
        key = key.strip().lower()
        if key == "rooms":
            if not re.fullmatch(r"\d+", value.strip()) or not MIN_ROOMS <= int(value) <= MAX_ROOMS:
                raise HouseSpecError(f"bad rooms={value!r} in {name!r}: rooms must be {MIN_ROOMS}..{MAX_ROOMS}")
            rooms = int(value)
        elif key == "types":
            types = tuple(t.strip().lower() for t in value.split(",") if t.strip())
            for t in types:
                if t not in ROOM_TYPES:
                    raise HouseSpecError(f"unknown room type {t!r} in {name!r}; valid room types: "
                                         f"{', '.join(ROOM_TYPES)}")
        else:
            raise HouseSpecError(f"unknown house parameter {key!r} in {name!r}; valid parameters: rooms, types")
    spec = HouseSpec(int(seed_text), rooms, types)
    _programme(random.Random(0), spec)  # refuses impossible combinations now, with the reason
    return spec


def _programme(rng: random.Random, spec: HouseSpec) -> tuple[list[tuple[str, str]], bool]:
    """(room id, programme) pairs and whether the kitchen opens onto the living room."""
    wanted = [t for t in dict.fromkeys(spec.types) if t != "living_room"]
    n = spec.rooms if spec.rooms is not None else rng.randint(MIN_ROOMS, MAX_ROOMS)
    hallway = n >= 4 or "hallway" in wanted
    if hallway and n < 3:
        raise HouseSpecError(f"{spec.name}: a hallway needs rooms=3 or more")
    if "hallway" in wanted:
        wanted.remove("hallway")
    if n - 1 - hallway < len(wanted):
        raise HouseSpecError(f"{spec.name}: {n} rooms cannot hold living_room, {', '.join(wanted)}"
                             + (" and a hallway" if hallway else "") + "; ask for more rooms")
    base = [t for t in ("bedroom", "bathroom") if t not in wanted] if n >= 4 else []  # a home has them if it can
    others = wanted + base[: n - 1 - hallway - len(wanted)]
    pool = ["kitchen", "study", "bedroom", "bathroom"]
    rng.shuffle(pool)
    free = n - 1 - hallway - len(others)
    for t in pool:
        if free == 0:
            break
        if t not in others or (t == "bedroom" and others.count("bedroom") < 2):
            others.append(t)
            free -= 1
    ids: list[tuple[str, str]] = [("living_room", "living_room")] + ([(HALLWAY, HALLWAY)] if hallway else [])
    for t in others:
        if t == "bedroom" and ("bedroom", "bedroom") in ids:
            ids.append(("bedroom_2", "bedroom_2"))
        else:
            ids.append((t, t))
    kitchen_joined = hallway and "kitchen" in others and rng.random() < 0.5
    return ids, kitchen_joined


def load_house(name: str) -> Scene:
    spec = parse_house_name(name)
    return generate_house(spec.seed, rooms=spec.rooms, types=spec.types)


@lru_cache(maxsize=64)
def generate_house(seed: int, rooms: int | None = None, types: tuple[str, ...] = ()) -> Scene:
    """The house of `seed` (cached: scenes are immutable). Raises HouseGenerationError if every sub-seed fails."""
    spec = HouseSpec(int(seed), rooms, tuple(types))
    refusals = []
    for sub in range(MAX_ATTEMPTS):
        rng = random.Random(f"vln-pilot-house/{spec.name}/{sub}")
        try:
            scene = _build(rng, spec, sub)
            validate(scene)
            return scene
        except (FurnishError, HouseInvalid) as exc:
            refusals.append(f"sub-seed {sub}: {exc}")
    raise HouseGenerationError(f"{spec.name}: no valid house in {MAX_ATTEMPTS} sub-seeds: " + "; ".join(refusals))


def _build(rng: random.Random, spec: HouseSpec, sub: int) -> Scene:
    ids, joined = _programme(random.Random(f"vln-pilot-house/{spec.name}"), spec)  # the same for every sub-seed
    plan = plan_house(rng, [(rid, prog if prog != "bedroom_2" else "bedroom") for rid, prog in ids], joined)
    programme = dict(ids)
    solids = shell(rng, plan)
    materials = furniture_materials(rng)
    targets, spawns, rooms = [], [], []
    for r in plan.rooms:
        name, aliases, colour = ROOM_INFO[programme[r.id]]
        rooms.append(Room(r.id, name, ((r.x0, r.y0), (r.x1, r.y0), (r.x1, r.y1), (r.x0, r.y1)), aliases, colour))
        materials += room_materials(rng, r)
        furnished = furnish_room(rng, plan, r, programme[r.id])
        solids += furnished.solids
        targets += furnished.targets
        spawn = place_spawn(rng, r, name, furnished.tall, FLIGHT_Z)
        if spawn is None:
            raise FurnishError(f"no free spawn point in the {r.id}")
        spawns.append(spawn)
    bx0, by0, bx1, by1 = plan.bounds
    return Scene(
        name=spec.name, description=_describe(plan, programme, sub), rooms=tuple(rooms),
        doors=tuple(to_door(d) for d in plan.doors), targets=tuple(targets), spawns=tuple(spawns),
        solids=tuple(solids), materials=tuple(materials), lights=tuple(lights(rng, plan)),
        bounds=((bx0 - 0.15, by0 - 0.15), (bx1 + 0.15, by1 + 0.15)), ceiling_height=WALL_H, flight_altitude=FLIGHT_Z,
        headlight=round(rng.uniform(0.3, 0.4), 3))


def _describe(plan: Plan, programme: dict[str, str], sub: int) -> str:
    names = ", ".join(ROOM_INFO[programme[r.id]][0] for r in plan.rooms)
    shut = sum(not d.open for d in plan.doors)
    return (f"A procedural house of {len(plan.rooms)} rooms ({names}); {plan.method} plan, "
            f"{sum(d.open for d in plan.doors)} open and {shut} closed doors (sub-seed {sub}).")
