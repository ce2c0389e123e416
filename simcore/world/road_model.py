"""The OpenDRIVE road network's data model: roads, lane sections, lanes, links and junctions, the ``s``
polynomials of elevation, superelevation, lane offsets and lane widths (`Poly3`), and the values the network's
queries answer with (`Pose`, `RoadCoordinates`, `LaneBoundary`).

A `Road` evaluates its own reference line (through its `simcore.world.road_geometry` records), elevation,
roll and lane borders at ``s``; the network-wide look-ups (by road id, world to road, topology) are
`simcore.world.opendrive.OpenDrive`'s. Parsed once (`simcore.world.opendrive_parse`) and never changed
afterwards: the memos kept here are pure functions of the file.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final, final

from simcore.world.native_calls import bisect_right
from simcore.world.road_geometry import Geometry

__all__ = [
    "DRIVING_LANE_TYPES",
    "Junction",
    "JunctionConnection",
    "Lane",
    "LaneBoundary",
    "LaneCross",
    "LaneSection",
    "Poly3",
    "Pose",
    "Road",
    "RoadCoordinates",
    "RoadLink",
]

DRIVING_LANE_TYPES: Final = frozenset(
    {"driving", "entry", "exit", "onramp", "offramp", "connectingramp", "bidirectional", "sliplane"}
)
"""Lane types (lower case) counted as drivable by ``lane_ids(..., driving_only=True)``."""


@dataclass(frozen=True)
class Pose:
    """A world pose. ``heading`` in rad, counter-clockwise from +x."""

    x: float
    y: float
    z: float
    heading: float


@dataclass(frozen=True)
class RoadCoordinates:
    """A position in road coordinates.

    ``offset`` is ``t`` minus the lane-centre ``t``; ``heading`` is the reference-line heading at ``s``.
    """

    road_id: str
    lane_id: int
    s: float
    t: float
    offset: float
    heading: float


@dataclass(frozen=True)
class Poly3:
    """``a + b*ds + c*ds**2 + d*ds**3`` with ``ds = s - s0`` (``s0`` is ``s`` or ``sOffset`` in the file)."""

    s0: float
    a: float
    b: float
    c: float
    d: float

    def value(self, s: float) -> float:
        """The polynomial at ``s`` (absolute in the same frame as ``s0``)."""
        ds = s - self.s0
        return self.a + ds * (self.b + ds * (self.c + ds * self.d))

    def slope(self, s: float) -> float:
        """The first derivative at ``s``."""
        ds = s - self.s0
        return self.b + ds * (2.0 * self.c + ds * 3.0 * self.d)


def _constant(p: Poly3) -> bool:
    """Does the polynomial give the same number (``a``) at every ``s``? (``a + ds·(0 + ds·(0 + ds·0))`` is
    ``a`` for every finite ``ds``, unless ``a`` is -0.0.)"""
    return (
        p.b == 0.0
        and p.c == 0.0
        and p.d == 0.0
        and math.isfinite(p.a)
        and (p.a != 0.0 or math.copysign(1.0, p.a) > 0)
    )


def _fixed_value(polys: Sequence[Poly3]) -> float | None:
    """The value `_poly_at(polys, ...).value(s)` gives at every ``s`` (0.0 without records) when it is one
    number (no or one record, `_constant`), else None."""
    if not polys:
        return 0.0
    if len(polys) == 1 and _constant(polys[0]):
        return polys[0].a
    return None


def _poly_at(polys: Sequence[Poly3], starts: list[float], s: float) -> Poly3 | None:
    """The record in effect at ``s`` (the last one starting at or before ``s``; the first one before it)."""
    if not polys:
        return None
    i = bisect_right(starts, s + 1e-12) - 1
    return polys[i if i > 0 else 0]


@dataclass(frozen=True)
class RoadLink:
    """A road's predecessor or successor: ``element_type`` is ``"road"`` or ``"junction"``."""

    element_type: str
    element_id: str
    contact_point: str | None  # "start" / "end" for roads, None for junctions


