"""esmini's FollowRouteController (ControllerFollowRoute.cpp): the entity drives its assigned route lane
independently, changing lanes in time to be in the lane that leads on at every junction. As esmini does it:

- properties (read when the controller is made, i.e. assigned): `laneChangeTime` (default 5 s, the
  sinusoidal lane change's duration), `minDistForCollision` (default 10 m; 0 or less: no check),
  `testMode` (`true`: the entity stops when the controller gives up);
- the path to the next waypoint of the route (its scenario waypoints) is planned by
  `simcore.scenario.controllers.lane_router` from where the entity is when the controller first steps with a
  route; a scenario waypoint on the road the entity is on is skipped (the next one is planned to); no path:
  the controller deactivates (the entity drives on along the route esmini itself planned);
- on a road of the path, when the entity is not in the waypoint's lane and within max(laneChangeTime × speed,
  25 m) of the waypoint (along s), it changes lane — unless a lane change is under way, the lane does not
  exist there or is narrower than 0.5 m, or (with the collision check on) another entity on the same road
  and side, in another lane, is within `minDistForCollision` of it (straight-line distance);
- the lane change starts on the step it is decided (the entity has moved this step already); from the next
  step the lane change moves the entity (speed along the lane, sinusoidal across it) until it ends;
- it works in additive mode: the scenario's speed actions keep setting the speed;
- a waypoint is passed when the entity is beyond it (along its travel direction) in its lane, or on the
  next road having come from it in that lane; beyond it in another lane it is missed and the path is
  planned again from where the entity is. Past the last waypoint the controller deactivates."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Final

from simcore.scenario import model as m
from simcore.scenario.controllers.lane_router import RoadPoint, calculate_path, waypoints
from simcore.scenario.motion import lane_at_t, shape_value
from simcore.world.native_calls import atan2, hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld
    from simcore.world.opendrive import OpenDrive

MIN_LANE_WIDTH: Final = 0.5
PASSED, MISSED, NOT_REACHED = "passed", "missed", "not reached"


def connected_lane(odr: OpenDrive, road_id: str, lane_id: int, s_from: float, s_to: float) -> int:
    """The lane `lane_id` at `s_from` becomes at `s_to` along its lane links (esmini's
    Road::GetConnectedLaneIdAtS); 0 where it ends."""
    road = odr.road(road_id)
    side = 1 if lane_id > 0 else -1
    sections = road.side_sections(side)
    here = road.section_at(s_from, side)
    there = road.section_at(s_to, side)
    i, j = sections.index(here), sections.index(there)
    lane = lane_id
    step = 1 if j >= i else -1
    for k in range(i, j, step):
        current = sections[k].lane(lane)
        if current is None:
            return 0
        link = current.successor if step > 0 else current.predecessor
        if link is None or sections[k + step].lane(link) is None:
            return 0
        lane = link
    return lane


class FollowRouteController:
    """esmini's FollowRouteController on one entity (see the module's doc)."""

    steps_in_init = True  # esmini's first frame steps it (with no time step) when Init activates it

    def __init__(
        self, world: ScenarioWorld, actor: Body, properties: dict[str, str], domains: frozenset[str]
    ) -> None:
        self.world = world
        self.actor = actor
        self.domains = domains
        self.lane_change_time = m.property_number(properties.get("laneChangeTime"), 5.0)
        self.min_dist_for_collision = m.property_number(properties.get("minDistForCollision"), 10.0)
        self.test_mode = properties.get("testMode", "") == "true"
        self.active = True
        self.path_calculated = False
        self.waypoints: list[RoadPoint] = []
        self.index = 0  # the next waypoint
        self.scenario_index = 0  # the route's waypoint planned to
        self.changing_lane = False
        self.lane_change: _RouteLaneChange | None = None
        self._started_at = -1  # the step the lane change started in (the entity already moved in it)
        self._ended_at = -1  # the step the lane change ended in (it moved the entity in it)

    @property
    def moves_itself(self) -> bool:
        """While its lane change runs (from the step after it started, to the one it ended in)."""
        step = self.world.step_index
        if self.lane_change is not None:
            return step != self._started_at
        return step == self._ended_at

    # --- one step -------------------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        body, odr = self.actor, self.world.road
        if not self.active or odr is None or body.road_id is None:
            return
        if not body.route_points:
            return
        if not self.path_calculated:
            self._calculate(odr)
            if not self.active:
                return
        if self.index >= len(self.waypoints):
            self._deactivate("past its last waypoint")
            return
        snapshot = (body.road_id, body.lane_id, body.s, body.direction)
        target = self.waypoints[self.index]
        if target.road_id == body.road_id:
            connected = connected_lane(odr, body.road_id, body.lane_id, body.s, target.s)
            same_lane = target.lane_id in (body.lane_id, connected)
            reach = max(self.lane_change_time * body.speed, 25.0)
            if (
                not same_lane
                and abs(body.s - target.s) < reach
                and self._can_change_lane(odr, target.lane_id)
            ):
                self.lane_change = _RouteLaneChange(self.world, body, target.lane_id, self.lane_change_time)
                self._started_at = -1
                self.changing_lane = True
        self._change_lane(dt)
        self._update_waypoints(odr, snapshot, target)

    def _change_lane(self, dt: float) -> None:
        runtime = self.lane_change
        if runtime is None:
            return
        step = self.world.step_index
        if self._started_at == -1:
            runtime.start()
            # started in esmini's first frame (the controllers step at Init with no time step): it moves
            # the entity from the first step on
            self._started_at = -2 if dt == 0.0 else step
            self.world.log.append(
                f"t={self.world.time:.2f} {self.actor.name}: FollowRoute changes to lane {runtime.target_lane}"
            )
            if runtime.done:  # a zero-time change
                self._end_lane_change(step)
            return
        runtime.step(dt)
        if runtime.done:
            self._end_lane_change(step)

    def _end_lane_change(self, step: int) -> None:
        self.changing_lane = False
        self.lane_change = None
        self._ended_at = step

    def _can_change_lane(self, odr: OpenDrive, lane: int) -> bool:
        body = self.actor
        if self.changing_lane:
            return False
        assert body.road_id is not None
        road = odr.road(body.road_id)
        side = 1 if lane > 0 else -1
        if lane == 0 or road.section_at(body.s, side).lane(lane) is None:
            return False
        if self.min_dist_for_collision <= 0:
            return True
        if odr.lane_width(body.road_id, lane, body.s) < MIN_LANE_WIDTH:
            return False
        for other in self.world.bodies.values():
            if other is body or other.gone or not other.placed:
                continue
            same_road = other.road_id == body.road_id
            same_lane = other.lane_id == body.lane_id
            if same_road and same_lane:
                continue
            near = hypot(other.x - body.x, other.y - body.y) < self.min_dist_for_collision
            same_side = (body.lane_id > 0) == (other.lane_id > 0) and other.lane_id != 0
            if near and same_side and same_road:
                return False
        return True

    # --- waypoints ------------------------------------------------------------------------------------

    def _calculate(self, odr: OpenDrive) -> None:
        body = self.actor
        assert body.road_id is not None
        points = body.route_points
        target = points[self.scenario_index]
        if target.road_id == body.road_id:
            self.scenario_index += 1
            if self.scenario_index >= len(points):
                self._deactivate("its start and target are on the same road")
                return
            target = points[self.scenario_index]
        start = RoadPoint(body.road_id, body.lane_id, body.s, body.direction)
        path = calculate_path(odr, start, target, body.route_strategies[self.scenario_index])
        if not path:
            self._deactivate(f"no path to road {target.road_id}, lane {target.lane_id}")
            return
        self.waypoints = waypoints(odr, path, start, target)
        body.route = [(node.road, node.direction) for node in path[1:]]
        self.path_calculated = True

    def _update_waypoints(self, odr: OpenDrive, snapshot: tuple[Any, ...], target: RoadPoint) -> None:
        status = self._status(odr, snapshot, target)
        if status == PASSED:
            self.index += 1
            if target.road_id == self.waypoints[-1].road_id:
                if self.scenario_index < len(self.actor.route_points) - 1:
                    self.scenario_index += 1
                    self.path_calculated = False
                    self._calculate(odr)
                    self.index = 0
                return
            # the roads still ahead to the next waypoint (esmini resets its route to it)
            roads = [(w.road_id, w.direction) for w in self.waypoints[self.index :]]
            self.actor.route = [r for r in roads if r[0] != self.actor.road_id]
        elif status == MISSED:
            self.path_calculated = False
            self._calculate(odr)
            self.index = 0

    def _status(self, odr: OpenDrive, snapshot: tuple[Any, ...], target: RoadPoint) -> str:
        road_id, lane_id, s, direction = snapshot
        same_road = target.road_id == road_id
        if same_road and ((direction > 0 and s > target.s) or (direction < 0 and s < target.s)):
            return PASSED if target.lane_id == lane_id else MISSED
        if same_road:
            return NOT_REACHED
        # the roads the entity may have come from: the link behind it (a junction: its connecting roads
        # from this road)
        for previous, previous_lane, _ in odr.connections(road_id, lane_id, -direction):
            if previous == target.road_id:
                return PASSED if previous_lane == target.lane_id else MISSED
        for previous, _, _ in odr.connections(road_id, None, -direction):
            if previous == target.road_id:
                return MISSED  # from another lane: esmini's connecting lane of this one is none (0)
        return NOT_REACHED

    def _deactivate(self, why: str) -> None:
        self.active = False
        if self.lane_change is not None:
            self._end_lane_change(self.world.step_index)
        if self.test_mode:
            self.actor.speed = 0.0
        self.world.log.append(
            f"t={self.world.time:.2f} {self.actor.name}: FollowRouteController deactivated ({why})"
        )


class _RouteLaneChange:
    """The controller's lane change: sinusoidal over its duration, to a lane that exists in the lane section
    whatever its width there (esmini's check of the width is the controller's, and only with the collision
    check on); the entity moves at its speed along the lane meanwhile."""

    def __init__(self, world: ScenarioWorld, actor: Body, lane: int, duration: float) -> None:
        self.world, self.actor, self.target_lane, self.duration = world, actor, lane, duration
        self.elapsed = 0.0
        self.offset0 = self.offset1 = 0.0
        self.direction = actor.direction
        self.done = False

    def start(self) -> None:
        actor, road = self.actor, self.world.road
        assert road is not None and actor.road_id is not None
        t_now = road.lane_center_t(actor.road_id, actor.lane_id, actor.s) + actor.offset
        actor.lane_id = self.target_lane
        actor.offset = t_now - road.lane_center_t(actor.road_id, self.target_lane, actor.s)
        self.offset0, self.offset1 = actor.offset, 0.0
        self.direction = actor.direction
        if self.duration <= 0.0:
            actor.offset = 0.0
            self.done = True

    def step(self, dt: float) -> None:
        actor = self.actor
        # onto a road that runs the other way (a junction's connecting road) the offsets keep their side of
        # the travel direction, as the entity's own offset does
        if actor.direction != self.direction:
            self.offset0, self.offset1 = -self.offset0, -self.offset1
            self.direction = actor.direction
        actor.extra["move_speed"] = actor.speed
        self.elapsed += dt
        progress = self.elapsed / self.duration
        offset = self.offset0 + (self.offset1 - self.offset0) * shape_value("sinusoidal", progress)
        actor.lateral_velocity = (offset - actor.offset) / dt
        actor.offset = offset
        if progress >= 1.0 - 1e-9:
            actor.offset = self.offset1
            actor.lateral_velocity = 0.0
            self.done = True
        elif self._leaves_road(dt):
            self._abandon()

    def _leaves_road(self, dt: float) -> bool:
        """The entity reaches its road's end this step (s units, as near as the step needs)."""
        actor, road = self.actor, self.world.road
        assert road is not None and actor.road_id is not None
        left = road.road_length(actor.road_id) - actor.s if actor.direction > 0 else actor.s
        return abs(actor.speed) * dt >= left

    def _abandon(self) -> None:
        """At the end of its road mid-change, esmini's entity goes on from the lane it is in by position: in
        another lane than the target one it leaves by that lane's link, and the lane change ends where it is
        (its offset and heading kept)."""
        actor, road = self.actor, self.world.road
        assert road is not None and actor.road_id is not None
        t = road.lane_center_t(actor.road_id, actor.lane_id, actor.s) + actor.offset
        lane, offset = lane_at_t(road, actor.road_id, actor.s, t)
        if lane == actor.lane_id or lane == 0:
            return
        drift = (
            atan2(actor.lateral_velocity * actor.direction, abs(actor.speed))
            if abs(actor.speed) > 0.1
            else 0.0
        )
        actor.lane_id, actor.offset = lane, offset
        actor.heading_offset += drift
        actor.lateral_velocity = 0.0
        self.done = True
        self.world.log.append(
            f"t={self.world.time:.2f} {actor.name}: FollowRoute lane change ends in lane {lane} at the road's end"
        )


def route_points(world: ScenarioWorld, positions: list[m.Position]) -> list[RoadPoint]:
    """The road points (road, lane, s) of a route's waypoints, as esmini keeps them when the route is
    assigned; a waypoint on no road is left out."""
    odr = world.road
    out: list[RoadPoint] = []
    if odr is None:
        return out
    for position in positions:
        if isinstance(position, m.LanePosition) and position.road_id in odr.roads:
            out.append(RoadPoint(position.road_id, position.lane_id, position.s))
            continue
        x, y, _, h = world.resolve_position(position)
        rc = odr.world_to_road(x, y, None, road_hint=getattr(position, "road_id", None))
        if rc is not None:
            out.append(RoadPoint(rc.road_id, rc.lane_id, rc.s, 1 if math.cos(h - rc.heading) >= 0 else -1))
    return out
