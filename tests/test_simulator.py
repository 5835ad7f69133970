"""The embedded simulator: collisions (walls, door frames, propeller tips), determinism, commands, cameras."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.records import Motion, Pose
from vlnpilot.sim import SimConfig, Simulator, drone

ONE_CM = Motion(forward_m=0.01)


def _door_pose(door, depth: float, lateral: float = 0.0, z: float = 1.0) -> Pose:
    """A pose in the door's frame (depth along its normal, lateral to its left), facing along the normal."""
    nx, ny = door.normal
    x = door.center[0] + depth * nx - lateral * ny
    y = door.center[1] + depth * ny + lateral * nx
    return Pose(x, y, z, door.normal_deg)


def _fly_until_collision(sim, command: str, max_steps: int):
    for _ in range(max_steps):
        obs = sim.step(command)
        if obs.collided:
            return obs
    pytest.fail(f"no collision after {max_steps} x {command} (pose {sim.pose})")


def _assert_stopped_at_contact(sim) -> None:
    """Never inside anything, and within 1 cm of the obstacle (1 cm further on touches it)."""
    assert sim.contact_at(sim.pose) is None
    assert sim.contact_at(ONE_CM.apply(sim.pose)) is not None


def _free_side(sim, door, offset: float) -> float:
    """+offset or -offset: the side of the doorway whose approach is not blocked by the open door leaf."""
    for lateral in (offset, -offset):
        if all(sim.contact_at(_door_pose(door, d, lateral)) is None for d in np.arange(-0.6, -0.1, 0.02)):
            return lateral
    pytest.fail(f"both sides of {door.id} are blocked")


# -- collisions ------------------------------------------------------------------------------------------
def test_flying_into_a_wall_stops_at_the_wall(geo_sim):
    sim = geo_sim
    sim.reset(Pose(7.25, 1.75, 1.0, -90.0))  # bathroom, facing the south wall (y = 0), nothing in between
    obs = _fly_until_collision(sim, "A3", 10)
    assert obs.contact.startswith("wall_bathroom_south"), obs.contact
    assert obs.contact_part in (drone.HULL, *drone.PROPELLERS)
    assert obs.pose == sim.pose and obs.pose.x == pytest.approx(7.25) and obs.pose.yaw_deg == -90.0
    assert obs.pose.y == pytest.approx(drone.LENGTH / 2, abs=0.01)  # the nose touches the wall face at y = 0
    _assert_stopped_at_contact(sim)
    # the next step against the wall is a collision again and does not move the drone further in
    again = sim.step("A1")
    assert again.collided and again.pose.y >= obs.pose.y - 1e-9
    assert sim.contact_at(sim.pose) is None


@pytest.mark.parametrize("door_id", ["door_living_bedroom", "door_bedroom_bathroom"])
def test_flying_into_a_door_jamb_reports_the_frame(geo_sim, door_id):
    sim = geo_sim
    door = sim.scene.door(door_id)
    lateral = _free_side(sim, door, door.width / 2 + 0.025)  # head-on at the middle of a jamb
    sim.reset(_door_pose(door, -0.6, lateral))
    obs = _fly_until_collision(sim, "A1", 8)
    assert obs.contact.startswith(f"{door.id}_frame_"), obs.contact
    _assert_stopped_at_contact(sim)


@pytest.mark.parametrize("door_id", ["door_living_bedroom", "door_bedroom_bathroom"])
def test_flying_through_the_centre_of_an_open_doorway_never_collides(geo_sim, door_id):
    sim = geo_sim
    door = sim.scene.door(door_id)
    assert door.open
    sim.reset(_door_pose(door, -0.6))
    assert sim.ground_truth().room() == door.rooms[0]
    for _ in range(12):
        obs = sim.step("A1")
        assert not obs.collided, (obs.contact, obs.pose)
    depth, lateral = door.frame_of(sim.pose.x, sim.pose.y)
    assert depth == pytest.approx(0.6) and lateral == pytest.approx(0.0, abs=1e-9)
    assert sim.ground_truth().room() == door.rooms[1]


@pytest.mark.parametrize("door_id", ["door_living_bedroom", "door_bedroom_bathroom"])
def test_off_centre_crossing_clips_a_propeller_on_the_frame(geo_sim, door_id):
    """The paper's failure: the hull would pass, but a propeller tip (1 cm of it) clips the jamb."""
    sim = geo_sim
    door = sim.scene.door(door_id)
    offset = door.width / 2 - drone.WIDTH / 2 + 0.01
    assert offset + drone.HULL_HALF[1] < door.width / 2  # the hull alone would clear the jamb
    lateral = _free_side(sim, door, offset)
    sim.reset(_door_pose(door, -0.6, lateral))
    obs = _fly_until_collision(sim, "A1", 12)
    assert obs.contact_part in drone.PROPELLERS and obs.contact_part.startswith("prop_front_")
    side = "left" if lateral > 0 else "right"
    assert obs.contact == f"{door.id}_frame_{side}"
    _assert_stopped_at_contact(sim)
    depth, _ = door.frame_of(obs.pose.x, obs.pose.y)
    assert -0.2 < depth < -0.05  # stopped in front of the jamb, not inside the doorway


