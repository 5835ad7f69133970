"""The built-in `cabin`, after the paper's Furnished Cabin: a compact wooden cabin of three rooms in a row.

    y ^  +-----------------+-------------+----------+
  3.6 |  | kitchen  fridge | nightstands | bathtub  |
      |  |                 |    bed      |    sink  |
      |  |  TV  sofa       |             |          |
      |  |          (door1)|  (door2)    |  toilet  |
    0 +  +---front door----+--wardrobe---+----------+--> x
         0                4.0           6.6        8.6

Living room and kitchen on the left, bedroom in the centre, bathroom on the right, as in the paper's
Figure 3. Open doorways (with frames and open door leaves) join living room-bedroom and
bedroom-bathroom, so the bathroom is two crossings from the living room. The closed front door and the
windows are distractors. Compact on purpose: with the paper's 10 cm forward moves in the navigation
states, two crossings must fit in 50 steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from vlnpilot.core.records import Pose
from vlnpilot.scene.model import EXTERIOR, Door, Light, Material, Room, Scene, Solid, Spawn, Target
from vlnpilot.scene.parts import box, cyl, doorway, ellipsoid, wall, window

# -- names (one constants block for the scene) ----------------------------------------------------
LIVING_ROOM, BEDROOM, BATHROOM = "living_room", "bedroom", "bathroom"
DOOR_LIVING_BEDROOM, DOOR_BEDROOM_BATHROOM, FRONT_DOOR = "door_living_bedroom", "door_bedroom_bathroom", "front_door"
REFRIGERATOR, MIRROR, SINK = "refrigerator", "mirror", "sink"

# -- dimensions (metres) --------------------------------------------------------------------------
X_LIVING, X_BATH, Y_MAX = 4.0, 8.6, 3.6  # east edges of the living room and the bathroom; north wall
WALL_H = 2.6  # ceiling height
T_IN, T_EXT = 0.10, 0.15  # interior and exterior wall thickness
JAMB, CASING = 0.05, 0.02  # door-frame jamb thickness; how far the casing stands proud of the wall
DOOR_W, DOOR_H = 0.80, 2.00  # clear opening of the interior doorways
FLIGHT_Z = 1.0


@dataclass(frozen=True)
class Layout:
    """What differs between versions of the cabin: the bedroom's depth, its furniture's x extents, the spawns.

    `cabin-v1` is the cabin of the first real-VLM baseline (trials/baseline): a 2.6 m bedroom that left a perfect
    pilot 7 steps of slack on the two-door rows. `cabin` (v2) has a 2.0 m bedroom with a 1.1 m bed, and spawns
    that face the way out, so that the oracle needs at most 35 of the paper's 50 steps on every row.
    """

    version: str
    x_bed: float  # east edge of the bedroom (the bedroom-bathroom wall's centre line)
    bed: tuple[float, float]  # x extent of the bed frame
    wardrobe_x1: float  # the wardrobe stands against the west wall, up to here
    nightstands: tuple[tuple[float, float], tuple[float, float]]  # x extents, left and right of the bed
    spawns: tuple[tuple[float, float, float], ...]  # (x, y, yaw) of the living room, bedroom and bathroom spawns


V1 = Layout("v1", 6.6, (4.75, 6.15), 4.65, ((4.28, 4.68), (6.20, 6.54)),
            ((3.25, 0.75, 135.0), (5.35, 1.05, 90.0), (7.25, 1.75, -60.0)))
V2 = Layout("v2", 6.0, (4.60, 5.70), 4.55, ((4.20, 4.57), (5.73, 5.93)),
            ((3.25, 0.85, 120.0), (5.15, 1.05, 90.0), (6.70, 1.20, -40.0)))

MATERIALS: tuple[Material, ...] = (
    Material("floor_living", texture="floor_wood", texrepeat=(1.0, 1.0), texuniform=True),
    Material("floor_bedroom", texture="floor_wood_light", texrepeat=(1.0, 1.0), texuniform=True),
    Material("floor_bathroom", texture="floor_tiles", texrepeat=(1.2, 1.2), texuniform=True),
    Material("wall_living", texture="log_wall", texrepeat=(0.8, 0.8), texuniform=True),
    Material("wall_bedroom", texture="log_wall_light", texrepeat=(0.8, 0.8), texuniform=True),
    Material("wall_bathroom", texture="bath_tiles", texrepeat=(1.5, 1.5), texuniform=True, specular=0.5),
    Material("wall_outside", texture="log_wall", texrepeat=(0.8, 0.8), texuniform=True),
    Material("ceiling", texture="painted_wood", texrepeat=(0.5, 0.5), texuniform=True),
    Material("door_frame", rgba=(0.93, 0.92, 0.88, 1.0), specular=0.3),
    Material("door_leaf", texture="furniture_wood", texrepeat=(1.0, 1.0)),
    Material("front_door", rgba=(0.45, 0.22, 0.12, 1.0), specular=0.3),
    Material("metal", rgba=(0.75, 0.75, 0.78, 1.0), specular=0.8, shininess=0.8),
    Material("chrome", rgba=(0.85, 0.87, 0.9, 1.0), specular=1.0, shininess=0.9),
    Material("stainless", rgba=(0.80, 0.82, 0.85, 1.0), specular=0.7, shininess=0.6),
    Material("black", rgba=(0.06, 0.06, 0.07, 1.0), specular=0.6, shininess=0.7),
    Material("dark_grey", rgba=(0.25, 0.25, 0.27, 1.0), specular=0.3),
    Material("tv_screen", rgba=(0.10, 0.16, 0.30, 1.0), specular=0.9, shininess=0.9, emission=0.35),
    Material("wood", texture="furniture_wood", texrepeat=(1.0, 1.0)),
    Material("dark_wood", rgba=(0.30, 0.19, 0.11, 1.0), specular=0.2),
    Material("painted_wood", texture="painted_wood", texrepeat=(1.0, 1.0)),
    Material("cabinet", rgba=(0.55, 0.68, 0.60, 1.0), specular=0.25),
    Material("countertop", rgba=(0.20, 0.20, 0.22, 1.0), specular=0.6, shininess=0.6),
    Material("kitchen_tiles", texture="kitchen_tiles", texrepeat=(2.0, 2.0), texuniform=True),
    Material("sofa", texture="sofa_fabric", texrepeat=(2.0, 2.0)),
    Material("cushion_red", rgba=(0.75, 0.25, 0.2, 1.0)),
    Material("cushion_yellow", rgba=(0.90, 0.75, 0.3, 1.0)),
    Material("rug", texture="rug", texrepeat=(1.0, 1.0)),
    Material("books", texture="books", texrepeat=(1.0, 1.0)),
    Material("lampshade", rgba=(0.98, 0.92, 0.78, 1.0), emission=0.6),
    Material("window_view", texture="window_view", texrepeat=(1.0, 1.0), emission=0.7),
    Material("window_frame", rgba=(0.95, 0.95, 0.95, 1.0)),
    Material("fridge", rgba=(0.86, 0.88, 0.90, 1.0), specular=0.8, shininess=0.7),
    Material("mattress", rgba=(0.95, 0.95, 0.93, 1.0)),
    Material("blanket", texture="blanket", texrepeat=(1.0, 1.0)),
    Material("pillow", rgba=(0.97, 0.97, 1.0, 1.0)),
    Material("mirror_glass", texture="mirror_glass", texrepeat=(1.0, 1.0), specular=1.0, shininess=1.0,
             emission=0.25),
    Material("mirror_frame", rgba=(0.72, 0.55, 0.25, 1.0), specular=0.6, shininess=0.6),
    Material("painting", texture="painting", texrepeat=(1.0, 1.0)),
    Material("ceramic", rgba=(0.97, 0.97, 0.97, 1.0), specular=0.7, shininess=0.7),
    Material("water", rgba=(0.70, 0.80, 0.88, 1.0), specular=0.9, shininess=0.9),
    Material("marble", rgba=(0.92, 0.92, 0.90, 1.0), specular=0.6, shininess=0.5),
    Material("bath_mat", texture="bath_mat", texrepeat=(1.0, 1.0)),
    Material("towel", rgba=(0.35, 0.6, 0.75, 1.0)),
    Material("curtain", rgba=(0.75, 0.88, 0.95, 1.0)),
    Material("plant", rgba=(0.20, 0.50, 0.22, 1.0)),
    Material("pot", rgba=(0.70, 0.35, 0.20, 1.0)),
)


# -- the cabin --------------------------------------------------------------------------------------
def _doors(lay: Layout) -> tuple[Door, ...]:
    return (
        Door(DOOR_LIVING_BEDROOM, (LIVING_ROOM, BEDROOM), (X_LIVING, 1.0), DOOR_W, DOOR_H, 0.0),
        Door(DOOR_BEDROOM_BATHROOM, (BEDROOM, BATHROOM), (lay.x_bed, 1.1), DOOR_W, DOOR_H, 0.0),
        Door(FRONT_DOOR, (LIVING_ROOM, EXTERIOR), (1.2, 0.0), 0.9, 2.05, -90.0, open=False),
    )
_WINDOWS = (  # (name, axis, wall line, centre along, width, z0, z1, outer face)
    ("living_window_south", "x", 0.0, 2.9, 1.0, 0.9, 1.9, -T_EXT),
    ("living_window_west", "y", 0.0, 2.95, 0.9, 1.0, 1.9, -T_EXT),
    ("bathroom_window_east", "y", X_BATH, 0.7, 0.6, 1.3, 1.85, X_BATH + T_EXT),
)


def _structure(lay: Layout) -> list[Solid]:
    s: list[Solid] = []
    X_BED = lay.x_bed  # noqa: N806 (the wall line, named like the other room edges)
    d1, d2, front = _doors(lay)
    cut = DOOR_W + 2 * JAMB
    door1 = (d1.center[1], cut, 0.0, DOOR_H + JAMB)
    door2 = (d2.center[1], cut, 0.0, DOOR_H + JAMB)
    win = {w[0]: (w[3], w[4], w[5], w[6]) for w in _WINDOWS}
    # floors (a collision slab plus a textured skin per room) and ceiling
    s.append(box("floor", -T_EXT, X_BATH + T_EXT, -T_EXT, Y_MAX + T_EXT, -0.10, -0.002, "dark_wood"))
    for room, x0, x1 in ((LIVING_ROOM, 0, X_LIVING), (BEDROOM, X_LIVING, X_BED), (BATHROOM, X_BED, X_BATH)):
        s.append(box(f"floor_{room}", x0, x1, 0, Y_MAX, -0.002, 0.0, f"floor_{room.split('_')[0]}", collide=False))
    s.append(box("ceiling", -T_EXT, X_BATH + T_EXT, -T_EXT, Y_MAX + T_EXT, WALL_H, WALL_H + 0.1, "ceiling"))
    # exterior walls, per room so that each room keeps its own wall finish
    ext = [
        ("wall_living_south", "x", 0.0, X_LIVING, -T_EXT, 0.0, "wall_living",
         ((front.center[0], front.width + 2 * JAMB, 0.0, front.height + JAMB), (*win["living_window_south"],))),
        ("wall_living_north", "x", 0.0, X_LIVING, Y_MAX, Y_MAX + T_EXT, "wall_living", ()),
        ("wall_living_west", "y", -T_EXT, Y_MAX + T_EXT, -T_EXT, 0.0, "wall_living", (win["living_window_west"],)),
        ("wall_bedroom_south", "x", X_LIVING, X_BED, -T_EXT, 0.0, "wall_bedroom", ()),
        ("wall_bedroom_north", "x", X_LIVING, X_BED, Y_MAX, Y_MAX + T_EXT, "wall_bedroom", ()),
        ("wall_bathroom_south", "x", X_BED, X_BATH + T_EXT, -T_EXT, 0.0, "wall_bathroom", ()),
        ("wall_bathroom_north", "x", X_BED, X_BATH + T_EXT, Y_MAX, Y_MAX + T_EXT, "wall_bathroom", ()),
        ("wall_bathroom_east", "y", 0.0, Y_MAX, X_BATH, X_BATH + T_EXT, "wall_bathroom",
         (win["bathroom_window_east"],)),
    ]
    for name, axis, a0, a1, c0, c1, mat, openings in ext:
        s += wall(name, axis, a0, a1, c0, c1, mat, openings, face=1 if c1 <= 0.0 else -1)
    # interior walls: two halves, each with the finish of its room
    s += wall("wall_living_bedroom_w", "y", 0, Y_MAX, X_LIVING - T_IN / 2, X_LIVING, "wall_living", (door1,), -1)
    s += wall("wall_living_bedroom_e", "y", 0, Y_MAX, X_LIVING, X_LIVING + T_IN / 2, "wall_bedroom", (door1,), 1)
    s += wall("wall_bedroom_bathroom_w", "y", 0, Y_MAX, X_BED - T_IN / 2, X_BED, "wall_bedroom", (door2,), -1)
    s += wall("wall_bedroom_bathroom_e", "y", 0, Y_MAX, X_BED, X_BED + T_IN / 2, "wall_bathroom", (door2,), 1)
    # doorways: door 1 opens into the living room (hinge on its north jamb), door 2 into the bedroom
    s += doorway(d1, T_IN, leaf_into=0, hinge="left")
    s += doorway(d2, T_IN, leaf_into=0, hinge="right")
    s += doorway(front, T_EXT, leaf_into=None, hinge="left")
    for name, axis, at, centre, width, z0, z1, outside in _WINDOWS:
        s += window(name, axis, at, centre, width, z0, z1, outside)
    return s


def _living_room() -> list[Solid]:
    s: list[Solid] = []
    # kitchen along the north wall: base cabinets, worktop, tiled splash-back, stove, hood, wall cabinets
    s.append(box("kitchen_cabinets", 0.0, 2.0, 3.02, Y_MAX, 0.0, 0.86, "cabinet"))
    s.append(box("kitchen_worktop", 0.0, 2.0, 2.98, Y_MAX, 0.86, 0.90, "countertop"))
    s.append(box("kitchen_splashback", 0.0, 2.0, Y_MAX - 0.012, Y_MAX, 0.90, 1.45, "kitchen_tiles", collide=False))
    for i, x in enumerate((0.37, 1.63)):
        s.append(box(f"kitchen_cabinet_handle_{i}", x - 0.08, x + 0.08, 2.995, 3.02, 0.72, 0.74, "chrome",
                     collide=False))
    s.append(box("stove_oven_door", 0.72, 1.28, 3.0, 3.02, 0.12, 0.72, "black", collide=False))
    s.append(box("stove_oven_handle", 0.78, 1.22, 2.985, 3.0, 0.66, 0.68, "chrome", collide=False))
    s.append(box("stove_top", 0.70, 1.30, 3.0, 3.58, 0.90, 0.915, "black"))
    for i, (bx, by) in enumerate(((0.85, 3.15), (1.15, 3.15), (0.85, 3.43), (1.15, 3.43))):
        s.append(cyl(f"stove_burner_{i}", bx, by, 0.915, 0.925, 0.075, "dark_grey", collide=False))
    s.append(box("range_hood", 0.70, 1.30, 3.25, Y_MAX, 1.65, 1.95, "stainless"))
    s.append(box("wall_cabinet_left", 0.0, 0.68, 3.25, Y_MAX, 1.50, 2.20, "cabinet"))
    s.append(box("wall_cabinet_right", 1.32, 2.0, 3.25, Y_MAX, 1.50, 2.20, "cabinet"))
    # refrigerator (target): tall, stainless, two doors with handles, facing south (-y)
    fx0, fx1, fy0 = 2.08, 2.80, 2.90
    s.append(box("refrigerator_body", fx0, fx1, fy0, Y_MAX - 0.02, 0.0, 1.85, "fridge", target=REFRIGERATOR))
    s.append(box("refrigerator_door_gap", fx0, fx1, fy0 - 0.006, fy0, 1.24, 1.255, "dark_grey", collide=False,
                 target=REFRIGERATOR))
    for i, (z0, z1) in enumerate(((0.75, 1.18), (1.32, 1.62))):
        s.append(box(f"refrigerator_handle_{i}", fx1 - 0.09, fx1 - 0.06, fy0 - 0.05, fy0, z0, z1, "chrome",
                     target=REFRIGERATOR))
    for i, (mx, mz, mat) in enumerate(((2.25, 1.45, "cushion_red"), (2.40, 1.50, "cushion_yellow"),
                                       (2.30, 1.05, "painting"), (2.55, 1.10, "tv_screen"))):
        s.append(box(f"refrigerator_note_{i}", mx - 0.05, mx + 0.05, fy0 - 0.004, fy0, mz - 0.06, mz + 0.06, mat,
                     collide=False, target=REFRIGERATOR))
    s.append(box("refrigerator_dispenser", 2.20, 2.42, fy0 - 0.006, fy0, 1.62, 1.78, "dark_grey", collide=False,
                 target=REFRIGERATOR))
    # TV on a low stand against the west wall, sofa facing it, coffee table and rug between
    s.append(box("tv_stand", 0.0, 0.45, 1.0, 2.2, 0.0, 0.48, "wood"))
    s.append(box("tv_body", 0.10, 0.16, 1.02, 2.18, 0.70, 1.38, "black"))
    s.append(box("tv_screen", 0.16, 0.165, 1.05, 2.15, 0.73, 1.35, "tv_screen", collide=False))
    s.append(box("tv_foot", 0.08, 0.30, 1.5, 1.7, 0.48, 0.70, "black"))
    s.append(box("sofa_base", 2.0, 2.8, 0.90, 2.40, 0.10, 0.42, "sofa"))
    s.append(box("sofa_seat", 2.05, 2.65, 1.05, 2.25, 0.42, 0.50, "sofa"))
    s.append(box("sofa_back", 2.62, 2.85, 0.90, 2.40, 0.10, 0.88, "sofa"))
    s.append(box("sofa_arm_south", 2.0, 2.85, 0.90, 1.05, 0.10, 0.62, "sofa"))
    s.append(box("sofa_arm_north", 2.0, 2.85, 2.25, 2.40, 0.10, 0.62, "sofa"))
    s.append(box("sofa_cushion_0", 2.48, 2.62, 1.15, 1.50, 0.50, 0.80, "cushion_red"))
    s.append(box("sofa_cushion_1", 2.48, 2.62, 1.85, 2.18, 0.50, 0.80, "cushion_yellow"))
    s.append(box("coffee_table_top", 0.95, 1.55, 1.25, 2.05, 0.38, 0.42, "wood"))
    for i, (lx, ly) in enumerate(((1.0, 1.3), (1.5, 1.3), (1.0, 2.0), (1.5, 2.0))):
        s.append(cyl(f"coffee_table_leg_{i}", lx, ly, 0.0, 0.38, 0.02, "dark_wood"))
    s.append(box("rug_living", 0.65, 1.90, 0.90, 2.40, 0.0, 0.006, "rug", collide=False))
    # bookshelf on the east wall, floor lamp, pot plant
    s.append(box("bookshelf", 3.62, X_LIVING - T_IN / 2, 2.3, 3.3, 0.0, 1.9, "wood"))
    s.append(box("bookshelf_books", 3.615, 3.62, 2.35, 3.25, 0.05, 1.85, "books", collide=False))
    s.append(cyl("floor_lamp_pole", 3.3, 2.75, 0.0, 1.5, 0.015, "metal"))
    s.append(cyl("floor_lamp_shade", 3.3, 2.75, 1.5, 1.75, 0.16, "lampshade"))
    s.append(cyl("plant_pot", 0.25, 0.3, 0.0, 0.35, 0.14, "pot"))
    s.append(ellipsoid("plant_leaves", 0.25, 0.3, 0.65, 0.25, 0.25, 0.35, "plant"))
    return s


def _bedroom(lay: Layout) -> list[Solid]:
    s: list[Solid] = []
    # double bed, head against the north wall
    b0, b1 = lay.bed
    s.append(box("bed_frame", b0, b1, 1.55, 3.55, 0.10, 0.32, "wood"))
    for i, (lx, ly) in enumerate(((b0 + 0.05, 1.6), (b1 - 0.05, 1.6))):
        s.append(box(f"bed_leg_{i}", lx - 0.04, lx + 0.04, ly - 0.04, ly + 0.04, 0.0, 0.10, "dark_wood"))
    s.append(box("bed_headboard", b0 - 0.03, b1 + 0.03, 3.50, 3.58, 0.0, 1.05, "wood"))
    s.append(box("bed_mattress", b0 + 0.03, b1 - 0.03, 1.58, 3.50, 0.32, 0.52, "mattress"))
    s.append(box("bed_blanket", b0 - 0.01, b1 + 0.01, 1.54, 2.95, 0.30, 0.55, "blanket"))
    s.append(ellipsoid("bed_pillow_left", b0 + 0.37, 3.22, 0.60, 0.28, 0.15, 0.08, "pillow"))
    s.append(ellipsoid("bed_pillow_right", b1 - 0.37, 3.22, 0.60, 0.28, 0.15, 0.08, "pillow"))
    # nightstands with lamps
    for side, (x0, x1) in zip(("left", "right"), lay.nightstands, strict=True):
        s.append(box(f"nightstand_{side}", x0, x1, 3.15, 3.58, 0.0, 0.55, "wood"))
        s.append(box(f"nightstand_{side}_drawer", x0 + 0.04, x1 - 0.04, 3.145, 3.15, 0.32, 0.48, "dark_wood",
                     collide=False))
        cx = (x0 + x1) / 2
        s.append(cyl(f"bedside_lamp_{side}_base", cx, 3.38, 0.55, 0.78, 0.04, "metal"))
        s.append(cyl(f"bedside_lamp_{side}_shade", cx, 3.38, 0.78, 0.96, 0.11, "lampshade"))
    # wardrobe against the west wall, north of the doorway (clear of the view through the door)
    wx = lay.wardrobe_x1
    s.append(box("wardrobe", X_LIVING + T_IN / 2, wx, 1.95, 3.10, 0.0, 2.05, "wood"))
    s.append(box("wardrobe_door_gap", wx, wx + 0.006, 2.52, 2.53, 0.05, 2.0, "dark_wood", collide=False))
    for i, y in enumerate((2.45, 2.60)):
        s.append(box(f"wardrobe_handle_{i}", wx, wx + 0.03, y - 0.01, y + 0.01, 0.9, 1.2, "chrome"))
    # full-length mirror (target) on the east wall, facing west
    mx = lay.x_bed - T_IN / 2
    s.append(box("mirror_frame", mx - 0.05, mx, 2.20, 3.00, 0.40, 2.00, "mirror_frame", target=MIRROR))
    s.append(box("mirror_glass", mx - 0.06, mx - 0.05, 2.25, 2.95, 0.45, 1.95, "mirror_glass", target=MIRROR))
    # a painting on the south wall and a rug beside the bed
    s.append(box("bedroom_painting", 4.55, 5.45, 0.0, 0.02, 1.25, 1.85, "painting", collide=False))
    s.append(box("rug_bedroom", 4.45, 4.72, 1.8, 3.0, 0.0, 0.006, "rug", collide=False))
    return s


def _bathroom() -> list[Solid]:
    s: list[Solid] = []
    wx = X_BATH  # east wall inner face
    # vanity with a sink (target), faucet and a towel, against the east wall, facing west
    s.append(box("vanity_cabinet", 8.08, wx, 1.50, 2.30, 0.0, 0.80, "painted_wood", target=SINK))
    s.append(box("vanity_top", 8.04, wx, 1.48, 2.32, 0.80, 0.85, "marble", target=SINK))
    s.append(cyl("sink_basin", 8.30, 1.90, 0.85, 0.91, 0.18, "ceramic", target=SINK))
    s.append(cyl("sink_water", 8.30, 1.90, 0.91, 0.915, 0.14, "water", collide=False, target=SINK))
    s.append(cyl("sink_faucet", 8.52, 1.90, 0.85, 1.05, 0.016, "chrome", target=SINK))
    s.append(box("sink_spout", 8.40, 8.53, 1.89, 1.91, 1.02, 1.05, "chrome", target=SINK))
    s.append(box("towel", 8.10, 8.14, 2.34, 2.60, 0.45, 0.84, "towel"))
    # toilet against the south wall
    s.append(box("toilet_tank", 7.72, 8.18, 0.02, 0.24, 0.40, 0.80, "ceramic"))
    s.append(ellipsoid("toilet_bowl", 7.95, 0.48, 0.22, 0.19, 0.26, 0.22, "ceramic"))
    s.append(box("toilet_seat", 7.78, 8.12, 0.26, 0.74, 0.40, 0.44, "ceramic"))
    # bathtub along the north wall with a shower and a curtain
    s.append(box("bathtub", 6.95, wx, 2.85, Y_MAX, 0.0, 0.55, "ceramic"))
    s.append(box("bathtub_inside", 7.05, wx - 0.08, 2.93, Y_MAX - 0.08, 0.55, 0.56, "water", collide=False))
    s.append(cyl("shower_pipe", 8.45, Y_MAX - 0.04, 0.55, 1.95, 0.015, "chrome"))
    s.append(box("shower_head", 8.40, 8.50, Y_MAX - 0.16, Y_MAX - 0.02, 1.92, 1.97, "chrome"))
    s.append(cyl("shower_rail", 6.95, 2.84, 1.95, 1.97, 0.01, "chrome", collide=False))
    s.append(box("shower_curtain", 8.15, wx, 2.80, 2.86, 0.70, 1.95, "curtain"))
    s.append(box("bath_mat", 7.2, 7.8, 2.35, 2.75, 0.0, 0.008, "bath_mat", collide=False))
    return s


def _rooms(lay: Layout) -> tuple[Room, ...]:
    x_bed = lay.x_bed
    return (
        Room(LIVING_ROOM, "living room / kitchen", ((0, 0), (X_LIVING, 0), (X_LIVING, Y_MAX), (0, Y_MAX)),
             aliases=("living room", "kitchen", "living room and kitchen", "living room or kitchen", "lounge",
                      "living"), color=(0.45, 0.80, 0.45)),
        Room(BEDROOM, "bedroom", ((X_LIVING, 0), (x_bed, 0), (x_bed, Y_MAX), (X_LIVING, Y_MAX)),
             aliases=("bed room", "sleeping room"), color=(0.85, 0.40, 0.85)),
        Room(BATHROOM, "bathroom", ((x_bed, 0), (X_BATH, 0), (X_BATH, Y_MAX), (x_bed, Y_MAX)),
             aliases=("bath room", "restroom", "washroom", "toilet"), color=(0.95, 0.85, 0.30)),
    )


def _targets(lay: Layout) -> tuple[Target, ...]:
    return (
        Target(REFRIGERATOR, "refrigerator", LIVING_ROOM, (2.44, 2.90, 0.95), -90.0, aliases=("fridge",)),
        Target(MIRROR, "mirror", BEDROOM, (lay.x_bed - T_IN / 2 - 0.06, 2.60, 1.20), 180.0,
               aliases=("full-length mirror", "looking glass")),
        Target(SINK, "sink", BATHROOM, (8.04, 1.90, 0.88), 180.0, aliases=("washbasin", "basin", "vanity")),
    )


_SPAWN_TEXT = (
    (LIVING_ROOM, "living room, near the bedroom door, facing the sofa and the kitchen"),
    (BEDROOM, "bedroom, at the foot of the bed, facing it"),
    (BATHROOM, "bathroom, facing the toilet"),
)


def _spawns(lay: Layout) -> tuple[Spawn, ...]:
    return tuple(Spawn(room, room, Pose(x, y, FLIGHT_Z, yaw), text)
                 for (room, text), (x, y, yaw) in zip(_SPAWN_TEXT, lay.spawns, strict=True))


def _build(name: str, lay: Layout) -> Scene:
    return Scene(
        name=name,
        description="A compact wooden cabin: living room and kitchen (left), bedroom (centre), bathroom (right).",
        rooms=_rooms(lay),
        doors=_doors(lay),
        targets=_targets(lay),
        spawns=_spawns(lay),
        solids=tuple(_structure(lay) + _living_room() + _bedroom(lay) + _bathroom()),
        materials=MATERIALS,
        lights=(
            Light("light_living", (2.0, 1.8, 2.35), (0.45, 0.42, 0.38), attenuation=(0.6, 0.15, 0.0)),
            Light("light_bedroom", (5.3, 1.8, 2.35), (0.45, 0.42, 0.38), attenuation=(0.6, 0.15, 0.0)),
            Light("light_bathroom", (7.6, 1.8, 2.35), (0.45, 0.45, 0.45), attenuation=(0.6, 0.15, 0.0)),
        ),
        bounds=((-T_EXT, -T_EXT), (X_BATH + T_EXT, Y_MAX + T_EXT)),
        ceiling_height=WALL_H,
        flight_altitude=FLIGHT_Z,
    )


@cache
def cabin() -> Scene:
    """The built-in cabin scene (v2; cached: it is immutable)."""
    return _build("cabin", V2)


@cache
def cabin_v1() -> Scene:
    """The cabin as the first real-VLM baseline flew it (kept so that its trials still replay)."""
    return _build("cabin-v1", V1)
