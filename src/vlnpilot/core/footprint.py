"""The success monitor's geometry: distance and angle from the drone to an object's footprint (pure, no simulator)."""

from __future__ import annotations

import math

from vlnpilot.core.records import Footprint, Pose, wrap_deg


def _inside(x: float, y: float, poly: tuple[tuple[float, float], ...]) -> bool:
    """Inside a convex counter-clockwise polygon (of at least three corners)?"""
    return len(poly) >= 3 and all((bx - ax) * (y - ay) - (by - ay) * (x - ax) >= 0
                                  for (ax, ay), (bx, by) in zip(poly, poly[1:] + poly[:1], strict=True))


def _segment_distance(x: float, y: float, a: tuple[float, float], b: tuple[float, float]) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, ((x - a[0]) * dx + (y - a[1]) * dy) / length2))
    return math.hypot(x - a[0] - t * dx, y - a[1] - t * dy)


def footprint_distance(pose: Pose, footprint: Footprint) -> float:
    """Horizontal distance from the drone to the nearest point of the footprint (0 above it)."""
    best = math.inf
    for poly in footprint:
        if _inside(pose.x, pose.y, poly):
            return 0.0
        best = min(best, *(_segment_distance(pose.x, pose.y, a, b) for a, b in zip(poly, poly[1:] + poly[:1],
                                                                                   strict=True)))
    return best


def footprint_off_heading_deg(pose: Pose, footprint: Footprint) -> float:
    """The smallest angle between the heading and a point of the footprint (0 when the heading crosses it)."""
    best = math.inf
    for poly in footprint:
        if _inside(pose.x, pose.y, poly):
            return 0.0
        bearings = [wrap_deg(math.degrees(math.atan2(y - pose.y, x - pose.x)) - pose.yaw_deg) for x, y in poly]
        mid = bearings[0]  # a convex polygon outside the drone spans less than 180 degrees: unwrap around a corner
        unwrapped = [mid + wrap_deg(b - mid) for b in bearings]
        lo, hi = min(unwrapped), max(unwrapped)
        best = min(best, 0.0 if lo <= 0.0 <= hi or lo <= 360.0 <= hi or lo <= -360.0 <= hi
                   else min(abs(wrap_deg(lo)), abs(wrap_deg(hi))))
    return best
