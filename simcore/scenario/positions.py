"""Where OpenSCENARIO positions are: world poses of every position type (lane, road, relative, route,
trajectory), routes through the road network, and the road coordinates of entities moved in world
coordinates. Pure functions of the road network and the entities' state (`ScenarioWorld`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario import paths
from simcore.scenario.motion import UNPOSED, along_lane, lane_shift, wrap_angle
from simcore.scenario.world import Pose

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld
    from simcore.world.opendrive import OpenDrive


def resolve(world: ScenarioWorld, position: m.Position, for_body: Body | None = None) -> Pose:
    """World (x, y, z, heading) of a position."""
    road = world.road

    def need_road() -> OpenDrive:
        if road is None:
            raise BadInput(
                f"{type(position).__name__} needs a road network (RoadNetwork/LogicFile)",
                file=world.source,
            )
        return road

    def orient(base: float, orientation: m.Orientation | None) -> float:
        if orientation is None:
            return base
        return orientation.h if orientation.type == "absolute" else wrap_angle(base + orientation.h)

    try:
        if isinstance(position, m.WorldPosition):
            z = position.z if position.z is not None else 0.0
            return position.x, position.y, z, position.h if position.h is not None else 0.0
        if isinstance(position, m.LanePosition):
            r = need_road()
            road_id, lane_id, s_on = walk_lane(r, position.road_id, position.lane_id, position.s)
            if (road_id, lane_id, s_on) != (position.road_id, position.lane_id, position.s):
                # beyond the road's ends: on along the lane's links (the position keeps its lane)
                length = r.road_length(road_id)
                if not 0.0 <= s_on <= length:
                    message = (
                        f"{position.source or world.source}: LanePosition: road {position.road_id} "
                        f"s={position.s:g} lies beyond "
                        f"the lanes' links: placed at the end of road {road_id}"
                    )
                    if message not in world.warnings:
                        world.warnings.append(message)
                    s_on = min(max(s_on, 0.0), length)
                pose = r.lane_to_world(road_id, lane_id, s_on, position.offset)
                return pose.x, pose.y, pose.z, wrap_angle(orient(pose.heading, position.orientation))
            length = r.road_length(position.road_id)
            s_on = position.s
            if not 0.0 <= s_on <= length:
                # beyond the end of a road with no link there: at its end (esmini runs such files too)
                message = (
                    f"{position.source or world.source}: LanePosition: road {position.road_id} "
                    f"s={position.s:g} lies beyond the road's end: placed at s={min(max(s_on, 0.0), length):g}"
                )
                if message not in world.warnings:
                    world.warnings.append(message)
                s_on = min(max(s_on, 0.0), length)
            pose = r.lane_to_world(position.road_id, position.lane_id, s_on, position.offset)
            # relative orientation is relative to the lane's driving direction (as esmini does)
            backward = r.drives_backward(position.road_id, position.lane_id)
            base = pose.heading + (math.pi if backward else 0.0)
            return pose.x, pose.y, pose.z, wrap_angle(orient(base, position.orientation))
        if isinstance(position, m.RoadPosition):
            r = need_road()
            pose = r.road_to_world(position.road_id, position.s, position.t)
            return pose.x, pose.y, pose.z, wrap_angle(orient(pose.heading, position.orientation))
        if isinstance(position, m.TrajectoryPosition):
            base_pose = (0.0, 0.0, 0.0, 0.0)
            if for_body is not None:
                base_pose = (for_body.x, for_body.y, for_body.z, for_body.heading)
            path = paths.sample(position.trajectory, world.resolve_position, base_pose)
            x, y, z, h = path.at(position.s)
            x -= position.t * math.sin(h)
            y += position.t * math.cos(h)
            return x, y, z, wrap_angle(orient(h, position.orientation))
        if isinstance(position, m.RoutePosition):
            if position.entity is not None:
                ref = world.body(position.entity)
                return ref.x, ref.y, ref.z, orient(ref.heading, position.orientation)
            r = need_road()
            assert position.route is not None
            road_id, s_on, direction = route_point(world, position.route, position.path_s or 0.0)
            if position.lane_id is not None:
                pose = r.lane_to_world(road_id, position.lane_id, s_on, position.lane_offset)
            else:
                pose = r.road_to_world(road_id, s_on, position.t)
            if position.lane_id is not None:
                # in a lane: facing the lane's driving direction whichever way the route runs, and an
                # Orientation relative to it (as esmini's RoutePosition, like a LanePosition)
                backward = r.drives_backward(road_id, position.lane_id)
                base = pose.heading + (math.pi if backward else 0.0)
            elif position.orientation is None:
                base = pose.heading + (math.pi if direction < 0 else 0.0)  # along the route
            else:
                base = pose.heading  # relative to the road's s direction (as a RoadPosition's)
            return pose.x, pose.y, pose.z, wrap_angle(orient(base, position.orientation))
        ref = world.body(position.entity)
        if isinstance(position, m.RelativeWorldPosition):
            return (
                ref.x + position.dx,
                ref.y + position.dy,
                ref.z + position.dz,
                orient(ref.heading, position.orientation),
            )
        if isinstance(position, m.RelativeObjectPosition):
            c, s = math.cos(ref.heading), math.sin(ref.heading)
            return (
                ref.x + c * position.dx - s * position.dy,
                ref.y + s * position.dx + c * position.dy,
                ref.z + position.dz,
                orient(ref.heading, position.orientation),
            )
        r = need_road()
        if ref.road_id is None:
            raise BadInput(
                f"{type(position).__name__}: entity {ref.name!r} is not on a road", file=world.source
            )
        if isinstance(position, m.RelativeLanePosition):
            # ds along the road's s whichever way the entity travels, dLane and offset across the road's
            # direction, facing the road's s; dsLane along the lane in the entity's travel direction, dLane
            # and offset across it, facing it (as esmini). Beyond the end of the road it goes on along the
            # lane onto the next road
            start = ref.direction if position.along_lane else 1
            road_id, lane_id, s_new, direction = along_lane(
                r, ref.road_id, ref.lane_id, ref.s, start, position.ds
            )
            if direction != start:
                # onto a road that runs the other way: esmini keeps the lane id and the s direction of the
                # road it started on (the mirrored lane, facing the other way)
                lane_id, direction = -lane_id, -direction
            world.memo[("road_hint", id(position))] = (
                road_id  # where it is, for a teleport (junctions overlap)
            )
            lane = lane_shift(r, road_id, s_new, lane_id, position.d_lane, direction)
            pose = r.lane_to_world(road_id, lane, s_new, position.offset * direction)
            if position.along_lane and lane != lane_id:
                # dsLane into another lane: facing that lane's driving direction
                direction = -1 if r.drives_backward(road_id, lane) else 1
            base = pose.heading + (math.pi if direction < 0 else 0.0)
            return pose.x, pose.y, pose.z, wrap_angle(orient(base, position.orientation))
        if isinstance(position, m.RelativeRoadPosition):
            t_ref = r.lane_center_t(ref.road_id, ref.lane_id, ref.s) + ref.offset
            road_id, lane_id, s_new, direction = along_lane(
                r, ref.road_id, ref.lane_id, ref.s, 1, position.ds
            )
            world.memo[("road_hint", id(position))] = road_id
            if road_id != ref.road_id:
                # onto another road: t keeps its distance from the lane's centre (t flips with s direction)
                t_ref = r.lane_center_t(road_id, lane_id, s_new) + ref.offset * direction
                pose = r.road_to_world(road_id, s_new, t_ref + position.dt)
                return pose.x, pose.y, pose.z, wrap_angle(orient(pose.heading, position.orientation))
            pose = r.road_to_world(ref.road_id, ref.s + position.ds, t_ref + position.dt)
            return pose.x, pose.y, pose.z, wrap_angle(orient(pose.heading, position.orientation))
    except (KeyError, ValueError) as exc:
        # the position's own file:line when the scenario gave it one
        where = getattr(position, "source", "") or world.source
        raise BadInput(f"{type(position).__name__}: {exc}", file=where) from None
    raise BadInput(f"position {type(position).__name__} is not supported", file=world.source)


def route_point(world: ScenarioWorld, route: m.Route, path_s: float) -> tuple[str, float, int]:
    """(road, s, direction) `path_s` metres along a route from its first waypoint."""
    road = world.road
    assert road is not None
    points = []
    for waypoint in route.waypoints:
        x, y, _, h = world.resolve_position(waypoint.position)
        rc = road.world_to_road(x, y, None, road_hint=getattr(waypoint.position, "road_id", None))
        if rc is None:
            raise BadInput(f"route {route.name!r}: a waypoint is on no road", file=world.source)
        points.append((rc, 1 if math.cos(h - rc.heading) >= 0 else -1))
    first, direction = points[0]
    legs: list[tuple[str, int]] = [(first.road_id, direction)]
    for rc, _ in points[1:]:
        leg = paths.plan(road, legs[-1], rc.road_id)
        if leg is None:
            raise BadInput(f"route {route.name!r}: no way to road {rc.road_id}", file=world.source)
        legs.extend(leg[1:])
    s_on = first.s
    remaining = path_s
    for i, (road_id, d) in enumerate(legs):
        length = road.road_length(road_id)
        if i > 0:
            s_on = 0.0 if d > 0 else length
        room = (length - s_on) if d > 0 else s_on
        if remaining <= room or i == len(legs) - 1:
            return road_id, min(max(s_on + d * remaining, 0.0), length), d
        remaining -= room
    return legs[-1][0], s_on, legs[-1][1]


def plan_route(world: ScenarioWorld, body: Body, targets: list[m.Position]) -> list[tuple[str, int]]:
    """The roads (id, direction) a body drives through to pass every target position in order."""
    road = world.road
    if road is None or body.road_id is None:
        return []
    state = (body.road_id, body.direction)
    lane, s_on = body.lane_id, body.s
    out: list[tuple[str, int]] = []
    for position in targets:
        x, y, _, _ = world.resolve_position(position)
        hint = getattr(position, "road_id", None)
        rc = road.world_to_road(x, y, None, road_hint=hint)
        if rc is None:
            continue
        target_lane = position.lane_id if isinstance(position, m.LanePosition) else rc.lane_id
        target_s = position.s if isinstance(position, m.LanePosition) else rc.s
        if state[0] == rc.road_id and not out:
            lane, s_on = target_lane, target_s
            continue
        # esmini plans a route's legs lane by lane (from the lane of the leg's start): a road its lanes do
        # not lead to makes the route invalid, and its entities drive on without one
        leg = paths.plan_in_lane(road, state, lane, rc.road_id, s_on)
        if leg is None:
            world.warnings.append(
                f"{world.source}: route of {body.name!r}: no way in lane {lane} to road {rc.road_id}: "
                "the route is ignored (as esmini does)"
            )
            return []
        out.extend(leg[1:])
        state = leg[-1]
        lane, s_on = target_lane, target_s
    return out


#: positions that depend on no entity
_FIXED_POSITIONS: Final = (m.WorldPosition, m.LanePosition, m.RoadPosition)


def fixed_point(world: ScenarioWorld, position: m.Position) -> Pose:
    """World pose of a condition's position: computed once when it depends on no entity."""
    if isinstance(position, _FIXED_POSITIONS):
        key = id(position)
        cached = world.memo.get(("fixed_point", key))
        if cached is None:
            cached = world.memo[("fixed_point", key)] = (position, world.resolve_position(position))
        return cached[1]
    return world.resolve_position(position)