@dataclass
class Lane:
    """One lane of a lane section."""

    id: int
    type: str
    widths: list[Poly3] = field(default_factory=list)  # s0 = sOffset (relative to the section start)
    borders: list[Poly3] = field(default_factory=list)
    predecessor: int | None = None
    successor: int | None = None
    level: bool = False

    def __post_init__(self) -> None:
        self.widths.sort(key=lambda p: p.s0)
        self.borders.sort(key=lambda p: p.s0)
        self._wstarts = [p.s0 for p in self.widths]
        self._bstarts = [p.s0 for p in self.borders]
        #: whether the width reaches zero somewhere in the lane's section (simcore/scenario/motion.py)
        self.may_vanish: bool | None = None

    def width_at(self, ds: float) -> float:
        """The width at ``ds`` from the section start (0 for the centre lane and lanes without widths)."""
        widths = self.widths
        if not widths:
            return 0.0
        if len(widths) == 1:  # the common case: one record, in effect before its start too
            p = widths[0]
        else:
            i = bisect_right(self._wstarts, ds + 1e-12) - 1
            p = widths[i if i > 0 else 0]
        d = ds - p.s0  # Poly3.value, inline (a hot path of every step)
        return p.a + d * (p.b + d * (p.c + d * p.d))

    def border_at(self, ds: float) -> float | None:
        """The ``border`` record value at ``ds`` (only used for lanes without widths)."""
        p = _poly_at(self.borders, self._bstarts, ds)
        return None if p is None else p.value(ds)


@dataclass
class LaneSection:
    """A lane section starting at ``s`` (ending at ``end``). ``left`` ids 1, 2, ...; ``right`` -1, -2, ..."""

    s: float
    end: float
    left: list[Lane]
    right: list[Lane]
    center: Lane | None
    single_side: bool = False

    def lane(self, lane_id: int) -> Lane | None:
        """The lane with ``lane_id`` in this section, or None."""
        if lane_id == 0:
            return self.center
        side = self.left if lane_id > 0 else self.right
        for lane in side:
            if lane.id == lane_id:
                return lane
        return None


@final
class LaneSpan:
    """One lane across a `LaneCross`: its id, the ``t`` range it covers and the ``t`` of its centre (a class,
    not a tuple: compiled, its fields are read as they are, where a tuple's are unpacked and checked)."""

    __slots__ = ("centre", "high", "lane_id", "low")

    def __init__(self, lane_id: int, low: float, high: float, centre: float) -> None:
        self.lane_id = lane_id
        self.low = low
        self.high = high
        self.centre = centre


#: lane ids a `LaneCross` keeps its lanes' centres for in a table (from its lowest id to its highest)
MAX_CENTRE_TABLE: Final = 64


