"""Driver models of esmini's controllers: the NaturalDriver (IDM speed, lane changes) and those that steer a
simple vehicle model of their own (vehicle::Vehicle): the OffroadFollower here, the FollowGhost controller in
`simcore.scenario.ghost`.

esmini's vehicle model (vehicle.cpp), as these controllers use it:

- DrivingControlTarget (target speed, heading error): acceleration max_acc·(target − v) within ±max_acc,
  speed within ±max_speed; wheel angle = the heading error within ±60°/(1 + steering_scale·v²);
- DrivingControlAnalog (throttle, steering in [-1, 1]): v += (max_dec if braking else max_acc)·throttle·dt;
  crossing zero from forward motion stops it with the handbrake on (released by a throttle that is not
  negative, in a step that does not accelerate); without throttle the speed decays by the engine brake
  factor 0.001 a step; speed within ±max_speed. The wheel angle grows by steering_rate·steering·dt scaled by
  1/(1 + 0.005·v²), returns by the factor (1 − 4·dt) and stays within ±60° times that scale;
- Update: a kinematic bicycle: the velocity at atan(0.15·tan(wheel angle)) from the heading, heading rate
  v·sin(that)/(0.15·length) (heading kept in [0, 2π)), position integrated with the new velocity.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

from simcore.scenario import model as m
from simcore.scenario.measure import axis_gaps
from simcore.scenario.motion import lane_at_t, wrap_angle
from simcore.world.native_calls import atan2, hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld

MAX_WHEEL_ANGLE: Final = math.radians(60.0)
SMALL: Final = 1e-10  # esmini's SMALL_NUMBER
NO_ROAD_SPEED_LIMIT: Final = 70 / 3.6  # esmini's speed limit off every road
_BIG: Final = 1e10  # esmini's LARGE_NUMBER


class Vehicle:
    """esmini's vehicle::Vehicle (see the module's doc)."""

    def __init__(self, body: Body) -> None:
        self.x, self.y, self.heading, self.speed = body.x, body.y, body.heading, body.speed
        self.length = body.entity.box.length
        self.wheel_angle = 0.0
        self.max_speed = 70.0
        self.max_acc = 20.0
        self.max_dec = 20.0
        self.steering_rate = 5.0
        self.steering_return = 4.0
        self.steering_scale = 0.02
        self.engine_brake = 0.001
        self.handbrake = False

    def control_target(self, dt: float, target_speed: float, heading_error: float) -> None:
        acc = min(max(self.max_acc * (target_speed - self.speed), -self.max_acc), self.max_acc)
        v = min(max(self.speed + acc * dt, -self.max_speed), self.max_speed)
        self.speed = v
        limit = MAX_WHEEL_ANGLE / (1.0 + self.steering_scale * v * v)
        self.wheel_angle = min(max(heading_error, -limit), limit)
        self.update(dt)

    def control_analog(self, dt: float, throttle: float, steering: float) -> None:
        old = self.speed
        if self.handbrake:
            if abs(throttle) < SMALL or throttle > SMALL:
                self.handbrake = False
        else:
            v = old + (self.max_dec if throttle < 0 else self.max_acc) * throttle * dt
            if old > 0 and v < 0:
                v, self.handbrake = 0.0, True
            else:
                if abs(throttle) < SMALL:
                    v *= 1.0 - self.engine_brake
                v = min(max(v, -self.max_speed), self.max_speed)
            self.speed = v
        v = self.speed
        scale = 1.0 / (1.0 + 0.005 * v * v)
        wheel = self.wheel_angle + scale * self.steering_rate * steering * dt
        wheel *= 1.0 - self.steering_return * dt
        limit = scale * MAX_WHEEL_ANGLE
        self.wheel_angle = min(max(wheel, -limit), limit)
        self.update(dt)

    def update(self, dt: float) -> None:
        v = self.speed
        slip = math.atan(0.15 * math.tan(self.wheel_angle))
        direction = slip + self.heading
        heading_rate = v * math.sin(slip) / (self.length * 0.15)
        heading = math.fmod(self.heading + dt * heading_rate, 2 * math.pi)
        self.heading = heading + 2 * math.pi if heading < 0 else heading
        self.x += dt * v * math.cos(direction)
        self.y += dt * v * math.sin(direction)


def put(world: ScenarioWorld, body: Body, vehicle: Vehicle) -> None:
    """The entity where its vehicle model is (its road position found from there)."""
    body.odometer += hypot(vehicle.x - body.x, vehicle.y - body.y)
    body.x, body.y, body.heading, body.speed = vehicle.x, vehicle.y, vehicle.heading, vehicle.speed
    body.mover = None
    world.locate(body)


def speed_limit(world: ScenarioWorld, body: Body) -> float:
    """esmini's Position::GetSpeedLimit: the road type's speed record where there is one; else off every
    road 70 km/h, on a road 120 km/h with more than one driving lane on the entity's side, else 60."""
    road = world.road
    if road is None or body.road_id is None:
        return NO_ROAD_SPEED_LIMIT
    recorded = road.speed_limit(body.road_id, body.s)
    if recorded is not None and recorded > 0:
        return recorded
    side = 1 if body.lane_id > 0 else -1
    lanes = [lane for lane in road.lane_ids(body.road_id, body.s, driving_only=True) if lane * side > 0]
    return 120 / 3.6 if len(lanes) > 1 else 60 / 3.6


