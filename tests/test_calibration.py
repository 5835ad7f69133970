"""The prompts' visual rules agree with the success monitor: rendered, not assumed.

Reach Object tells the pilot that an object is within the success distance only when it spans at least
OBJECT_CLOSE_WIDTH_FRACTION of the image width (a visible floor in front of it would put it beyond 2 m). Here
every target is rendered on its facing axis well inside the monitor's success distance, just beyond it and at
twice it: the stated rule must hold at the first and fail at the others. A change of threshold, camera or
furniture that breaks the agreement fails here (doubling `SuccessConfig.object_distance_m` without touching the
prompts does).
"""

from __future__ import annotations

import numpy as np
import pytest

from vlnpilot.prompting import render_state_prompt, system_prompt
from vlnpilot.sim import Simulator
from vlnpilot.sim.target_views import facing_view, free_standpoint, view, width_fraction
from vlnpilot.success import OBJECT_CLOSE_WIDTH_FRACTION, SuccessConfig, visual_cue_values
from vlnpilot.types import Pose

SUCCESS_M = SuccessConfig().object_distance_m


@pytest.fixture(scope="module")
def sim():
    with Simulator("cabin") as s:
        yield s


@pytest.fixture(scope="module")
def sims():
    """Both cabins: the v2 bedroom and bathroom are too shallow to stand 2 m in front of the mirror and the sink."""
    with Simulator("cabin") as v2, Simulator("cabin-v1") as v1:
        yield {"cabin": v2, "cabin-v1": v1}


def _ids(sim: Simulator, prefix: str) -> list[int]:
    return [i for i in range(sim.model.ngeom) if sim.geom_name(i).startswith(prefix)]


def _floor_at_bottom(sim: Simulator, seg: np.ndarray, ids) -> bool:
    """Is floor visible in the bottom rows, below the object (within its columns)?"""
    cols = np.flatnonzero(np.isin(seg, list(ids)).any(axis=0))
    bottom = seg[-3:, cols[0]: cols[-1] + 1]
    return bool(np.isin(bottom, _ids(sim, "floor")).any())


def object_looks_close(sim: Simulator, target_id: str, distance: float) -> bool:
    """The Reach Object stop rule, evaluated on a render: wide enough and no floor in front."""
    seg = facing_view(sim, target_id, distance)
    ids = sim.target_geoms[target_id]
    return width_fraction(seg, ids) >= OBJECT_CLOSE_WIDTH_FRACTION and not _floor_at_bottom(sim, seg, ids)


TARGETS = ["refrigerator", "mirror", "sink"]


@pytest.mark.parametrize("target_id", TARGETS)
def test_stop_rule_holds_well_inside_the_success_distance(sims, target_id: str) -> None:
    """A pilot that obeys the rule can stop: every target passes it from 0.7 of the success distance."""
    for name, sim in sims.items():
        assert object_looks_close(sim, target_id, 0.7 * SUCCESS_M), f"{name} {target_id}: 'far' at 0.7x"


@pytest.mark.parametrize("factor", [1.1, 2.0])
@pytest.mark.parametrize("target_id", TARGETS)
def test_stop_rule_fails_beyond_the_success_distance(sims, target_id: str, factor: float) -> None:
    """A pilot that obeys the rule never declares too early: no target passes it from beyond the distance."""
    checked = 0
    for name, sim in sims.items():
        if not free_standpoint(sim, target_id, factor * SUCCESS_M):
            continue  # the room is too shallow, or furniture stands there
        assert not object_looks_close(sim, target_id, factor * SUCCESS_M), f"{name} {target_id}: 'close' at {factor}x"
        checked += 1
    if factor < 1.5:  # just beyond the distance there is always room; 2 m in front of the mirror there is not
        assert checked, f"no cabin has room to view the {target_id} from {factor * SUCCESS_M} m"


def test_height_is_no_distance_cue(sims) -> None:
    """Why the old rule ("a third of the width or height") failed: a fridge fills the height from 2 m."""
    sim, target_id = sims["cabin"], "refrigerator"
    seg = facing_view(sim, target_id, 2 * SUCCESS_M)
    rows = np.flatnonzero(np.isin(seg, list(sim.target_geoms[target_id])).any(axis=1))
    assert (rows[-1] - rows[0] + 1) / seg.shape[0] > 0.5


def test_prompts_state_the_calibrated_numbers() -> None:
    values = visual_cue_values()
    text = render_state_prompt("Reach Object")
    assert f"at least {values['close_width_pct']} of the image width" in text
    assert f"within {values['success_distance']}" in text
    assert "third of its width or height" not in text  # the rule that disagreed with the monitor


def _door_frame_visible(sim: Simulator, door_id: str, before_m: float) -> tuple[bool, bool]:
    """(left jamb visible, right jamb visible), centred on the doorway, `before_m` before its plane."""
    door = next(d for d in sim.scene.doors if d.id == door_id)
    nx, ny = door.normal
    seg = view(sim, Pose(door.center[0] - before_m * nx, door.center[1] - before_m * ny, sim.scene.flight_altitude,
                         door.normal_deg))
    return (bool(np.isin(seg, _ids(sim, f"{door_id}_frame_left")).any()),
            bool(np.isin(seg, _ids(sim, f"{door_id}_frame_right")).any()))


@pytest.mark.parametrize("door_id", ["door_living_bedroom", "door_bedroom_bathroom"])
def test_door_frame_leaves_the_image_about_half_a_metre_before_the_doorway(sim: Simulator, door_id: str) -> None:
    """The system prompt says a frame that has left the image does not mean the drone is through."""
    assert "its frame leaves the sides of the image, when the drone is still about half a metre before it" \
        in system_prompt()
    assert _door_frame_visible(sim, door_id, 1.0) == (True, True)
    assert _door_frame_visible(sim, door_id, 0.35) == (False, False)  # still 0.35 m before the plane
