"""Scene -> MJCF (scene/mjcf.py): the text compiles in MuJoCo, every solid becomes the geom it describes, the
output is deterministic, and the geoms the rest of the system names (floors, door frames, targets) exist."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from vlnpilot.scene import load_scene
from vlnpilot.scene.mjcf import scene_to_mjcf
from vlnpilot.scene.model import Solid
from vlnpilot.sim import drone

SCENES = ["cabin", "house:43?rooms=6"]
GEOM_TYPES = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
              "sphere": mujoco.mjtGeom.mjGEOM_SPHERE, "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID,
              "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE, "plane": mujoco.mjtGeom.mjGEOM_PLANE}
PNG = b"\x89PNG\r\n\x1a\n"


def _compile(scene, **options) -> mujoco.MjModel:
    xml, assets = scene_to_mjcf(scene, **options)
    return mujoco.MjModel.from_xml_string(xml, assets)


def _geom(model: mujoco.MjModel, name: str) -> int:
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
    assert gid >= 0, f"no geom {name!r}"
    return gid


@pytest.fixture(scope="module", params=SCENES)
def compiled(request):
    scene = load_scene(request.param)
    return scene, _compile(scene)


def test_every_solid_is_a_geom_of_its_shape_place_size_and_material(compiled):
    scene, model = compiled
    assert model.ngeom == len(scene.solids) and model.nbody == 1  # all static, in the world body
    for s in scene.solids:
        g = _geom(model, s.name)
        assert model.geom_type[g] == GEOM_TYPES[s.shape], s.name
        np.testing.assert_allclose(model.geom_pos[g], s.pos, rtol=1e-4, atol=1e-6, err_msg=s.name)
        expected = {"box": s.size, "ellipsoid": s.size, "cylinder": (*s.size[:2], 0.0),
                    "sphere": (s.size[0], 0.0, 0.0), "capsule": (*s.size[:2], 0.0),
                    "plane": (s.size[0], s.size[1], 0.5)}[s.shape]
        np.testing.assert_allclose(model.geom_size[g], expected, rtol=1e-4, atol=1e-6, err_msg=s.name)
        material = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_MATERIAL, model.geom_matid[g])
        assert material == s.material, s.name


def test_solid_geoms_collide_with_the_drone_and_never_with_each_other(compiled):
    scene, model = compiled
    solid = [s for s in scene.solids if s.collide]
    visual = [s for s in scene.solids if not s.collide]
    assert solid and visual
    for s in visual:  # rugs, pictures, wall skins: seen, never touched
        g = _geom(model, s.name)
        assert (model.geom_contype[g], model.geom_conaffinity[g], model.geom_group[g]) == (0, 0, 1), s.name
    for s in solid:
        g = _geom(model, s.name)
        ct, ca = int(model.geom_contype[g]), int(model.geom_conaffinity[g])
        assert model.geom_group[g] == 0 and not (ct & ca), s.name  # world-world pairs are never tested
        assert (ct & drone.DRONE_CONAFFINITY) or (drone.DRONE_CONTYPE & ca), s.name  # the drone's are


def test_rooms_doors_and_targets_have_their_named_geoms(compiled):
    scene, model = compiled
    for room in scene.rooms:
        _geom(model, f"floor_{room.id}")
    for door in scene.doors:
        for part in ("frame_left", "frame_right", "frame_top"):
            g = _geom(model, f"{door.id}_{part}")
            assert model.geom_contype[g], f"{door.id}_{part} must be collision geometry"
    for target in scene.targets:
        parts = [s.name for s in scene.solids if s.target == target.id]
        assert parts, f"target {target.id} has no solid"
        for name in parts:
            _geom(model, name)


def test_materials_lights_and_textures_reach_the_model(compiled):
    scene, model = compiled
    xml, assets = scene_to_mjcf(scene)
    textures = {m.texture for m in scene.materials if m.texture}
    assert set(assets) == {f"{t}.png" for t in textures}  # exactly the textures in use, as PNG files
    assert all(data.startswith(PNG) for data in assets.values())
    assert model.ntex == len(textures) and model.nmat == len(scene.materials)
    assert model.nlight == len(scene.lights)
    for m in scene.materials:
        mid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_MATERIAL, m.name)
        np.testing.assert_allclose(model.mat_rgba[mid], m.rgba, rtol=1e-4, err_msg=m.name)


def test_output_is_deterministic():
    first = scene_to_mjcf(load_scene("cabin"))
    assert scene_to_mjcf(load_scene("cabin")) == first  # same text, same texture bytes
    house = scene_to_mjcf(load_scene("house:43?rooms=6"))
    assert scene_to_mjcf(load_scene("house:43?rooms=6")) == house and house[0] != first[0]


def test_render_size_shadows_and_extra_bodies():
    scene = load_scene("cabin")
    model = _compile(scene, max_render=(640, 480))
    assert (model.vis.global_.offwidth, model.vis.global_.offheight) == (640, 480)
    assert not model.light_castshadow.any()
    assert _compile(scene, shadows=True).light_castshadow.all()
    with_drone = _compile(scene, bodies=drone.drone_body_xml(), assets_xml=drone.drone_assets_xml())
    assert mujoco.mj_name2id(with_drone, mujoco.mjtObj.mjOBJ_BODY, drone.BODY) > 0
    _geom(with_drone, drone.HULL)


def test_orientation_yaw_euler_and_plane_axes():
    base = load_scene("cabin")
    box = Solid("turned_box", "box", (1.0, 1.0, 1.0), (0.3, 0.1, 0.2), base.materials[0].name, yaw_deg=90.0)
    tilted = Solid("tilted_box", "box", (2.0, 1.0, 1.0), (0.3, 0.1, 0.2), base.materials[0].name,
                   yaw_deg=45.0, euler_deg=(90.0, 0.0, 0.0))  # euler wins over yaw
    skin = Solid("north_skin", "plane", (3.0, 1.0, 1.0), (0.5, 0.5, 0.0), base.materials[0].name, collide=False,
                 xyaxes=(1.0, 0.0, 0.0, 0.0, 0.0, 1.0))  # in-plane x and z: the normal is -y
    model = _compile(dataclasses.replace(base, solids=(*base.solids, box, tilted, skin)))
    h = math.sqrt(0.5)  # cos and sin of 45 degrees; the MJCF keeps 5 significant digits of radians (atol)
    np.testing.assert_allclose(model.geom_quat[_geom(model, "turned_box")], (h, 0, 0, h), atol=1e-5)
    np.testing.assert_allclose(model.geom_quat[_geom(model, "tilted_box")], (h, h, 0, 0), atol=1e-5)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    normal = data.geom_xmat[_geom(model, "north_skin")].reshape(3, 3)[:, 2]
    np.testing.assert_allclose(normal, (0.0, -1.0, 0.0), atol=1e-5)