class OffroadFollower:
    """esmini's OffroadFollower: drives toward another entity disregarding roads and lanes, to stop
    `targetDistance` (m, default 20) from it (between reference points). Each step, after every entity
    moved: steering = the bearing of the lead relative to the heading (wrapped) within ±1, throttle =
    0.5·(distance − targetDistance) − 0.5·(v − v_lead) within ±1, into the analog vehicle model with the
    entity's maximum acceleration and deceleration, steering rate `steeringRate` (default 4) and a maximum
    speed of min(1.2 × the speed limit where it is, the entity's maximum speed). Without `followEntity` (or
    with one that does not exist) it does nothing."""

    def __init__(self, world: ScenarioWorld, actor: Body, properties: dict[str, str]) -> None:
        self.world = world
        self.actor = actor
        lead = properties.get("followEntity")
        self.lead = world.bodies.get(lead) if lead else None
        self.target_distance = m.property_number(properties.get("targetDistance"), 20.0)
        self.vehicle = Vehicle(actor)
        perf = actor.entity.performance
        self.vehicle.max_acc = perf.max_acceleration
        self.vehicle.max_dec = perf.max_deceleration
        self.vehicle.steering_rate = m.property_number(properties.get("steeringRate"), 4.0)

    def step(self, dt: float) -> None:
        lead, a, vehicle = self.lead, self.actor, self.vehicle
        if lead is None or lead.gone:
            return
        vehicle.max_speed = min(1.2 * speed_limit(self.world, a), a.entity.performance.max_speed)
        dx, dy = lead.x - a.x, lead.y - a.y
        bearing = atan2(dy, dx) - a.heading
        bearing = atan2(math.sin(bearing), math.cos(bearing))
        distance = hypot(dx, dy)
        steering = min(max(bearing, -1.0), 1.0)
        throttle = min(max(0.5 * (distance - self.target_distance) - 0.5 * (a.speed - lead.speed), -1.0), 1.0)
        vehicle.control_analog(dt, throttle, steering)
        put(self.world, a, vehicle)


# --- esmini's NaturalDriver ----------------------------------------------------------------------------------

# the vehicles around a NaturalDriver: the nearest ahead and behind in its lane and in the lanes beside it
LEAD, FOLLOWING, LEFT_LEAD, LEFT_FOLLOW, RIGHT_LEAD, RIGHT_FOLLOW = range(6)