def test_rotation_into_a_jamb_is_a_collision_too(geo_sim):
    sim = geo_sim
    door = sim.scene.door("door_bedroom_bathroom")
    lateral = _free_side(sim, door, door.width / 2 - drone.WIDTH / 2 - 0.004)
    sim.reset(_door_pose(door, 0.0, lateral))  # inside the doorway, 4 mm clear of a jamb
    obs = sim.step("C3" if lateral > 0 else "B3")  # turning towards that jamb swings a propeller into it
    assert obs.collided and obs.contact.startswith(f"{door.id}_frame_") and obs.contact_part in drone.PROPELLERS
    assert sim.contact_at(sim.pose) is None


# -- commands ---------------------------------------------------------------------------------------------------
def test_command_directions(geo_sim):
    sim = geo_sim
    start = sim.reset("bedroom").pose
    c, s = start.heading()
    moves = {
        "A1": (0.10 * c, 0.10 * s, 0.0), "A2": (0.25 * c, 0.25 * s, 0.0),
        "B1": (0.0, 0.0, -15.0), "B2": (0.0, 0.0, -45.0), "B3": (0.0, 0.0, -90.0),
        "C1": (0.0, 0.0, 15.0), "C2": (0.0, 0.0, 45.0), "C3": (0.0, 0.0, 90.0),
        "D1": (-0.10 * s, 0.10 * c, 0.0), "D2": (0.10 * s, -0.10 * c, 0.0), "E": (0.0, 0.0, 0.0),
    }
    for code, (dx, dy, dyaw) in moves.items():
        before = sim.reset("bedroom").pose
        obs = sim.step(code)
        assert not obs.collided, code
        assert obs.step == 1
        assert obs.pose.x - before.x == pytest.approx(dx, abs=1e-9), code
        assert obs.pose.y - before.y == pytest.approx(dy, abs=1e-9), code
        assert obs.pose.z == before.z
        assert obs.pose.yaw_deg - before.yaw_deg == pytest.approx(dyaw), code
    assert set(moves) | {"A3"} == set(COMMANDS)


def test_a_non_finite_motion_is_refused(geo_sim):
    sim = geo_sim
    before = sim.reset("bedroom").pose
    with pytest.raises(ValueError):
        Motion(forward_m=float("nan"))
    bad = Motion()
    object.__setattr__(bad, "yaw_deg", float("inf"))  # smuggled past the dataclass check
    with pytest.raises(ConfigError):
        sim.move(bad)
    with pytest.raises(ConfigError):
        sim.move((0.1, 0.0, 0.0, 0.0))
    assert sim.pose == before and sim.step_count == 0


# -- determinism -----------------------------------------------------------------------------------------------
SEQUENCE = ("A2", "C1", "A1", "D1", "B2", "A1")


def _run(sim, seed: int, spawn: str = "living_room"):
    observations = [sim.reset(spawn, seed=seed)]
    observations += [sim.step(c) for c in SEQUENCE]
    return observations


def test_same_seed_same_commands_same_poses_and_images(sim):
    first, second = _run(sim, seed=7), _run(sim, seed=7)
    for a, b in zip(first, second, strict=True):
        assert a.pose == b.pose and a.collided == b.collided and a.step == b.step
        assert a.front_rgb.shape == (480, 640, 3) and a.front_rgb.dtype == np.uint8
        assert np.array_equal(a.front_rgb, b.front_rgb)
        assert np.array_equal(a.rear_rgb, b.rear_rgb)
    assert not np.array_equal(first[0].front_rgb, first[-1].front_rgb)  # the drone did move and look elsewhere


def test_seeded_spawn_jitter_is_reproducible():
    with Simulator("cabin", SimConfig(width=64, height=48, rear_width=64, rear_height=48, spawn_jitter_m=0.1,
                                      spawn_jitter_deg=10.0)) as jittery:
        a, b, c = _run(jittery, seed=3), _run(jittery, seed=3), _run(jittery, seed=4)
    assert [o.pose for o in a] == [o.pose for o in b]
    assert all(np.array_equal(x.front_rgb, y.front_rgb) for x, y in zip(a, b, strict=True))
    assert a[0].pose != c[0].pose


def _first_jitter_draw(seed: int, metres: float, degrees: float) -> tuple[float, float, float]:
    """The spawn jitter's first draw for `seed`, as the simulator has always drawn it: dx, dy, then dyaw."""
    rng = np.random.default_rng(seed)
    dx, dy = rng.uniform(-metres, metres, 2)
    return float(dx), float(dy), float(rng.uniform(-degrees, degrees))


