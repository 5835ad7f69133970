"""Shortest flyable paths on the validated occupancy grid (`scene/validate.py`) at flight height.

A free cell of that grid is a place the drone's centre may be (solids grown by the drone's bounding radius plus
the shield's margin), so a path of free cells goes around furniture and through doorways as a drone can. The
length is A* on the 8-connected grid (no corner cutting), then the path pulled taut with straight clear segments:
a feasible path, so never shorter than the true geodesic, and within a cell or so of it.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from vlnpilot.scene.validate import CELL_M, Grid

Point = tuple[float, float]
_STEPS = [(di, dj, math.hypot(di, dj)) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
SNAP_M = 0.3  # a start or end this close to free space (a pose grazing the margin) is moved onto it


def geodesic_length(grid: Grid, a: Point, b: Point) -> float | None:
    """Length in metres of the shortest clear path from `a` to `b`, or None when no clear path joins them."""
    start, goal = _snap(grid, a), _snap(grid, b)
    if start is None or goal is None:
        return None
    cells = _astar(grid.blocked, start, goal)
    if cells is None:
        return None
    points = [a, *(_centre(grid, c) for c in cells[1:-1]), b]
    taut = _pull_taut(grid, points)
    return sum(math.dist(p, q) for p, q in zip(taut, taut[1:], strict=False))


def _centre(grid: Grid, cell: tuple[int, int]) -> Point:
    return grid.x0 + (cell[0] + 0.5) * CELL_M, grid.y0 + (cell[1] + 0.5) * CELL_M


def _snap(grid: Grid, p: Point) -> tuple[int, int] | None:
    """The free cell holding `p`, else the nearest free cell within SNAP_M, else None."""
    i, j = grid.cell(*p)
    if grid.free(*p):
        return i, j
    r = int(SNAP_M / CELL_M)
    ni, nj = grid.blocked.shape
    best = None
    for ci in range(max(i - r, 0), min(i + r + 1, ni)):
        for cj in range(max(j - r, 0), min(j + r + 1, nj)):
            d = math.hypot(ci - i, cj - j)
            if not grid.blocked[ci, cj] and d <= r and (best is None or d < best[0]):
                best = (d, (ci, cj))
    return None if best is None else best[1]


def _astar(blocked: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]] | None:
    """Free cells from start to goal, 8-connected; a diagonal step needs both its side cells free.

    Cells are flat indices into a padded copy of the grid (a blocked border), so no step needs a bounds check."""
    ni, nj = blocked.shape
    w = nj + 2
    free = (~np.pad(blocked, 1, constant_values=True)).ravel().tolist()
    steps = [(di * w + dj, di * w, dj, cost) for di, dj, cost in _STEPS]
    s, g = (start[0] + 1) * w + start[1] + 1, (goal[0] + 1) * w + goal[1] + 1
    gi, gj = divmod(g, w)
    diag = math.sqrt(2) - 1

    def h(c: int) -> float:
        ci, cj = divmod(c, w)
        dx, dy = abs(ci - gi), abs(cj - gj)
        return max(dx, dy) + diag * min(dx, dy)

    cost: dict[int, float] = {s: 0.0}
    parent: dict[int, int] = {}
    frontier = [(h(s), 0.0, s)]  # ties go to the deeper cell: far fewer expansions in open rooms
    while frontier:
        _, _, c = heapq.heappop(frontier)
        if c == g:
            path = [c]
            while c in parent:
                c = parent[c]
                path.append(c)
            return [(c // w - 1, c % w - 1) for c in reversed(path)]
        base = cost[c]
        for off, side_i, side_j, step in steps:
            n = c + off
            if not free[n] or (side_i and side_j and not (free[c + side_i] and free[c + side_j])):
                continue
            new = base + step
            if new < cost.get(n, math.inf):
                cost[n], parent[n] = new, c
                heapq.heappush(frontier, (new + h(n), -new, n))
    return None


def _pull_taut(grid: Grid, points: list[Point]) -> list[Point]:
    """Keep only the corners: from each kept point, go on along the path while the straight line stays clear."""
    kept, k = [points[0]], 0
    while k < len(points) - 1:
        nxt = k + 1
        while nxt + 1 < len(points) and _clear(grid, points[k], points[nxt + 1]):
            nxt += 1
        kept.append(points[nxt])
        k = nxt
    return kept


def _clear(grid: Grid, a: Point, b: Point) -> bool:
    """`Grid.segment_free` (the same samples, half a cell apart), with numpy."""
    n = max(1, int(math.dist(a, b) / (CELL_M / 2)))
    k = np.arange(n + 1) / n
    i = ((a[0] + (b[0] - a[0]) * k - grid.x0) / CELL_M).astype(int)
    j = ((a[1] + (b[1] - a[1]) * k - grid.y0) / CELL_M).astype(int)
    ni, nj = grid.blocked.shape
    inside = (i >= 0) & (i < ni) & (j >= 0) & (j < nj)
    return bool(inside.all()) and not grid.blocked[i, j].any()