class LaneCross:
    """The lane borders across a stretch of a road where they do not change with ``s`` (the same lane
    section on each side, each with constant widths and a constant or no laneOffset), and the look-ups that
    the per-step queries make on them, derived once (the same floats the per-``s`` loops compute)."""

    __slots__ = (
        "_known",
        "_lowest",
        "_table",
        "around",
        "borders",
        "centres",
        "driving_ids",
        "ids",
        "inside",
    )

    def __init__(self, right: list[tuple[Lane, float, float]], left: list[tuple[Lane, float, float]]) -> None:
        #: every non-centre lane's ``(lane, t_inner, t_outer)``, right side first (`Road.all_borders`)
        self.borders = right + left
        #: lane id -> ``t`` of its centre (`OpenDrive.lane_center_t`: the first lane of that id on its side)
        self.centres: dict[int, float] = {}
        for side, borders in ((-1, right), (1, left)):
            for lane, inner, outer in borders:
                if lane.id != 0 and (lane.id > 0) == (side > 0) and lane.id not in self.centres:
                    self.centres[lane.id] = 0.5 * (inner + outer)
        # the same as a table from the lowest id, for `centre_of` (lane ids are small numbers around 0; ids
        # too far apart for a small table stay in the dict only)
        ids = sorted(self.centres)
        span = ids[-1] - ids[0] + 1 if ids else 0
        self._lowest = ids[0] if ids and span <= MAX_CENTRE_TABLE else 0
        size = span if ids and span <= MAX_CENTRE_TABLE else 0
        self._known: list[bool] = [self._lowest + i in self.centres for i in range(size)]
        self._table: list[float] = [self.centres.get(self._lowest + i, 0.0) for i in range(size)]
        #: the lanes wider than 1e-9, in `borders` order
        self.inside: tuple[LaneSpan, ...] = tuple(
            LaneSpan(lane.id, min(inner, outer), max(inner, outer), 0.5 * (inner + outer))
            for lane, inner, outer in self.borders
            if abs(outer - inner) > 1e-9
        )
        #: the same for lanes (not 0) of any width but zero, their ``t`` range widened by 1e-9 each way
        self.around: tuple[LaneSpan, ...] = tuple(
            LaneSpan(lane.id, lo - 1e-9, hi + 1e-9, 0.5 * (inner + outer))
            for lane, inner, outer in self.borders
            if lane.id != 0 and inner != outer
            for lo, hi in ((inner, outer) if inner < outer else (outer, inner),)
        )
        #: `OpenDrive.lane_ids`: the lanes of positive width, ascending; the drivable ones among them
        wide = [(lane.id, lane.type) for lane, inner, outer in self.borders if not abs(outer - inner) <= 1e-9]
        self.ids: tuple[int, ...] = tuple(sorted(lane_id for lane_id, _ in wide))
        self.driving_ids: tuple[int, ...] = tuple(
            sorted(lane_id for lane_id, kind in wide if kind.lower() in DRIVING_LANE_TYPES)
        )

    def centre_of(self, lane_id: int) -> tuple[bool, float]:
        """``(True, t of the centre of lane `lane_id`)`` as `centres` has it, else ``(False, 0.0)`` (compiled:
        a list read and a pair of plain values, where the dict's look-up boxes the id and the ``t``)."""
        i = lane_id - self._lowest
        if 0 <= i < len(self._table):
            return self._known[i], self._table[i]
        if self._table:
            return False, 0.0
        centre = self.centres.get(lane_id)
        return (False, 0.0) if centre is None else (True, centre)

    def lane_at(self, t: float) -> tuple[int, float]:
        """The lane containing lateral position ``t`` (else the one with the closest centre) and the offset
        from its centre: `simcore.scenario.motion.lane_at_t` on this stretch of road."""
        best_lane, best_offset, best = 0, t, math.inf
        for lane in self.around:
            centre = lane.centre
            if lane.low <= t <= lane.high:
                return lane.lane_id, t - centre
            if abs(t - centre) < best:
                best, best_lane, best_offset = abs(t - centre), lane.lane_id, t - centre
        return best_lane, best_offset


