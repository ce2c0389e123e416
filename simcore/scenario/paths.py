"""Geometry of trajectories (polyline, clothoid / clothoid spline, NURBS) as dense sampled paths, and route
planning over the OpenDRIVE road graph."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from simcore.scenario import model as m
from simcore.world.native_calls import atan2, bisect_right, hypot

if TYPE_CHECKING:
    from simcore.world.opendrive import OpenDrive

#: world (x, y, z, heading) of a position, resolved when the action starts
Resolver = Callable[[m.Position], tuple[float, float, float, float]]

CLOTHOID_STEP: Final = 0.05  # m between clothoid samples
NURBS_SAMPLES_PER_POINT: Final = 60


@dataclass
class SampledPath:
    """A path sampled densely: cumulative length `s`, points, headings, optional times."""

    s: list[float]
    x: list[float]
    y: list[float]
    z: list[float]
    h: list[float]
    t: list[float] | None  # trajectory time at each sample (None: no timing)
    v: list[float] | None = (
        None  # speeds at the samples: constant acceleration between them (timed polylines)
    )

    @property
    def length(self) -> float:
        return self.s[-1]

    def at(self, s: float) -> tuple[float, float, float, float]:
        """(x, y, z, heading) at arc length s (clamped)."""
        if s <= 0.0:
            return self.x[0], self.y[0], self.z[0], self.h[0]
        if s >= self.s[-1]:
            return self.x[-1], self.y[-1], self.z[-1], self.h[-1]
        i = bisect_right(self.s, s) - 1
        seg = self.s[i + 1] - self.s[i]
        f = (s - self.s[i]) / seg if seg > 0 else 0.0
        dh = (self.h[i + 1] - self.h[i] + math.pi) % (2 * math.pi) - math.pi
        return (
            self.x[i] + f * (self.x[i + 1] - self.x[i]),
            self.y[i] + f * (self.y[i + 1] - self.y[i]),
            self.z[i] + f * (self.z[i + 1] - self.z[i]),
            self.h[i] + f * dh,
        )

    def project(self, x: float, y: float) -> tuple[float, float]:
        """(arc length, distance) of the point of the path nearest to (x, y)."""
        best_s, best_d2 = 0.0, math.inf
        xs, ys, ss = self.x, self.y, self.s
        for i in range(len(ss) - 1):
            dx, dy = xs[i + 1] - xs[i], ys[i + 1] - ys[i]
            seg2 = dx * dx + dy * dy
            f = 0.0 if seg2 <= 0.0 else min(max(((x - xs[i]) * dx + (y - ys[i]) * dy) / seg2, 0.0), 1.0)
            px, py = xs[i] + f * dx - x, ys[i] + f * dy - y
            d2 = px * px + py * py
            if d2 < best_d2:
                best_s, best_d2 = ss[i] + f * (ss[i + 1] - ss[i]), d2
        if len(ss) == 1:
            best_d2 = (xs[0] - x) ** 2 + (ys[0] - y) ** 2
        return best_s, math.sqrt(best_d2)

    def time_at_s(self, s: float) -> float:
        """Trajectory time at arc length `s` (linear between the samples; clamped)."""
        assert self.t is not None
        if s <= self.s[0]:
            return self.t[0]
        if s >= self.s[-1]:
            return self.t[-1]
        i = bisect_right(self.s, s) - 1
        seg = self.s[i + 1] - self.s[i]
        f = (s - self.s[i]) / seg if seg > 0 else 0.0
        return self.t[i] + f * (self.t[i + 1] - self.t[i])

    def s_at_time(self, time: float) -> float:
        """Arc length where the path is at trajectory time `time` (times must be non-decreasing)."""
        assert self.t is not None
        ts = self.t
        if time <= ts[0]:
            return 0.0
        if time >= ts[-1]:
            return self.s[-1]
        i = bisect_right(ts, time) - 1
        span = ts[i + 1] - ts[i]
        if span <= 0:
            return self.s[i + 1]
        tau = time - ts[i]
        length = self.s[i + 1] - self.s[i]
        if self.v is not None:
            # speed changes linearly between the vertices (as esmini interpolates timed polylines)
            v0, v1 = self.v[i], self.v[i + 1]
            along = v0 * tau + 0.5 * (v1 - v0) / span * tau * tau
            return self.s[i] + min(max(along, 0.0), length)
        return self.s[i] + tau / span * length


def _from_points(points: list[tuple[float, float, float]], times: list[float] | None) -> SampledPath:
    xs: list[float] = []
    ys: list[float] = []
    zs: list[float] = []
    ss: list[float] = []
    hs: list[float] = []
    kept_times: list[float] = []
    total = 0.0
    for i, (x, y, z) in enumerate(points):
        if xs:
            d = hypot(x - xs[-1], y - ys[-1])
            if d < 1e-9 and (times is None or times[i] <= kept_times[-1]):
                continue  # a repeated point (kept when timed: the entity waits there)
            total += d
        xs.append(x)
        ys.append(y)
        zs.append(z)
        ss.append(total)
        if times is not None:
            kept_times.append(times[i])
    if len(xs) == 1:
        hs = [0.0]
    else:
        seg: list[float] = []
        for i in range(len(xs) - 1):
            dx, dy = xs[i + 1] - xs[i], ys[i + 1] - ys[i]
            if hypot(dx, dy) < 1e-9:  # a pause: keep the heading it had
                seg.append(seg[-1] if seg else 0.0)
            else:
                seg.append(atan2(dy, dx))
        for i in range(len(seg) - 1, 0, -1):  # leading pauses take the first real heading
            if hypot(xs[i] - xs[i - 1], ys[i] - ys[i - 1]) < 1e-9 and i - 1 == 0:
                seg[0] = seg[i]
        hs = [*seg, seg[-1]]
    return SampledPath(ss, xs, ys, zs, hs, kept_times if times is not None else None)


def polyline(shape: m.Polyline, resolve: Resolver) -> tuple[SampledPath, float | None]:
    """The polyline as a path (segment headings) and the heading of its first vertex."""
    points, times = [], []
    first_heading = None
    for vertex in shape.vertices:
        x, y, z, h = resolve(vertex.position)
        if first_heading is None:
            first_heading = h
        points.append((x, y, z))
        times.append(vertex.time if vertex.time is not None else math.nan)
    timed = all(not math.isnan(t) for t in times)
    path = _from_points(points, times if timed else None)
    if path.t is not None and len(path.s) > 1:
        path.v = vertex_speeds(path, None)
    if len(path.x) == 1:
        path.h = [first_heading or 0.0]
    return path, first_heading


def vertex_speeds(path: SampledPath, first: float | None) -> list[float]:
    """Speeds at a timed path's samples such that each segment's mean speed covers it: v(i+1) = 2 Li/Ti -
    v(i), from `first` (esmini's follow mode: the entity's speed when the action starts), else from the first
    segment's mean speed."""
    assert path.t is not None
    speeds = [0.0] * len(path.s)
    for i in range(len(path.s) - 1):
        span = path.t[i + 1] - path.t[i]
        mean = (path.s[i + 1] - path.s[i]) / span if span > 0 else 0.0
        if i == 0:
            speeds[0] = mean if first is None else first
        speeds[i + 1] = max(2 * mean - speeds[i], 0.0)
    return speeds


