"""Rich scene detail (scene/detail.py, docs/scenes.md): `plain` is today's MJCF byte for byte; `rich` adds only
visual geoms, in the group that the segmentation, the depth camera and the range sensors never see, at the
real-world sizes it documents, the same for the same scene; `--detail` refuses a bad value in one line."""

from __future__ import annotations

import hashlib
import json

import mujoco
import numpy as np
import pytest

from cli_support import run_main
from tello_support import loopback_only, rig  # noqa: F401  (loopback_only: the autouse guard)
from vlnpilot.bench.command import bench_command
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.records import Pose
from vlnpilot.episode.config import EpisodeConfig
from vlnpilot.scene import detail as D
from vlnpilot.scene import load_scene
from vlnpilot.scene.mjcf import scene_to_mjcf
from vlnpilot.sim import SimConfig, Simulator, drone
from vlnpilot.sim.gym_env import CabinEnv
from vlnpilot.sim.house_env import HouseEnv
from vlnpilot.sim.mirrors import reflect_in_view

# sha256 (first 16 hex) of the MJCF text and its textures, with the drone, as the scenes were before --detail:
# `plain` must keep them, so every recorded trial replays in the scene it saw.
PLAIN_MJCF = {"cabin": "27b0005b6687a4f3", "cabin-v1": "67545737361adc26", "house:3": "f88f9e781ff38155",
              "house:11?rooms=5": "42cf7980e5c186e1"}
MIRROR_VIEW = Pose(5.0, 2.6, 1.0, 0.0)  # in the cabin's bedroom, facing the full-length mirror


def _mjcf(scene: str, detail: str = "plain") -> tuple[str, dict[str, bytes]]:
    return scene_to_mjcf(load_scene(scene), bodies=drone.drone_body_xml(), assets_xml=drone.drone_assets_xml(),
                         detail=detail)


def _digest(xml: str, assets: dict[str, bytes]) -> str:
    blob = xml.encode() + b"".join(k.encode() + v for k, v in sorted(assets.items()))
    return hashlib.sha256(blob).hexdigest()[:16]


@pytest.mark.parametrize("scene", sorted(PLAIN_MJCF))
def test_plain_is_the_mjcf_of_before_byte_for_byte(scene: str) -> None:
    assert _digest(*_mjcf(scene)) == PLAIN_MJCF[scene]
    assert D.with_detail(load_scene(scene), "plain") is load_scene(scene)


@pytest.mark.parametrize("scene", ["cabin", "house:11?rooms=5"])
def test_rich_adds_only_visual_geoms_in_the_detail_group_and_changes_no_solid(scene: str) -> None:
    plain = mujoco.MjModel.from_xml_string(*_mjcf(scene))
    rich = mujoco.MjModel.from_xml_string(*_mjcf(scene, "rich"))
    names = {mujoco.mj_id2name(rich, mujoco.mjtObj.mjOBJ_GEOM, g): g for g in range(rich.ngeom)}
    added = [n for n in names if mujoco.mj_name2id(plain, mujoco.mjtObj.mjOBJ_GEOM, n) < 0]
    assert len(added) > 30 and all(n.startswith(D.PREFIX) for n in added)
    for n in added:
        g = names[n]
        assert (rich.geom_contype[g], rich.geom_conaffinity[g], rich.geom_group[g]) == (0, 0, D.DETAIL_GROUP), n
    for g in range(plain.ngeom):  # every geom of the plain scene, as it was
        n = mujoco.mj_id2name(plain, mujoco.mjtObj.mjOBJ_GEOM, g)
        r = names[n]
        for field in ("geom_type", "geom_pos", "geom_size", "geom_quat", "geom_contype", "geom_conaffinity",
                      "geom_group"):
            np.testing.assert_array_equal(getattr(rich, field)[r], getattr(plain, field)[g], err_msg=f"{n} {field}")
    kinds = {n.removeprefix(D.PREFIX).split("_")[0] for n in added}
    assert {"skirting", "architrave", "switch", "handle", "picture", "mirror"} <= kinds
    assert kinds & {"books", "cup", "bowl", "board", "lamp"}, kinds  # clutter on some surface


def test_rich_detail_is_deterministic_per_scene() -> None:
    assert _mjcf("house:11?rooms=5", "rich") == _mjcf("house:11?rooms=5", "rich")
    assert D.with_detail(load_scene("house:11?rooms=5"), "rich") == D.with_detail(load_scene("house:11?rooms=5"),
                                                                                 "rich")
    pictures = [{s.name for s in D.with_detail(load_scene(n), "rich").solids if "picture" in s.name}
                for n in ("house:11?rooms=5", "house:12?rooms=5")]
    assert pictures[0] != pictures[1]  # another house, other walls


