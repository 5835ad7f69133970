"""Small, valid pilot inputs for tests (no simulator needed)."""

from __future__ import annotations

from typing import Any

import numpy as np

from vlnpilot.core.decision import PilotInput
from vlnpilot.core.fsm import State

SAMPLE_MAP: dict[str, Any] = {
    "nodes": [{"id": "hall", "name": "Hall"}, {"id": "kitchen", "name": "Kitchen"},
              {"id": "bedroom", "name": "Bedroom"}],
    "edges": [{"from": "hall", "to": "kitchen"}, {"from": "hall", "to": "bedroom"}],
}


def sample_image(height: int = 48, width: int = 64, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, size=(height, width, 3), dtype=np.uint8)


def sample_input(state: State | str = State.SEARCH_OBJECT, **overrides: Any) -> PilotInput:
    fields: dict[str, Any] = {
        "image": sample_image(),
        "query": "Find the red cup in the kitchen",
        "topological_map": SAMPLE_MAP,
        "state": State(state) if isinstance(state, str) else state,
        "previous_movement": "B1",
        "step": 3,
    }
    fields.update(overrides)
    return PilotInput(**fields)
