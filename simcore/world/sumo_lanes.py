"""SUMO lane geometry on the Python side: where a point is along a lane, found from the last place.

SUMO's `moveToXY` searches the lanes' polylines (hundreds of points for a long curved road) on every call; a
scripted vehicle that stays on its edge moves a few metres per step, so its new place is found by walking the
polyline from the segment of the last one (a handful of segments). Pure functions and plain data; the libsumo
calls are in simcore.world.sumo.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Final, NamedTuple

from simcore.world.native_calls import hypot

#: slack (m) for float rounding when a lane is shown to be farther than another without walking it: far more
#: than the rounding of distances between points with map coordinates up to 10,000 km
CLEARLY_FARTHER_M: Final = 1e-6


@dataclass(frozen=True, slots=True)
class LaneShape:
    """A SUMO lane: its polyline, the length along it at each point, and SUMO's length of the lane (positions
    on the lane are geometry offsets scaled by length / polyline length, as SUMO's
    `interpolateGeometryPosToLanePos`). Per segment i (points i → i+1): its vector (dxs, dys), squared
    length and length, derived once (the shape never changes)."""

    lane_id: str
    xs: tuple[float, ...]
    ys: tuple[float, ...]
    along: tuple[float, ...]
    length: float
    dxs: tuple[float, ...]
    dys: tuple[float, ...]
    seg2s: tuple[float, ...]
    seglens: tuple[float, ...]
    scale: float  # lane position per metre of polyline

    @staticmethod
    def of(lane_id: str, points: tuple[tuple[float, ...], ...], length: float) -> LaneShape:
        xs = tuple(float(p[0]) for p in points)
        ys = tuple(float(p[1]) for p in points)
        along = [0.0]
        for i in range(1, len(xs)):
            along.append(along[-1] + hypot(xs[i] - xs[i - 1], ys[i] - ys[i - 1]))
        dxs = tuple(xs[i + 1] - xs[i] for i in range(len(xs) - 1))
        dys = tuple(ys[i + 1] - ys[i] for i in range(len(ys) - 1))
        seg2s = tuple(dx * dx + dy * dy for dx, dy in zip(dxs, dys, strict=True))
        total = along[-1]
        return LaneShape(
            lane_id,
            xs,
            ys,
            tuple(along),
            length,
            dxs,
            dys,
            seg2s,
            tuple(math.sqrt(s2) for s2 in seg2s),
            length / total if total > 0.0 else 1.0,
        )


class OnLane(NamedTuple):  # built once or twice a step: a tuple is the cheapest immutable record
    distance: float  # from the polyline, m
    pos: float  # SUMO lane position
    segment: int  # the polyline segment it projects onto (the next search starts there)


#: OnLane((distance, pos, segment)) without the Python-level __new__ of a NamedTuple (called every step)
_on_lane: Final = functools.partial(tuple.__new__, OnLane)


def _along_segment(shape: LaneShape, i: int, x: float, y: float) -> float:
    """The parameter of (x, y)'s projection onto segment i's line (0 at point i, 1 at point i+1; 0 for a
    segment of no length)."""
    seg2 = shape.seg2s[i]
    if seg2 > 0.0:
        return ((x - shape.xs[i]) * shape.dxs[i] + (y - shape.ys[i]) * shape.dys[i]) / seg2
    return 0.0


def _squared_distance(shape: LaneShape, i: int, u: float, x: float, y: float) -> float:
    """Squared distance from (x, y) to its foot on segment i (parameter u, clamped to the segment)."""
    c = min(max(u, 0.0), 1.0)
    fx = shape.xs[i] + c * shape.dxs[i] - x
    fy = shape.ys[i] + c * shape.dys[i] - y
    return fx * fx + fy * fy


def locate_on(shape: LaneShape, x: float, y: float, hint: int | None, max_walk: int = 64) -> OnLane | None:
    """Where (x, y) projects onto `shape`, walking from segment `hint` (all segments when None). None when
    the walk does not settle within `max_walk` segments or the point lies before the start or past the end
    of the lane (the caller then asks SUMO). Called every step per lane: the segment arithmetic of
    `_along_segment` is written out here (the same operations, so the same floats), and clamps are written
    as conditional expressions (`min(max(u, 0.0), 1.0)` gives the same value, NaN and -0.0 included, but a
    call of the builtin min or max costs several times as much in CPython 3.11)."""
    xs, ys, dxs, dys, seg2s = shape.xs, shape.ys, shape.dxs, shape.dys, shape.seg2s
    last = len(xs) - 2
    if last < 0:
        return None
    if hint is None:  # the segment nearest to (x, y), the first on a tie
        best, best_d2 = 0, math.inf
        for i in range(last + 1):
            x0, y0, dx, dy, seg2 = xs[i], ys[i], dxs[i], dys[i], seg2s[i]
            u = ((x - x0) * dx + (y - y0) * dy) / seg2 if seg2 > 0.0 else 0.0
            c = 1.0 if u > 1.0 else (0.0 if u < 0.0 else u)
            fx, fy = x0 + c * dx - x, y0 + c * dy - y
            d2 = fx * fx + fy * fy
            if d2 < best_d2:
                best, best_d2 = i, d2
        i = best
    else:
        i = 0 if hint < 0 else (last if hint > last else hint)
    seg2 = seg2s[i]
    u = ((x - xs[i]) * dxs[i] + (y - ys[i]) * dys[i]) / seg2 if seg2 > 0.0 else 0.0
    if u > 1.0 or u < 0.0:
        for _ in range(max_walk):
            if u > 1.0 and i < last:
                seg2 = seg2s[i + 1]
                ahead = (
                    ((x - xs[i + 1]) * dxs[i + 1] + (y - ys[i + 1]) * dys[i + 1]) / seg2
                    if seg2 > 0.0
                    else 0.0
                )
                if ahead >= 0.0:
                    i += 1
                    u = ahead
                    continue
            elif u < 0.0 and i > 0:
                seg2 = seg2s[i - 1]
                behind = (
                    ((x - xs[i - 1]) * dxs[i - 1] + (y - ys[i - 1]) * dys[i - 1]) / seg2
                    if seg2 > 0.0
                    else 0.0
                )
                if behind <= 1.0:
                    i -= 1
                    u = behind
                    continue
            break  # on segment i, or outside a bend, nearest to the vertex between two segments
        else:
            return None
        if (u < 0.0 and i == 0) or (u > 1.0 and i == last):
            return None  # before the lane's start or past its end
        c = 1.0 if u > 1.0 else (0.0 if u < 0.0 else u)
    else:
        c = u
    fx = xs[i] + c * dxs[i] - x
    fy = ys[i] + c * dys[i] - y
    return _on_lane((math.sqrt(fx * fx + fy * fy), (shape.along[i] + c * shape.seglens[i]) * shape.scale, i))


def _point_to_segment(px: float, py: float, shape: LaneShape, i: int) -> float:
    return math.sqrt(_squared_distance(shape, i, _along_segment(shape, i, px, py), px, py))


def _orientation(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> float:
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


def segment_gap(a: LaneShape, i: int, b: LaneShape, j: int) -> float:
    """The distance between segment i of `a` and segment j of `b` (0 when they touch or cross)."""
    ax, ay, bx, by = a.xs[i], a.ys[i], a.xs[i + 1], a.ys[i + 1]
    cx, cy, dx, dy = b.xs[j], b.ys[j], b.xs[j + 1], b.ys[j + 1]
    if (
        _orientation(ax, ay, bx, by, cx, cy) * _orientation(ax, ay, bx, by, dx, dy) <= 0.0
        and _orientation(cx, cy, dx, dy, ax, ay) * _orientation(cx, cy, dx, dy, bx, by) <= 0.0
    ):
        return 0.0  # crossing, touching or collinear: no gap claimed
    return min(
        _point_to_segment(ax, ay, b, j),
        _point_to_segment(bx, by, b, j),
        _point_to_segment(cx, cy, a, i),
        _point_to_segment(dx, dy, a, i),
    )


#: (lane, segment, other lane, segment) → segment_gap, for the lanes of one edge
SegmentGaps = dict[tuple[str, int, str, int], float]


@dataclass(slots=True)
class EdgeLanes:
    """The lanes of one SUMO edge (index order) and the gaps between their segments found so far."""

    lanes: list[LaneShape]
    gaps: SegmentGaps = field(default_factory=dict)
    by_id: dict[str, LaneShape] = field(init=False)

    def __post_init__(self) -> None:
        self.by_id = {lane.lane_id: lane for lane in self.lanes}


#: SUMO's description of a lane: id, polyline points, length
RawLane = tuple[str, tuple[tuple[float, ...], ...], float]
_EDGES: Final[dict[tuple[RawLane, ...], EdgeLanes]] = {}
MAX_CACHED_EDGES: Final = 4096


def edge_lanes(raw: tuple[RawLane, ...]) -> EdgeLanes:
    """The lanes of an edge, built once per process: a warm worker runs one network many times. Keyed by
    the lanes' ids, points and lengths as SUMO gives them, so an entry is only ever reused for the very same
    geometry (and its gaps with it); the cache is emptied when it reaches MAX_CACHED_EDGES edges."""
    found = _EDGES.get(raw)
    if found is None:
        if len(_EDGES) >= MAX_CACHED_EDGES:
            _EDGES.clear()
        found = _EDGES[raw] = EdgeLanes([LaneShape.of(*lane) for lane in raw])
    return found


def nearest_lane(
    shapes: list[LaneShape],
    x: float,
    y: float,
    hints: dict[str, int],
    near: LaneShape | None = None,
    gaps: SegmentGaps | None = None,
) -> tuple[LaneShape, OnLane] | None:
    """The lane among `shapes` whose polyline is nearest to (x, y) (the first on a tie, as SUMO), or None.
    `hints` (lane → segment to start the walk from) is updated with where (x, y) was found on each lane.

    With `near` (the lane (x, y) was on last, one of `shapes`) and a `gaps` cache, that lane is walked
    first and any other lane shown to be farther is not walked (`_nearest_after`): the answer and the hints
    are the same as walking every lane."""
    if near is not None and gaps is not None:
        on = locate_on(near, x, y, hints.get(near.lane_id))
        if on is not None:
            return _nearest_after(shapes, x, y, hints, near, on, gaps)
    best: tuple[LaneShape, OnLane] | None = None
    for shape in shapes:
        best = _kept(best, shape, locate_on(shape, x, y, hints.get(shape.lane_id)), hints)
    return best


def _kept(
    best: tuple[LaneShape, OnLane] | None, shape: LaneShape, on: OnLane | None, hints: dict[str, int]
) -> tuple[LaneShape, OnLane] | None:
    """One lane's walk taken into nearest_lane's answer: its hint updated (dropped when the walk found
    nothing) and the nearer of `best` and it kept (the first on a tie)."""
    if on is None:
        hints.pop(shape.lane_id, None)
        return best
    hints[shape.lane_id] = on.segment
    return (shape, on) if best is None or on.distance < best[1].distance else best


def _nearest_after(
    shapes: list[LaneShape],
    x: float,
    y: float,
    hints: dict[str, int],
    near: LaneShape,
    near_on: OnLane,
    gaps: SegmentGaps,
) -> tuple[LaneShape, OnLane] | None:
    """nearest_lane's loop once (x, y) is known to be `near_on` on lane `near`. Another lane's walk from its
    hint j stays on segment j when (x, y) projects inside it; its distance to segment j is then at least
    gap(near's segment, j) - near_on.distance (triangle inequality through (x, y)'s foot on `near`), more
    than near_on.distance when the gap exceeds twice that: the lane is not the nearest, and its hint stays
    j. Any other lane is walked. Runs every step: the projection of locate_on is written out here."""
    near_id, near_segment = near.lane_id, near_on.segment
    reach = 2.0 * near_on.distance + CLEARLY_FARTHER_M
    best: tuple[LaneShape, OnLane] | None = None
    for shape in shapes:
        lane_id = shape.lane_id
        if shape is near:
            on: OnLane | None = near_on
        else:
            hint = hints.get(lane_id)
            last = len(shape.xs) - 2
            if hint is not None and last >= 0:
                j = 0 if hint < 0 else (last if hint > last else hint)
                seg2 = shape.seg2s[j]
                u = (
                    ((x - shape.xs[j]) * shape.dxs[j] + (y - shape.ys[j]) * shape.dys[j]) / seg2
                    if seg2 > 0.0
                    else 0.0
                )
                if 0.0 <= u <= 1.0:
                    key = (near_id, near_segment, lane_id, j)
                    gap = gaps.get(key)
                    if gap is None:
                        gap = gaps[key] = segment_gap(near, near_segment, shape, j)
                    if gap > reach:
                        hints[lane_id] = j
                        continue
            on = locate_on(shape, x, y, hint)
        best = _kept(best, shape, on, hints)
    return best
