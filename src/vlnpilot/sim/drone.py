"""The simulated DJI Tello: real size, propellers as collision geometry, front and rear cameras.

Sizes from the Tello spec sheet: 98 x 92.5 x 41 mm including propellers and guards. The four propeller
discs are separate collision geoms so that a propeller tip clipping a door frame is reported as such.
"""

from __future__ import annotations

from vlnpilot.core.tello_spec import (  # noqa: F401  (re-exported for the simulator)
    BOUNDING_RADIUS,
    DIAGONAL_FOV_DEG,
    HEIGHT,
    LENGTH,
    PROP_RADIUS,
    PROP_X,
    PROP_Y,
    WIDTH,
    horizontal_fov_deg,
    vertical_fov_deg,
)

# -- names (one constants block for the robot) ----------------------------------------------------
BODY = "drone"
JOINT = "drone_free"
FRONT_CAMERA, REAR_CAMERA = "front", "rear"
PROPELLERS = ("prop_front_left", "prop_front_right", "prop_rear_left", "prop_rear_right")
HULL = "drone_hull"

# -- dimensions (metres), from the spec sheet -------------------------------------------------------
PROP_Z = HEIGHT / 2 - 0.004
PROP_HALF_THICKNESS = 0.004
HULL_HALF = (0.034, 0.021, 0.0165)
HULL_Z = -HEIGHT / 2 + HULL_HALF[2]  # hull bottom at the spec-sheet outline; props on top

FRONT_FOVY = vertical_fov_deg()
CAMERA_FORWARD_M = LENGTH / 2 + 0.002  # the front camera, this far ahead of the body centre, level
REAR_CAMERA_POS = (-0.55, 0.0, 0.30)  # chase view: behind and above, looking at the drone
REAR_FOVY = 60.0

DRONE_CONTYPE, DRONE_CONAFFINITY = 2, 1  # collides with world geoms (see scene.mjcf)


def drone_assets_xml() -> str:
    return """<material name="drone_shell" rgba="0.92 0.92 0.90 1" specular="0.5" shininess="0.5"/>
    <material name="drone_prop" rgba="0.15 0.15 0.17 0.85" specular="0.3"/>
    <material name="drone_lens" rgba="0.05 0.05 0.08 1" specular="0.9" shininess="0.9"/>"""


def drone_body_xml() -> str:
    """The drone body with a free joint; its pose is set kinematically by the simulator."""
    col = f'contype="{DRONE_CONTYPE}" conaffinity="{DRONE_CONAFFINITY}" group="2"'
    hx, hy, hz = HULL_HALF
    props = []
    for name in PROPELLERS:
        sx = PROP_X if "front" in name else -PROP_X
        sy = PROP_Y if "left" in name else -PROP_Y
        props.append(
            f'<geom name="{name}" type="cylinder" size="{PROP_RADIUS:.4f} {PROP_HALF_THICKNESS:.4f}" '
            f'pos="{sx:.4f} {sy:.4f} {PROP_Z:.4f}" material="drone_prop" {col}/>'
        )
    # The camera looks along its -z axis; xyaxes gives its image x (right) and y (up) in the body frame.
    rx, _, rz = REAR_CAMERA_POS
    return f"""<body name="{BODY}" pos="0 0 1">
      <freejoint name="{JOINT}"/>
      <geom name="{HULL}" type="box" size="{hx} {hy} {hz}" pos="0 0 {HULL_Z:.4f}" material="drone_shell"
            mass="0.08" {col}/>
      {chr(10).join('      ' + p for p in props).strip()}
      <geom name="drone_lens" type="cylinder" size="0.006 0.002" pos="{hx + 0.001:.4f} 0 0" euler="0 1.5708 0"
            material="drone_lens" contype="0" conaffinity="0" group="2"/>
      <camera name="{FRONT_CAMERA}" pos="{CAMERA_FORWARD_M:.4f} 0 0" xyaxes="0 -1 0 0 0 1" fovy="{FRONT_FOVY:.3f}"/>
      <camera name="{REAR_CAMERA}" pos="{rx} 0 {rz}" xyaxes="0 -1 0 {rz} 0 {-rx}" fovy="{REAR_FOVY}"/>
    </body>"""
