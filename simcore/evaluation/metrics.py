"""Run metrics measured from the ego, one `WorldFrame` at a time, in constant memory.

`MetricsAccumulator.update(frame)` is called every simulation step; `result()` gives the numbers the
criteria are evaluated on (name → float) and `details()` the non-numeric facts (who was hit, …).

Geometry is 2D, on the ground plane (x east, y north). An entity's footprint is its bounding box
(`EntityState.corners()`), an oriented rectangle. Two footprints collide when they overlap or touch
(separating-axis test, within `TOUCH_TOLERANCE`); distances are free-space distances between footprints.

Metrics (see `METRICS`; "absent" means the key is not in `result()`):

- `collision` 1.0 when the ego's box overlapped any other entity's box at some frame, else 0.0.
- `collisionTime` simulated time of the first frame with a collision; absent without a collision.
- `minDistance` minimum free-space distance between the ego's box and any other entity's box
  (0 when they overlap); absent when the ego never had another entity to measure against.
- `minTimeHeadway` minimum over frames and over entities ahead of the ego in its lane of
  gap / ego speed, sampled only while the ego's (signed) speed is above `HEADWAY_MIN_SPEED`.
  "In its lane": when both the ego and the entity carry `LaneCoordinates`, the same `road_id` and
  `lane_id`; otherwise the entity's box centre within ±`lane_width`/2 laterally of the ego's box centre,
  in the ego's frame. "Ahead": the entity's box centre is in front of the ego's box centre along the ego's
  heading. The gap is the free-space longitudinal gap along the ego's heading (ego's front to the entity's
  nearest extent), clamped at 0 when the boxes overlap longitudinally; it is a straight-line measure,
  exact on straight roads. Absent when never defined (nobody ahead in lane while the ego moved).
- `minTimeToCollision` minimum of gap / closing speed over the same entities, sampled only while the
  closing speed (ego speed minus the entity's speed along the ego's heading) is above
  `TTC_MIN_CLOSING_SPEED`. Absent when the ego never closed in on anybody ahead in its lane.
- `minLateralDistance` minimum lateral free-space gap (across the ego's heading) to entities whose boxes
  overlap the ego's box longitudinally (side by side); 0 when the boxes overlap. Absent when never
  side by side.
- `maxDeceleration` largest deceleration of the ego, a positive number (max of −acceleration; 0 when it
  never decelerated). `maxAcceleration` likewise for acceleration.
- `maxSpeed` largest |speed| of the ego; `meanSpeed` time average of |speed| (trapezoidal over frame
  times; the single speed when there is one frame); `egoDistance` path length of the ego's reference point.
- `simSeconds` time of the last frame.

The ego is `frame.ego` when set (it must be in the frame), else the first entity. A frame without entities
only advances `simSeconds`. `stopTriggered` is not measured here: the runner knows how the run ended and
adds it (1.0/0.0) to the metrics before the criteria are evaluated.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar, Final, final

from simcore.world.frozen import freeze
from simcore.world.native_calls import hypot
from simcore.world.state import EntityState, Value, WorldFrame, corner_coordinates

Point = tuple[float, float]

#: Boxes closer than this (m) count as touching, hence colliding (absorbs rounding of rotated corners).
TOUCH_TOLERANCE: Final = 1e-9
#: Slack (m) on the bounding circles whose distance bounds the footprints' from below (more than any
#: rounding of theirs): only where that bound is below the least distance so far is the exact one computed.
BOUND_MARGIN: Final = 1e-6
#: Lane width (m) assumed for the "same lane" test of entities without lane coordinates.
LANE_WIDTH: Final = 3.5
#: Time headway is only sampled while the ego is faster than this (m/s).
HEADWAY_MIN_SPEED: Final = 0.1
#: Time to collision is only sampled while the closing speed is above this (m/s).
TTC_MIN_CLOSING_SPEED: Final = 0.01

#: Every metric name this module (or the runner, for `stopTriggered`) can produce, with what it means
#: when it is absent from `result()`.
METRICS: dict[str, str] = {
    "collision": "no frame with an ego was recorded",
    "collisionTime": "the ego never collided",
    "minDistance": "there was never another entity besides the ego",
    "minTimeHeadway": (
        f"there was never an entity ahead of the ego in its lane while the ego moved faster than "
        f"{HEADWAY_MIN_SPEED} m/s"
    ),
    "minTimeToCollision": (
        f"the ego never closed in (faster than {TTC_MIN_CLOSING_SPEED} m/s) on an entity ahead in its lane"
    ),
    "minLateralDistance": "no entity was ever side by side with the ego",
    "maxDeceleration": "no frame with an ego was recorded",
    "maxAcceleration": "no frame with an ego was recorded",
    "maxSpeed": "no frame with an ego was recorded",
    "meanSpeed": "no frame with an ego was recorded",
    "egoDistance": "no frame with an ego was recorded",
    "simSeconds": "no frame was recorded",
    "stopTriggered": "the runner did not report how the run ended",
    # spec.v2x (simcore/v2x/metrics.py)
    "v2x.packetDeliveryRatio": "V2X is off (spec.v2x) or no message went between two stations",
    "v2x.ageOfInformation.mean": "V2X is off or no station received a message",
    "v2x.ageOfInformation.max": "V2X is off or no station received a message",
    "v2x.cpmObjectCoverage": "V2X is off, there is no ego, or its own sensors never missed a nearby object",
    "v2x.cpmObjectsFromV2xOnly": "V2X is off",
    "v2x.hazardToFirstDenm": "V2X is off, no other station had a hazard, or no hazard DENM reached the ego",
    "v2x.hazards": "V2X is off",
    "v2x.hazardsMissed": "V2X is off",
    "v2x.messages.cam": "V2X is off",
    "v2x.messages.cpm": "V2X is off",
    "v2x.messages.denm": "V2X is off",
}
KNOWN_METRICS = frozenset(METRICS)


#: the fields of `Box`, in order
BOX_FIELDS: Final = ("x0", "y0", "x1", "y1", "x2", "y2", "x3", "y3", "fx", "fy", "lx", "ly")


@final
class Box(Value):
    """A ground-plane footprint: four corners, counter-clockwise from front-left ((x0, y0) … (x3, y3)), and
    the two unit axes of the box, forward (fx, fy) and left (lx, ly). The axes come from the heading, so
    they stay valid for degenerate (zero length or width) boxes, and they are the separating-axis
    candidates of the box. Plain float fields, so that the compiled overlap and distance tests read them
    without unpacking; `corners` and `axes` give them as points."""

    __slots__ = BOX_FIELDS
    FIELDS: ClassVar[tuple[str, ...]] = BOX_FIELDS
    x0: Final[float]
    y0: Final[float]
    x1: Final[float]
    y1: Final[float]
    x2: Final[float]
    y2: Final[float]
    x3: Final[float]
    y3: Final[float]
    fx: Final[float]
    fy: Final[float]
    lx: Final[float]
    ly: Final[float]

    def __init__(
        self,
        x0: float,
        y0: float,
        x1: float,
        y1: float,
        x2: float,
        y2: float,
        x3: float,
        y3: float,
        fx: float,
        fy: float,
        lx: float,
        ly: float,
    ) -> None:
        self.x0 = x0
        self.y0 = y0
        self.x1 = x1
        self.y1 = y1
        self.x2 = x2
        self.y2 = y2
        self.x3 = x3
        self.y3 = y3
        self.fx = fx
        self.fy = fy
        self.lx = lx
        self.ly = ly

    @staticmethod
    def of_points(corners: Sequence[Point], axes: Sequence[Point]) -> Box:
        """The box of four corners (counter-clockwise) and its (forward, left) axes."""
        (x0, y0), (x1, y1), (x2, y2), (x3, y3) = corners
        (fx, fy), (lx, ly) = axes
        return Box(x0, y0, x1, y1, x2, y2, x3, y3, fx, fy, lx, ly)

    @staticmethod
    def of(entity: EntityState) -> Box:
        b = entity.bbox
        return footprint(entity.x, entity.y, entity.heading, b.center_x, b.center_y, b.length, b.width)

    @property
    def corners(self) -> tuple[Point, Point, Point, Point]:
        return (self.x0, self.y0), (self.x1, self.y1), (self.x2, self.y2), (self.x3, self.y3)

    @property
    def axes(self) -> tuple[Point, Point]:
        return (self.fx, self.fy), (self.lx, self.ly)

    def values(self) -> tuple[float, ...]:
        """The fields, in order."""
        return (
            self.x0,
            self.y0,
            self.x1,
            self.y1,
            self.x2,
            self.y2,
            self.x3,
            self.y3,
            self.fx,
            self.fy,
            self.lx,
            self.ly,
        )

    def __repr__(self) -> str:
        return f"Box(corners={self.corners!r}, axes={self.axes!r})"


freeze(Box)


def footprint(
    x: float, y: float, heading: float, center_x: float, center_y: float, length: float, width: float
) -> Box:
    """The footprint of a box centred (`center_x`, `center_y`) from a reference point (x, y) in the frame of
    `heading`: the corners `EntityState.corners()` gives, with the box's axes."""
    x0, y0, x1, y1, x2, y2, x3, y3, c, s = corner_coordinates(
        x, y, heading, center_x, center_y, length, width
    )
    return Box(x0, y0, x1, y1, x2, y2, x3, y3, c, s, -s, c)


