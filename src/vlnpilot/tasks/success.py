"""The success monitor's thresholds, and what the front camera shows at them: one source for monitor and prompts.

The prompts state visual criteria ("close enough", "through the door") in terms the front image shows. Those
criteria must agree with the monitor that judges the episode; the numbers live here, beside the thresholds,
and `tests/test_calibration.py` renders the scene to check that they still separate success from failure.
"""

from __future__ import annotations

from dataclasses import dataclass

from vlnpilot.core.commands import COMMANDS
from vlnpilot.scene.model import target_kind


@dataclass(frozen=True)
class SuccessConfig:
    """The paper's success conditions; thresholds as options."""

    object_distance_m: float = 1.0
    object_facing_deg: float = 20.0
    object_must_be_visible: bool = True


DEFAULT_SUCCESS = SuccessConfig()


# What the front camera shows inside the monitor's success distance, calibrated on our renders against
# SuccessConfig (tests/test_calibration.py renders every target of the cabins and of a dozen houses on its facing
# axis): how wide each kind of object must look for the drone to be within the success distance. At 0.7 of it
# every target of a kind looks at least that wide, at 1.1 and 2 times it none does. One fraction cannot serve
# every kind: a desk spans 65 % of the width from 1.1 m, a toilet never does within 1 m
# (bench/object_width_cues.py measures it in 40 houses), so the rule names the kinds.
OBJECT_CLOSE_WIDTH_FRACTION = 0.65  # a fridge, a mirror, a sink cabinet, and any kind not listed below
FILLS_THE_WIDTH = 1.0  # "the whole width": both ends of the object outside the image


@dataclass(frozen=True)
class CloseCue:
    """How wide objects of `kinds` must look (fraction of the image width) to be within the success distance;
    `then_m`: fly this much further after that (objects so wide that they fill the image from beyond it)."""

    kinds: tuple[str, ...]  # target kinds, as the scenes name them (`desk`, `tv`, ...)
    shown_as: str  # how the prompt names them
    width_fraction: float
    then_m: float = 0.0


FRIDGE_SIZED = CloseCue(("refrigerator", "mirror", "sink"), "a fridge, a mirror (its frame), a sink (with the "
                        "cabinet under it), or any object of about their size", OBJECT_CLOSE_WIDTH_FRACTION)
OBJECT_CLOSE_CUES: tuple[CloseCue, ...] = (
    CloseCue(("toilet",), "a toilet", 0.25),
    CloseCue(("plant",), "a potted plant", 0.35),
    CloseCue(("stove",), "a stove (the cooktop and oven, not the counter beside them)", 0.50),
    FRIDGE_SIZED,
    CloseCue(("shower",), "a shower", 0.80),
    CloseCue(("bookshelf",), "a bookshelf", 0.85),
    CloseCue(("tv",), "a TV (with the cabinet it stands on)", FILLS_THE_WIDTH),
    CloseCue(("bed", "desk", "wardrobe"), "a bed, a desk, a wardrobe, a sofa or anything wider", FILLS_THE_WIDTH,
             then_m=0.5),
)


def close_cue(target_id: str) -> CloseCue:
    """The cue for a target (`desk_2`) or a kind of object (`desk`); a kind not listed is taken as fridge-sized."""
    kind = target_kind(target_id)
    return next((c for c in OBJECT_CLOSE_CUES if kind in c.kinds), FRIDGE_SIZED)


_A1_M = COMMANDS["A1"].amount  # the shortest forward move, in metres


def _cue_text(cue: CloseCue) -> str:
    if cue.width_fraction < FILLS_THE_WIDTH:
        return f"{cue.shown_as}: {cue.width_fraction:.0%} of the image width".replace("%", " %")
    then = (f", then about {cue.then_m:g} m further straight ahead (about {round(cue.then_m / _A1_M)} `A1`, or until "
            "the safety system stops the drone): center its middle and face it squarely before its ends leave the "
            "image, because they tell where its middle is") if cue.then_m else ""
    return f"{cue.shown_as}: the whole width (both its ends outside the image){then}"


def visual_cue_values(config: SuccessConfig = DEFAULT_SUCCESS) -> dict[str, str]:
    """The calibrated numbers that the prompts state, as template values (one source for prompt and test)."""
    return {"close_cues": "\n".join(f"  - {_cue_text(c)}" for c in OBJECT_CLOSE_CUES),
            "success_distance": f"{config.object_distance_m:g} m"}