def test_the_detail_has_its_documented_real_world_sizes() -> None:
    scene = load_scene("cabin")
    rich = D.with_detail(scene, "rich")
    parts = [s for s in rich.solids if D.is_detail(s.name)]

    def of(kind: str) -> list:
        return [s for s in parts if s.name.startswith(D.PREFIX + kind)]

    assert of("skirting") and all(abs(s.size[2] * 2 - D.SKIRTING_H) < 1e-9 and abs(s.pos[2] - 0.04) < 1e-9
                                  for s in of("skirting"))
    plates = [s for s in of("switch") if not s.name.endswith("rocker")]
    assert len(plates) == 5  # both sides of the two open doorways, and inside the front door
    assert all(abs(s.pos[2] - D.SWITCH_Z) < 1e-9 and abs(2 * s.size[2] - D.SWITCH_PLATE) < 1e-9 for s in plates)
    assert all(abs(s.pos[2] - D.HANDLE_Z) < 1e-9 for s in of("handle"))
    heads = [s for s in of("architrave") if s.name.endswith("_top")]
    assert len(heads) == 5 and all(abs(2 * s.size[2] - D.ARCHITRAVE_W) < 1e-9 for s in heads)  # as the switches
    floors = {m.name: m for m in rich.materials}
    r = floors["floor_living"].texrepeat[0]  # a texture spans 2 / texrepeat metres: 8 boards of 14 cm
    assert floors["floor_living"].texture == "floor_planks" and abs(2 / r / D.PLANKS_PER_TEXTURE - 0.14) < 1e-3
    assert abs(2 / floors["floor_bathroom"].texrepeat[0] / 4 - D.FLOOR_TILE) < 1e-3
    changed = {m.name for m in rich.materials if m not in scene.materials and not m.name.startswith(D.PREFIX)}
    assert changed == {"floor_living", "floor_bedroom", "floor_bathroom", "wall_bathroom"}


def test_clutter_stands_on_its_surface_below_flight_altitude() -> None:
    for name in ("cabin", "house:11?rooms=5", "house:43?rooms=6"):
        scene = load_scene(name)
        tops = {s.name: s for s in D._surfaces(scene)}
        clutter = [s for s in D.with_detail(scene, "rich").solids if D.is_detail(s.name)
                   and s.name.removeprefix(D.PREFIX).split("_")[0] in ("books", "cup", "bowl", "board", "lamp")]
        for s in clutter:
            top = next(t for n, t in tops.items() if f"_{n}_" in s.name)
            x0, y0, _, x1, y1, z = D._aabb(top)
            bx0, by0, bz0, bx1, by1, bz1 = D._aabb(s)
            assert x0 <= bx0 and bx1 <= x1 and y0 <= by0 and by1 <= y1, s.name
            assert bz0 >= z - 1e-9 and bz1 <= scene.flight_altitude - D.CLUTTER_CLEARANCE + 1e-9, s.name


def test_only_the_rgb_cameras_see_the_detail() -> None:
    """Segmentation (target visibility), depth, range sensors and contacts are those of the plain scene."""
    config = dict(sensors="multiranger", range_noise=False, width=160, height=120, rear_camera=False)
    with Simulator("cabin", SimConfig(**config)) as plain, \
            Simulator("cabin", SimConfig(**config, detail="rich")) as rich:
        for sim in (plain, rich):
            sim.reset(MIRROR_VIEW)
        np.testing.assert_array_equal(rich.segmentation(), plain.segmentation())
        np.testing.assert_array_equal(rich.front_depth(80, 60), plain.front_depth(80, 60))
        assert rich.ranges() == plain.ranges()
        assert rich.target_pixel_fraction("mirror") == plain.target_pixel_fraction("mirror") > 0.05
        rgb_plain, rgb_rich = plain.render(), rich.render()
        assert np.abs(rgb_rich.astype(int) - rgb_plain.astype(int)).mean() > 2.0  # the mirror reflects the room
        for x in np.linspace(4.5, 5.6, 12):  # the drone stops where it stopped: detail has no collision geometry
            pose = Pose(float(x), 0.35, 1.0, 0.0)
            assert rich.contact_at(pose) == plain.contact_at(pose)


def test_a_bad_detail_is_refused_in_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                            tmp_path) -> None:
    for make in (lambda: SimConfig(detail="fancy"), lambda: EpisodeConfig(detail="fancy")):
        with pytest.raises(ConfigError, match=r"unknown detail 'fancy'; valid: plain, rich"):
            make()
    for args in (("run", "go to the bathroom", "--pilot", "oracle", "--detail", "fancy", "--out", str(tmp_path / "r")),
                 ("bench", "--detail", "fancy", "--out", str(tmp_path / "b")), ("scene", "render", "--detail", "HD"),
                 ("tello-emulator", "--detail", "HD", "--port", "18889")):
        code, _, err = run_main(monkeypatch, capsys, *args)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "valid: plain, rich" in err, (args, err)
    code, _, err = run_main(monkeypatch, capsys, "run", "go to the bathroom", "--robot", "tello", "--detail", "rich",
                            "--out", str(tmp_path / "t"))
    assert code == 2 and "--detail rich applies to --robot sim" in err, err  # a real camera sees the real room
    with pytest.raises(ConfigError, match="valid: plain, rich"):  # the library refuses it before anything flies
        bench_command(suite="paper", pilots="oracle", out=tmp_path / "lib", episode_options={"detail": "4k"})
    assert not any((tmp_path / d).exists() for d in ("r", "b", "t", "lib"))