def clothoid(
    shape: m.Clothoid, resolve: Resolver, start_pose: tuple[float, float, float, float]
) -> SampledPath:
    xs: list[float] = []
    ys: list[float] = []
    zs: list[float] = []
    hs: list[float] = []
    ss: list[float] = []
    times: list[float] = []
    timed = all(seg.time_start is not None and seg.time_end is not None for seg in shape.segments)
    x, y, z, h = start_pose
    total = 0.0
    for seg in shape.segments:
        if seg.start is not None:
            x, y, z, h = resolve(seg.start)
        h += seg.h_offset
        n = max(math.ceil(seg.length / CLOTHOID_STEP), 1)
        step = seg.length / n
        k_dot = (seg.curvature_end - seg.curvature_start) / seg.length if seg.length > 0 else 0.0
        h0 = h
        for i in range(n + 1):
            u = i * step
            if i > 0:
                # exact heading; position by the midpoint rule over one small step
                um = u - step / 2
                hm = h0 + seg.curvature_start * um + 0.5 * k_dot * um * um
                x += step * math.cos(hm)
                y += step * math.sin(hm)
                total += step
            elif xs:
                continue  # the segment starts where the previous one ended
            xs.append(x)
            ys.append(y)
            zs.append(z)
            hs.append(h0 + seg.curvature_start * u + 0.5 * k_dot * u * u)
            ss.append(total)
            if timed:
                assert seg.time_start is not None and seg.time_end is not None
                f = u / seg.length if seg.length > 0 else 1.0
                times.append(seg.time_start + f * (seg.time_end - seg.time_start))
        h = h0 + seg.curvature_start * seg.length + 0.5 * k_dot * seg.length**2
    return SampledPath(ss, xs, ys, zs, hs, times if timed else None)