def _least_greatest(v0: float, v1: float, v2: float, v3: float) -> tuple[float, float]:
    """`min(v0, v1, v2, v3)` and `max(v0, v1, v2, v3)` as the built-ins take them (the first of equals),
    written out: compiled, no float is boxed (the built-ins of four arguments stay Python calls)."""
    least = greatest = v0
    if v1 < least:
        least = v1
    if v1 > greatest:
        greatest = v1
    if v2 < least:
        least = v2
    if v2 > greatest:
        greatest = v2
    if v3 < least:
        least = v3
    if v3 > greatest:
        greatest = v3
    return least, greatest


def projections(a: Box, b: Box, ax: float, ay: float) -> tuple[float, float, float, float]:
    """(least, greatest) projection of a's corners on the axis (ax, ay), then b's."""
    p_lo, p_hi = _least_greatest(
        a.x0 * ax + a.y0 * ay, a.x1 * ax + a.y1 * ay, a.x2 * ax + a.y2 * ay, a.x3 * ax + a.y3 * ay
    )
    q_lo, q_hi = _least_greatest(
        b.x0 * ax + b.y0 * ay, b.x1 * ax + b.y1 * ay, b.x2 * ax + b.y2 * ay, b.x3 * ax + b.y3 * ay
    )
    return p_lo, p_hi, q_lo, q_hi


