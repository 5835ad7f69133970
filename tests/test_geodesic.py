"""The shortest path for SPL is geodesic on the validated occupancy grid: around furniture, through doorways."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vlnpilot.scene import load_scene
from vlnpilot.scene.geodesic import geodesic_length
from vlnpilot.scene.validate import CELL_M, CLEARANCE_M, Grid, occupancy
from vlnpilot.tasks.success import DEFAULT_SUCCESS
from vlnpilot.tasks.task import parse_query, shortest_path_length, shortest_path_points


def _wall_with_gap() -> Grid:
    """A 4 m x 4 m grid, a wall along x = 2 m from y = 0 to y = 3 m (the gap is above it)."""
    blocked = np.zeros((100, 100), bool)
    blocked[49:51, :75] = True
    return Grid(blocked, 0.0, 0.0)


def test_straight_line_in_free_space() -> None:
    grid = Grid(np.zeros((100, 100), bool), 0.0, 0.0)
    assert geodesic_length(grid, (0.5, 0.5), (3.5, 2.5)) == pytest.approx(math.dist((0.5, 0.5), (3.5, 2.5)), abs=0.01)


def test_around_a_wall_through_its_gap() -> None:
    a, b = (1.0, 1.0), (3.0, 1.0)
    corner_l, corner_r = (49 * CELL_M, 75 * CELL_M), (51 * CELL_M, 75 * CELL_M)  # the wall's free corners
    around = math.dist(a, corner_l) + math.dist(corner_l, corner_r) + math.dist(corner_r, b)
    got = geodesic_length(_wall_with_gap(), a, b)
    assert got is not None and around - 0.01 <= got <= around + 2 * CELL_M


def test_no_path_is_none() -> None:
    blocked = np.zeros((100, 100), bool)
    blocked[49:51, :] = True
    assert geodesic_length(Grid(blocked, 0.0, 0.0), (1.0, 1.0), (3.0, 1.0)) is None


def test_cabin_spl_path_goes_around_furniture() -> None:
    """From the bedroom to the fridge the line through the door centres crosses furniture; the geodesic does not,
    and is longer by what the detour costs."""
    scene = load_scene("cabin")
    start = scene.spawn("bedroom").pose
    task = parse_query("Find the refrigerator", scene)
    through_doors = shortest_path_points(scene, start, task, DEFAULT_SUCCESS)
    grid = occupancy(scene, CLEARANCE_M)
    assert not all(grid.segment_free(p, q) for p, q in zip(through_doors, through_doors[1:], strict=False))
    straight = sum(math.dist(p, q) for p, q in zip(through_doors, through_doors[1:], strict=False))
    assert shortest_path_length(scene, start, task) > straight + 0.1