def _basis(knots: tuple[float, ...], order: int, i: int, u: float) -> float:
    """Cox–de Boor B-spline basis N_{i,order}(u) (order = degree + 1)."""
    if order == 1:
        last = u >= knots[-1] and knots[i] < knots[i + 1] and knots[i + 1] == knots[-1]
        return 1.0 if (knots[i] <= u < knots[i + 1]) or last else 0.0
    out = 0.0
    d1 = knots[i + order - 1] - knots[i]
    if d1 > 0:
        out += (u - knots[i]) / d1 * _basis(knots, order - 1, i, u)
    d2 = knots[i + order] - knots[i + 1]
    if d2 > 0:
        out += (knots[i + order] - u) / d2 * _basis(knots, order - 1, i + 1, u)
    return out


def _piecewise_linear(xs: list[float], ys: list[float], x: float) -> float:
    if x <= xs[0]:
        return ys[0]
    for i in range(1, len(xs)):
        if x <= xs[i]:
            span = xs[i] - xs[i - 1]
            f = (x - xs[i - 1]) / span if span > 0 else 1.0
            return ys[i - 1] + f * (ys[i] - ys[i - 1])
    return ys[-1]


def _nurbs_times(
    knots: tuple[float, ...],
    order: int,
    pts: list[tuple[float, float, float, float]],
    times: list[float],
    u0: float,
    u1: float,
) -> tuple[list[float], list[float]]:
    """(curve parameters, trajectory times) of esmini's coarse sampling of a timed NURBS: about one sample a
    metre of the control polygon; each control point's time belongs to the sample where its basis function,
    read just ahead of the sample (just behind at the end), is largest; between two such samples time is
    linear in the parameter, moving on to the next pair once past its first (as esmini's NurbsShape)."""
    count = len(pts)
    polygon = sum(math.dist(pts[i - 1][:2], pts[i][:2]) for i in range(1, count))
    steps = int(1 + polygon / 1.0)
    step = (u1 - u0) / steps
    top = u1 - 1e-10
    params = [u0 + i * step for i in range(steps + 1)]
    peak_value = [0.0] * count
    peak_at = [u0] * count
    for i, u in enumerate(params):
        probe = min(max(u + 0.01 * step if i < steps else u - 0.01 * step, knots[0]), top)
        for j in range(count):
            b = _basis(knots, order, j, probe)
            if b > peak_value[j]:
                peak_value[j], peak_at[j] = b, u
    out: list[float] = []
    current = 0
    for u in params:
        if current + 1 < count and u >= peak_at[current + 1]:
            current = min(current + 1, count - 2)
        lo, hi = peak_at[current], peak_at[min(current + 1, count - 1)]
        w = (u - lo) / (hi - lo) if hi != lo else 0.0
        t_next = times[min(current + 1, count - 1)]
        out.append(times[current] + w * (t_next - times[current]))
    return params, out


def nurbs(shape: m.Nurbs, resolve: Resolver) -> SampledPath:
    pts = [resolve(c.position) for c in shape.control_points]
    weights = [c.weight for c in shape.control_points]
    times = [c.time for c in shape.control_points]
    timed = all(t is not None for t in times)
    knots = shape.knots
    u0, u1 = knots[shape.order - 1], knots[len(pts)]
    # control points' times to the curve parameter as esmini maps them (`_nurbs_times`)
    params, param_times = (
        _nurbs_times(knots, shape.order, pts, [float(t or 0.0) for t in times], u0, u1) if timed else ([], [])
    )
    n = max(NURBS_SAMPLES_PER_POINT * len(pts), 2)
    out_pts: list[tuple[float, float, float]] = []
    out_t: list[float] = []
    for j in range(n + 1):
        u = u0 + (u1 - u0) * j / n
        num_x = num_y = num_z = den = 0.0
        for i, (px, py, pz, _) in enumerate(pts):
            b = _basis(knots, shape.order, i, u) * weights[i]
            if b == 0.0:
                continue
            num_x += b * px
            num_y += b * py
            num_z += b * pz
            den += b
        if den <= 0:
            continue
        out_pts.append((num_x / den, num_y / den, num_z / den))
        if timed:
            out_t.append(_piecewise_linear(params, param_times, u))
    return _from_points(out_pts, out_t if timed else None)


