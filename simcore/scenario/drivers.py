"""Driver models of esmini's controllers that steer a simple vehicle model of their own (vehicle::Vehicle):
the OffroadFollower here, the FollowGhost controller in `simcore.scenario.ghost`.

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
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simcore.scenario.engine import ScenarioEngine
    from simcore.scenario.motion import Body

MAX_WHEEL_ANGLE = math.radians(60.0)
SMALL = 1e-10  # esmini's SMALL_NUMBER
NO_ROAD_SPEED_LIMIT = 70 / 3.6  # esmini's speed limit off every road


def _float(text: str | None, default: float) -> float:
    try:
        return float(text) if text is not None and text.strip() else default
    except ValueError:
        return default


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


def put(engine: ScenarioEngine, body: Body, vehicle: Vehicle) -> None:
    """The entity where its vehicle model is (its road position found from there)."""
    body.odometer += math.hypot(vehicle.x - body.x, vehicle.y - body.y)
    body.x, body.y, body.heading, body.speed = vehicle.x, vehicle.y, vehicle.heading, vehicle.speed
    body.mover = None
    engine._locate(body)


def speed_limit(engine: ScenarioEngine, body: Body) -> float:
    """esmini's Position::GetSpeedLimit without the road's speed records (CARLOS does not read them): off
    every road 70 km/h; on a road 120 km/h with more than one driving lane on the entity's side, else 60."""
    road = engine.road
    if road is None or body.road_id is None:
        return NO_ROAD_SPEED_LIMIT
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

    def __init__(self, engine: ScenarioEngine, actor: Body, properties: dict[str, str]) -> None:
        self.engine = engine
        self.actor = actor
        lead = properties.get("followEntity")
        self.lead = engine.bodies.get(lead) if lead else None
        self.target_distance = _float(properties.get("targetDistance"), 20.0)
        self.vehicle = Vehicle(actor)
        perf = actor.entity.performance
        self.vehicle.max_acc = perf.max_acceleration
        self.vehicle.max_dec = perf.max_deceleration
        self.vehicle.steering_rate = _float(properties.get("steeringRate"), 4.0)

    def step(self, dt: float) -> None:
        lead, a, vehicle = self.lead, self.actor, self.vehicle
        if lead is None or lead.gone:
            return
        vehicle.max_speed = min(1.2 * speed_limit(self.engine, a), a.entity.performance.max_speed)
        dx, dy = lead.x - a.x, lead.y - a.y
        bearing = math.atan2(dy, dx) - a.heading
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))
        distance = math.hypot(dx, dy)
        steering = min(max(bearing, -1.0), 1.0)
        throttle = min(max(0.5 * (distance - self.target_distance) - 0.5 * (a.speed - lead.speed), -1.0), 1.0)
        vehicle.control_analog(dt, throttle, steering)
        put(self.engine, a, vehicle)
