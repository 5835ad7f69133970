"""Safety beyond the paper: a volumetric shield, a door-crossing assist and an oscillation guard.

The paper's two failures: the model has no sense of the drone's size, so propeller tips clip door frames;
and a model that wants the door perfectly centred oscillates until the step limit. The controller asks a
`SafetyLayer` to filter every validated command before the drone moves, in this order:

1. **Oscillation guard** (`OscillationGuard`). Counts direction reversals of the pilot's *proposed* rotations
   (B after C) and lateral moves (D1 after D2) since the last forward progress. When `threshold` reversals fall
   within the last `window` steps it fires (an event, recorded; one per stretch until the next forward move or
   state change), tells the pilot in the next prompt, and vetoes the next proposal that reverses the last
   executed direction (once per event, so that a pilot that heeds the note can still make a genuine
   correction). How the veto "accepts the current alignment as good enough":
   - in Oriented Towards Door, if the door assist says the drone fits the doorway ahead (centre within
     ±(width/2 - drone half-width - margin) of the centre line, heading within `accept_heading_deg` of the door
     normal, door within `accept_distance_m`), the reversal is replaced by A1 and the FSM advances to Go Through
     Door: the controller commits to the crossing, and the assist keeps the crossing centred;
   - otherwise (not aligned enough, or another state such as Reach Object) the reversal is replaced by E
     (hover) and the pilot is told that its alignment is accepted and it should move on (a cooperative pilot
     then moves forward or changes state).
   With the shield off the guard still detects and records events (for comparison) but never acts or speaks.
2. **Door-crossing assist** (`DoorAssist`, Oriented Towards Door and Go Through Door only). Before a forward
   move it checks, from the scene's door geometry and the drone's pose, whether the drone's outline inflated by
   the margin would enter the door frame's depth band while reaching beyond the opening; if so it replaces the
   forward move by D1 or D2 towards the doorway's centre line. When the shield would turn a forward move in
   those states into a hover (e.g. an open door leaf beside the passage), it steps towards the centre line
   instead if that step is safe, so that a pilot that may only fly A1 (Go Through Door) is not stuck.
3. **Shield** (`GeometryShield` or `DepthShield`). Predicts from the Tello's real outline with propellers
   (`tello_spec`) plus `margin_m` whether the motion would collide; an unsafe move is shortened (A3 -> A2 -> A1,
   B3 -> B2 -> B1, ...) or replaced by hovering (E). Inside the margin already (e.g. after a close approach),
   a motion is unsafe only if it brings the drone closer than it is, so the drone can always back out.

Every change is an `Intervention(step, source, proposed, executed, reason)`: in `episode.jsonl`, the summary,
`EpisodeResult.interventions`, and, as text, in the next prompt's controller feedback.

Knowledge sources (`make_shield(name, env)`, from what `env` declares in `environment.Capabilities`; a shield
the environment cannot serve is refused with one line naming the ones it can). Shields are chosen by name from
`SHIELD_REGISTRY` (`core.registry`, entry-point group `vlnpilot.shields`): `off`, `geometry`, `depth`, `assist`
and any a third party registers with `@register_shield("NAME")`:
- `geometry` (needs `ground_truth`): the simulator's collision geometry through a narrow query
  (`clearance_at(pose, max_distance)` of `types.GroundTruth`), evaluated at a superset of the poses at which the
  simulator checks the motion (its `substeps`). Exact: a command it lets through never collides in the
  simulator (property-tested). The upper bound.
- `depth` (needs `depth`, not ground truth): only the front depth image (`environment.DepthSensing`), as a
  drone with a depth sensor would have, plus odometry (the pose). Each step's image is back-projected (the
  camera's declared vertical FOV, `front_fovy_deg`, 4:3) into points within a slab around the
  flight height and kept as a short memory (`memory_steps` steps, within `memory_radius_m`, voxel-thinned) in
  the odometry frame. Motions are checked against that memory with the same outline and margin. It assumes
  unseen space is free and that odometry is good over the memory's span. The camera sees a 69 x 55 degree cone
  in front; for **lateral moves** (and the sides in general) it relies on the memory only: a 10 cm sideways
  move is vetoed only if a remembered point lies in its path, so an obstacle never seen (e.g. approached
  sideways from outside the field of view) is not caught. **Rotations** are checked the same way; an in-place
  rotation sweeps only the bounding circle (6.7 cm radius), and anything that close was normally seen when the
  drone approached it. Door jambs beside a crossing drone are remembered from the approach.

Visual aid (`EpisodeConfig.overlay = "corridor"`): `draw_corridor` draws the propeller tips' paths on the
image the pilot sees; recorded frames stay raw (the run's config records the overlay, so it can be redrawn).
"""

# The package is split by job (config, shields, assist, guard, layer, overlay); every name that callers
# imported from the single module `vlnpilot.safety` is still importable from here.
from vlnpilot.safety.assist import (
    DoorAlignment,
    DoorAssist,
)
from vlnpilot.safety.config import (
    ASSIST_NOTE,
    DEFAULT_SHIELD,
    DOOR_STATES,
    GUARD_NOTE,
    OVERLAYS,
    SHIELD_NOTE,
    DepthConfig,
    Intervention,
    OscillationConfig,
    OscillationEvent,
    SafetyConfig,
    SafetyVerdict,
    default_shield,
    obstacle_kind,
)
from vlnpilot.safety.guard import (
    OscillationGuard,
)
from vlnpilot.safety.layer import (
    SafetyLayer,
    make_safety,
)
from vlnpilot.safety.overlay import (
    corridor_pixels,
    draw_corridor,
)
from vlnpilot.safety.shields import (
    SHIELD_REGISTRY,
    ClearanceQuery,
    DepthShield,
    GeometryShield,
    Shield,
    make_shield,
    outline_corners,
    register_shield,
    shorter_commands,
)

__all__ = [
    "ASSIST_NOTE",
    "ClearanceQuery",
    "DEFAULT_SHIELD", "default_shield",
    "DOOR_STATES",
    "DepthConfig",
    "DepthShield",
    "DoorAlignment",
    "DoorAssist",
    "GUARD_NOTE",
    "GeometryShield",
    "Intervention",
    "OVERLAYS",
    "OscillationConfig",
    "OscillationEvent",
    "OscillationGuard",
    "SHIELD_REGISTRY",
    "SHIELD_NOTE",
    "SafetyConfig",
    "SafetyLayer",
    "SafetyVerdict",
    "Shield",
    "corridor_pixels",
    "draw_corridor",
    "make_safety",
    "make_shield",
    "obstacle_kind",
    "register_shield",
    "outline_corners",
    "shorter_commands",
]