def sample(
    trajectory: m.Trajectory, resolve: Resolver, start_pose: tuple[float, float, float, float]
) -> SampledPath:
    shape = trajectory.shape
    if isinstance(shape, m.Polyline):
        return polyline(shape, resolve)[0]
    if isinstance(shape, m.Clothoid):
        return clothoid(shape, resolve, start_pose)
    return nurbs(shape, resolve)


# --- routes ----------------------------------------------------------------------------------------------

State = tuple[str, int]  # (road id, travel direction along s)


def plan(road: OpenDrive, start: State, goal_road: str, max_roads: int = 2000) -> list[State] | None:
    """The shortest sequence of roads (by length driven) from `start` to `goal_road`, both included."""
    import heapq

    if start[0] == goal_road:
        return [start]
    best: dict[State, float] = {start: 0.0}
    previous: dict[State, State | None] = {start: None}
    heap: list[tuple[float, int, State]] = [(0.0, 0, start)]
    counter = 0
    while heap and len(previous) < max_roads:
        cost, _, current = heapq.heappop(heap)
        if current[0] == goal_road:
            out = [current]
            back = previous[current]
            while back is not None:
                out.append(back)
                back = previous[back]
            return out[::-1]
        if cost > best.get(current, math.inf):
            continue
        # leaving `current` costs its length (the start road's part does not matter for the choice)
        step = road.road_length(current[0]) if current != start else 0.0
        for nxt_road, _lane, nxt_dir in road.connections(current[0], None, current[1]):
            state = (nxt_road, nxt_dir)
            new_cost = cost + step
            if new_cost < best.get(state, math.inf):
                best[state] = new_cost
                previous[state] = current
                counter += 1
                heapq.heappush(heap, (new_cost, counter, state))
    return None


def plan_in_lane(
    road: OpenDrive,
    start: State,
    lane: int,
    goal_road: str,
    s: float | None = None,
    max_nodes: int = 4000,
) -> list[State] | None:
    """As `plan`, but a way esmini's route planner takes: it leaves every road in the lane it is in (along
    that lane's links through the road's lane sections), starting from `lane` at `s` on the start road (its
    far end when None); onto the goal road any lane will do. None when no such way exists."""
    import heapq

    if start[0] == goal_road:
        return [start]
    Key = tuple[str, int, int]
    first: Key = (start[0], start[1], lane)
    best: dict[Key, float] = {first: 0.0}
    previous: dict[Key, Key | None] = {first: None}
    heap: list[tuple[float, int, Key]] = [(0.0, 0, first)]
    counter = 0
    while heap and len(previous) < max_nodes:
        cost, _, current = heapq.heappop(heap)
        if cost > best.get(current, math.inf):
            continue
        road_id, direction, entered = current
        if road_id == goal_road:
            out: list[State] = []
            back: Key | None = current
            while back is not None:
                out.append((back[0], back[1]))
                back = previous[back]
            return out[::-1]
        length = road.road_length(road_id)
        if current == first:
            end_s = length if direction > 0 else 0.0
            leaving = entered if s is None else _lane_through(road, road_id, entered, s, end_s)
            step = 0.0
        else:
            start_s, end_s = (0.0, length) if direction > 0 else (length, 0.0)
            leaving, step = _lane_through(road, road_id, entered, start_s, end_s), length
        if leaving == 0:
            continue
        for nxt_road, nxt_lane, nxt_dir in road.connections(road_id, leaving, direction):
            state = (nxt_road, nxt_dir, nxt_lane)
            if nxt_road == goal_road:
                state = (nxt_road, nxt_dir, 0)  # landing on the goal road: its lane does not matter
            new_cost = cost + step
            if new_cost < best.get(state, math.inf):
                best[state] = new_cost
                previous[state] = current
                counter += 1
                heapq.heappush(heap, (new_cost, counter, state))
    return None


def _lane_through(road: OpenDrive, road_id: str, lane: int, s_from: float, s_to: float) -> int:
    """The lane `lane` at `s_from` is at `s_to` along its links through the road's lane sections (0: it
    ends before)."""
    if lane == 0:
        return 0
    r = road.road(road_id)
    side = 1 if lane > 0 else -1
    sections = r.side_sections(side)
    i, j = sections.index(r.section_at(s_from, side)), sections.index(r.section_at(s_to, side))
    step = 1 if j >= i else -1
    for k in range(i, j, step):
        here = sections[k].lane(lane)
        if here is None:
            return 0
        link = here.successor if step > 0 else here.predecessor
        if link is None or sections[k + step].lane(link) is None:
            return 0
        lane = link
    return lane if sections[j].lane(lane) is not None else 0
