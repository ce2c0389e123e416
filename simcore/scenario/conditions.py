"""OpenSCENARIO conditions: one evaluate function per condition type, and the registry that maps each type
of `simcore.scenario.model` to it (esmini's OSCCondition: each condition type owns its evaluation).

Value conditions read the clock, the stores and the storyboard; entity conditions are evaluated for one
triggering entity. Both read the run only through `ScenarioWorld`.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any, Final

from simcore.errors import BadInput
from simcore.evaluation.metrics import boxes_overlap
from simcore.scenario import model as m
from simcore.scenario.measure import LARGE, bounding_radii, directional
from simcore.scenario.motion import wrap_angle
from simcore.scenario.positions import fixed_point
from simcore.scenario.storyboard import state_of, transition_of
from simcore.world.native_calls import hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld

_COMPARE: Final[dict[str, Callable[[Any, Any], Any]]] = {
    "greaterThan": operator.gt,
    "lessThan": operator.lt,
    "equalTo": lambda a, b: abs(a - b) < 1e-9 if isinstance(a, float) else a == b,
    "greaterOrEqual": operator.ge,
    "lessOrEqual": operator.le,
    "notEqualTo": operator.ne,
}


def compare(rule: str, a: Any, b: Any) -> bool:
    return bool(_COMPARE[rule](a, b))


def compare_floats(rule: str, a: float, b: float) -> bool:
    """`compare` of two floats as plain comparisons (compiled: no look-up, no call, nothing boxed); the same
    answers as `_COMPARE`'s, a KeyError for an unknown rule as there."""
    if rule == "greaterThan":
        return a > b
    if rule == "lessThan":
        return a < b
    if rule == "equalTo":
        return abs(a - b) < 1e-9
    if rule == "greaterOrEqual":
        return a >= b
    if rule == "lessOrEqual":
        return a <= b
    if rule == "notEqualTo":
        return a != b
    raise KeyError(rule)


#: a condition's value now, bound to one run (see `bind`); an entity condition adds the entities that fulfil
#: it to the list given (None: nobody asks which)
Bound = Callable[[list[str] | None], bool]
#: an entity condition bound to one run, evaluated for one triggering entity
EntityTest = Callable[["Body"], bool]


def holds(cond: m.Condition, world: ScenarioWorld, triggering: list[str] | None) -> bool:
    """Whether a condition's value holds now (before its edge and delay); the entities that fulfil an
    entity condition are added to `triggering`."""
    return bind(cond, world)(triggering)


def bind(cond: m.Condition, world: ScenarioWorld) -> Bound:
    """A condition's evaluation in `world`, with what does not change during the run looked up once (the
    evaluator of its type, its entities, its rule). Raises what evaluating it would raise (an entity
    condition of a type not supported, a storyboard element that does not exist): bind when evaluating."""
    if cond.value_condition is not None:
        c = cond.value_condition
        binder = VALUE_BINDERS.get(type(c))
        if binder is not None:
            return binder(c, world)
        evaluate_value = VALUE_CONDITIONS[type(c)]
        return lambda triggering: evaluate_value(c, world)
    condition = cond.entity_condition
    assert condition is not None
    return _for_entities(cond, world, _bind_entity(condition, world))


def _bind_entity(condition: m.EntityCondition, world: ScenarioWorld) -> EntityTest:
    binder = ENTITY_BINDERS.get(type(condition))
    if binder is not None:
        return binder(condition, world)
    evaluate = ENTITY_CONDITIONS.get(type(condition))
    if evaluate is None:
        raise BadInput(f"condition {type(condition).__name__} is not supported", file=world.source)
    return partial(evaluate, condition, world)