class NaturalDriver:
    """esmini's NaturalDriver controller (ControllerNaturalDriver): the Intelligent Driver Model for the
    speed and MOBIL-like lane changes, on the longitudinal domain. Its semantics as esmini implements them:

    - properties `desiredSpeed` (m/s, default 15), `desiredDistance` (IDM s0, m, 20), `thw` (IDM T, s, 2),
      `maxAcc` (IDM a, 3), `maxDec` (IDM −b, −3; also the lowest acceleration applied), `lookAheadDistance`
      (m, 115: vehicles farther, centre to centre, are not seen), `laneChangeDuration` (s, 3),
      `laneChangeDelay` (s, 1), `maxImposedBraking` (m/s², 3), `laneChangeAccGain` (m/s², 0.2), `politeness`
      (0.5), `route` (the lane id it aims for, −1);
    - IDM: acceleration a·(1 − (v/v0)⁴) − a·(s*/s)², s* = s0 + max(0, v·T + v·(v − v_lead)/(2·sqrt(a·b))), s
      the bumper-to-bumper gap along the road to the nearest vehicle ahead in its lane (every other entity
      counts, whatever drives it); the entity's speed is integrated, within [0, desiredSpeed] and its maximum
      speed, and it moves itself with it (esmini's override mode);
    - lane changes, while driving (not changing lanes) and at least laneChangeDuration + laneChangeDelay
      after the last one began: to the left lane first, else the right, when the vehicle behind there would
      not have to brake harder than maxImposedBraking behind it, and either the lane is `route` and its own
      predicted acceleration there is not below −maxImposedBraking, or the gain (its acceleration there less
      here, plus politeness × the changes it causes to the followers' accelerations) exceeds
      laneChangeAccGain; not when another NaturalDriver close ahead is changing into the same lane. The lane
      change is a sinusoidal one of laneChangeDuration, started at the next step; meanwhile the speed is
      kept;
    - esmini steps it once at activation in Init with a zero time step (its first frame): a lane change it
      decides there starts with the first step.

    The `mode` property is ignored (esmini moves the entity from the controller in either mode)."""

    def __init__(
        self,
        world: ScenarioWorld,
        actor: Body,
        properties: dict[str, str],
        peers: dict[str, NaturalDriver] | None = None,
    ) -> None:
        self.world = world
        self.actor = actor
        # the NaturalDrivers active in the run (this one among them once active): a lane change is given up
        # for another one changing into the same lane close ahead
        self.peers: dict[str, NaturalDriver] = peers if peers is not None else {}
        p = properties.get
        self.desired_distance = m.property_number(p("desiredDistance"), 20.0)
        self.desired_speed = m.property_number(p("desiredSpeed"), 15.0)
        self.lane_change_duration = m.property_number(p("laneChangeDuration"), 3.0)
        self.lookahead = m.property_number(p("lookAheadDistance"), 115.0)
        self.max_deceleration = m.property_number(p("maxDec"), -3.0)
        self.max_acceleration = m.property_number(p("maxAcc"), 3.0)
        self.lane_change_delay = m.property_number(p("laneChangeDelay"), 1.0)
        self.thw = m.property_number(p("thw"), 2.0)
        self.max_imposed_braking = m.property_number(p("maxImposedBraking"), 3.0)
        self.acc_gain = m.property_number(p("laneChangeAccGain"), 0.2)
        self.politeness = m.property_number(p("politeness"), 0.5)
        try:
            self.route = int(float(p("route") or -1))
        except ValueError:
            self.route = -1
        self.current_speed = actor.speed
        self.changing = False  # state CHANGE_LANE: the speed is kept
        self.injected = False  # a lane change began less than duration + delay ago
        self.cooldown = self.lane_change_duration + self.lane_change_delay
        self.target_lane = 0
        self.pending_lane: int | None = None  # a lane change to start (the engine starts it)
        self.around: list[tuple[Body, float] | None] = [None] * 6  # vehicles of interest, with their ds

    # the IDM
    def _gap(self, follow: Body, lead: Body, ds: float) -> float:
        """esmini's EstimateFreespace: the road distance less the boxes' extents (0 at most when behind)."""
        if abs(wrap_angle(follow.heading - lead.heading)) >= math.pi / 2:
            return ds
        bf, bl = follow.entity.box, lead.entity.box
        extents = (bf.length / 2 + bf.center_x) + (bl.length / 2 - bl.center_x)
        return max(ds - extents, 0.0) if ds > 0 else min(ds + extents, 0.0)

    def _desired_gap(self, follow_speed: float, lead_speed: float) -> float:
        ab = -self.max_acceleration * self.max_deceleration
        relative = follow_speed - lead_speed
        return self.desired_distance + max(
            0.0, follow_speed * self.thw + follow_speed * relative / (2 * math.sqrt(ab))
        )

    def _acceleration(self, follow: Body | None, lead: Body | None) -> float:
        if follow is None:
            return 0.0
        v = follow.speed
        acc = self.max_acceleration * (1 - (v / self.desired_speed) ** 4)
        if lead is not None:
            delta = self.world.measure.road_delta_entity(follow, lead) if follow.road_id is not None else None
            ds = delta[0] if delta is not None else _BIG
            gap = self._gap(follow, lead, ds)
            if gap == 0:
                gap = SMALL
            acc -= self.max_acceleration * (self._desired_gap(v, lead.speed) / gap) ** 2
        return acc

    # the surroundings
    def _lane(self, body: Body) -> int:
        road = self.world.road
        if road is None or body.road_id is None or not body.offset:
            return body.lane_id
        return lane_at_t(road, body.road_id, body.s, self.world.measure.t_of(body))[0]

    def _update_surroundings(self) -> list[Body]:
        a, world = self.actor, self.world
        around: list[tuple[Body, float] | None] = [None] * 6
        seen: list[Body] = []
        if a.road_id is None:
            self.around = around
            return seen
        my_lane = self._lane(a)
        side = -1 if my_lane < 0 else 1
        for other in world.bodies.values():
            if other is a or other.gone or not other.placed:
                continue
            if hypot(other.x - a.x, other.y - a.y) > self.lookahead:
                continue
            seen.append(other)
            delta = world.measure.road_delta_entity(a, other)
            if delta is None:
                continue
            ds = delta[0]
            lanes = (self._lane(other) - my_lane) * -side
            if lanes == 0:
                ahead, behind = LEAD, FOLLOWING
            elif lanes == 1:
                ahead, behind = LEFT_LEAD, LEFT_FOLLOW
            elif lanes == -1:
                ahead, behind = RIGHT_LEAD, RIGHT_FOLLOW
            else:
                continue
            if ds >= 0:
                best = around[ahead]
                if best is None or ds < best[1]:
                    around[ahead] = (other, ds)
            else:
                best = around[behind]
                if best is None or ds > best[1]:
                    around[behind] = (other, ds)
        self.around = around
        return seen

    def _vehicle(self, kind: int) -> Body | None:
        found = self.around[kind]
        return found[0] if found is not None else None

    def _adjacent_lanes(self) -> tuple[int, int]:
        """(left, right) driving lanes beside it on its side of the road (0: none)."""
        a, road = self.actor, self.world.road
        if road is None or a.road_id is None:
            return 0, 0
        lane = self._lane(a)
        sign = 1 if lane > 0 else -1
        driving = [x for x in road.lane_ids(a.road_id, a.s, driving_only=True) if x * sign > 0]
        if len(driving) <= 1:
            return 0, 0
        left, right = lane - sign, lane + sign
        return (left if left in driving else 0), (right if right in driving else 0)

    def _lane_change_possible(self, lane: int, left: bool) -> bool:
        a = self.actor
        adj_lead = self._vehicle(LEFT_LEAD if left else RIGHT_LEAD)
        adj_follow = self._vehicle(LEFT_FOLLOW if left else RIGHT_FOLLOW)
        new_follow = self._acceleration(adj_follow, adj_lead)
        new_follow_predicted = self._acceleration(adj_follow, a)
        if new_follow_predicted < -self.max_imposed_braking:
            return False
        predicted = self._acceleration(a, adj_lead)
        if lane == self.route:
            return predicted >= -self.max_imposed_braking
        lead, following = self._vehicle(LEAD), self._vehicle(FOLLOWING)
        now = self._acceleration(a, lead)
        old_follow = self._acceleration(following, a)
        old_follow_predicted = self._acceleration(following, lead)
        gain = predicted - now
        gain += self.politeness * (new_follow_predicted - new_follow + old_follow_predicted - old_follow)
        return gain > self.acc_gain + SMALL

    def _abort(self, seen: list[Body]) -> bool:
        """Another NaturalDriver close ahead (within its desired gap) is changing into the same lane."""
        drivers = self.peers
        for other in seen:
            driver = drivers.get(other.name)
            if driver is None or not driver.injected or driver.target_lane != self.target_lane:
                continue
            if self._lane(other) == self._lane(self.actor):
                continue
            delta = self.world.measure.road_delta_entity(self.actor, other)
            if delta is None:
                continue
            gap = self._gap(self.actor, other, delta[0])
            if 0 <= gap < self._desired_gap(other.speed, self.current_speed):
                return True
        return False

    def step(self, dt: float) -> None:
        a = self.actor
        seen = self._update_surroundings()
        acceleration = 0.0
        initiate = False
        if not self.changing:
            acceleration = max(self._acceleration(a, self._vehicle(LEAD)), self.max_deceleration)
            if not self.injected:
                left, right = self._adjacent_lanes()
                if left or right:
                    for lane, is_left in ((left, True), (right, False)):
                        if lane == 0:
                            continue
                        initiate = self._lane_change_possible(lane, is_left)
                        if initiate and a.speed > 0:
                            self.target_lane = lane
                            self.changing = True
                            break
        if initiate and self.target_lane != 0:
            if self._abort(seen):
                self.target_lane = 0
                self.changing = False
            else:
                self.pending_lane = self.target_lane
                self.injected = True
        if self.injected:
            self.cooldown -= dt
            if self.changing and self.cooldown <= self.lane_change_delay:
                self.target_lane = 0
                self.changing = False
            if self.cooldown < 0.0:
                self.cooldown = self.lane_change_delay + self.lane_change_duration
                self.injected = False
        v = self.current_speed + acceleration * dt
        if v >= self.desired_speed:
            v = self.desired_speed
        elif v > a.entity.performance.max_speed:
            v = a.entity.performance.max_speed
        elif v < 0.0:
            v = 0.0
        self.current_speed = v
        a.speed = v