def _axis_gap(a: Box, b: Box, ax: float, ay: float) -> float:
    """Gap between the projections of the boxes on the axis (negative when they overlap on it)."""
    p_lo, p_hi, q_lo, q_hi = projections(a, b, ax, ay)
    gap, other = q_lo - p_hi, p_lo - q_hi
    return other if other > gap else gap  # max(gap, other)


def separation(a: Box, b: Box) -> float:
    """Largest gap between the projections of `a` and `b` on the four candidate separating axes.

    Positive: the boxes are disjoint and at least that far apart (a lower bound of `box_distance`).
    Zero or negative: no candidate axis separates them: they touch or overlap (separating-axis theorem)."""
    gap = _axis_gap(a, b, a.fx, a.fy)  # the max of the four, as the built-in takes it (unrolled, unboxed)
    other = _axis_gap(a, b, a.lx, a.ly)
    if other > gap:
        gap = other
    other = _axis_gap(a, b, b.fx, b.fy)
    if other > gap:
        gap = other
    other = _axis_gap(a, b, b.lx, b.ly)
    return other if other > gap else gap


def boxes_overlap(a: Box, b: Box) -> bool:
    """Whether the boxes overlap or touch (within `TOUCH_TOLERANCE`): the separating-axis test.
    Equivalent to `separation(a, b) <= TOUCH_TOLERANCE`, stopping at the first separating axis."""
    return (
        _axis_gap(a, b, a.fx, a.fy) <= TOUCH_TOLERANCE
        and _axis_gap(a, b, a.lx, a.ly) <= TOUCH_TOLERANCE
        and _axis_gap(a, b, b.fx, b.fy) <= TOUCH_TOLERANCE
        and _axis_gap(a, b, b.lx, b.ly) <= TOUCH_TOLERANCE
    )