def _for_entities(cond: m.Condition, world: ScenarioWorld, evaluate: EntityTest) -> Bound:
    """An entity condition over its triggering entities."""
    names = cond.triggering_entities
    if len(names) == 1:
        # one entity: "any" and "all" alike hold when it is in the world and fulfils the condition
        name = names[0]
        # a named entity is looked up once (raising as then); $owner, the actor of the action running now, at
        # every evaluation
        fixed = world.body(name) if name != "$owner" else None

        def one(triggering: list[str] | None) -> bool:
            body = fixed if fixed is not None else world.body(name)
            if body.gone:
                return False
            result = evaluate(body)
            if result and triggering is not None:
                triggering.append(name)
            return result

        return one
    every = cond.triggering_rule == "all"

    def each(triggering: list[str] | None) -> bool:
        # entities not in the world are skipped; "any" stops at the first entity that fulfils it (the one
        # that triggers), "all" at the first that does not (as esmini)
        result = False
        hits: list[str] = []
        for name in names:
            body = world.body(name)
            if body.gone:
                continue
            result = evaluate(body)
            if result:
                hits.append(name)
                if not every:
                    break
            elif every:
                return False
        if result and triggering is not None:
            triggering.extend(hits)
        return result

    return each


# --- value conditions -------------------------------------------------------------------------------------


def simulation_time(c: m.SimulationTimeCondition, world: ScenarioWorld) -> bool:
    return bind_simulation_time(c, world)(None)


def bind_simulation_time(c: m.SimulationTimeCondition, world: ScenarioWorld) -> Bound:
    # to a nanosecond: step 3 of 0.05 s is at 0.15000000000000002 s, which is not "greater than 0.15" (esmini
    # holds a condition "t > k·dt" from step k + 1 on, for every k)
    # (rounding to digits is slow: the condition's value is rounded once; the clock only near it, where the
    # rounding decides: more than a microsecond away, rounding by at most half a nanosecond changes no order)
    value = round(c.value, 9)
    rule = c.rule
    if rule not in _COMPARE:
        return lambda triggering: compare(c.rule, world.time, value)  # raises as `compare` does

    def now_holds(triggering: list[str] | None) -> bool:
        now = world.time
        return compare_floats(rule, now if abs(now - value) > 1e-6 else round(now, 9), value)

    return now_holds


def storyboard_element_state(c: m.StoryboardElementStateCondition, world: ScenarioWorld) -> bool:
    return bind_storyboard_element_state(c, world)(None)


def bind_storyboard_element_state(c: m.StoryboardElementStateCondition, world: ScenarioWorld) -> Bound:
    """The condition's evaluation, made once per run (kept in `world.memo`: it counts the transitions it has
    seen, whichever way it is evaluated)."""
    key = ("element_state", id(c))
    bound: Bound | None = world.memo.get(key)
    if bound is not None:
        return bound
    nodes = world.registry.find(c.element_type, c.element_ref)
    if not nodes:
        raise BadInput(
            f"StoryboardElementStateCondition refers to {c.element_type} {c.element_ref!r}, which does not exist",
            file=world.source,
        )
    transition = transition_of(c.state)
    if transition is None:
        state = state_of(c.state)  # (None: a name of neither, which no element matches)

        def in_state(triggering: list[str] | None) -> bool:
            return any(node.state is state for node in nodes)

        bound = in_state
    else:
        # a transition holds when the element went through it since this condition was last evaluated
        # (every transition counts once for each condition, however late it looks; as esmini): per element,
        # how many of those transitions this condition has seen
        name = transition.value
        seen = [0] * len(nodes)

        def went_through(triggering: list[str] | None) -> bool:
            happened = False
            for i, node in enumerate(nodes):
                count = node.counts.get(name, 0)
                if count > seen[i]:
                    happened = True
                    seen[i] = count
            return happened

        bound = went_through
    world.memo[key] = bound
    return bound


def traffic_signal(c: m.TrafficSignalCondition, world: ScenarioWorld) -> bool:
    return world.signals.get(c.name) == c.state


def traffic_signal_controller(c: m.TrafficSignalControllerCondition, world: ScenarioWorld) -> bool:
    return world.signal_phases.get(c.controller) == c.phase


def stored_value(c: m.ParameterCondition | m.VariableCondition, world: ScenarioWorld) -> bool:
    """ParameterCondition and VariableCondition: the value in its store, compared as the type it has."""
    store = world.variables if isinstance(c, m.VariableCondition) else world.parameter_values
    value = store.get(c.name)
    if value is None:
        kind = "VariableCondition" if isinstance(c, m.VariableCondition) else "ParameterCondition"
        raise BadInput(f"{kind} on undeclared name {c.name!r}", file=world.source)
    if isinstance(value, bool):
        return compare(c.rule, value, c.value.lower() == "true")
    if isinstance(value, int | float):
        return compare(c.rule, float(value), float(c.value))
    return compare(c.rule, value, c.value)


