"""SUMO lane geometry on the Python side: where a point is along a lane, found from the last place.

SUMO's `moveToXY` searches the lanes' polylines (hundreds of points for a long curved road) on every call; a
scripted vehicle that stays on its edge moves a few metres per step, so its new place is found by walking the
polyline from the segment of the last one (a handful of segments). Pure functions and plain data; the libsumo
calls are in simcore.world.sumo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple


@dataclass(frozen=True, slots=True)
class LaneShape:
    """A SUMO lane: its polyline, the length along it at each point, and SUMO's length of the lane (positions
    on the lane are geometry offsets scaled by length / polyline length, as SUMO's
    `interpolateGeometryPosToLanePos`)."""

    lane_id: str
    xs: tuple[float, ...]
    ys: tuple[float, ...]
    along: tuple[float, ...]
    length: float

    @staticmethod
    def of(lane_id: str, points: tuple[tuple[float, ...], ...], length: float) -> LaneShape:
        xs = tuple(float(p[0]) for p in points)
        ys = tuple(float(p[1]) for p in points)
        along = [0.0]
        for i in range(1, len(xs)):
            along.append(along[-1] + math.hypot(xs[i] - xs[i - 1], ys[i] - ys[i - 1]))
        return LaneShape(lane_id, xs, ys, tuple(along), length)

    @property
    def scale(self) -> float:
        """Lane position per metre of polyline."""
        total = self.along[-1]
        return self.length / total if total > 0.0 else 1.0


class OnLane(NamedTuple):  # built three times a step: a tuple is the cheapest immutable record
    distance: float  # from the polyline, m
    pos: float  # SUMO lane position
    segment: int  # the polyline segment it projects onto (the next search starts there)


def _onto_segment(shape: LaneShape, i: int, x: float, y: float) -> tuple[float, float, float]:
    """(parameter along segment i, unclamped; squared distance to the clamped foot; segment length)."""
    x0, y0 = shape.xs[i], shape.ys[i]
    dx, dy = shape.xs[i + 1] - x0, shape.ys[i + 1] - y0
    seg2 = dx * dx + dy * dy
    u = ((x - x0) * dx + (y - y0) * dy) / seg2 if seg2 > 0.0 else 0.0
    c = min(max(u, 0.0), 1.0)
    fx, fy = x0 + c * dx - x, y0 + c * dy - y
    return u, fx * fx + fy * fy, math.sqrt(seg2)


def locate_on(shape: LaneShape, x: float, y: float, hint: int | None, max_walk: int = 64) -> OnLane | None:
    """Where (x, y) projects onto `shape`, walking from segment `hint` (all segments when None). None when
    the walk does not settle within `max_walk` segments or the point lies before the start or past the end
    of the lane (the caller then asks SUMO)."""
    last = len(shape.xs) - 2
    if last < 0:
        return None
    if hint is None:
        best, best_d2 = 0, math.inf
        for i in range(last + 1):
            d2 = _onto_segment(shape, i, x, y)[1]
            if d2 < best_d2:
                best, best_d2 = i, d2
        i = best
    else:
        i = min(max(hint, 0), last)
    u, d2, seg = _onto_segment(shape, i, x, y)
    for _ in range(max_walk):
        if u > 1.0 and i < last:
            ahead = _onto_segment(shape, i + 1, x, y)
            if ahead[0] >= 0.0:
                i += 1
                u, d2, seg = ahead
                continue
        elif u < 0.0 and i > 0:
            behind = _onto_segment(shape, i - 1, x, y)
            if behind[0] <= 1.0:
                i -= 1
                u, d2, seg = behind
                continue
        break  # on segment i, or outside a bend, nearest to the vertex between two segments
    else:
        return None
    if (u < 0.0 and i == 0) or (u > 1.0 and i == last):
        return None  # before the lane's start or past its end
    offset = shape.along[i] + min(max(u, 0.0), 1.0) * seg
    return OnLane(math.sqrt(d2), offset * shape.scale, i)


def nearest_lane(
    shapes: list[LaneShape], x: float, y: float, hints: dict[str, int]
) -> tuple[LaneShape, OnLane] | None:
    """The lane among `shapes` whose polyline is nearest to (x, y) (the first on a tie, as SUMO), or None.
    `hints` (lane → segment to start the walk from) is updated with where (x, y) was found on each lane."""
    best: tuple[LaneShape, OnLane] | None = None
    for shape in shapes:
        on = locate_on(shape, x, y, hints.get(shape.lane_id))
        if on is None:
            hints.pop(shape.lane_id, None)
            continue
        hints[shape.lane_id] = on.segment
        if best is None or on.distance < best[1].distance:
            best = (shape, on)
    return best