def test_the_yaw_jitter_keeps_the_spawn_yaw_in_range():
    """A spawn facing 180 degrees jittered by +-10 stays in (-180, 180] (it reached -186, outside the gym's space)."""
    facing_west = Pose(2.0, 2.0, 1.0, 180.0)  # the living room, nothing near
    with Simulator("cabin", SimConfig(render=False, spawn_jitter_deg=10.0)) as jittery:
        yaws = [jittery.reset(facing_west, seed=seed).pose.yaw_deg for seed in range(10)]
    assert all(-180.0 < yaw <= 180.0 for yaw in yaws), yaws
    assert any(yaw < 0 for yaw in yaws) and any(yaw > 0 for yaw in yaws)  # jittered both ways round


def test_a_jittered_spawn_that_touches_a_door_is_drawn_again():
    """Seed 43's first draw puts the bedroom spawn into the bathroom door's leaf: the next free draw serves (reset
    raised ConfigError); a seed whose first draw was free keeps the pose it always had."""
    with Simulator("cabin", SimConfig(render=False, spawn_jitter_m=0.3)) as jittery:
        spawn = jittery.scene.spawn("bedroom").pose
        dx, dy, _ = _first_jitter_draw(43, 0.3, 0.0)
        assert jittery.contact_at(Pose(spawn.x + dx, spawn.y + dy, spawn.z, spawn.yaw_deg)) is not None
        redrawn = jittery.reset("bedroom", seed=43).pose
        assert redrawn == jittery.reset("bedroom", seed=43).pose  # the same seed, the same pose
        assert jittery.contact_at(redrawn) is None and redrawn != spawn
        dx, dy, _ = _first_jitter_draw(42, 0.3, 0.0)
        assert jittery.reset("bedroom", seed=42).pose == Pose(spawn.x + dx, spawn.y + dy, spawn.z, spawn.yaw_deg)


def test_a_spawn_every_jitter_draw_of_which_touches_falls_back_to_the_spawn(monkeypatch: pytest.MonkeyPatch):
    with Simulator("cabin", SimConfig(render=False, spawn_jitter_m=0.3, spawn_jitter_deg=10.0)) as jittery:
        spawn = jittery.scene.spawn("bedroom").pose
        touches_unless_at_spawn = jittery.contact_at

        def contact_at(pose: Pose):
            return ("wall", "body") if pose != spawn else touches_unless_at_spawn(pose)

        monkeypatch.setattr(jittery, "contact_at", contact_at)
        assert jittery.reset("bedroom", seed=43).pose == spawn


# -- the drone ---------------------------------------------------------------------------------------------------
def test_tello_size_from_the_collision_geometry(geo_sim):
    m = geo_sim.model
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    names = set()
    for g in geo_sim.drone_geoms:
        if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
            continue  # visual only (the lens)
        names.add(geo_sim.geom_name(g))
        size, pos = m.geom_size[g], m.geom_pos[g]
        if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            half = size
        else:
            assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER  # upright propeller discs
            half = np.array([size[0], size[0], size[1]])
        lo, hi = np.minimum(lo, pos - half), np.maximum(hi, pos + half)
    assert names == {drone.HULL, *drone.PROPELLERS}  # propellers are collision geometry of their own
    np.testing.assert_allclose((hi - lo) * 1000, [98.0, 92.5, 41.0], atol=2.0)


def test_front_camera_is_4_3_with_the_tello_field_of_view(sim):
    obs = sim.reset("living_room")
    h, w, _ = obs.front_rgb.shape
    assert w * 3 == h * 4 and (w, h) == (640, 480)
    assert obs.rear_rgb.shape == (480, 640, 3)
    cam = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_CAMERA, drone.FRONT_CAMERA)
    half_v = math.tan(math.radians(sim.model.cam_fovy[cam]) / 2)
    diagonal = 2 * math.degrees(math.atan(half_v * math.hypot(w / h, 1)))
    assert diagonal == pytest.approx(82.6, abs=0.5)


def test_resolution_limits():
    with pytest.raises(ConfigError):
        SimConfig(width=1280, height=960)
    SimConfig(width=960, height=720)  # the largest allowed


def test_without_the_rear_camera_the_front_is_the_same_and_the_rear_a_placeholder(sim):
    with Simulator("cabin", SimConfig(rear_camera=False)) as lean:
        both, front_only = _run(sim, seed=5), _run(lean, seed=5)
        calls: list[str] = []
        renderer = lean._renderers[(640, 480)]  # the one renderer of both 640x480 cameras
        update = renderer.update_scene
        renderer.update_scene = lambda data, camera, **k: calls.append(camera) or update(data, camera=camera, **k)
        lean.step("E")
    assert calls == [drone.FRONT_CAMERA]  # the chase camera is never rendered
    for a, b in zip(both, front_only, strict=True):
        assert a.pose == b.pose and np.array_equal(a.front_rgb, b.front_rgb)
        assert a.rear_rgb.shape == (480, 640, 3) and b.rear_rgb.shape == (1, 1, 3)