def unsupported(c: m.UnsupportedCondition, world: ScenarioWorld, body: Body | None = None) -> bool:
    """A condition CARLOS does not model (warned about at load): never holds."""
    return False


# --- entity conditions ------------------------------------------------------------------------------------


def speed(c: m.SpeedCondition, world: ScenarioWorld, body: Body) -> bool:
    if c.direction is None:
        return compare(c.rule, body.speed, c.value)
    return compare(c.rule, directional(body, body.heading, c.direction), c.value)


def acceleration(c: m.AccelerationCondition, world: ScenarioWorld, body: Body) -> bool:
    return compare(c.rule, body.acceleration, c.value)


def traveled_distance(c: m.TraveledDistanceCondition, world: ScenarioWorld, body: Body) -> bool:
    return body.odometer >= c.value


def stand_still(c: m.StandStillCondition, world: ScenarioWorld, body: Body) -> bool:
    since = body.standstill_since
    return since is not None and world.time - since >= c.duration - 1e-9


def end_of_road(c: m.EndOfRoadCondition, world: ScenarioWorld, body: Body) -> bool:
    since = body.end_of_road_since
    return since is not None and world.time - since >= c.duration - 1e-9


def relative_speed(c: m.RelativeSpeedCondition, world: ScenarioWorld, body: Body) -> bool:
    other = world.body(c.entity)
    if c.direction is None:
        return compare(c.rule, body.speed - other.speed, c.value)
    # both velocities in the reference entity's frame (as esmini)
    relative = directional(body, other.heading, c.direction) - directional(other, other.heading, c.direction)
    return compare(c.rule, relative, c.value)


#: m: boxes whose bounding circles are this far apart do not collide (their separating-axis gap is at least
#: 1/√2 of it, far above `TOUCH_TOLERANCE`), so their footprints are not built
APART: Final = 1e-3


def collision(c: m.CollisionCondition, world: ScenarioWorld, body: Body) -> bool:
    return bind_collision(c, world)(body)


def bind_collision(c: m.CollisionCondition, world: ScenarioWorld) -> EntityTest:
    # the footprints this step (the ones `EntityState.corners()` gives, without building the states)
    name = c.entity
    if name:

        def with_entity(body: Body) -> bool:
            other = world.body(name)
            measure = world.measure
            if measure.box_distance_lower_bound(body, other) > APART:
                return False
            return boxes_overlap(measure.box(body), measure.box(other))

        return with_entity

    def with_any(body: Body) -> bool:
        measure = world.measure
        mine = None
        for other in world.bodies.values():
            if other is body or measure.box_distance_lower_bound(body, other) > APART:
                continue
            if mine is None:
                mine = measure.box(body)
            if boxes_overlap(mine, measure.box(other)):
                return True
        return False

    return with_any


#: rad: esmini's ReachPosition with an Orientation wants the heading within
REACH_ANGLE_TOLERANCE: Final = 0.05


def reach_position(c: m.ReachPositionCondition, world: ScenarioWorld, body: Body) -> bool:
    x, y, _, h = fixed_point(world, c.position)
    if hypot(body.x - x, body.y - y) >= c.tolerance:
        return False
    if getattr(c.position, "orientation", None) is not None:
        # a position with an Orientation is reached with that heading only, within 0.05 rad, both read in
        # [0, 2π) (as esmini checks it: 6.27 and 0.01 rad differ)
        return abs(body.heading % math.tau - h % math.tau) < REACH_ANGLE_TOLERANCE
    return True


def distance(c: m.DistanceCondition, world: ScenarioWorld, body: Body) -> bool:
    x, y, _, _ = fixed_point(world, c.position)
    measured = world.measure.to_point(body, x, y, c.coordinate_system, c.distance_type, c.freespace)
    return compare(c.rule, LARGE if measured is None else abs(measured), c.value)


def relative_distance(c: m.RelativeDistanceCondition, world: ScenarioWorld, body: Body) -> bool:
    return bind_relative_distance(c, world)(body)


