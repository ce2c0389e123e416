"""What entity conditions measure: distances between entities (or to a position) in the coordinate systems
and distance types of OpenSCENARIO 1.1+, time headway and time to collision.

Where the standard leaves a choice open, this follows esmini (the reference player of the conformance
corpus; its roadmanager `Position::Distance` and `Object::Distance`):

- distances are signed: positive when the target is ahead of the measuring entity;
- in the entity coordinate system, without freespace, the measuring frame is the road's heading at the
  entity, turned to the entity's driving direction (not the entity's own heading), except for the lateral
  distance between two entities, which is across the entity's own heading (it turns during a lane change,
  as esmini's does); with freespace, the
  longitudinal and lateral distances are the gaps between the bounding boxes along the entity's own axes
  (0 where the projections overlap), and the Euclidean one the shortest distance between the boxes;
- in the road and lane coordinate systems, the difference of s (longitudinal) or t (lateral) along the
  road network, in the entity's driving direction;
- the defaults of TimeHeadwayCondition, TimeToCollisionCondition and DistanceCondition (coordinate system
  `entity`, distance type `euclidianDistance`; `alongRoute="true"` of 1.0 selects `road`);
- headway and time to collision are not defined (the condition does not hold) when the target is behind,
  when the measuring entity stands still, or (time to collision) when the entities do not close in.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final, Protocol

from simcore.evaluation.metrics import Box, box_distance, boxes_overlap, footprint, projections
from simcore.scenario import paths
from simcore.scenario.motion import reference_heading
from simcore.world.native_calls import hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.world.opendrive import OpenDrive

#: a distance that could not be measured (no road connection): compared as a very large value (as esmini)
LARGE: Final = 1e10
SMALL: Final = 1e-10

Point = tuple[float, float]


class RoadClock(Protocol):
    """What measurements read besides the bodies: the road network and the step (their caches' age)."""

    @property
    def road(self) -> OpenDrive | None: ...

    @property
    def step_index(self) -> int: ...


class Measure:
    """Distance measurements for one engine, with per-step caches of what every condition asks again."""

    def __init__(self, world: RoadClock) -> None:
        self.world = world
        self._step = -1
        self._stale = False
        self._frame: dict[str, float] = {}  # body name → heading of its measuring frame (this step)
        self._road_t: dict[str, float] = {}  # body name → t of its reference point (this step)
        self._boxes: dict[str, Box] = {}  # body name → bounding box footprint (this step)
        self._plans: dict[tuple[str, int, str], list[tuple[str, int]] | None] = {}
        self._points: dict[tuple[float, float, str | None], tuple[str, float, float] | None] = {}

    def _fresh(self) -> None:
        if self._stale or self._step != self.world.step_index:
            self._step = self.world.step_index
            self._stale = False
            self._frame.clear()
            self._road_t.clear()
            self._boxes.clear()

    def clear(self) -> None:
        """Forget what was measured on the bodies (they moved); done when next asked."""
        self._stale = True

    # --- frames ---------------------------------------------------------------------------------------

    def frame_heading(self, body: Body) -> float:
        """The road's heading at the entity, in its driving direction (its own heading when off road)."""
        self._fresh()
        cached = self._frame.get(body.name)
        if cached is not None:
            return cached
        heading = body.heading
        road = self.world.road
        if road is not None and body.road_id is not None and body.road_id in road.roads:
            r = road.road(body.road_id)
            h_road = reference_heading(r, body, min(max(body.s, 0.0), r.length))
            heading = h_road if math.cos(body.heading - h_road) >= 0 else h_road + math.pi
        self._frame[body.name] = heading
        return heading

    def local(self, body: Body, x: float, y: float) -> Point:
        """(x, y) in the entity's measuring frame, from its reference point."""
        h = self.frame_heading(body)
        c, s = math.cos(h), math.sin(h)
        dx, dy = x - body.x, y - body.y
        return c * dx + s * dy, -s * dx + c * dy

    def signed_euclid(self, body: Body, x: float, y: float) -> float:
        dx, dy = self.local(body, x, y)
        return math.copysign(hypot(dx, dy), 1.0 if dx > 0 else -1.0)

    # --- road coordinates -----------------------------------------------------------------------------

    def t_of(self, body: Body) -> float:
        self._fresh()
        cached = self._road_t.get(body.name)
        if cached is None:
            road = self.world.road
            assert road is not None and body.road_id is not None
            cached = road.lane_center_t(body.road_id, body.lane_id, body.s) + body.offset
            self._road_t[body.name] = cached
        return cached

    def _point_on_road(self, x: float, y: float, hint: str | None) -> tuple[str, float, float] | None:
        key = (x, y, hint)
        if key not in self._points:
            road = self.world.road
            rc = road.world_to_road(x, y, None, road_hint=hint) if road is not None else None
            self._points[key] = None if rc is None else (rc.road_id, rc.s, rc.t)
        return self._points[key]

    def _plan(self, start: str, direction: int, goal: str) -> list[tuple[str, int]] | None:
        key = (start, direction, goal)
        if key not in self._plans:
            road = self.world.road
            assert road is not None
            self._plans[key] = paths.plan(road, (start, direction), goal, max_roads=200)
        return self._plans[key]

    def road_delta(self, a: Body, road_id: str, s: float, t: float) -> Point | None:
        """(ds, dt) from the entity to a road position along the road network, in the entity's driving
        direction (dt + to the left of it); None when the roads do not connect."""
        road = self.world.road
        if road is None or a.road_id is None:
            return None
        d = 1 if a.direction >= 0 else -1
        t_a = self.t_of(a)
        if road_id == a.road_id:
            return (s - a.s) * d, (t - t_a) * d
        best: Point | None = None
        for sign in (1, -1):
            legs = self._plan(a.road_id, d * sign, road_id)
            if legs is None:
                continue
            first_len = road.road_length(a.road_id)
            along = (first_len - a.s) if d * sign > 0 else a.s
            for leg_road, _ in legs[1:-1]:
                along += road.road_length(leg_road)
            last_dir = legs[-1][1]
            along += s if last_dir > 0 else road.road_length(road_id) - s
            candidate = (along * sign, t * last_dir * sign - t_a * d)
            if best is None or abs(candidate[0]) < abs(best[0]):
                best = candidate
        return best

    # --- distances ------------------------------------------------------------------------------------

    def to_entity(self, a: Body, b: Body, system: str, kind: str, freespace: bool) -> float | None:
        """Signed distance from entity a to entity b (None: not measurable)."""
        euclid = kind in ("euclidianDistance", "cartesianDistance")
        if freespace:
            if system == "entity" or euclid:
                box_a, box_b = self.box(a), self.box(b)
                lon, lat = axis_gaps(box_a, box_b)
                if system == "entity" and kind == "longitudinal":
                    return lon
                if system == "entity" and kind == "lateral":
                    return lat
                return box_distance(box_a, box_b) * (1.0 if lon >= 0 else -1.0)
            delta = self.road_delta_entity(a, b)
            if delta is None:
                return None
            ds, dt = delta
            if kind == "longitudinal":
                return _shrink(ds, _extent_along(a, ds >= 0) + _extent_along(b, ds < 0))
            return _shrink(dt, (a.entity.box.width + b.entity.box.width) / 2)
        if euclid:
            return self.signed_euclid(a, b.x, b.y)
        if system in ("road", "lane", "trajectory"):
            delta = self.road_delta_entity(a, b)
            if delta is None:
                return None
            return delta[0] if kind == "longitudinal" else delta[1]
        if kind == "lateral":
            # across the entity's own heading (esmini: during a lane change the lateral distance to an
            # entity ahead or behind turns with the changing entity)
            c, s = math.cos(a.heading), math.sin(a.heading)
            return -s * (b.x - a.x) + c * (b.y - a.y)
        dx, dy = self.local(a, b.x, b.y)
        return dx if kind == "longitudinal" else dy

    def road_delta_entity(self, a: Body, b: Body) -> Point | None:
        if b.road_id is None or self.world.road is None:
            return None
        return self.road_delta(a, b.road_id, b.s, self.t_of(b))

    def to_point(self, a: Body, x: float, y: float, system: str, kind: str, freespace: bool) -> float | None:
        """Signed distance from entity a to the point (x, y) (None: not measurable)."""
        euclid = kind in ("euclidianDistance", "cartesianDistance")
        if freespace and (system == "entity" or euclid):
            dist, lon, lat = _point_gaps(self.box(a), a.heading, x, y)
            if system == "entity" and kind == "longitudinal":
                return lon
            if system == "entity" and kind == "lateral":
                return lat
            return dist * (1.0 if lon >= 0 else -1.0)
        if euclid:
            return self.signed_euclid(a, x, y)
        if system in ("road", "lane", "trajectory"):
            on_road = self._point_on_road(x, y, a.road_id)
            if on_road is None:
                return None
            delta = self.road_delta(a, *on_road)
            if delta is None:
                return None
            ds, dt = delta
            if freespace:
                if kind == "longitudinal":
                    return _shrink(ds, _extent_along(a, ds >= 0))
                return _shrink(dt, a.entity.box.width / 2)
            return ds if kind == "longitudinal" else dt
        dx, dy = self.local(a, x, y)
        return dx if kind == "longitudinal" else dy

    def box_distance_lower_bound(self, a: Body, b: Body) -> float:
        """A cheap lower bound of the distance between two bounding boxes: their centres' distance less
        both half diagonals."""
        ba, bb = a.entity.box, b.entity.box
        ca, sa = math.cos(a.heading), math.sin(a.heading)
        cb, sb = math.cos(b.heading), math.sin(b.heading)
        dx = (b.x + cb * bb.center_x - sb * bb.center_y) - (a.x + ca * ba.center_x - sa * ba.center_y)
        dy = (b.y + sb * bb.center_x + cb * bb.center_y) - (a.y + sa * ba.center_x + ca * ba.center_y)
        # (math.sqrt: compiled, a native call, where math.hypot is a Python call; a bound needs no last bit)
        return math.sqrt(dx * dx + dy * dy) - bounding_radii(a, b)

    def box(self, body: Body) -> Box:
        """The entity's bounding box footprint (this step)."""
        self._fresh()
        cached = self._boxes.get(body.name)
        if cached is None:
            box = body.entity.box
            cached = self._boxes[body.name] = footprint(
                body.x, body.y, body.heading, box.center_x, box.center_y, box.length, box.width
            )
        return cached

    # --- headway and time to collision ------------------------------------------------------------------

    def headway(self, a: Body, b: Body, system: str, kind: str, freespace: bool) -> float | None:
        """Time headway from a to b; None where it is not defined (b behind, a standing still)."""
        if a.speed < SMALL:
            return None
        dist = self.to_entity(a, b, system, kind, freespace)
        if dist is None:
            dist = LARGE
        if dist < 0 or a.speed < SMALL:
            return None
        return abs(dist / a.speed)

    def time_to_collision(
        self, a: Body, b: Body | None, point: Point | None, system: str, kind: str, freespace: bool
    ) -> float | None:
        """Time until a reaches b (or the point) at the current speeds; None where not defined."""
        if b is not None:
            dist = self.to_entity(a, b, system, kind, freespace)
            # velocities as moved over the last step (a trajectory's heading may differ from its motion)
            bvx, bvy = b.vx, b.vy
            if abs(bvx) < SMALL and abs(bvy) < SMALL:
                rel_speed = a.speed
            else:
                avx, avy = a.vx, a.vy
                projected = (avx * bvx + avy * bvy) / hypot(bvx, bvy)
                rel_speed = _sign(a.speed) * _sign(projected) * (projected - abs(b.speed))
        else:
            assert point is not None
            dist = self.to_point(a, point[0], point[1], system, kind, freespace)
            rel_speed = a.speed
        if dist is None:
            dist = LARGE
        if abs(dist) < SMALL or abs(rel_speed) < SMALL:
            return None
        ttc = dist / rel_speed
        return ttc if ttc >= 0 else None

    def relative_distance(
        self, a: Body, b: Body, kind: str, freespace: bool, signed: bool = False, system: str = "entity"
    ) -> float:
        """Distance from a to b in a's frame (longitudinal: along a's heading; lateral: across it). In road
        or lane coordinates on one road, longitudinal is the difference of s (as esmini measures it)."""
        if (
            system in ("road", "lane")
            and kind == "longitudinal"
            and a.road_id is not None
            and a.road_id == b.road_id
        ):
            # along the road between reference points, positive in a's travel direction
            ds = (b.s - a.s) * a.direction
            if freespace:
                ba, bb = a.entity.box, b.entity.box
                if ds >= 0:  # b ahead: a's front to b's rear
                    extent = (ba.center_x + ba.length / 2) - (bb.center_x - bb.length / 2)
                else:
                    extent = (bb.center_x + bb.length / 2) - (ba.center_x - ba.length / 2)
                ds = math.copysign(max(abs(ds) - extent, 0.0), ds)
            return ds if signed else abs(ds)
        if kind in ("euclidianDistance", "cartesianDistance"):
            if freespace:
                return box_distance(self.box(a), self.box(b))
            return hypot(b.x - a.x, b.y - a.y)
        if freespace:
            ax, ay = box_center(a)
            bx, by = box_center(b)
        else:  # between reference points (as esmini measures without freespace)
            ax, ay, bx, by = a.x, a.y, b.x, b.y
        c, s = math.cos(a.heading), math.sin(a.heading)
        dx, dy = bx - ax, by - ay
        lon, lat = c * dx + s * dy, -s * dx + c * dy
        value = lon if kind == "longitudinal" else lat
        if freespace:
            rel = b.heading - a.heading
            if kind == "longitudinal":
                extent_b = (
                    abs(math.cos(rel)) * b.entity.box.length / 2 + abs(math.sin(rel)) * b.entity.box.width / 2
                )
                extent = a.entity.box.length / 2 + extent_b
            else:
                extent_b = (
                    abs(math.sin(rel)) * b.entity.box.length / 2 + abs(math.cos(rel)) * b.entity.box.width / 2
                )
                extent = a.entity.box.width / 2 + extent_b
            magnitude = max(abs(value) - extent, 0.0)
            value = math.copysign(magnitude, value)
        return value if signed else abs(value)


def bounding_radii(a: Body, b: Body) -> float:
    """The radii of the two bodies' bounding circles, added: half of each box's diagonal."""
    ba, bb = a.entity.box, b.entity.box
    return 0.5 * (
        math.sqrt(ba.length * ba.length + ba.width * ba.width)
        + math.sqrt(bb.length * bb.length + bb.width * bb.width)
    )


def _sign(value: float) -> float:
    return -1.0 if value < 0 else 1.0


def _shrink(value: float, extent: float) -> float:
    """A reference-point distance reduced by the extents of the boxes (0 when they overlap)."""
    return math.copysign(max(abs(value) - extent, 0.0), value)


def _extent_along(body: Body, front: bool) -> float:
    box = body.entity.box
    return box.center_x + box.length / 2 if front else box.length / 2 - box.center_x


def axis_gaps(a: Box, b: Box) -> Point:
    """Gaps between the boxes' projections on a's forward and left axes: positive when b is ahead (left),
    negative behind (right), 0 where the projections overlap."""
    return _projection_gap(a, b, a.fx, a.fy), _projection_gap(a, b, a.lx, a.ly)


def _projection_gap(a: Box, b: Box, ax: float, ay: float) -> float:
    a_min, a_max, b_min, b_max = projections(a, b, ax, ay)
    if a_max < b_min - SMALL:
        return b_min - a_max
    if a_min > b_max + SMALL:
        return b_max - a_min
    return 0.0


def _point_gaps(box: Box, heading: float, x: float, y: float) -> tuple[float, float, float]:
    """(distance, longitudinal, lateral) from a box to a point: the vector from the nearest point of the
    box to the point, in the box's frame; zeros when the point is inside."""
    point_box = Box(x, y, x, y, x, y, x, y, 1.0, 0.0, 0.0, 1.0)
    if boxes_overlap(box, point_box):
        return 0.0, 0.0, 0.0
    best = (math.inf, 0.0, 0.0)
    corners = box.corners
    for i in range(4):
        x0, y0 = corners[i - 1]
        x1, y1 = corners[i]
        dx, dy = x1 - x0, y1 - y0
        length2 = dx * dx + dy * dy
        u = 0.0 if length2 <= 0 else min(max(((x - x0) * dx + (y - y0) * dy) / length2, 0.0), 1.0)
        vx, vy = x - (x0 + u * dx), y - (y0 + u * dy)
        d = hypot(vx, vy)
        if d < best[0]:
            best = (d, vx, vy)
    d, vx, vy = best
    c, s = math.cos(heading), math.sin(heading)
    return d, c * vx + s * vy, -s * vx + c * vy


def directional(body: Body, heading: float, direction: str) -> float:
    """A body's velocity along (longitudinal) or across (lateral, + left) `heading`; vertical: none here."""
    if direction == "vertical":
        return 0.0
    c, s = math.cos(heading), math.sin(heading)
    vx, vy = body.vx, body.vy
    return c * vx + s * vy if direction == "longitudinal" else -s * vx + c * vy


def box_center(body: Body) -> tuple[float, float]:
    """Centre of a body's bounding box in the map frame."""
    box = body.entity.box
    c, s = math.cos(body.heading), math.sin(body.heading)
    return body.x + c * box.center_x - s * box.center_y, body.y + s * box.center_x + c * box.center_y
