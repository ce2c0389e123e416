"""esmini's LoomingController (ControllerLooming.cpp): a car-following driver on the longitudinal domain (the
only one it operates: esmini skips an activation on the lateral one, with a warning). As esmini runs it:

- properties `timeGap` (s, default 1.5) and `setSpeed` (m/s; default, and in additive mode always, the
  speed at activation);
- the vehicle to follow: the nearest entity ahead along the road within 130 m, in a lane linked to its own
  (no lane change between them) and less than 5 m across, its gap measured bumper to bumper;
- the demand: with a vehicle to follow closer than 1 m, 0; with one farther, f − f·(v − v_set) −
  (1 − f)·(v − min(v_set, v_lead)) with f = min(1, (gap − d)/d), d = 3 m + timeGap·max(v, v_lead); with none,
  v_set − v;
- the demand, within ±1, is the throttle of esmini's analog vehicle model (its maximum acceleration and
  deceleration the entity's; no throttle: the engine brake takes 0.1 % a step), whose speed the entity takes;
  it moves along its lane with it (esmini's steering toward the near and far points does not move an entity
  the controller does not drive laterally)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

from simcore.scenario import model as m
from simcore.scenario.drivers import Vehicle
from simcore.scenario.motion import wrap_angle

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld

LOOKAHEAD: Final = 130.0  # m along the road
MIN_LATERAL: Final = 5.0  # m across
MIN_DISTANCE: Final = 3.0  # m kept to the vehicle ahead


class LoomingController:
    """esmini's LoomingController on one entity (see the module's doc)."""

    moves_itself = True

    def __init__(
        self, world: ScenarioWorld, actor: Body, properties: dict[str, str], domains: frozenset[str]
    ) -> None:
        self.world = world
        self.actor = actor
        self.domains = domains
        self.time_gap = m.property_number(properties.get("timeGap"), 1.5)
        given = properties.get("setSpeed")
        additive = properties.get("mode") == "additive"
        self.set_speed = actor.speed if additive or given is None else m.property_number(given, actor.speed)
        self.vehicle = Vehicle(actor)
        perf = actor.entity.performance
        self.vehicle.max_acc = perf.max_acceleration
        self.vehicle.max_dec = perf.max_deceleration
        self.vehicle.steering_rate = 4.0
        self.lead: str | None = None

    def _lead(self) -> tuple[Body, float] | None:
        a, world = self.actor, self.world
        if a.road_id is None:
            return None
        box_a = a.entity.box
        front_a = box_a.length / 2 + box_a.center_x
        best: tuple[Body, float] | None = None
        for other in world.bodies.values():
            if other is a or other.gone or not other.placed or other.road_id is None:
                continue
            delta = world.measure.road_delta_entity(a, other)
            if delta is None or abs(delta[0]) > LOOKAHEAD:
                continue
            ds, dt_lat = delta
            box_b = other.entity.box
            same_way = abs(wrap_angle(other.heading - a.heading)) < math.pi / 2
            rear_b = box_b.length / 2 - box_b.center_x if same_way else box_b.length / 2 + box_b.center_x
            gap = ds - front_a - rear_b
            if (
                0.0 < gap < (best[1] if best else math.inf)
                and abs(dt_lat) < MIN_LATERAL
                and _linked(world, a, other)
            ):
                best = other, gap
        return best

    def step(self, dt: float) -> None:
        a = self.actor
        v = a.speed
        found = self._lead()
        self.lead = found[0].name if found else None
        if found is not None:
            lead, gap = found
            if gap < 1.0:
                acc = 0.0
            else:
                follow = MIN_DISTANCE + self.time_gap * abs(max(v, lead.speed))
                factor = min(1.0, (gap - follow) / follow)
                dv_min = v - min(self.set_speed, lead.speed)
                dv_set = v - self.set_speed
                acc = factor - factor * dv_set - (1.0 - factor) * dv_min
        else:
            acc = self.set_speed - v
        vehicle = self.vehicle
        vehicle.control_analog(dt, min(max(acc, -1.0), 1.0), 0.0)
        a.speed = vehicle.speed


def _linked(world: ScenarioWorld, a: Body, b: Body) -> bool:
    """b is in a lane a's lane leads to (no lane change between them): the same lane id on the same road,
    else on another road the lane its lane links reach (esmini's Delta with dLaneId 0)."""
    if a.road_id == b.road_id:
        return a.lane_id == b.lane_id
    road = world.road
    if road is None or a.road_id is None:
        return False
    from simcore.scenario.motion import along_lane

    reached = along_lane(road, a.road_id, a.lane_id, a.s, a.direction, LOOKAHEAD)
    return reached[0] == b.road_id and reached[1] == b.lane_id