def _between_entities(
    c: m.RelativeDistanceCondition | m.TimeHeadwayCondition,
) -> tuple[str, str, str, bool, str, float]:
    """(other entity, coordinate system, distance type, freespace, rule, value) of a condition measured
    between two entities, read once when it is bound: the model is no compiled class, each read of a field
    a look-up by name."""
    return c.entity, c.coordinate_system, c.distance_type, c.freespace, c.rule, c.value


def bind_relative_distance(c: m.RelativeDistanceCondition, world: ScenarioWorld) -> EntityTest:
    name, system, kind, freespace, rule, value = _between_entities(c)
    euclid = kind in ("euclidianDistance", "cartesianDistance")
    bounded = freespace and (euclid or system == "entity")

    def test(body: Body) -> bool:
        other = world.body(name)
        if other.gone:
            return False
        measure = world.measure
        if bounded:
            # a bound clear of the value decides the comparison as the distance would: far apart, the lower
            # bound of the distance between the boxes; close, the distance of their centres, which neither
            # the distance between the boxes nor their gap along any axis exceeds
            lower = measure.box_distance_lower_bound(body, other)
            if euclid and lower > value + 1e-6:
                return compare_floats(rule, lower, value)
            upper = lower + bounding_radii(body, other)
            if upper < value - 1e-6:
                return compare_floats(rule, upper, value)
        measured = measure.to_entity(body, other, system, kind, freespace)
        return compare_floats(rule, LARGE if measured is None else abs(measured), value)

    return test


def time_headway(c: m.TimeHeadwayCondition, world: ScenarioWorld, body: Body) -> bool:
    return bind_time_headway(c, world)(body)


def bind_time_headway(c: m.TimeHeadwayCondition, world: ScenarioWorld) -> EntityTest:
    name, system, kind, freespace, rule, value = _between_entities(c)

    def test(body: Body) -> bool:
        other = world.body(name)
        if other.gone:
            return False
        headway = world.measure.headway(body, other, system, kind, freespace)
        return headway is not None and compare_floats(rule, headway, value)

    return test


def time_to_collision(c: m.TimeToCollisionCondition, world: ScenarioWorld, body: Body) -> bool:
    point: tuple[float, float] | None = None
    target: Body | None = None
    if c.position is not None:
        x, y, _, _ = fixed_point(world, c.position)
        point = (x, y)
    else:
        target = world.body(c.entity)
        if target.gone:
            return False
    ttc = world.measure.time_to_collision(
        body, target, point, c.coordinate_system, c.distance_type, c.freespace
    )
    return ttc is not None and compare(c.rule, ttc, c.value)


def offroad(c: m.OffroadCondition, world: ScenarioWorld, body: Body) -> bool:
    if body.road_id is None or _outside_driving_lanes(world, body):
        since = body.extra.setdefault("offroad_since", world.time)
        return world.time - since >= c.duration - 1e-9
    body.extra.pop("offroad_since", None)
    return False


def angle(c: m.AngleCondition | m.RelativeAngleCondition, world: ScenarioWorld, body: Body) -> bool:
    def angle_of(b: Body, kind: str) -> float:
        return b.heading if kind == "heading" else b.pitch if kind == "pitch" else b.roll

    value = angle_of(body, c.angle_type)
    if isinstance(c, m.RelativeAngleCondition):
        other = world.body(c.entity)
        if other.gone:
            return False
        value -= angle_of(other, c.angle_type)
    elif c.coordinate_system in ("road", "lane", "trajectory") and c.angle_type == "heading":
        # relative to the road's reference line (the lane's direction in the lane system)
        if world.road is None or body.road_id is None:
            return False
        reference = world.road.road_to_world(body.road_id, body.s, 0.0).heading
        if c.coordinate_system != "road" and world.road.drives_backward(body.road_id, body.lane_id):
            reference += math.pi
        value -= reference
    return abs(wrap_angle(value - c.angle)) <= c.tolerance + 1e-9


def _outside_driving_lanes(world: ScenarioWorld, body: Body) -> bool:
    """The reference point is beyond every driving lane of its road (off the road)."""
    road = world.road
    if road is None or body.road_id is None:
        return True
    r = road.road(body.road_id)
    s = min(max(body.s, 0.0), r.length)
    t = road.lane_center_t(body.road_id, body.lane_id, body.s) + body.offset
    for lane, inner, outer in r.all_borders(s):
        if lane.id != 0 and lane.type != "none" and min(inner, outer) <= t <= max(inner, outer):
            return False
    return True


