"""What esmini's controllers read of an entity's road position (roadmanager::Position) and of two entities'
relation on the road, computed from a body: its t, lane and lane offset, its heading relative to the road,
its velocity and acceleration along the road's s and t axes, the freespace distance between two bounding
boxes in road coordinates and the overlap of a bounding box with another's front line."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from simcore.scenario.motion import lane_point, reference_heading, wrap_angle
from simcore.world.native_calls import hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld

SMALL = 1e-10  # esmini's SMALL_NUMBER
LARGE = 1e10  # esmini's LARGE_NUMBER


def sign(value: float) -> float:
    """esmini's SIGN: -1 for negative values, else 1."""
    return -1.0 if value < 0 else 1.0


@dataclass(frozen=True)
class RoadPose:
    """An entity's road position as esmini's Position holds it."""

    road_id: str
    s: float
    t: float
    lane_id: int  # the lane its reference point is in now (changes mid lane change)
    offset: float  # from that lane's centre, + toward +t
    road_heading: float  # the reference line's heading at s
    h_relative: float  # the entity's heading relative to the road's s direction, in [-pi, pi)
    vel_s: float  # velocity along the road's s axis (over the last step), m/s
    vel_t: float  # across it (+ toward +t), m/s
    acc_s: float  # acceleration along the s axis, m/s²


def road_pose(world: ScenarioWorld, body: Body) -> RoadPose | None:
    """The entity's road position (None off every road)."""
    road = world.road
    if road is None or body.road_id is None or body.road_id not in road.roads:
        return None
    r = road.road(body.road_id)
    s = min(max(body.s, 0.0), r.length)
    t, lane, offset = lane_point(road, body.road_id, body.lane_id, s, body.offset)
    h_road = reference_heading(r, body, s)
    c, sn = math.cos(h_road), math.sin(h_road)
    vx, vy = body.vx, body.vy  # over the last step (0 before the first, as esmini's)
    # along s: the change of the velocity over the last step (from displacements, as esmini's)
    pvx, pvy = body.previous_velocity
    acc_s = ((vx - pvx) * c + (vy - pvy) * sn) / world.dt
    return RoadPose(
        road_id=body.road_id,
        s=s,
        t=t,
        lane_id=lane,
        offset=offset,
        road_heading=h_road,
        h_relative=wrap_angle(body.heading - h_road),
        vel_s=vx * c + vy * sn,
        vel_t=-vx * sn + vy * c,
        acc_s=acc_s,
    )


def _extents(body: Body, h_relative: float) -> tuple[float, float, float, float]:
    """(min Δs, max Δs, min Δt, max Δt) of the bounding box's corners from the reference point, along the
    road's axes (the road taken as straight across the box)."""
    box = body.entity.box
    c, s = math.cos(h_relative), math.sin(h_relative)
    xs, ys = [], []
    for dx in (box.center_x - box.length / 2, box.center_x + box.length / 2):
        for dy in (box.center_y - box.width / 2, box.center_y + box.width / 2):
            xs.append(c * dx - s * dy)
            ys.append(s * dx + c * dy)
    return min(xs), max(xs), min(ys), max(ys)


def freespace_road(
    a: Body, pose_a: RoadPose, b: Body, pose_b: RoadPose, delta: tuple[float, float]
) -> tuple[float, float]:
    """esmini's Object::FreeSpaceDistanceObjectRoadLane in road coordinates: (longitudinal, lateral) gaps
    between the two bounding boxes along the road's s and t axes, given the reference points' road delta
    (ds, dt) in a's driving direction. Both are signed (+: b ahead, b to the left in a's driving direction)
    and 0 where the boxes' projections overlap."""
    d = 1.0 if a.direction >= 0 else -1.0
    a0, a1, at0, at1 = _extents(a, pose_a.h_relative)
    b0, b1, bt0, bt1 = _extents(b, pose_b.h_relative)
    # into a's driving direction frame
    a_s = sorted((d * a0, d * a1))
    a_t = sorted((d * at0, d * at1))
    b_s = sorted((delta[0] + d * b0, delta[0] + d * b1))
    b_t = sorted((delta[1] + d * bt0, delta[1] + d * bt1))
    if b_s[0] > a_s[1]:
        ds = b_s[0] - a_s[1]
    elif b_s[1] < a_s[0]:
        ds = b_s[1] - a_s[0]
    else:
        ds = 0.0
    if b_t[0] > a_t[1]:
        dt = b_t[0] - a_t[1]
    elif b_t[1] < a_t[0]:
        dt = b_t[1] - a_t[0]
    else:
        dt = 0.0
    return ds, dt


# esmini's Object::OverlapType, in its order (compared with >)
OVERLAP_NONE, OVERLAP_PART, OVERLAP_INSIDE, OVERLAP_FULL, OVERLAP_INSIDE_AND_FULL = range(5)


def overlapping_front(own: Body, target: Body, tolerance: float) -> int:
    """esmini's Object::OverlappingFront: the target's bounding box corners projected on the front line of
    own bounding box: all within (INSIDE), some (PART), beyond both ends (FULL), both (INSIDE_AND_FULL);
    a corner within `tolerance` (m) of an end counts on that end's side, one outside by less counts as
    inside."""
    ob = own.entity.box
    c, s = math.cos(own.heading), math.sin(own.heading)
    fx = ob.center_x + ob.length / 2
    left = (own.x + c * fx - s * (ob.width / 2), own.y + s * fx + c * (ob.width / 2))
    right = (own.x + c * fx + s * (ob.width / 2), own.y + s * fx - c * (ob.width / 2))
    lx, ly = right[0] - left[0], right[1] - left[1]
    width = hypot(lx, ly)
    tb = target.entity.box
    tc, ts = math.cos(target.heading), math.sin(target.heading)
    inside = outside_left = outside_right = 0
    for dx in (tb.center_x + tb.length / 2, tb.center_x - tb.length / 2):
        for dy in (tb.center_y + tb.width / 2, tb.center_y - tb.width / 2):
            px, py = target.x + tc * dx - ts * dy, target.y + ts * dx + tc * dy
            u = ((px - left[0]) * lx + (py - left[1]) * ly) / width if width > 0 else 0.0
            if 0.0 <= u <= width:
                inside += 1
                norm = u / width if width > 0 else 0.0
                if norm * ob.width < tolerance:
                    outside_left += 1
                elif (1 - norm) * ob.width < tolerance:
                    outside_right += 1
            else:
                dist = u if u < 0 else u - width  # from the nearer end: - beyond the left, + the right
                if abs(dist) < tolerance:
                    inside += 1
                if dist < 0:
                    outside_left += 1
                else:
                    outside_right += 1
    if inside == 4 and outside_left and outside_right:
        return OVERLAP_INSIDE_AND_FULL
    if inside == 4:
        return OVERLAP_INSIDE
    if outside_left and outside_right:
        return OVERLAP_FULL
    if inside:
        return OVERLAP_PART
    return OVERLAP_NONE