def walk_lane(road: OpenDrive, road_id: str, lane_id: int, s: float) -> tuple[str, int, float]:
    """A lane position past a road's end continued along the lane's successors (before its start, along
    its predecessors)."""
    for _ in range(32):
        if road_id not in road.roads:
            return road_id, lane_id, s
        length = road.road_length(road_id)
        if 0.0 <= s <= length:
            return road_id, lane_id, s
        direction = 1 if s > length else -1
        nxt = road.successor(road_id, lane_id, direction)
        if nxt is None:
            return road_id, lane_id, s
        over = s - length if direction > 0 else -s
        road_id, lane_id, new_dir = nxt
        s = over if new_dir > 0 else road.road_length(road_id) - over
    return road_id, lane_id, s


def _nearest_road_point(road: OpenDrive, body: Body) -> tuple[str, int, float, float, float, float] | None:
    """The road point under a body, ``(road, lane, s, t, offset, reference heading)``: near its last road
    position first, else anywhere."""
    road_id = body.road_id
    if road_id is not None:
        near = road.near_lane(body.x, body.y, road_id, body.s)
        if near is not None:
            return (road_id, *near)
    return _road_point_anywhere(road, body)


def _road_point_anywhere(road: OpenDrive, body: Body) -> tuple[str, int, float, float, float, float] | None:
    """`_nearest_road_point` searched on every road (its last road preferred where roads overlap)."""
    rc = road.world_to_road(body.x, body.y, None, road_hint=body.road_id)
    return None if rc is None else (rc.road_id, rc.lane_id, rc.s, rc.t, rc.offset, rc.heading)