@dataclass
class Road:
    """One ``<road>``: reference line, elevation, lane offset, lane sections and links."""

    id: str
    name: str
    length: float
    junction: str
    geometries: list[Geometry]
    elevations: list[Poly3]
    lane_offsets: list[Poly3]
    lane_sections: list[LaneSection]
    predecessor: RoadLink | None = None
    successor: RoadLink | None = None
    superelevations: list[Poly3] = field(default_factory=list)
    rule: str = "RHT"  # traffic rule: RHT (right-hand traffic) or LHT
    speeds: list[tuple[float, float]] = field(default_factory=list)  # (s, max m/s) of <type><speed>

    def speed_limit(self, s: float) -> float | None:
        """The road type's speed limit at ``s`` (m/s), None where no <type> record gives one."""
        value = None
        for start, limit in self.speeds:
            if start <= s + 1e-9:
                value = limit
        return value

    def __post_init__(self) -> None:
        self._gstarts = [g.s for g in self.geometries]
        self._estarts = [p.s0 for p in self.elevations]
        self._ostarts = [p.s0 for p in self.lane_offsets]
        self._rstarts = [p.s0 for p in self.superelevations]
        # per side: the sections defining that side (a singleSide section only defines the side it has)
        self._side_sections: dict[int, list[LaneSection]] = {}
        for side in (1, -1):
            secs = [
                sec
                for sec in self.lane_sections
                if not sec.single_side or (sec.left if side > 0 else sec.right)
            ]
            self._side_sections[side] = secs or list(self.lane_sections)
        self._side_starts = {k: [sec.s for sec in v] for k, v in self._side_sections.items()}
        # the planView record `geometry_at` gives for each s in [lo, hi)
        n = len(self.geometries)
        self._gspans = [
            (g, self._gstarts[i] if i > 0 else -math.inf, self._gstarts[i + 1] if i + 1 < n else math.inf)
            for i, g in enumerate(self.geometries)
        ]
        # elevation and laneOffset where one record gives the same number at every s (else None)
        self._z_fixed = _fixed_value(self.elevations)
        self._offset_fixed = _fixed_value(self.lane_offsets)
        # where both sides' lane sections change (`cross_at`); the crosses themselves are built on first use
        self._cross_starts = sorted(set(self._side_starts[1]) | set(self._side_starts[-1]))
        self._crosses: list[LaneCross | None] | None = None
        self._uniform: LaneCross | None = None  # the cross of every s, where there is one
        # memos of look-ups asked for several times per step (bounded: cleared past 256 entries), declared
        # here rather than added on first use: a fixed set of attributes, as a compiler such as mypyc needs
        self._borders: dict[tuple[float, int], list[tuple[Lane, float, float]]] = {}
        self._fixed: dict[tuple[int, int], list[tuple[Lane, float, float]] | None] = {}
        self._all_borders: dict[float, list[tuple[Lane, float, float]]] = {}
        #: `OpenDrive.lane_center_t` where `centre_t` has no table (simcore/world/opendrive.py)
        self.centre_memo: dict[tuple[float, int], float] = {}
        #: per side, whether its lanes keep their ids along the road (simcore/scenario/motion.py)
        self.plain_sides: dict[int, bool] = {}

    # -- reference line
    def geometry_at(self, s: float) -> Geometry:
        """The planView record containing ``s``."""
        i = bisect_right(self._gstarts, s) - 1
        geometries = self.geometries
        return geometries[0 if i < 0 else i if i < len(geometries) else len(geometries) - 1]

    def geometry_span(self, s: float) -> tuple[Geometry, float, float]:
        """``(record, lo, hi)``: the planView record `geometry_at` gives at ``s``, and the range ``[lo, hi)``
        of every ``s`` it gives that record for (a caller moving along the road asks again only on leaving it)."""
        i = bisect_right(self._gstarts, s) - 1
        return self._gspans[i if i > 0 else 0]

    def reference_xyh(self, s: float) -> tuple[float, float, float]:
        """``(x, y, heading)`` of the reference line at ``s``."""
        i = bisect_right(self._gstarts, s) - 1  # as geometry_at (inline: every step)
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        return g.local(ds if ds >= 0.0 else 0.0)

    def curvature(self, s: float) -> float:
        """Reference-line curvature at ``s``."""
        i = bisect_right(self._gstarts, s) - 1  # as geometry_at (inline: every step)
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        return g.curvature(ds if ds >= 0.0 else 0.0)

    def elevation(self, s: float) -> float:
        """``z`` of the reference line at ``s`` (0 without an elevationProfile)."""
        z = self._z_fixed
        if z is not None:
            return z
        p = _poly_at(self.elevations, self._estarts, s)
        return 0.0 if p is None else p.value(s)

    def roll(self, s: float) -> float:
        """Superelevation (roll about the reference line, rad) at ``s``; 0 without lateralProfile."""
        p = _poly_at(self.superelevations, self._rstarts, s)
        return 0.0 if p is None else p.value(s)

    def world_xyz(self, s: float, t: float) -> tuple[float, float, float, float]:
        """World ``(x, y, z, reference heading)`` of road coordinates ``(s, t)``."""
        i = bisect_right(self._gstarts, s) - 1  # as reference_xyh, with the heading's cos and sin
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        x, y, h, cos_h, sin_h = g.frame(ds if ds >= 0.0 else 0.0)
        z = self._z_fixed
        if z is None:
            z = self.elevation(s)
        if self.superelevations:
            r = self.roll(s)
            th = t * math.cos(r)
            z += t * math.sin(r)
        else:
            th = t
        return x - th * sin_h, y + th * cos_h, z, h

    def world_xyzk(self, s: float, t: float) -> tuple[float, float, float, float, float]:
        """`world_xyz` and the reference line's `curvature` at ``s``, from one look-up of the planView record
        (an entity posed at ``s`` moves on from there at the next step, scaled by that curvature)."""
        i = bisect_right(self._gstarts, s) - 1
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        if ds < 0.0:
            ds = 0.0
        x, y, h, cos_h, sin_h, k = g.frame_k(ds)
        z = self._z_fixed
        if z is None:  # self.elevation(s): records there are (else 0.0 were fixed), the one at s
            i = bisect_right(self._estarts, s + 1e-12) - 1  # as _poly_at
            p = self.elevations[i if i > 0 else 0]
            e = s - p.s0  # as Poly3.value
            z = p.a + e * (p.b + e * (p.c + e * p.d))
        if self.superelevations:
            r = self.roll(s)
            th = t * math.cos(r)
            z += t * math.sin(r)
        else:
            th = t
        return x - th * sin_h, y + th * cos_h, z, h, k

    def world_points(self, s: float, ts: Sequence[float]) -> list[tuple[float, float, float]]:
        """World ``(x, y, z)`` of ``(s, t)`` for every ``t`` in ``ts``: :meth:`world_xyz` with the reference
        frame at ``s`` computed once (sampling every lane border at one ``s``)."""
        i = bisect_right(self._gstarts, s) - 1
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        x, y, _h, cos_h, sin_h = g.frame(ds if ds >= 0.0 else 0.0)
        z = self._z_fixed
        if z is None:
            z = self.elevation(s)
        if self.superelevations:
            r = self.roll(s)
            cos_r, sin_r = math.cos(r), math.sin(r)
            return [(x - t * cos_r * sin_h, y + t * cos_r * cos_h, z + t * sin_r) for t in ts]
        return [(x - t * sin_h, y + t * cos_h, z) for t in ts]

    def lane_offset(self, s: float) -> float:
        """``t`` of the centre lane (laneOffset) at ``s``."""
        off = self._offset_fixed
        if off is not None:
            return off
        p = _poly_at(self.lane_offsets, self._ostarts, s)
        return 0.0 if p is None else p.value(s)

    # -- lanes
    def section_at(self, s: float, side: int = -1) -> LaneSection:
        """The lane section in effect at ``s`` for the lanes of ``side`` (+1 left, -1 right)."""
        key = 1 if side > 0 else -1
        i = bisect_right(self._side_starts[key], s + 1e-9) - 1
        return self._side_sections[key][i if i > 0 else 0]

    def side_sections(self, side: int) -> list[LaneSection]:
        """The lane sections defining the lanes of ``side`` (+1 left, -1 right), in ``s`` order."""
        return self._side_sections[1 if side > 0 else -1]

    def side_borders(self, s: float, side: int) -> list[tuple[Lane, float, float]]:
        """``(lane, t_inner, t_outer)`` for the lanes of ``side`` at ``s``, innermost first (memoised: the
        same road position is asked for several times per simulation step; callers must not mutate)."""
        cache = self._borders
        hit = cache.get((s, side))
        if hit is not None:
            return hit
        if len(cache) > 256:
            cache.clear()
        out = cache[(s, side)] = self._side_borders(s, side)
        return out

    def _side_borders(self, s: float, side: int) -> list[tuple[Lane, float, float]]:
        sec = self.section_at(s, side)
        lanes = sec.left if side > 0 else sec.right
        if not lanes:
            return []
        fixed = self._fixed_borders(sec, side)
        return fixed if fixed is not None else self._borders_in(sec, lanes, s, side)

    def _fixed_borders(self, sec: LaneSection, side: int) -> list[tuple[Lane, float, float]] | None:
        """The borders of a section's side where they are the same at every ``s`` of it (constant widths,
        constant or no laneOffset: the sums below give the same numbers at every ``s``), else None."""
        fixed = self._fixed
        key = (id(sec), side)
        if key in fixed:
            return fixed[key]
        lanes = sec.left if side > 0 else sec.right
        constant = len(self.lane_offsets) <= 1 and all(_constant(p) for p in self.lane_offsets)
        constant = constant and all(len(lane.widths) == 1 and _constant(lane.widths[0]) for lane in lanes)
        out = fixed[key] = self._borders_in(sec, lanes, sec.s, side) if constant else None
        return out

    def _borders_in(
        self, sec: LaneSection, lanes: list[Lane], s: float, side: int
    ) -> list[tuple[Lane, float, float]]:
        ds = s - sec.s
        off = self.lane_offset(s)
        out: list[tuple[Lane, float, float]] = []
        acc = 0.0
        for lane in lanes:
            widths = lane.widths
            if len(widths) == 1:  # the common case, as Lane.width_at (inline: every step, every lane)
                p = widths[0]
                d = ds - p.s0
                w = p.a + d * (p.b + d * (p.c + d * p.d))
            elif widths:
                w = lane.width_at(ds)
            else:
                b = lane.border_at(ds)
                w = 0.0 if b is None else abs(b) - acc
            inner = off + side * acc
            acc += w
            out.append((lane, inner, off + side * acc))
        return out

    def cross_at(self, s: float) -> LaneCross | None:
        """The lane borders at ``s`` with their derived look-ups where they are the same over the whole
        stretch between lane section changes around ``s`` (see `LaneCross`), else None. Built once per
        road on first use, from the parsed road (which is never changed afterwards)."""
        crosses = self._crosses
        if crosses is None:
            crosses = self._crosses = self._build_crosses()
            first = crosses[0]
            self._uniform = first if all(c is first for c in crosses) else None
        uniform = self._uniform
        if uniform is not None:  # one lane section on each side, the same borders all along the road
            return uniform
        # index 0: before every section start; k + 1: from the k-th start (as section_at's s + 1e-9)
        return crosses[bisect_right(self._cross_starts, s + 1e-9)]

    def centre_t(self, lane_id: int, s: float) -> float | None:
        """``t`` of the centre of lane `lane_id` (not 0) at ``s`` in ``[0, length]`` from the lane borders'
        table of the stretch of road around ``s`` (`cross_at`); None where there is none: the caller asks
        `OpenDrive.lane_center_t`, which gives the same float here."""
        if lane_id == 0 or not 0.0 <= s <= self.length:
            return None
        cross = self._uniform
        if cross is None:
            cross = self.cross_at(s)
            if cross is None:
                return None
        known, centre = cross.centre_of(lane_id)
        return centre if known else None

    def _build_crosses(self) -> list[LaneCross | None]:
        def index(key: int, q: float) -> int:  # as section_at
            i = bisect_right(self._side_starts[key], q) - 1
            return i if i > 0 else 0

        made: dict[tuple[int, int], LaneCross | None] = {}
        out: list[LaneCross | None] = []
        for right, left in [(0, 0)] + [(index(-1, q), index(1, q)) for q in self._cross_starts]:
            if (right, left) not in made:
                r, le = self._fixed_side(-1, right), self._fixed_side(1, left)
                made[(right, left)] = None if r is None or le is None else LaneCross(r, le)
            out.append(made[(right, left)])
        return out

    def _fixed_side(self, key: int, index: int) -> list[tuple[Lane, float, float]] | None:
        """`_side_borders` of the `index`-th section of side `key` where it is the same at every s."""
        sec = self._side_sections[key][index]
        if not (sec.left if key > 0 else sec.right):
            return []
        return self._fixed_borders(sec, key)

    def all_borders(self, s: float) -> list[tuple[Lane, float, float]]:
        """Borders of every non-centre lane at ``s`` (right side first, then left; memoised as
        `side_borders`: callers must not mutate)."""
        cross = self.cross_at(s)
        if cross is not None:
            return cross.borders
        cache = self._all_borders
        hit = cache.get(s)
        if hit is not None:
            return hit
        if len(cache) > 256:
            cache.clear()
        out = cache[s] = self.side_borders(s, -1) + self.side_borders(s, 1)
        return out


@dataclass(frozen=True)
class JunctionConnection:
    """One junction ``<connection>``; ``lane_links`` are ``(from, to)`` lane ids.

    For a direct junction (OpenDRIVE 1.7 ``type="direct"``) ``connecting_road`` is the ``linkedRoad``.
    """

    id: str
    incoming_road: str
    connecting_road: str
    contact_point: str
    lane_links: tuple[tuple[int, int], ...]


@dataclass
class Junction:
    """A ``<junction>`` and its connections (in file order)."""

    id: str
    name: str
    connections: list[JunctionConnection]


@dataclass(frozen=True)
class LaneBoundary:
    """Samples of one lane's inner and outer border within one lane section (for triangulation).

    ``s`` has shape (N,), ``inner``/``outer`` shape (N, 3) of world x, y, z.
    """

    road_id: str
    section_index: int
    lane_id: int
    lane_type: str
    # numpy arrays (typed Any: numpy is imported only where they are built, and a compiled module needs the
    # names of its dataclasses' field types when it loads)
    s: Any
    inner: Any
    outer: Any