def relative_clearance(c: m.RelativeClearanceCondition, world: ScenarioWorld, body: Body) -> bool:
    """True when the lanes and distances given are clear of the listed (else of all) entities; freeSpace
    chooses bounding-box distances over reference points. As esmini: without a RelativeLaneRange it never
    holds; the range must hold at least one driving lane (lane ids from the entity's own id + from to + to,
    the opposite direction's only with oppositeLanes)."""
    road = world.road
    if c.lanes is None or road is None or body.road_id is None:
        return False
    low, high = body.lane_id + c.lanes[0], body.lane_id + c.lanes[1]
    if not any(
        low <= lane <= high and (c.opposite_lanes or (lane > 0) == (body.lane_id > 0))
        for lane in road.lane_ids(body.road_id, body.s, driving_only=True)
    ):
        return False
    others = [world.body(n) for n in c.entities] if c.entities else list(world.bodies.values())
    lanes = sorted(road.lane_ids(body.road_id, body.s))
    for other in others:
        if other is body or other.gone:
            continue
        lon = world.measure.relative_distance(body, other, "longitudinal", c.free_space, signed=True)
        if not (-c.distance_backward <= lon <= c.distance_forward):
            continue
        if other.road_id != body.road_id or other.lane_id not in lanes or body.lane_id not in lanes:
            continue
        d_lane = (lanes.index(other.lane_id) - lanes.index(body.lane_id)) * body.direction
        if not c.opposite_lanes and other.direction != body.direction:
            continue
        if c.lanes[0] <= d_lane <= c.lanes[1]:
            return False  # occupied
    return True


ValueEvaluator = Callable[[Any, "ScenarioWorld"], bool]
EntityEvaluator = Callable[[Any, "ScenarioWorld", "Body"], bool]
ValueBinder = Callable[[Any, "ScenarioWorld"], Bound]
EntityBinder = Callable[[Any, "ScenarioWorld"], EntityTest]

#: value condition type → its evaluation
VALUE_CONDITIONS: Final[dict[type, ValueEvaluator]] = {
    m.SimulationTimeCondition: simulation_time,
    m.StoryboardElementStateCondition: storyboard_element_state,
    m.ParameterCondition: stored_value,
    m.VariableCondition: stored_value,
    m.TrafficSignalCondition: traffic_signal,
    m.TrafficSignalControllerCondition: traffic_signal_controller,
    m.UnsupportedCondition: unsupported,
}

#: entity condition type → its evaluation for one triggering entity, bound to one run, where binding saves
#: work at every evaluation
ENTITY_BINDERS: Final[dict[type, EntityBinder]] = {
    m.CollisionCondition: bind_collision,
    m.TimeHeadwayCondition: bind_time_headway,
    m.RelativeDistanceCondition: bind_relative_distance,
}

#: value condition type → its evaluation bound to one run, where binding saves work at every evaluation
VALUE_BINDERS: Final[dict[type, ValueBinder]] = {
    m.SimulationTimeCondition: bind_simulation_time,
    m.StoryboardElementStateCondition: bind_storyboard_element_state,
}

#: entity condition type → its evaluation for one triggering entity
ENTITY_CONDITIONS: Final[dict[type, EntityEvaluator]] = {
    m.SpeedCondition: speed,
    m.AccelerationCondition: acceleration,
    m.TraveledDistanceCondition: traveled_distance,
    m.StandStillCondition: stand_still,
    m.EndOfRoadCondition: end_of_road,
    m.RelativeSpeedCondition: relative_speed,
    m.CollisionCondition: collision,
    m.ReachPositionCondition: reach_position,
    m.DistanceCondition: distance,
    m.RelativeDistanceCondition: relative_distance,
    m.TimeHeadwayCondition: time_headway,
    m.TimeToCollisionCondition: time_to_collision,
    m.OffroadCondition: offroad,
    m.AngleCondition: angle,
    m.RelativeAngleCondition: angle,
    m.RelativeClearanceCondition: relative_clearance,
    m.UnsupportedCondition: unsupported,
}