def locate(road: OpenDrive | None, body: Body) -> None:
    """Road coordinates (road, lane, s, offset, direction, z) of a body moved in world coordinates."""
    if road is None:
        return
    last = body.road_id
    near = None if last is None else road.near_lane(body.x, body.y, last, body.s)
    if last is not None and near is not None:  # on its road still (`_nearest_road_point`, without a tuple)
        road_id = last
        lane_id, s, t, offset, heading = near
    else:
        point = _road_point_anywhere(road, body)
        if point is None:
            return
        road_id, lane_id, s, t, offset, heading = point
    body.road_id, body.lane_id, body.s, body.offset = road_id, lane_id, s, offset
    body.direction = 1 if math.cos(body.heading - heading) >= 0 else -1
    body.z = road.road_z(road_id, s, t)


def track(road: OpenDrive | None, body: Body, lock_lane: bool = False) -> None:
    """Road coordinates of a body moved freely (a trajectory): its lane, s and offset from x/y. With
    `lock_lane` the body follows that lane afterwards, in the direction it is heading."""
    if road is None:
        return
    point = _nearest_road_point(road, body)
    if point is None:
        body.road_id = None
        return
    body.road_id, body.lane_id, body.s, _, body.offset, heading = point
    body.direction = 1 if math.cos(body.heading - heading) >= 0 else -1
    body.heading_offset = 0.0
    body.posed = UNPOSED
    if lock_lane:
        body.lateral_velocity = 0.0
