"""Pure-Python OpenDRIVE (1.4–1.7) road geometry.

Parses the road network of an ``.xodr`` file (planView geometry, elevation, lane offsets, lane sections,
lanes and their widths, road and lane links, junctions) and answers the geometric questions a scenario
engine needs: road/lane coordinates to world poses, world points back to road coordinates, lane topology
(what lane follows the end of a lane) and sampled lane borders for later triangulation.

Supported planView geometries: ``line``, ``arc``, ``spiral`` (clothoid, via Fresnel integrals, any
curvStart/curvEnd), ``poly3`` and ``paramPoly3`` (``pRange`` ``arcLength`` or ``normalized``). For
``poly3`` and ``paramPoly3`` the road ``s`` is mapped to the curve parameter through a numerically
integrated arc-length table, so ``s`` is a true arc length along the curve.

Deliberately not modelled (documented limitations):

* ``lateralProfile``: ``superelevation`` is applied as a roll of the whole cross section about the reference
  line (``t`` is measured in the tilted plane: horizontal offset ``t*cos(roll)``, height ``t*sin(roll)``,
  as esmini does); ``crossfall`` and ``shape`` are ignored. Pose headings never include pitch or roll.
* Lane ``height`` records, road marks, objects, signals and the header ``geoReference``/``offset`` are ignored.
* Lane ``border`` records are used only for lanes without ``width`` records; the border polynomial is taken
  as the outer border's distance from the centre lane (laneOffset-shifted reference line).

XML is parsed with :mod:`defusedxml` (files are untrusted), files over 64 MiB are refused, and every
problem in the input is reported as :class:`OpenDriveError` naming the file and the element.

This module is the entry point: the network (`OpenDrive`: look-ups by id, lane queries, topology, world to
road, lane-border sampling) and `load`. Its parts: `simcore.world.road_geometry` (the planView records),
`simcore.world.road_model` (roads, lane sections, lanes, junctions and the values queries return) and
`simcore.world.opendrive_parse` (the bounded, safe XML parsing and `OpenDriveError`).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

from simcore.world.frozen import builder
from simcore.world.native_calls import atan2, hypot
from simcore.world.opendrive_parse import MAX_FILE_BYTES, OpenDriveError, parse_network, read_bounded
from simcore.world.road_geometry import linspace
from simcore.world.road_model import (
    DRIVING_LANE_TYPES,
    Junction,
    Lane,
    LaneBoundary,
    Pose,
    Road,
    RoadCoordinates,
)

__all__ = ["OpenDrive", "OpenDriveError", "PointGrid", "load"]

#: networks `OpenDrive.shared` keeps per process, by file name and content (the most recently used ones)
_SHARED_MAX: Final = 4
_SHARED: Final[dict[tuple[str, bytes], OpenDrive]] = {}

_S_TOL: Final = 1e-3  # m: s values this far outside [0, length] are clamped silently


class PointGrid:
    """Points in square cells of side `cell`, for `query_ball_point(p, r)` with r <= cell: the indices of
    the points within r of p, ascending (the set scipy's cKDTree finds; this index costs no scipy import,
    whose load outweighs a whole run on a small road, and no numpy import: a query looks at a few dozen
    points, which plain Python does faster than numpy's per-call overhead)."""

    def __init__(self, data: Sequence[Sequence[float]], cell: float) -> None:
        self.xs: list[float] = [float(p[0]) for p in data]
        self.ys: list[float] = [float(p[1]) for p in data]
        self.cell = max(cell, 1e-9)
        buckets: dict[tuple[int, int], list[int]] = {}
        c = self.cell
        for i, (x, y) in enumerate(zip(self.xs, self.ys, strict=True)):
            buckets.setdefault((math.floor(x / c), math.floor(y / c)), []).append(i)
        self._buckets = buckets

    def query_ball_point(self, point: Sequence[float], r: float) -> list[int]:
        x, y = float(point[0]), float(point[1])
        span = max(1, math.ceil(r / self.cell))
        kx, ky = math.floor(x / self.cell), math.floor(y / self.cell)
        xs, ys, r2 = self.xs, self.ys, r * r
        near = [
            i
            for gx in range(kx - span, kx + span + 1)
            for gy in range(ky - span, ky + span + 1)
            for i in self._buckets.get((gx, gy), ())
            if (xs[i] - x) ** 2 + (ys[i] - y) ** 2 <= r2
        ]
        near.sort()
        return near


_road_coordinates: Final = builder(RoadCoordinates)  # RoadCoordinates(...), built as fast as a plain object


class OpenDrive:
    """A parsed OpenDRIVE road network with geometric queries. Build with :meth:`from_file` / :meth:`from_string`."""

    def __init__(
        self, roads: dict[str, Road], junctions: dict[str, Junction], name: str = "<string>"
    ) -> None:
        self.name = name
        self.roads = roads
        self.junctions = junctions
        self._index: Any = None
        self.signals: dict[str, str] = {}  # <signal> id → name (traffic signals are otherwise not modelled)

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_file(cls, path: str | Path) -> OpenDrive:
        """Parse an ``.xodr`` file (refused if larger than 64 MiB)."""
        return cls._from_bytes(read_bounded(Path(path)), str(path))

    @classmethod
    def shared(cls, path: str | Path) -> OpenDrive:
        """:meth:`from_file`, parsed once per process for the same file content: a worker running run after
        run on one road (a sweep) parses it and builds its spatial index once. Callers treat the network as
        read-only (its lazily built index and memos are pure functions of the file)."""
        data = read_bounded(Path(path))
        key = (str(path), hashlib.sha256(data).digest())
        network = _SHARED.pop(key, None)
        if network is None:
            network = cls._from_bytes(data, str(path))
        _SHARED[key] = network  # most recently used last
        while len(_SHARED) > _SHARED_MAX:
            del _SHARED[next(iter(_SHARED))]
        return network

    @classmethod
    def from_string(cls, text: str, name: str = "<string>") -> OpenDrive:
        """Parse OpenDRIVE XML text; ``name`` is used in error messages."""
        data = text.encode("utf-8")
        if len(data) > MAX_FILE_BYTES:
            raise OpenDriveError(f"{name}: input is larger than the {MAX_FILE_BYTES} byte limit")
        return cls._from_bytes(data, name)

    @classmethod
    def _from_bytes(cls, data: bytes, name: str) -> OpenDrive:
        roads, junctions, signals = parse_network(data, name)
        network = cls(roads, junctions, name)
        network.signals = signals
        return network

    # ---------------------------------------------------------------- basic queries
    def road(self, road_id: str) -> Road:
        """The road with ``road_id``; :class:`OpenDriveError` if there is none."""
        road = self.roads.get(road_id)
        if road is not None:
            return road
        try:
            return self.roads[str(road_id)]
        except KeyError:
            raise OpenDriveError(f"{self.name}: no road id={road_id}") from None

    def road_length(self, road_id: str) -> float:
        """Length of the road's reference line."""
        return self.road(road_id).length

    def _check_s(self, road: Road, s: float) -> float:
        if -_S_TOL <= s <= road.length + _S_TOL:
            return min(max(s, 0.0), road.length)
        raise OpenDriveError(f"{self.name}: road id={road.id}: s={s} outside [0, {road.length}]")

    def reference_pose(self, road_id: str, s: float) -> Pose:
        """Pose of the reference line at ``s`` (no lane offset)."""
        road = self.road(road_id)
        s = self._check_s(road, s)
        x, y, h = road.reference_xyh(s)
        return Pose(x, y, road.elevation(s), h)

    def road_to_world(self, road_id: str, s: float, t: float) -> Pose:
        """World pose of road coordinates ``(s, t)``; the heading is the reference-line heading."""
        road = self.road(road_id)
        s = self._check_s(road, s)
        return Pose(*road.world_xyz(s, t))

    def road_xyzh(self, road_id: str, s: float, t: float) -> tuple[float, float, float, float]:
        """`road_to_world` as a plain ``(x, y, z, heading)`` tuple (for the per-step motion)."""
        road = self.roads.get(road_id)
        if road is None:
            road = self.road(road_id)
        if not 0.0 <= s <= road.length:
            s = self._check_s(road, s)
        return road.world_xyz(s, t)

    def road_z(self, road_id: str, s: float, t: float) -> float:
        """``z`` of road coordinates ``(s, t)`` (the one `road_to_world` gives)."""
        road = self.roads.get(road_id)
        if road is None:
            road = self.road(road_id)
        if not 0.0 <= s <= road.length:
            s = self._check_s(road, s)
        z = road.elevation(s)
        if road.superelevations:
            z += t * math.sin(road.roll(s))
        return z

    def _lane_borders(self, road: Road, lane_id: int, s: float) -> tuple[Lane, float, float]:
        if lane_id == 0:
            off = road.lane_offset(s)
            sec = road.section_at(s)
            lane = sec.center or Lane(0, "none")
            return lane, off, off
        for lane, inner, outer in road.side_borders(s, 1 if lane_id > 0 else -1):
            if lane.id == lane_id:
                return lane, inner, outer
        raise OpenDriveError(f"{self.name}: road id={road.id}: no lane id={lane_id} at s={s:.3f}")

    def lane_center_t(self, road_id: str, lane_id: int, s: float) -> float:
        """``t`` of the lane's centre at ``s`` (includes laneOffset; lane 0 gives the laneOffset)."""
        road = self.roads.get(road_id)
        if road is None:
            road = self.road(road_id)
        if not 0.0 <= s <= road.length:
            s = self._check_s(road, s)
        centre = road.centre_t(lane_id, s)
        if centre is not None:
            return centre
        if lane_id == 0:
            return road.lane_offset(s)
        centers = road.centre_memo
        hit = centers.get((s, lane_id))
        if hit is not None:
            return hit
        if len(centers) > 256:
            centers.clear()
        for lane, inner, outer in road.side_borders(s, 1 if lane_id > 0 else -1):
            if lane.id == lane_id:
                centers[(s, lane_id)] = t = 0.5 * (inner + outer)
                return t
        raise OpenDriveError(f"{self.name}: road id={road.id}: no lane id={lane_id} at s={s:.3f}")

    def lane_width(self, road_id: str, lane_id: int, s: float) -> float:
        """Width of the lane at ``s`` (0 for lane 0)."""
        road = self.road(road_id)
        _, inner, outer = self._lane_borders(road, lane_id, self._check_s(road, s))
        return abs(outer - inner)

    def lane_type(self, road_id: str, lane_id: int, s: float) -> str:
        """The lane's ``type`` attribute at ``s``."""
        road = self.road(road_id)
        lane, _, _ = self._lane_borders(road, lane_id, self._check_s(road, s))
        return lane.type

    def lane_to_world(self, road_id: str, lane_id: int, s: float, offset: float = 0.0) -> Pose:
        """World pose ``offset`` m to the left (+t) of the lane centre at ``s``.

        The heading is the direction of the curve of constant ``offset`` from the lane centre in the
        direction of increasing ``s`` (the reference heading plus the slope of lane widths / laneOffset);
        add pi for travel toward decreasing ``s``.
        """
        road = self.road(road_id)
        s = self._check_s(road, s)
        t = self.lane_center_t(road_id, lane_id, s) + offset
        x, y, z, h = road.world_xyz(s, t)
        return Pose(x, y, z, h + self._lane_slope_angle(road, lane_id, s, t))

    def drives_backward(self, road_id: str, lane_id: int) -> bool:
        """Whether traffic in the lane travels toward decreasing s (left lanes in right-hand traffic)."""
        return (lane_id > 0) != (self.road(road_id).rule == "LHT")

    def lane_heading(self, road_id: str, lane_id: int, s: float) -> float:
        """Heading (toward increasing ``s``) of the lane centre line at ``s``."""
        return self.lane_to_world(road_id, lane_id, s).heading

    def _lane_slope_angle(self, road: Road, lane_id: int, s: float, t: float) -> float:
        """Angle between the lane-centre curve and the reference line at ``s`` (from dt/ds and curvature)."""
        sec = road.section_at(s, 1 if lane_id > 0 else -1)
        eps = 1e-3
        lo = max(sec.s, s - eps, 0.0)
        hi = min(sec.end, s + eps, road.length)
        if hi <= lo:
            return 0.0
        hi_q = hi - 1e-9 if hi >= sec.end and sec.end < road.length else hi
        _, i0, o0 = self._lane_borders(road, lane_id, lo)
        _, i1, o1 = self._lane_borders(road, lane_id, hi_q)
        c0 = c1 = c = 1.0
        if road.superelevations:  # horizontal offsets: t is measured in the rolled cross section
            c0, c1, c = math.cos(road.roll(lo)), math.cos(road.roll(hi_q)), math.cos(road.roll(s))
        _, ic, oc = self._lane_borders(road, lane_id, s)
        off = t - 0.5 * (ic + oc)
        dt = ((0.5 * (i1 + o1) + off) * c1 - (0.5 * (i0 + o0) + off) * c0) / (hi_q - lo)
        return atan2(dt, 1.0 - road.curvature(s) * t * c)

    def speed_limit(self, road_id: str, s: float) -> float | None:
        """The speed limit (m/s) of the road's type at ``s``; None without a speed record."""
        return self.road(road_id).speed_limit(s)

    def lane_ids(self, road_id: str, s: float, driving_only: bool = False) -> list[int]:
        """Ids of the lanes (not 0) with positive width at ``s``, right to left; optionally drivable ones only."""
        road = self.road(road_id)
        s = self._check_s(road, s)
        cross = road.cross_at(s)
        if cross is not None:
            return list(cross.driving_ids if driving_only else cross.ids)
        out = []
        for lane, inner, outer in road.all_borders(s):
            if abs(outer - inner) <= 1e-9:
                continue
            if driving_only and lane.type.lower() not in DRIVING_LANE_TYPES:
                continue
            out.append(lane.id)
        return sorted(out)

    # ---------------------------------------------------------------- topology
    def successor(self, road_id: str, lane_id: int, s_direction: int) -> tuple[str, int, int] | None:
        """Where an entity goes when it leaves the end of ``road_id``/``lane_id`` travelling in ``s_direction``.

        ``s_direction`` +1 leaves at ``s = length`` via the road's successor, -1 leaves at ``s = 0`` via its
        predecessor; ``lane_id`` is the lane in the last (first) lane section. Follows the lane's own link
        for a road link, and for a junction the first connection from this road with a laneLink from
        ``lane_id``. Returns ``(road_id, lane_id, new_s_direction)`` or None at a dead end.
        """
        road = self.road(road_id)
        if s_direction not in (1, -1):
            raise ValueError(f"s_direction must be +1 or -1, got {s_direction}")
        link = road.successor if s_direction > 0 else road.predecessor
        if link is None:
            return None
        if link.element_type == "road":
            if link.element_id not in self.roads:
                return None
            sec = road.lane_sections[-1] if s_direction > 0 else road.lane_sections[0]
            lane = sec.lane(lane_id)
            if lane is None:
                raise OpenDriveError(f"{self.name}: road id={road.id}: no lane id={lane_id} at its end")
            target = lane.successor if s_direction > 0 else lane.predecessor
            if target is None:
                return None
            return link.element_id, target, 1 if link.contact_point == "start" else -1
        junction = self.junctions.get(link.element_id)
        if junction is None:
            return None
        for conn in junction.connections:
            if conn.incoming_road != road.id or conn.connecting_road not in self.roads:
                continue
            for frm, to in conn.lane_links:
                if frm == lane_id:
                    return conn.connecting_road, to, 1 if conn.contact_point == "start" else -1
        return None

    def connections(self, road_id: str, lane_id: int | None, s_direction: int) -> list[tuple[str, int, int]]:
        """Every way on from the end of ``road_id`` in ``s_direction`` (all junction connections, not only the
        first): ``(road_id, lane_id, new_s_direction)``. ``lane_id`` None: from any lane of the road."""
        road = self.road(road_id)
        link = road.successor if s_direction > 0 else road.predecessor
        if link is None:
            return []
        out: list[tuple[str, int, int]] = []
        if link.element_type == "road":
            if link.element_id not in self.roads:
                return []
            sec = road.lane_sections[-1] if s_direction > 0 else road.lane_sections[0]
            lanes = [ln for ln in sec.left + sec.right if lane_id is None or ln.id == lane_id]
            for lane in lanes:
                target = lane.successor if s_direction > 0 else lane.predecessor
                if target is not None:
                    out.append((link.element_id, target, 1 if link.contact_point == "start" else -1))
            return out
        junction = self.junctions.get(link.element_id)
        if junction is None:
            return []
        for conn in junction.connections:
            if conn.incoming_road != road.id or conn.connecting_road not in self.roads:
                continue
            for frm, to in conn.lane_links:
                if lane_id is None or frm == lane_id:
                    out.append((conn.connecting_road, to, 1 if conn.contact_point == "start" else -1))
        return out

    # ---------------------------------------------------------------- sampling
    def sample_lane_boundaries(self, road_id: str, step: float = 1.0) -> list[LaneBoundary]:
        """Inner/outer border points of every lane (not lane 0) of each lane section, every ``step`` m or less.

        Each section is sampled from its start to its end inclusive; zero-width stretches are kept so the
        arrays of one lane stay aligned (triangulation can drop degenerate triangles).
        """
        import numpy as np  # here only: arrays for sensors' scene meshes and report plots

        if step <= 0:
            raise ValueError("step must be positive")
        road = self.road(road_id)
        out: list[LaneBoundary] = []
        for si, sec in enumerate(road.lane_sections):
            n = max(1, math.ceil((sec.end - sec.s) / step))
            ss = np.linspace(sec.s, sec.end, n + 1)
            lane_ids = [ln.id for ln in sec.right + sec.left]
            if not lane_ids:
                continue
            inner = {lid: np.zeros((len(ss), 3)) for lid in lane_ids}
            outer = {lid: np.zeros((len(ss), 3)) for lid in lane_ids}
            for k, s in enumerate(ss):
                s = float(s)
                q = min(s, sec.end - 1e-9) if sec.end > sec.s else s
                borders = [
                    border
                    for side in (-1, 1)
                    if road.section_at(q, side) is sec
                    for border in road.side_borders(q, side)
                ]
                points = road.world_points(s, [t for _, ti, to in borders for t in (ti, to)])
                for j, (lane, _, _) in enumerate(borders):
                    inner[lane.id][k] = points[2 * j]
                    outer[lane.id][k] = points[2 * j + 1]
            for lane in sec.right + sec.left:
                out.append(LaneBoundary(road.id, si, lane.id, lane.type, ss, inner[lane.id], outer[lane.id]))
        return out

    # ---------------------------------------------------------------- world -> road
    def _build_index(self) -> dict[str, Any]:

        xs: list[float] = []
        ys: list[float] = []
        rix: list[int] = []
        ss: list[float] = []
        reach: list[float] = []
        road_list = list(self.roads.values())
        spacing: list[float] = []
        for ri, road in enumerate(road_list):
            n = max(2, math.ceil(road.length / 2.0) + 1)
            sp = road.length / (n - 1)
            spacing.append(sp)
            for s in linspace(0.0, road.length, n):
                x, y, _ = road.reference_xyh(s)
                ext = 0.0
                for _lane, inner, outer in road.all_borders(s):
                    ext = max(ext, abs(inner), abs(outer) + 0.5 * abs(outer - inner))
                xs.append(x)
                ys.append(y)
                rix.append(ri)
                ss.append(s)
                reach.append(ext + sp + 0.5)
        return {
            "tree": PointGrid(list(zip(xs, ys, strict=True)), float(max(reach))),
            "roads": road_list,
            "rix": rix,
            "s": ss,
            "reach": reach,
            "max_reach": float(max(reach)),
            "spacing": spacing,
        }

    def _project(
        self, road: Road, px: float, py: float, s0: float, spacing: float
    ) -> tuple[float, float, float, float]:
        """Newton projection of ``(px, py)`` on the reference line from ``s0``: ``(s, t, along_residual,
        reference heading at s)``."""
        s = s0
        along = 0.0
        t = 0.0
        h = 0.0
        at = math.nan  # the s that h is the heading at
        length = road.length
        most = 2.0 * spacing + 1.0  # the longest Newton step either way
        least = -2.0 * spacing - 1.0
        g, lo, hi = road.geometry_span(s)
        g_s, straight = g.s, g.straight  # the record's, asked again only on leaving it
        for _ in range(30):
            if not lo <= s < hi:  # left the record: as road.reference_xyh(s) and road.curvature(s)
                g, lo, hi = road.geometry_span(s)
                g_s, straight = g.s, g.straight
            ds = s - g_s
            x, y, h, c, sn = g.frame(ds if ds >= 0.0 else 0.0)  # (compiled: a native call, no bound method)
            at = s
            dx, dy = px - x, py - y
            along = dx * c + dy * sn
            t = -dx * sn + dy * c
            if -1e-9 < along < 1e-9:  # abs(along) < 1e-9 (False for NaN either way)
                break
            if straight:  # 1.0 - 0.0 * t is 1.0 (or NaN where t is not finite): either way the step is along
                step = along
            else:
                denom = 1.0 - g.curvature(ds if ds >= 0.0 else 0.0) * t
                step = along / denom if denom > 0.2 else along
            # max(least, min(most, step)) and min(max(s + step, 0.0), length), without the calls
            step = step if step < most else most
            step = step if step > least else least
            s_new = s + step
            s_new = 0.0 if s_new < 0.0 else s_new
            s_new = length if length < s_new else s_new
            moved = s_new - s
            if -1e-10 < moved < 1e-10:  # abs(s_new - s) < 1e-10
                break
            s = s_new
        if at != s:
            _, _, h = road.reference_xyh(s)
        return s, t, along, h

    def world_to_road(
        self, x: float, y: float, z: float | None = None, road_hint: str | None = None
    ) -> RoadCoordinates | None:
        """The road and lane containing world point ``(x, y)`` (``z`` disambiguates stacked roads).

        Candidates come from a k-d tree of reference-line samples (every <= 2 m); ``s`` is refined by
        Newton projection. A point laterally outside the outermost lane by up to half that lane's width is
        still mapped (to that lane); beyond that, or more than 5 cm past the road ends, it is off the road.
        Candidates strictly inside a lane and inside the road's s range come first; among several such roads
        (junctions), one within 2 m of ``z`` (if given) wins, then ``road_hint``, then the nearest
        elevation, then the smallest ``|offset|`` relative to the lane width. All lane types count.
        Returns None when the point is on no road.
        """
        if self._index is None:
            self._index = self._build_index()
        idx = self._index
        cand = idx["tree"].query_ball_point([x, y], idx["max_reach"])
        if not cand:
            return None
        tree: PointGrid = idx["tree"]
        xs, ys = tree.xs, tree.ys
        reach: list[float] = idx["reach"]
        rix, sample_s, spacing = idx["rix"], idx["s"], idx["spacing"]
        roads: list[Road] = idx["roads"]
        best: tuple[tuple[float, ...], RoadCoordinates] | None = None
        # the hinted road first: a point strictly inside one of its lanes (key (0, 0, 0, …)) is on it, whatever
        # the other roads give (their keys are greater at the third place, where a NaN never is; road ids are
        # unique). Its seeds are the ones the full search below gives it (its samples in the same order);
        # without such a hit every road is searched in order, the hinted road's candidates kept.
        hinted: list[tuple[tuple[float, ...], RoadCoordinates] | None] | None = None
        hint_ri = -1
        if road_hint is not None:
            ri_of: dict[str, int] | None = idx.get("ri_of")
            if ri_of is None:
                ri_of = idx["ri_of"] = {road.id: ri for ri, road in enumerate(roads)}
            hint_ri = ri_of.get(road_hint, -1)
            if hint_ri >= 0:
                mine = [
                    (d, ci)
                    for ci in cand
                    if rix[ci] == hint_ri and (d := hypot(xs[ci] - x, ys[ci] - y)) <= reach[ci]
                ]
                mine.sort()
                starts: list[float] = []
                gap = 3.0 * spacing[hint_ri]
                for _, ci in mine:
                    if len(starts) == 3:
                        break
                    s0 = sample_s[ci]
                    for o in starts:
                        if not abs(s0 - o) > gap:
                            break
                    else:
                        starts.append(s0)
                road, sp = roads[hint_ri], spacing[hint_ri]
                hinted = [self._candidate(road, x, y, z, s0, sp, road_hint) for s0 in starts]
                for found in hinted:
                    if found is not None and (best is None or found[0] < best[0]):
                        best = found
                if best is not None and best[0][0] == 0.0 and best[0][1] == 0.0:
                    return best[1]
                best = None
        near = [(d, ci) for ci in cand if (d := hypot(xs[ci] - x, ys[ci] - y)) <= reach[ci]]
        near.sort()  # by distance, ties by index
        seeds: dict[int, list[float]] = {}
        for _, ci in near:
            ri = rix[ci]
            lst = seeds.get(ri)
            if lst is None:
                lst = seeds[ri] = []
            if len(lst) < 3:
                # up to 3 seeds per road, each more than 3 samples from the ones before
                s0 = sample_s[ci]
                gap = 3.0 * spacing[ri]
                for o in lst:
                    if not abs(s0 - o) > gap:
                        break
                else:
                    lst.append(s0)
        for ri, starts in seeds.items():
            if ri == hint_ri and hinted is not None:
                candidates: list[tuple[tuple[float, ...], RoadCoordinates] | None] = hinted
            else:
                road, sp = roads[ri], spacing[ri]
                candidates = [self._candidate(road, x, y, z, s0, sp, road_hint) for s0 in starts]
            for found in candidates:
                if found is not None and (best is None or found[0] < best[0]):
                    best = found
        return None if best is None else best[1]

    def _candidate(
        self, road: Road, x: float, y: float, z: float | None, s0: float, sp: float, road_hint: str | None
    ) -> tuple[tuple[float, ...], RoadCoordinates] | None:
        """`world_to_road`'s candidate from the seed `s0` on `road`: (its sort key, its road coordinates), or
        None when the point is beyond the road's ends or more than half the outermost lane's width outside."""
        s, t, along, h = self._project(road, x, y, s0, sp)
        if road.superelevations:
            t /= max(math.cos(road.roll(s)), 1e-6)
        if abs(along) > 0.05:  # beyond the road's ends (or not converged)
            return None
        borders = [b for b in road.all_borders(s) if abs(b[2] - b[1]) > 1e-9]
        if not borders:
            return None
        lane_hit: tuple[Lane, float, float] | None = None
        outside = math.inf
        for b in borders:
            lo, hi = min(b[1], b[2]), max(b[1], b[2])
            dist = 0.0 if lo <= t <= hi else min(abs(t - lo), abs(t - hi))
            if dist < outside or (
                dist == outside and lane_hit is not None and abs(b[0].id) < abs(lane_hit[0].id)
            ):
                outside, lane_hit = dist, b
        assert lane_hit is not None
        lane, inner, outer = lane_hit
        width = abs(outer - inner)
        if outside > 0.5 * width:
            return None
        offset = t - 0.5 * (inner + outer)
        dz = abs(z - road.world_xyz(s, t)[2]) if z is not None else 0.0
        key = (
            0.0 if outside == 0.0 and abs(along) < 1e-6 else 1.0,
            0.0 if dz < 2.0 else 1.0,
            0.0 if road.id == road_hint else 1.0,
            dz,
            outside + abs(along),
            abs(offset) / max(width, 1e-6),
        )
        return key, _road_coordinates(road.id, lane.id, s, t, offset, h)

    def world_to_road_near(
        self, x: float, y: float, road_id: str, s_previous: float
    ) -> RoadCoordinates | None:
        """Fast path for tracking a moving entity: project onto `road_id` from its previous `s`. Returns None
        (use :meth:`world_to_road`) when the point is not strictly inside a lane of that road, e.g. after it
        left the road or where roads overlap in a junction."""
        near = self.near_lane(x, y, road_id, s_previous)
        return None if near is None else _road_coordinates(self.roads[road_id].id, *near)

    def project_on(self, road_id: str, x: float, y: float, s_hint: float) -> tuple[float, float] | None:
        """(s, t) of a point projected on one road's reference line from `s_hint`, whether or not a lane is
        there; None off the road's ends."""
        road = self.roads.get(road_id)
        if road is None:
            return None
        s, t, along, _ = self._project(road, x, y, min(max(s_hint, 0.0), road.length), 50.0)
        if abs(along) > 1e-6:
            return None
        return s, t

    def near_lane(
        self, x: float, y: float, road_id: str, s_previous: float
    ) -> tuple[int, float, float, float, float] | None:
        """`world_to_road_near` as a plain ``(lane_id, s, t, offset, heading)`` (for the per-step tracking)."""
        road = self.roads.get(road_id)
        if road is None or road.junction != "-1":
            return None
        s0 = 0.0 if s_previous < 0.0 else s_previous  # min(max(s_previous, 0.0), road.length)
        s0 = road.length if road.length < s0 else s0
        s, t, along, h = self._project(road, x, y, s0, 2.0)
        if road.superelevations:
            t /= max(math.cos(road.roll(s)), 1e-6)
        if along > 1e-6 or along < -1e-6:  # abs(along) > 1e-6 (False for NaN either way)
            return None
        cross = road.cross_at(s)
        if cross is not None:
            for span in cross.inside:
                if span.low <= t <= span.high:
                    return span.lane_id, s, t, t - span.centre, h
            return None
        for lane, inner, outer in road.all_borders(s):
            if inner < outer:
                if outer - inner > 1e-9 and inner <= t <= outer:
                    return lane.id, s, t, t - 0.5 * (inner + outer), h
            elif inner - outer > 1e-9 and outer <= t <= inner:
                return lane.id, s, t, t - 0.5 * (inner + outer), h
        return None


def load(path: str | Path) -> OpenDrive:
    """Shorthand for :meth:`OpenDrive.from_file`."""
    return OpenDrive.from_file(path)