def test_the_gym_environments_take_the_detail() -> None:
    for env in (CabinEnv(detail="rich", width=64, height=48), HouseEnv(7, 4, detail="rich", width=64, height=48)):
        env.reset(seed=0)
        sim = env.unwrapped.sim if isinstance(env, CabinEnv) else env._env.sim
        assert sim.config.detail == "rich" and (sim.model.geom_group == D.DETAIL_GROUP).sum() > 20
        env.close()


def test_a_rich_run_records_its_detail_and_its_replay_renders_it(monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    flown, replayed, plain = tmp_path / "flown", tmp_path / "replayed", tmp_path / "plain"
    common = ("--max-steps", "3", "--no-video", "-q")
    assert run_main(monkeypatch, capsys, "run", "go to the bathroom", "--pilot", "oracle", "--detail", "rich",
                    "--out", str(flown), *common)[0] == 0
    assert run_main(monkeypatch, capsys, "run", "go to the bathroom", "--pilot", f"replay:{flown}",
                    "--out", str(replayed), *common)[0] == 0
    assert run_main(monkeypatch, capsys, "run", "go to the bathroom", "--pilot", "oracle", "--out", str(plain),
                    *common)[0] == 0
    config = {d.name: json.loads((d / "summary.json").read_text())["config"] for d in (flown, replayed, plain)}
    assert config["flown"]["detail"] == config["replayed"]["detail"] == "rich"
    assert "detail" not in config["plain"]  # plain runs record what they recorded before


def _mirror_views(sim: Simulator) -> list[Pose]:
    """A pose 1.3 m in front of each reflective plane, facing it."""
    rich = D.with_detail(sim.scene, "rich")
    views = []
    for p in (s for s in rich.solids if s.name.startswith(D.PREFIX + "mirror")):
        nx, ny = p.xyaxes[1], -p.xyaxes[0]  # x cross up
        views.append(Pose(p.pos[0] + 1.3 * nx, p.pos[1] + 1.3 * ny, 1.0,
                          float(np.degrees(np.arctan2(-ny, -nx)))))
    return views


def test_every_mirror_in_view_reflects_and_a_frame_without_one_reflects_none() -> None:
    """MuJoCo reflects one geom a frame; sim/mirrors.py gives that reflection to the mirror in view."""
    with Simulator("house:11?rooms=5", SimConfig(detail="rich", rear_camera=False, width=160, height=120)) as sim:
        views = _mirror_views(sim)
        assert len(views) == 2  # the bathroom's vanity mirror and the bedroom's full-length one
        material = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_MATERIAL, "detail_mirror")
        for pose in views:
            reflecting = sim.reset(pose).front_rgb
            sim.model.mat_reflectance[material] = 0.0
            glass = sim.render()
            sim.model.mat_reflectance[material] = 0.95
            assert np.abs(reflecting.astype(int) - glass.astype(int)).mean() > 2.0, pose
        sim.reset(Pose(views[1].x, views[1].y, 1.0, views[1].yaw_deg + 180.0))  # the mirror behind the drone
        renderer = sim._renderer(160, 120)
        renderer.update_scene(sim.data, camera=drone.FRONT_CAMERA, scene_option=sim._rgb_option)
        reflect_in_view(renderer.scene, sim._mirrors, 160 / 120, (sim.model, sim.data, sim._body_id))
        assert all(renderer.scene.geoms[i].reflectance == 0 for i in range(renderer.scene.ngeom))


@pytest.mark.parametrize("pose", [Pose(4.5, 1.2, 1.0, 10.0), Pose(4.3, 3.3, 1.0, 10.0), Pose(4.3, 3.3, 1.0, -60.0),
                                  MIRROR_VIEW])
def test_a_mirror_at_the_edge_of_the_view_still_reflects(pose: Pose) -> None:
    """The cabin's one mirror: the frame is MuJoCo's own (which always reflects it) wherever the mirror shows."""
    with Simulator("cabin", SimConfig(detail="rich", rear_camera=False)) as culled, \
            Simulator("cabin", SimConfig(detail="rich", rear_camera=False)) as always:
        always._mirrors = frozenset()
        np.testing.assert_array_equal(culled.reset(pose).front_rgb, always.reset(pose).front_rgb)


def test_the_tello_emulator_streams_the_detail_it_is_given() -> None:
    """`vln-pilot tello-emulator --detail rich`: the video the Tello backend receives shows the rich scene."""
    frames = {}
    for detail in ("plain", "rich"):
        with rig(spawn="bedroom", emulator={"detail": detail}) as (_, env):
            frames[detail] = env.reset("bedroom").front_rgb.astype(int)
    assert np.abs(frames["rich"] - frames["plain"]).mean() > 2.0