def _disjoint_distance(a: Box, b: Box) -> float:
    """Distance between two disjoint convex polygons: the nearest pair is a vertex of one and an edge
    of the other (squared distances compared, one square root)."""
    best = math.inf
    for p, q in ((a, b), (b, a)):
        best = _edge_to_corners(best, q.x3, q.y3, q.x0, q.y0, p)
        best = _edge_to_corners(best, q.x0, q.y0, q.x1, q.y1, p)
        best = _edge_to_corners(best, q.x1, q.y1, q.x2, q.y2, p)
        best = _edge_to_corners(best, q.x2, q.y2, q.x3, q.y3, p)
    return math.sqrt(best)


def _edge_to_corners(best: float, x0: float, y0: float, x1: float, y1: float, p: Box) -> float:
    """The least of `best` and the squared distances from the corners of `p` to the edge (x0, y0)-(x1, y1)."""
    dx, dy = x1 - x0, y1 - y0
    length2 = dx * dx + dy * dy
    best = _to_edge(best, p.x0, p.y0, x0, y0, x1, y1, dx, dy, length2)
    best = _to_edge(best, p.x1, p.y1, x0, y0, x1, y1, dx, dy, length2)
    best = _to_edge(best, p.x2, p.y2, x0, y0, x1, y1, dx, dy, length2)
    return _to_edge(best, p.x3, p.y3, x0, y0, x1, y1, dx, dy, length2)


def _to_edge(
    best: float,
    px: float,
    py: float,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    dx: float,
    dy: float,
    length2: float,
) -> float:
    """The lesser of `best` and the squared distance from (px, py) to the edge from (x0, y0) to (x1, y1)
    (direction (dx, dy), squared length `length2`)."""
    rx, ry = px - x0, py - y0
    if length2 > 0.0:
        t = (rx * dx + ry * dy) / length2
        if t > 1.0:
            rx, ry = px - x1, py - y1
        elif t > 0.0:
            rx, ry = rx - t * dx, ry - t * dy
    d2 = rx * rx + ry * ry
    return d2 if d2 < best else best


def box_distance(a: Box, b: Box) -> float:
    """Free-space distance between two boxes: 0 when they overlap or touch (`boxes_overlap`), else the
    Euclidean distance between their nearest points (> `TOUCH_TOLERANCE`)."""
    if boxes_overlap(a, b):
        return 0.0
    return _disjoint_distance(a, b)


