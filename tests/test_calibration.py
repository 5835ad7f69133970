"""The prompts' visual rules agree with the success monitor: rendered, not assumed.

Reach Object tells the pilot how wide each kind of object must look to be within the success distance
(`success.OBJECT_CLOSE_CUES`; a visible floor in front of it would put it beyond 2 m). Here every target of both
cabins and of a dozen procedural houses is rendered on its facing axis well inside the monitor's success distance,
just beyond it and at twice it: each kind's cue must hold at the first and fail at the others. The widest kinds
fill the image from beyond the distance, so their cue adds half a metre: they must not fill it yet from that far.
A change of threshold, camera or furniture that breaks the agreement fails here (doubling
`SuccessConfig.object_distance_m` without touching the prompts does; so does one 65 % rule for every kind).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from vlnpilot.core.records import Pose
from vlnpilot.prompting.render import render_state_prompt, system_prompt
from vlnpilot.scene.model import target_kind
from vlnpilot.sim import Simulator
from vlnpilot.sim.target_views import facing_view, free_standpoint, view, width_fraction
from vlnpilot.tasks.success import (
    OBJECT_CLOSE_CUES,
    OBJECT_CLOSE_WIDTH_FRACTION,
    SuccessConfig,
    close_cue,
    visual_cue_values,
)

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
    if not cols.size:  # not in view at all (another piece stands before it)
        return False
    bottom = seg[-3:, cols[0]: cols[-1] + 1]
    return bool(np.isin(bottom, _ids(sim, "floor")).any())


SCENES = ("cabin", "cabin-v1", *(f"house:{seed}" for seed in range(12)))
FACTORS = (0.7, 1.1, 2.0)


@dataclass(frozen=True)
class Seen:
    """One target seen from `distance` in front of it: how wide it looks, and whether floor shows before it."""

    scene: str
    target_id: str
    distance: float
    width: float
    floor_before: bool

    def looks_close(self) -> bool:
        """The Reach Object stop rule for this target's kind, without its extra half metre."""
        return self.width >= close_cue(self.target_id).width_fraction and not self.floor_before


@pytest.fixture(scope="module")
def seen() -> list[Seen]:
    """Every target of SCENES from every distance it can be viewed from (rendered once for all the tests)."""
    out = []
    for name in SCENES:
        with Simulator(name) as sim:
            for target in sim.scene.targets:
                cue = close_cue(target.id)
                for d in {*(k * SUCCESS_M for k in FACTORS), SUCCESS_M + cue.then_m}:
                    if free_standpoint(sim, target.id, d):
                        seg, ids = facing_view(sim, target.id, d), sim.target_geoms[target.id]
                        out.append(Seen(name, target.id, round(d, 3), width_fraction(seg, ids),
                                        _floor_at_bottom(sim, seg, ids)))
    return out


def _kinds(seen: list[Seen]) -> set[str]:
    return {target_kind(s.target_id) for s in seen}


def test_every_kind_is_rendered() -> None:
    kinds = {kind for cue in OBJECT_CLOSE_CUES for kind in cue.kinds}
    assert kinds >= {"refrigerator", "mirror", "sink", "toilet", "desk", "tv", "bed"}


def test_every_cue_holds_well_inside_the_success_distance(seen: list[Seen]) -> None:
    """A pilot that obeys its kind's cue can stop: every target passes it from 0.7 of the success distance
    (the widest kinds then fly their extra half metre, which the next test bounds)."""
    near = [s for s in seen if s.distance == round(0.7 * SUCCESS_M, 3)]
    assert _kinds(near) >= {"refrigerator", "mirror", "sink", "toilet", "plant", "desk", "tv", "bed", "wardrobe"}
    far_off = [f"{s.scene} {s.target_id}: {s.width:.0%}" for s in near if not s.looks_close()
               and not close_cue(s.target_id).then_m]
    assert not far_off, f"looks far at 0.7x: {far_off}"


@pytest.mark.parametrize("factor", [1.1, 2.0])
def test_no_cue_holds_beyond_the_success_distance(seen: list[Seen], factor: float) -> None:
    """A pilot that obeys its kind's cue never declares too early: no target passes it from beyond the distance,
    and the widest kinds do not yet fill the image from their extra half metre beyond it."""
    beyond = [s for s in seen if s.distance == round(factor * SUCCESS_M, 3) and not close_cue(s.target_id).then_m]
    beyond += [s for s in seen if close_cue(s.target_id).then_m
               and s.distance == round(SUCCESS_M + close_cue(s.target_id).then_m, 3)]
    if factor < 1.5:  # just beyond the distance there is room in every scene; 2 m in front of a mirror there is not
        assert _kinds(beyond) >= {"refrigerator", "mirror", "sink", "toilet", "desk", "tv", "bed"}
    too_early = [f"{s.scene} {s.target_id} at {s.distance} m: {s.width:.0%}" for s in beyond if s.looks_close()]
    assert not too_early, f"looks close from too far: {too_early}"


def test_one_width_for_every_kind_would_disagree_with_the_monitor(seen: list[Seen]) -> None:
    """Why the cue names the kinds: with the cabin's 65 % for everything, a desk or a TV looks close from 1.1 m
    and a toilet never does within 1 m."""
    at = {(target_kind(s.target_id), s.distance): s.width for s in seen}
    assert at[("desk", 1.1)] >= OBJECT_CLOSE_WIDTH_FRACTION and at[("tv", 1.1)] >= OBJECT_CLOSE_WIDTH_FRACTION
    assert at[("toilet", 0.7)] < OBJECT_CLOSE_WIDTH_FRACTION


def test_height_is_no_distance_cue(sims) -> None:
    """Why the old rule ("a third of the width or height") failed: a fridge fills the height from 2 m."""
    sim, target_id = sims["cabin"], "refrigerator"
    seg = facing_view(sim, target_id, 2 * SUCCESS_M)
    rows = np.flatnonzero(np.isin(seg, list(sim.target_geoms[target_id])).any(axis=1))
    assert (rows[-1] - rows[0] + 1) / seg.shape[0] > 0.5


def test_prompts_state_the_calibrated_numbers() -> None:
    values = visual_cue_values()
    text = render_state_prompt("Reach Object")
    for cue in OBJECT_CLOSE_CUES:  # every kind's cue, with its number, is in the prompt
        assert cue.shown_as in text
    assert values["close_cues"] in text and "a toilet: 25 % of the image width" in text
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
