"""The simulator's ground truth (sim/ground_truth.py) against geometry computed by hand from the cabin's plan.

The cabin's living room spans x 0..4, y 0..3.6 on the walls' centre lines; its north wall is 0.15 m thick
(inner face at y = 3.6), the partition to the bedroom 0.05 m (living-room face at x = 3.95). The drone is
98 mm long and 92.5 mm wide, propeller tips included, so its front reaches LENGTH / 2 ahead of its centre.
"""

from __future__ import annotations

import math

import pytest

from vlnpilot.core.records import Pose
from vlnpilot.sim import drone

NORTH_FACE_Y = 3.6  # wall_living_north_0: centre y 3.675, half thickness 0.075
PARTITION_FACE_X = 3.95  # wall_living_bedroom_w_*: centre x 3.975, half thickness 0.025
FACING_NORTH, FACING_EAST = 90.0, 0.0
MM_TENTH = 1e-4  # the drone's MJCF keeps 5 significant digits (a rotor at y 0.025, not 0.02505)


@pytest.fixture
def gt(geo_sim):
    geo_sim.reset(Pose(2.0, 1.8, 1.0, FACING_NORTH))
    return geo_sim.ground_truth()


def test_room_follows_the_plan(geo_sim):
    for room in geo_sim.scene.rooms:
        x, y = room.centroid
        geo_sim.reset(Pose(x, y, 1.0, 0.0))
        assert geo_sim.ground_truth().room() == room.id
    geo_sim.reset(Pose(3.9, 1.8, 1.0, 0.0))  # just west of the partition's centre line
    assert geo_sim.ground_truth().room() == "living_room"
    geo_sim.reset(Pose(4.1, 1.8, 1.0, 0.0))
    assert geo_sim.ground_truth().room() == "bedroom"


def test_target_distance_and_bearing_by_hand(geo_sim, gt):
    fridge = geo_sim.scene.target("refrigerator")
    assert fridge.position[:2] == (2.44, 2.9)
    dx, dy = 2.44 - 2.0, 2.9 - 1.8
    distance, bearing = gt.target_distance_bearing("refrigerator")
    assert distance == pytest.approx(math.hypot(dx, dy))  # 1.185 m; height is not part of it
    assert bearing == pytest.approx(math.degrees(math.atan2(dy, dx)) - 90.0)  # -21.8: to the right of north
    assert bearing < 0  # negative bearings are to the drone's right (clockwise)

    geo_sim.reset(Pose(2.0, 1.8, 1.0, 270.0))  # facing south: the fridge is behind, to the left
    _, behind = gt.target_distance_bearing("refrigerator")
    assert behind == pytest.approx(math.degrees(math.atan2(dy, dx)) - 270.0 + 360.0)  # wrapped into (-180, 180]
    assert -180.0 < behind <= 180.0


def test_clearance_to_the_wall_ahead_by_hand(geo_sim, gt):
    for gap in (0.20, 0.15):
        dist, geom, part = gt.clearance_at(Pose(3.0, NORTH_FACE_Y - gap, 1.0, FACING_NORTH), 0.4)
        assert dist == pytest.approx(gap - drone.LENGTH / 2, abs=MM_TENTH)
        assert geom == "wall_living_north_0" and part.startswith("prop_front_")  # the front propellers lead

    dist, geom, _ = gt.clearance_at(Pose(PARTITION_FACE_X - 0.25, 2.0, 1.0, FACING_EAST), 0.4)
    assert geom.startswith("wall_living_bedroom_") and dist == pytest.approx(0.25 - drone.LENGTH / 2, abs=MM_TENTH)
    # side-on to the same wall the drone is narrower than it is long
    dist, geom, _ = gt.clearance_at(Pose(PARTITION_FACE_X - 0.25, 2.0, 1.0, FACING_NORTH), 0.4)
    assert geom.startswith("wall_living_bedroom_") and dist == pytest.approx(0.25 - drone.WIDTH / 2, abs=MM_TENTH)


