"""One answered call before a timed one: a model pilot's first request in a cold process (the SDK's lazy imports,
the first connection) can outlast a short step deadline and then send nothing at all."""

from __future__ import annotations

from typing import Any

from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.episode.loop import run_episode
from vlnpilot.tasks.task import parse_query

WARM_UP = {"room": "living_room", "movement": "C1", "state": "Recognize Room", "description": "warm-up",
           "door_position": "not_visible"}


def warm_up(fake: Any, sim: Any, pilot: Any) -> int:
    """Fly one answered step of `pilot` against `fake` in the cabin's living room; the requests the fake has seen."""
    fake.push("decision", decision=WARM_UP)
    run_episode(sim, pilot, parse_query("Go to the bedroom", sim.scene), EpisodeConfig(max_steps=1),
                spawn="living_room")
    return len(fake.requests)