class MetricsAccumulator:
    """Accumulates the run metrics frame by frame in constant memory (see the module docstring)."""

    __slots__ = (
        "_collision",
        "_collision_entities",
        "_collision_time",
        "_collision_with",
        "_distance",
        "_first_time",
        "_has_ego",
        "_lane_width",
        "_max_acc",
        "_max_dec",
        "_max_speed",
        "_min_distance",
        "_min_distance_with",
        "_min_lateral",
        "_min_thw",
        "_min_thw_with",
        "_min_ttc",
        "_min_ttc_with",
        "_prev_speed",
        "_prev_time",
        "_prev_x",
        "_prev_y",
        "_sim_seconds",
        "_speed_integral",
    )

    def __init__(self, lane_width: float = LANE_WIDTH) -> None:
        if not lane_width > 0:
            raise ValueError(f"lane_width must be positive, not {lane_width!r}")
        self._lane_width = lane_width
        self._sim_seconds: float | None = None
        self._has_ego = False
        self._first_time = 0.0
        # time, x, y, |speed| of the ego in the last frame (`_has_ego`: there was one)
        self._prev_time = self._prev_x = self._prev_y = self._prev_speed = 0.0
        self._distance = 0.0
        self._speed_integral = 0.0
        self._max_speed = 0.0
        self._max_acc = 0.0
        self._max_dec = 0.0
        self._collision = False
        self._collision_time: float | None = None
        self._collision_with: str | None = None
        self._collision_entities: dict[str, None] = {}  # insertion-ordered set, bounded by the entities
        self._min_distance = math.inf
        self._min_distance_with: str | None = None
        self._min_thw = math.inf
        self._min_thw_with: str | None = None
        self._min_ttc = math.inf
        self._min_ttc_with: str | None = None
        self._min_lateral = math.inf

    @staticmethod
    def _ego(frame: WorldFrame) -> EntityState:
        if frame.ego is None:
            return frame.entities[0]
        for entity in frame.entities:
            if entity.name == frame.ego:
                return entity
        raise ValueError(
            f"the ego {frame.ego!r} is not among the entities of the frame at t={frame.time:g} s "
            f"(step {frame.step}): {', '.join(e.name for e in frame.entities)}"
        )

    def update(self, frame: WorldFrame) -> None:
        """Takes the next frame (frames in time order)."""
        t = frame.time
        self._sim_seconds = t
        if not frame.entities:
            return
        ego = self._ego(frame)

        # Ego kinematics.
        speed = abs(ego.speed)
        if not self._has_ego:
            self._first_time = t
        else:
            self._distance += hypot(ego.x - self._prev_x, ego.y - self._prev_y)
            self._speed_integral += 0.5 * (self._prev_speed + speed) * (t - self._prev_time)
        self._prev_time, self._prev_x, self._prev_y, self._prev_speed = t, ego.x, ego.y, speed
        self._has_ego = True
        if speed > self._max_speed:
            self._max_speed = speed
        acc = ego.acceleration
        if acc > self._max_acc:
            self._max_acc = acc
        if -acc > self._max_dec:
            self._max_dec = -acc

        # Ego geometry, in its own frame: f forward, l left, around the box centre (the centres are the
        # floats `EntityState.box_center()` gives)
        h = ego.heading
        fx, fy = math.cos(h), math.sin(h)
        bbox = ego.bbox
        bx, by = bbox.center_x, bbox.center_y
        ex, ey = ego.x + fx * bx - fy * by, ego.y + fy * bx + fx * by
        e_hl, e_hw = bbox.length / 2, bbox.width / 2
        # the bounding circle's radius, a bit wide (`lower` below stays a lower bound whatever the rounding)
        e_radius = math.sqrt(e_hl * e_hl + e_hw * e_hw) + BOUND_MARGIN
        e_speed = ego.speed
        e_lane = ego.lane
        half_lane = self._lane_width / 2
        ego_box: Box | None = None

        for other in frame.entities:
            if other is ego:
                continue
            o_heading = other.heading
            oc, os = math.cos(o_heading), math.sin(o_heading)
            bbox = other.bbox
            bx, by = bbox.center_x, bbox.center_y
            dx, dy = (other.x + oc * bx - os * by) - ex, (other.y + os * bx + oc * by) - ey
            o_hl, o_hw = bbox.length / 2, bbox.width / 2

            # Collision and distance; the bounding circles give a cheap lower bound of the distance.
            lower = math.sqrt(dx * dx + dy * dy) - e_radius - math.sqrt(o_hl * o_hl + o_hw * o_hw)
            if lower <= TOUCH_TOLERANCE or lower < self._min_distance:
                if ego_box is None:
                    ego_box = Box.of(ego)
                other_box = Box.of(other)
                gap = separation(ego_box, other_box)  # <= TOUCH_TOLERANCE: overlap; else <= the distance
                if gap <= TOUCH_TOLERANCE:
                    distance = 0.0
                    if not self._collision:
                        self._collision = True
                        self._collision_time = t
                        self._collision_with = other.name
                    self._collision_entities.setdefault(other.name, None)
                elif gap < self._min_distance:
                    distance = _disjoint_distance(ego_box, other_box)
                else:
                    distance = math.inf
                if distance < self._min_distance:
                    self._min_distance = distance
                    self._min_distance_with = other.name

            # Longitudinal / lateral position and extents of the other box in the ego's frame.
            lon = dx * fx + dy * fy
            lat = dy * fx - dx * fy
            rel = o_heading - h
            cr, sr = math.cos(rel), abs(math.sin(rel))
            acr = abs(cr)
            o_lon = o_hl * acr + o_hw * sr
            o_lat = o_hl * sr + o_hw * acr

            if abs(lon) < o_lon + e_hl:  # side by side
                lateral = abs(lat) - o_lat - e_hw
                if lateral < self._min_lateral:
                    self._min_lateral = max(lateral, 0.0)

            if lon <= 0.0:
                continue
            o_lane = other.lane
            if e_lane is not None and o_lane is not None:
                if o_lane.road_id != e_lane.road_id or o_lane.lane_id != e_lane.lane_id:
                    continue
            elif abs(lat) > half_lane:
                continue
            gap = max(lon - o_lon - e_hl, 0.0)
            if e_speed > HEADWAY_MIN_SPEED:
                thw = gap / e_speed
                if thw < self._min_thw:
                    self._min_thw = thw
                    self._min_thw_with = other.name
            closing = e_speed - other.speed * cr
            if closing > TTC_MIN_CLOSING_SPEED:
                ttc = gap / closing
                if ttc < self._min_ttc:
                    self._min_ttc = ttc
                    self._min_ttc_with = other.name

    def result(self) -> dict[str, float]:
        """The metrics so far; a metric that was never defined is absent (see the module docstring)."""
        out: dict[str, float] = {}
        if self._has_ego:
            out["collision"] = 1.0 if self._collision else 0.0
            if self._collision_time is not None:
                out["collisionTime"] = float(self._collision_time)
            if self._min_distance < math.inf:
                out["minDistance"] = self._min_distance
            if self._min_thw < math.inf:
                out["minTimeHeadway"] = self._min_thw
            if self._min_ttc < math.inf:
                out["minTimeToCollision"] = self._min_ttc
            if self._min_lateral < math.inf:
                out["minLateralDistance"] = self._min_lateral
            out["maxDeceleration"] = float(self._max_dec)
            out["maxAcceleration"] = float(self._max_acc)
            out["maxSpeed"] = float(self._max_speed)
            duration = self._prev_time - self._first_time
            out["meanSpeed"] = float(self._speed_integral / duration if duration > 0 else self._prev_speed)
            out["egoDistance"] = float(self._distance)
        if self._sim_seconds is not None:
            out["simSeconds"] = float(self._sim_seconds)
        return out

    def details(self) -> dict[str, str | list[str]]:
        """Non-numeric facts: `collisionWith` (the entity hit first), `collisionEntities` (every entity
        hit, in order of first contact), `minDistanceWith`, `minTimeHeadwayWith`, `minTimeToCollisionWith`
        (the entity each minimum was measured against); each only when defined."""
        out: dict[str, str | list[str]] = {}
        if self._collision_with is not None:
            out["collisionWith"] = self._collision_with
            out["collisionEntities"] = list(self._collision_entities)
        if self._min_distance_with is not None:
            out["minDistanceWith"] = self._min_distance_with
        if self._min_thw_with is not None:
            out["minTimeHeadwayWith"] = self._min_thw_with
        if self._min_ttc_with is not None:
            out["minTimeToCollisionWith"] = self._min_ttc_with
        return out