def test_clearance_is_negative_inside_a_wall_and_none_beyond_the_query(gt):
    dist, geom, _ = gt.clearance_at(Pose(3.0, NORTH_FACE_Y - 0.02, 1.0, FACING_NORTH), 0.4)
    assert geom == "wall_living_north_0" and dist == pytest.approx(0.02 - drone.LENGTH / 2, abs=MM_TENTH) and dist < 0
    assert gt.clearance_at(Pose(3.0, NORTH_FACE_Y - 0.20, 1.0, FACING_NORTH), 0.1) is None  # 0.151 m > 0.1 m


def test_contact_at_names_the_wall_and_queries_leave_the_drone_where_it_is(geo_sim, gt):
    inside = Pose(3.0, NORTH_FACE_Y - 0.02, 1.0, FACING_NORTH)
    assert gt.contact_at(inside) == "wall_living_north_0"
    assert gt.contact_at(Pose(3.0, NORTH_FACE_Y - 0.06, 1.0, FACING_NORTH)) is None  # 11 mm short of the wall
    gt.clearance_at(inside, 0.4)
    assert gt.pose() == Pose(2.0, 1.8, 1.0, FACING_NORTH)
    assert tuple(geo_sim.data.qpos[:3]) == pytest.approx((2.0, 1.8, 1.0))  # the model is back at the drone's pose
    assert not geo_sim.step("A1").collided


def test_each_target_is_visible_from_in_front_and_not_from_behind(sim):
    for target in sim.scene.targets:
        fx, fy = math.cos(math.radians(target.facing_deg)), math.sin(math.radians(target.facing_deg))
        x, y = target.position[0] + 0.8 * fx, target.position[1] + 0.8 * fy
        sim.reset(Pose(x, y, sim.scene.flight_altitude, target.facing_deg + 180.0))
        gt = sim.ground_truth()
        assert gt.room() == target.room
        assert gt.target_visible(target.id), target.id
        distance, bearing = gt.target_distance_bearing(target.id)
        assert distance == pytest.approx(0.8, abs=1e-6) and bearing == pytest.approx(0.0, abs=1e-6)
        sim.reset(Pose(x, y, sim.scene.flight_altitude, target.facing_deg))
        assert not sim.ground_truth().target_visible(target.id), target.id


def test_a_target_is_not_visible_from_another_room_through_a_wall(sim):
    mirror = sim.scene.target("mirror")  # on the bedroom's east wall, facing west
    sim.reset(Pose(mirror.position[0] + 0.8, mirror.position[1], sim.scene.flight_altitude, 180.0))
    gt = sim.ground_truth()
    assert gt.room() == "bathroom"  # 0.8 m from the mirror, facing it, but behind the partition
    assert not gt.target_visible("mirror")


def test_target_footprint_by_hand(geo_sim, gt):
    """The fridge's body spans x 2.08..2.80, y 2.90..3.58 (refrigerator_body), the strip of its door gap is 3 mm
    proud of it (y 2.894) and its handles reach y 2.85: the monitor measures to the nearest corner of the door gap
    and counts the heading that passes 2.6 deg beside the body's far corner."""
    from vlnpilot.core.footprint import footprint_distance, footprint_off_heading_deg

    footprint = gt.target_footprint("refrigerator")
    xs = [x for poly in footprint for x, _ in poly]
    ys = [y for poly in footprint for _, y in poly]
    assert (min(xs), max(xs), max(ys)) == pytest.approx((2.08, 2.80, 3.58))
    assert min(ys) == pytest.approx(2.85)  # the handles' fronts
    pose = gt.pose()  # (2.0, 1.8), facing north
    assert footprint_distance(pose, footprint) == pytest.approx(math.hypot(2.08 - 2.0, 2.894 - 1.8))
    assert footprint_off_heading_deg(pose, footprint) == pytest.approx(90.0 - math.degrees(math.atan2(1.78, 0.08)))
    assert footprint_distance(Pose(2.44, 2.5, 1.0, 90.0), footprint) == pytest.approx(2.894 - 2.5)  # between handles
    assert footprint_off_heading_deg(Pose(2.44, 2.5, 1.0, 90.0), footprint) == 0.0
