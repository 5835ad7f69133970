"""The door-crossing assist: keeps a forward move through a doorway clear of the frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vlnpilot.core import tello_spec
from vlnpilot.core.commands import COMMANDS, HOVER, Command, Kind
from vlnpilot.core.records import Motion, Pose, wrap_deg
from vlnpilot.safety.config import SafetyConfig
from vlnpilot.safety.shields import _fractions, outline_corners
from vlnpilot.scene.model import Door, Scene


# -- door-crossing assist ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DoorAlignment:
    door: Door
    lateral_m: float  # drone centre from the doorway's centre line, + = to the drone's left
    clearance_m: float  # how far the centre may be off the line: width/2 - half-width - margin
    heading_err_deg: float  # door axis relative to the heading, + = to the left
    distance_m: float  # along the door axis from the drone to the door plane (negative once past it)

    @property
    def fits(self) -> bool:
        return abs(self.lateral_m) <= self.clearance_m


class DoorAssist:
    """Keeps a door crossing inside the clearance the doorway leaves (scene map plus the drone's pose)."""

    def __init__(self, scene: Scene, config: SafetyConfig):
        self.doors = scene.open_doors()
        self.config = config

    def clearance(self, door: Door) -> float:
        return door.width / 2 - tello_spec.HALF_WIDTH - self.config.margin_m

    def _axis(self, door: Door, pose: Pose) -> float | None:
        """+1 if the drone faces along the door normal, -1 against it, None if too oblique to be crossing."""
        rel = abs(wrap_deg(pose.yaw_deg - door.normal_deg))
        lim = self.config.assist_heading_deg
        return 1.0 if rel <= lim else -1.0 if rel >= 180 - lim else None

    def alignment(self, pose: Pose, max_distance: float | None = None,
                  behind_m: float | None = None) -> DoorAlignment | None:
        """The doorway the drone faces (ahead, or at most `behind_m` past its plane) and the alignment, or None."""
        best: DoorAlignment | None = None
        behind = self.config.door_half_depth_m if behind_m is None else behind_m
        for door in self.doors:
            sign = self._axis(door, pose)
            if sign is None:
                continue
            depth, lateral = door.frame_of(pose.x, pose.y)
            ahead = -depth * sign  # along the drone's direction of travel, to the door plane
            if abs(lateral) > door.width / 2 + self.config.door_search_m or ahead < -behind:
                continue
            if max_distance is not None and ahead > max_distance:
                continue
            axis_deg = door.normal_deg if sign > 0 else door.normal_deg + 180.0
            a = DoorAlignment(door, lateral * sign, self.clearance(door), wrap_deg(axis_deg - pose.yaw_deg), ahead)
            if best is None or abs(a.distance_m) < abs(best.distance_m):
                best = a
        return best

    def conflict(self, pose: Pose, motion: Motion) -> tuple[Door, float] | None:
        """(door, centre's lateral offset in the door frame) if the motion would bring the outline (grown by the
        margin) into a door frame's depth band beyond the opening, else None."""
        m, hd = self.config.margin_m, self.config.door_half_depth_m
        for door in self.doors:
            if self._axis(door, pose) is None:
                continue
            _, lat0 = door.frame_of(pose.x, pose.y)
            if abs(lat0) > door.width / 2 + self.config.door_search_m:
                continue
            for frac in [0.0, *_fractions(motion, self.config, None)]:
                p = motion.apply(pose, frac)
                corners = outline_corners(p, m)
                nx, ny = door.normal
                dx, dy = corners[:, 0] - door.center[0], corners[:, 1] - door.center[1]
                depth, lateral = dx * nx + dy * ny, -dx * ny + dy * nx
                if depth.max() >= -hd and depth.min() <= hd and np.abs(lateral).max() > door.width / 2:
                    return door, door.frame_of(p.x, p.y)[1]
        return None

    def correction(self, pose: Pose, command: Command) -> tuple[Command, str] | None:
        """D1/D2 towards the centre line (or E if the door is too narrow) instead of a forward move that would
        bring a propeller into the frame; None when the forward move is fine."""
        if command.kind is not Kind.FORWARD:
            return None
        hit = self.conflict(pose, command.motion())
        if hit is None:
            return None
        door, lateral = hit
        sign = self._axis(door, pose) or 1.0
        lat_drone = lateral * sign  # + = the drone is left of the centre line
        clear = self.clearance(door)
        side = "left" if lat_drone > 0 else "right"
        what = (f"the drone is {abs(lat_drone) * 100:.0f} cm {side} of the centre line of the doorway, which "
                f"leaves ±{clear * 100:.0f} cm (opening {door.width * 100:.0f} cm, drone {tello_spec.WIDTH * 100:.1f} "
                f"cm wide, margin {self.config.margin_m * 100:.0f} cm): {command.code} would bring a propeller into "
                f"the door frame")
        if clear < COMMANDS["D1"].amount / 2:
            return HOVER, f"{what}; the opening is too narrow to correct with 10 cm moves, so the drone hovers"
        fix = COMMANDS["D2"] if lat_drone > 0 else COMMANDS["D1"]
        return fix, f"{what}, so the drone moves {'right' if lat_drone > 0 else 'left'} 10 cm first"


    def centring(self, pose: Pose) -> tuple[Command, DoorAlignment] | None:
        """A sideways step towards the centre line of the doorway being approached or crossed (within 1 m of its
        plane on either side), when the drone is at least half a step off it; else None."""
        a = self.alignment(pose, self.config.oscillation.accept_distance_m, behind_m=1.0)
        if a is None or abs(a.lateral_m) < COMMANDS["D1"].amount / 2:
            return None
        return (COMMANDS["D2"] if a.lateral_m > 0 else COMMANDS["D1"]), a
