"""The DJI Tello's physical and camera specification: one source for the simulator, the shield and the robot.

Sizes from the Tello spec sheet: 98 x 92.5 x 41 mm including propellers and guards; camera 82.6° diagonal
field of view, 4:3.
"""

from __future__ import annotations

import math

LENGTH, WIDTH, HEIGHT = 0.098, 0.0925, 0.041
PROP_RADIUS = 0.0212
PROP_X = LENGTH / 2 - PROP_RADIUS  # rotor centres so that the tips reach the spec-sheet outline
PROP_Y = WIDTH / 2 - PROP_RADIUS
HALF_WIDTH = WIDTH / 2
BOUNDING_RADIUS = math.hypot(LENGTH / 2, WIDTH / 2)  # horizontal, for quick clearance checks

DIAGONAL_FOV_DEG = 82.6
ASPECT = 4 / 3


def vertical_fov_deg(diagonal_deg: float = DIAGONAL_FOV_DEG, aspect: float = ASPECT) -> float:
    """Vertical field of view of a camera with the given diagonal FOV and aspect ratio."""
    half_diag = math.tan(math.radians(diagonal_deg) / 2)
    return math.degrees(2 * math.atan(half_diag / math.hypot(aspect, 1)))


def horizontal_fov_deg(diagonal_deg: float = DIAGONAL_FOV_DEG, aspect: float = ASPECT) -> float:
    half_diag = math.tan(math.radians(diagonal_deg) / 2)
    return math.degrees(2 * math.atan(half_diag * aspect / math.hypot(aspect, 1)))

# How long a command takes in the air (issue 24: the episode clock that moves people, pets and timed events).
# The SDK's default move speed and a measured-order yaw rate, plus the settle the robot waits before its frame
# (tello.yaml's move_settle_s order); a hover (E) holds for HOVER_S.
MOVE_SPEED_MPS = 0.5
YAW_RATE_DPS = 90.0
SETTLE_S = 0.3
HOVER_S = 1.0


def motion_duration_s(forward_m: float = 0.0, lateral_m: float = 0.0, vertical_m: float = 0.0,
                      yaw_deg: float = 0.0) -> float:
    """Seconds a body-frame motion takes: translation at MOVE_SPEED_MPS, yaw at YAW_RATE_DPS, then the settle;
    a null motion (hover) holds for HOVER_S."""
    trans = math.hypot(forward_m, lateral_m) + abs(vertical_m)
    if trans == 0 and yaw_deg == 0:
        return HOVER_S
    return trans / MOVE_SPEED_MPS + abs(yaw_deg) / YAW_RATE_DPS + SETTLE_S