class AccDriver:
    """esmini's ACCController (and ALKSController, which is the same controller): a longitudinal driver
    that holds a set speed and keeps a time gap to the vehicle ahead in its lane. Its semantics as esmini
    implements them:

    - properties `timeGap` (s, default 1.5), `setSpeed` (m/s; default: the speed at activation), `lateralDist`
      (m, default 5: vehicles farther across are not followed), `mode` (`override`, `additive`; without the
      property, additive), `virtual` (true: it only computes, the entity is not moved by it);
    - activation takes the entity's speed as its current speed, and as set speed in additive mode or when no
      `setSpeed` is given; while it runs, a speed other than the one it set last (a speed action in additive
      mode) becomes the new set speed;
    - the vehicle to follow: the nearest entity ahead along the road in the same lane, within `lateralDist`,
      bumper to bumper, looked for up to max(50 m, 6 m + v²/max deceleration); also a very close entity just
      in front (bounding boxes less than its length + 1 m apart, lateral gap within -0.5…0.2 m);
    - following: closer than 1 m it stops at once; else it accelerates by
      2.5·f − f·(v − v_set) − (1 − f)·(v − min(v_set, v_lead)), f = min(1, (gap − d)/d), d = 3 m + timeGap·
      max(v, v_lead), within the entity's acceleration/deceleration limits, and never above its set speed;
    - free road: toward the set speed at 0.7·max acceleration per m/s of difference, at most 0.7·max
      acceleration, without overshooting;
    - it steps after every entity has moved (as esmini steps controllers after the default motion): in
      override mode it then moves its entity with the new speed (speed actions on it end without effect);
      in additive mode the entity moves on with its speed and the new speed applies from the next step."""

    MIN_DISTANCE = 3.0  # m kept at standstill
    ACCELERATION_FACTOR = 0.7

    def __init__(self, world: ScenarioWorld, actor: Body, properties: dict[str, str]) -> None:
        self.world = world
        self.actor = actor
        self.time_gap = m.property_number(properties.get("timeGap"), 1.5)
        self.lateral_dist = m.property_number(properties.get("lateralDist"), 5.0)
        mode = properties.get("mode")
        self.override = mode is not None and mode != "additive"
        self.virtual = properties.get("virtual", "").strip().lower() == "true"
        self.current_speed = actor.speed
        given = properties.get("setSpeed")
        self.set_speed = (
            actor.speed if (not self.override or given is None) else m.property_number(given, actor.speed)
        )
        self.lead: str | None = None  # the entity it follows (None: free road)

    def step(self, dt: float) -> None:
        a, world = self.actor, self.world
        if self.virtual:
            self.current_speed = a.speed
        elif abs(a.speed - self.current_speed) > 1e-3:
            self.set_speed = a.speed  # set by someone else (a speed action): respected as the new set speed
        perf = a.entity.performance
        v = self.current_speed
        lookahead = max(50.0, 2 * self.MIN_DISTANCE + v * v / max(perf.max_deceleration, 1e-9))
        box_a = a.entity.box
        front_a = box_a.length / 2 + box_a.center_x
        best_gap, lead = _BIG, None
        measure = world.measure
        for other in world.bodies.values():
            if other is a or other.gone or not other.placed:
                continue
            box_b = other.entity.box
            delta = measure.road_delta_entity(a, other) if a.road_id is not None else None
            if delta is not None and abs(delta[0]) <= lookahead:
                ds, dt_lat = delta
                turn = abs(wrap_angle(other.heading - a.heading))
                rear_b = (
                    box_b.length / 2 - box_b.center_x
                    if turn < math.pi / 2
                    else box_b.length / 2 + box_b.center_x
                )
                gap = ds - front_a - rear_b
                if 0.0 < gap < best_gap and abs(dt_lat) < self.lateral_dist and _same_lane(world, a, other):
                    best_gap, lead = gap, other
            if lead is not other:
                # a very close entity just in front (whatever the lanes say)
                reach = box_a.length + box_b.length + 1.0 + 0.5 * max(0.0, v - other.speed)
                if abs(other.x - a.x) < reach and abs(other.y - a.y) < reach:
                    lon, lat = axis_gaps(measure.box(a), measure.box(other))
                    if 0.0 < lon < 1.0 + box_b.length + 0.5 * max(0.0, v - other.speed) and -0.5 < lat < 0.2:
                        best_gap, lead = lon, other
        if lead is not None:
            if best_gap < 1.0:
                v = 0.0
            else:
                follow = self.MIN_DISTANCE + self.time_gap * abs(max(v, lead.speed))
                factor = min(1.0, (best_gap - follow) / follow)
                dv_min = v - min(self.set_speed, lead.speed)
                dv_set = v - self.set_speed
                acc = 2.5 * factor - factor * dv_set - (1.0 - factor) * dv_min
                acc = min(max(acc, -perf.max_deceleration), perf.max_acceleration)
                v = min(max(0.0, v + acc * dt), self.set_speed)
        else:
            gain = self.ACCELERATION_FACTOR * perf.max_acceleration
            acc = min(max((self.set_speed - v) * gain, -perf.max_deceleration), gain)
            ahead = v + acc * dt
            v = self.set_speed if abs(ahead - self.set_speed) > abs(v - self.set_speed) else ahead
        self.lead = lead.name if lead is not None else None
        self.current_speed = v
        if not self.virtual:
            a.speed = v


def _same_lane(world: ScenarioWorld, a: Body, b: Body) -> bool:
    """b is in a's lane (esmini: no lane change between them along the road): the lanes their reference
    points are in now (during a lane change, the one it has reached), by id (across a road link too: the
    corpus's roads keep lane ids across links)."""
    road = world.road
    if road is None or a.road_id is None or b.road_id is None:
        return a.lane_id == b.lane_id
    measure = world.measure
    lane_a = lane_at_t(road, a.road_id, a.s, measure.t_of(a))[0] if a.offset else a.lane_id
    lane_b = lane_at_t(road, b.road_id, b.s, measure.t_of(b))[0] if b.offset else b.lane_id
    return lane_a == lane_b
