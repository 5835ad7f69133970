"""The scene model: rooms, the topological map, name look-ups and spawns."""

from __future__ import annotations

import pytest

from vlnpilot.core.errors import UnknownNameError
from vlnpilot.scene import SCENES, load_scene
from vlnpilot.scene.model import EXTERIOR


def test_room_at_every_room_and_outside(scene):
    for room in scene.rooms:
        cx, cy = room.centroid
        assert scene.room_at(cx, cy) == room.id
    (xmin, ymin), (xmax, ymax) = scene.bounds
    for x, y in ((xmin - 1.0, ymin - 1.0), (xmax + 1.0, (ymin + ymax) / 2), ((xmin + xmax) / 2, ymax + 0.5),
                 (-0.5, 1.0)):
        assert scene.room_at(x, y) is None


def test_room_at_each_side_of_every_open_door(scene):
    for door in scene.open_doors():
        nx, ny = door.normal
        before = scene.room_at(door.center[0] - 0.3 * nx, door.center[1] - 0.3 * ny)
        after = scene.room_at(door.center[0] + 0.3 * nx, door.center[1] + 0.3 * ny)
        assert (before, after) == door.rooms


def test_topological_map(scene):
    topo = scene.topological_map()
    assert {n["id"] for n in topo["nodes"]} == {"living_room", "bedroom", "bathroom"}
    assert len(topo["nodes"]) == 3
    edges = {(e["from"], e["to"], e["via"]) for e in topo["edges"]}
    assert edges == {("living_room", "bedroom", "door_living_bedroom"),
                     ("bedroom", "bathroom", "door_bedroom_bathroom")}
    front = scene.door("front_door")
    assert not front.open and EXTERIOR in front.rooms
    assert all(e["via"] != "front_door" for e in topo["edges"])
    assert all(EXTERIOR not in (e["from"], e["to"]) for e in topo["edges"])


def test_room_path_goes_through_the_bedroom(scene):
    assert scene.room_path("living_room", "bathroom") == ["living_room", "bedroom", "bathroom"]
    assert scene.room_path("bathroom", "living_room") == ["bathroom", "bedroom", "living_room"]
    assert scene.room_path("bedroom", "bedroom") == ["bedroom"]


@pytest.mark.parametrize(
    ("lookup", "kind", "valid"),
    [
        (lambda s: load_scene("castle"), "scene", sorted(SCENES)),
        (lambda s: s.spawn("attic"), "spawn", ["bathroom", "bedroom", "living_room"]),
        (lambda s: s.target("piano"), "target", ["mirror", "refrigerator", "sink"]),
        (lambda s: s.room("garage"), "room", ["bathroom", "bedroom", "living_room"]),
        (lambda s: s.room_path("living_room", "garage"), "room", ["bathroom", "bedroom", "living_room"]),
    ],
)
def test_unknown_names_list_the_valid_ones(scene, lookup, kind, valid):
    with pytest.raises(UnknownNameError) as info:
        lookup(scene)
    message = str(info.value)
    assert f"unknown {kind}" in message
    for name in valid:
        assert name in message
    assert isinstance(info.value, KeyError)  # callers may catch it as a KeyError too


def test_aliases_resolve(scene):
    assert scene.find_room("kitchen").id == "living_room"
    assert scene.find_room("Living Room").id == "living_room"
    assert scene.find_room("bath-room").id == "bathroom"
    assert scene.find_room("garage") is None
    assert scene.find_target("fridge").id == "refrigerator"
    assert scene.find_target("Refrigerator").id == "refrigerator"
    assert scene.find_target("washbasin").id == "sink"
    assert scene.find_target("piano") is None


def test_targets_are_in_their_rooms(scene):
    for t in scene.targets:
        assert scene.room_at(t.position[0], t.position[1]) == t.room, t.id


def test_every_spawn_is_inside_its_room_and_collision_free(scene, geo_sim):
    assert len(scene.spawns) == 3
    assert {s.room for s in scene.spawns} == {r.id for r in scene.rooms}
    for spawn in scene.spawns:
        p = spawn.pose
        assert scene.room_at(p.x, p.y) == spawn.room, spawn.id
        assert p.z == pytest.approx(scene.flight_altitude)
        assert geo_sim.contact_at(p) is None, spawn.id


# -- the floor plan (report.floorplan draws the scene) ------------------------------------------------------
def test_floorplan_draws_rooms_doors_targets_and_a_trajectory(scene, tmp_path):
    from matplotlib.colors import to_rgb

    from vlnpilot.core.records import Pose
    from vlnpilot.report.floorplan import draw_floorplan, save_floorplan

    path = save_floorplan(scene, tmp_path / "plans" / "map.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    trajectory = [(3.25, 0.75), Pose(3.6, 1.0, 1.0, 0.0), (4.2, 1.0)]
    states = ["Recognize Room", "Oriented Towards Door", "Go Through Door"]
    ax = draw_floorplan(scene, trajectory=trajectory, states=states, collision=(4.2, 1.0), goal="bedroom")
    fills = {tuple(round(c, 3) for c in p.get_facecolor()[:3]) for p in ax.patches}
    for room in scene.rooms:  # each room filled with its diagram colour
        assert tuple(round(c, 3) for c in room.color) in fills
    texts = {t.get_text() for t in ax.texts}
    assert {"living room / kitchen", "bedroom\n(goal)", "bathroom"} <= texts
    assert {t.name for t in scene.targets} <= texts and "front_door" in texts
    legend = {t.get_text() for t in ax.get_legend().get_texts()}
    assert set(states) | {"collision", "open door", "closed door", "target", "spawn"} <= legend
    closed = [ln for ln in ax.lines if ln.get_color() == "red" and ln.get_linewidth() >= 4]
    assert len(closed) == 1  # the closed front door
    assert any(to_rgb(ln.get_color()) == to_rgb("red") and ln.get_marker() == "X" for ln in ax.lines)

    with pytest.raises(UnknownNameError, match="bedroom"):
        draw_floorplan(scene, goal="garage")
    with pytest.raises(ValueError):
        draw_floorplan(scene, trajectory=trajectory, states=states[:2])


def test_the_fingerprint_covers_the_furniture() -> None:
    """A recording names the scene it flew by its fingerprint: moving one solid must change it."""
    from dataclasses import replace

    from vlnpilot.scene import load_scene

    cabin = load_scene("cabin")
    assert cabin.fingerprint() == load_scene("cabin").fingerprint()
    bed = next(i for i, s in enumerate(cabin.solids) if s.name == "bed_frame")
    moved = replace(cabin.solids[bed], pos=(cabin.solids[bed].pos[0] + 0.01, *cabin.solids[bed].pos[1:]))
    shifted = replace(cabin, solids=(*cabin.solids[:bed], moved, *cabin.solids[bed + 1:]))
    assert shifted.fingerprint() != cabin.fingerprint()
    assert cabin.fingerprint() != load_scene("cabin-v1").fingerprint()
