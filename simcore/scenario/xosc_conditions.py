"""Triggers and conditions for the OpenSCENARIO parser: a trigger's ConditionGroups, each Condition's edge
and delay, its ByValueCondition or ByEntityCondition (with triggering entities, rules, distance frames).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from simcore.scenario import model as m
from simcore.scenario.xosc_positions import _position
from simcore.scenario.xosc_reader import _freespace, _Reader

_RULES = ("greaterThan", "lessThan", "equalTo", "greaterOrEqual", "lessOrEqual", "notEqualTo")


def _rule(reader: _Reader, element: ET.Element) -> m.Rule:
    rule = reader.attr(element, "rule")
    if rule not in _RULES:
        raise reader.fail(f"rule={rule!r}: expected one of {', '.join(_RULES)}", element)
    return rule  # type: ignore[return-value]


def _trigger(reader: _Reader, element: ET.Element) -> m.Trigger:
    groups = []
    for group in element.findall("ConditionGroup"):
        groups.append(tuple(_condition(reader, c) for c in group.findall("Condition")))
    return m.Trigger(groups=tuple(g for g in groups if g))


def _start_trigger(reader: _Reader, element: ET.Element | None) -> m.Trigger | None:
    """A StartTrigger; an empty one (no condition) starts at once, as esmini does (None)."""
    if element is None:
        return None
    trigger = _trigger(reader, element)
    return trigger if trigger.groups else None


def _condition(reader: _Reader, element: ET.Element) -> m.Condition:
    edge = reader.attr(element, "conditionEdge", "none")
    if edge not in ("rising", "falling", "risingOrFalling", "none"):
        raise reader.fail(
            f"conditionEdge={edge!r}: expected rising, falling, risingOrFalling or none", element
        )
    name = reader.attr(element, "name", "")
    delay = reader.num(element, "delay", 0.0)
    body = reader.only_child(element)
    if body.tag == "ByValueCondition":
        return m.Condition(
            name=name,
            delay=delay,
            edge=edge,  # type: ignore[arg-type]
            value_condition=_value_condition(reader, reader.only_child(body)),
        )
    if body.tag == "ByEntityCondition":
        te = reader.child(body, "TriggeringEntities")
        rule = reader.attr(te, "triggeringEntitiesRule", "any")
        if rule not in ("any", "all"):
            raise reader.fail(f"triggeringEntitiesRule={rule!r}: expected any or all", te)
        entities = tuple(reader.attr(r, "entityRef") for r in te.findall("EntityRef"))
        inner = reader.only_child(reader.child(body, "EntityCondition"))
        return m.Condition(
            name=name,
            delay=delay,
            edge=edge,  # type: ignore[arg-type]
            entity_condition=_entity_condition(reader, inner),
            triggering_entities=entities,
            triggering_rule=rule,  # type: ignore[arg-type]
        )
    raise reader.fail(f"unknown condition <{body.tag}>", body)


_ELEMENT_STATES = (
    "startTransition",
    "endTransition",
    "stopTransition",
    "skipTransition",
    "completeState",
    "runningState",
    "standbyState",
)
_ELEMENT_TYPES = ("story", "act", "maneuverGroup", "maneuver", "event", "action")


def _value_condition(reader: _Reader, c: ET.Element) -> m.ValueCondition:
    if c.tag == "SimulationTimeCondition":
        return m.SimulationTimeCondition(value=reader.num(c, "value"), rule=_rule(reader, c))
    if c.tag == "StoryboardElementStateCondition":
        state = reader.attr(c, "state")
        if state not in _ELEMENT_STATES:
            raise reader.fail(f"state={state!r}: expected one of {', '.join(_ELEMENT_STATES)}", c)
        kind = reader.attr(c, "storyboardElementType")
        if kind not in _ELEMENT_TYPES:
            raise reader.fail(
                f"storyboardElementType={kind!r}: expected one of {', '.join(_ELEMENT_TYPES)}", c
            )
        return m.StoryboardElementStateCondition(
            element_type=kind,
            element_ref=reader.attr(c, "storyboardElementRef"),
            state=state,
        )
    if c.tag == "ParameterCondition":
        return m.ParameterCondition(
            name=reader.attr(c, "parameterRef").lstrip("$"),
            value=reader.attr(c, "value"),
            rule=_rule(reader, c),
        )
    if c.tag == "VariableCondition":
        return m.VariableCondition(
            name=reader.attr(c, "variableRef").lstrip("$"),
            value=reader.attr(c, "value"),
            rule=_rule(reader, c),
        )
    if c.tag == "TrafficSignalCondition":
        return m.TrafficSignalCondition(name=reader.attr(c, "name"), state=reader.attr(c, "state"))
    if c.tag == "TrafficSignalControllerCondition":
        return m.TrafficSignalControllerCondition(
            controller=reader.attr(c, "trafficSignalControllerRef"), phase=reader.attr(c, "phase")
        )
    if c.tag in (
        "UserDefinedValueCondition",
        "TimeOfDayCondition",
    ):
        reader.warn(f"{c.tag} is not evaluated: it never holds", c)
        return m.UnsupportedCondition(c.tag)
    raise reader.fail(f"ByValueCondition/{c.tag} is not supported", c)


_SYSTEMS = ("entity", "road", "lane", "trajectory")
_DISTANCE_TYPES = ("longitudinal", "lateral", "cartesianDistance", "euclidianDistance")


def _distance_frame(reader: _Reader, c: ET.Element) -> tuple[str, str]:
    """coordinateSystem and relativeDistanceType of a distance, headway or time-to-collision condition
    (1.1+), defaulting to the entity system and the Euclidean distance; without either, 1.0's
    alongRoute="true" selects the road system."""
    system = reader.attr(c, "coordinateSystem", "")
    kind = reader.attr(c, "relativeDistanceType", "")
    if not system and not kind and c.get("alongRoute") is not None and reader.boolean(c, "alongRoute"):
        system = "road"
    system = system or "entity"
    kind = kind or "euclidianDistance"
    if system not in _SYSTEMS:
        raise reader.fail(f"coordinateSystem={system!r}: expected one of {', '.join(_SYSTEMS)}", c)
    if kind not in _DISTANCE_TYPES:
        raise reader.fail(f"relativeDistanceType={kind!r}: expected one of {', '.join(_DISTANCE_TYPES)}", c)
    return system, kind


def _direction(reader: _Reader, c: ET.Element) -> str | None:
    """The DirectionalDimension of a speed condition (1.2+), None when absent."""
    if c.get("direction") is None:
        return None
    direction = reader.attr(c, "direction")
    if direction not in ("longitudinal", "lateral", "vertical"):
        raise reader.fail(f"direction={direction!r}: expected longitudinal, lateral or vertical", c)
    return direction


def _entity_condition(reader: _Reader, c: ET.Element) -> m.EntityCondition:
    tag = c.tag
    if tag == "RelativeDistanceCondition":
        kind = reader.attr(c, "relativeDistanceType")
        if kind not in ("longitudinal", "lateral", "cartesianDistance", "euclidianDistance"):
            raise reader.fail(f"relativeDistanceType={kind!r} is not supported", c)
        return m.RelativeDistanceCondition(
            entity=reader.attr(c, "entityRef"),
            distance_type=kind,  # type: ignore[arg-type]
            freespace=_freespace(reader, c),
            value=reader.num(c, "value"),
            rule=_rule(reader, c),
            coordinate_system=reader.attr(c, "coordinateSystem", "entity"),
        )
    if tag == "SpeedCondition":
        return m.SpeedCondition(
            value=reader.num(c, "value"), rule=_rule(reader, c), direction=_direction(reader, c)
        )
    if tag == "RelativeSpeedCondition":
        return m.RelativeSpeedCondition(
            entity=reader.attr(c, "entityRef"),
            value=reader.num(c, "value"),
            rule=_rule(reader, c),
            direction=_direction(reader, c),
        )
    if tag == "AccelerationCondition":
        return m.AccelerationCondition(value=reader.num(c, "value"), rule=_rule(reader, c))
    if tag == "TraveledDistanceCondition":
        return m.TraveledDistanceCondition(value=reader.num(c, "value"))
    if tag == "ReachPositionCondition":
        return m.ReachPositionCondition(
            position=_position(reader, reader.child(c, "Position")), tolerance=reader.num(c, "tolerance")
        )
    if tag == "DistanceCondition":
        system, kind = _distance_frame(reader, c)
        return m.DistanceCondition(
            position=_position(reader, reader.child(c, "Position")),
            freespace=_freespace(reader, c),
            value=reader.num(c, "value"),
            rule=_rule(reader, c),
            distance_type=kind,
            coordinate_system=system,
        )
    if tag in ("TimeHeadwayCondition", "TimeToCollisionCondition"):
        system, kind = _distance_frame(reader, c)
        if tag == "TimeToCollisionCondition":
            target_el = reader.only_child(reader.child(c, "TimeToCollisionConditionTarget"))
            if target_el.tag == "Position":
                return m.TimeToCollisionCondition(
                    entity="",
                    freespace=_freespace(reader, c),
                    value=reader.num(c, "value"),
                    rule=_rule(reader, c),
                    coordinate_system=system,
                    position=_position(reader, target_el),
                    distance_type=kind,
                )
            return m.TimeToCollisionCondition(
                entity=reader.attr(target_el, "entityRef"),
                freespace=_freespace(reader, c),
                value=reader.num(c, "value"),
                rule=_rule(reader, c),
                coordinate_system=system,
                distance_type=kind,
            )
        return m.TimeHeadwayCondition(
            entity=reader.attr(c, "entityRef"),
            freespace=_freespace(reader, c),
            value=reader.num(c, "value"),
            rule=_rule(reader, c),
            coordinate_system=system,
            distance_type=kind,
        )
    if tag == "StandStillCondition":
        return m.StandStillCondition(duration=reader.num(c, "duration"))
    if tag == "EndOfRoadCondition":
        return m.EndOfRoadCondition(duration=reader.num(c, "duration"))
    if tag == "CollisionCondition":
        ref = c.find("EntityRef")
        return m.CollisionCondition(entity=reader.attr(ref, "entityRef") if ref is not None else None)
    if tag == "OffroadCondition":
        return m.OffroadCondition(duration=reader.num(c, "duration"))
    if tag == "RelativeClearanceCondition":
        lanes = None
        rng = c.find("RelativeLaneRange")
        if rng is not None:
            lanes = (reader.integer(rng, "from", -99), reader.integer(rng, "to", 99))
        return m.RelativeClearanceCondition(
            entities=tuple(reader.attr(r, "entityRef") for r in c.findall("EntityRef")),
            free_space=reader.boolean(c, "freeSpace", True),
            distance_forward=reader.num(c, "distanceForward", 0.0),
            distance_backward=reader.num(c, "distanceBackward", 0.0),
            opposite_lanes=reader.boolean(c, "oppositeLanes", False),
            lanes=lanes,
        )
    if tag in ("AngleCondition", "RelativeAngleCondition"):
        angle_type = reader.attr(c, "angleType")
        if angle_type not in ("heading", "pitch", "roll"):
            raise reader.fail(f"angleType={angle_type!r}: expected heading, pitch or roll", c)
        tolerance = reader.num(c, "angleTolerance")
        if tolerance < 0:
            raise reader.fail(f"angleTolerance={tolerance:g} is negative", c)
        if tag == "RelativeAngleCondition":
            return m.RelativeAngleCondition(
                entity=reader.attr(c, "entityRef"),
                angle_type=angle_type,  # type: ignore[arg-type]
                angle=reader.num(c, "angle"),
                tolerance=tolerance,
            )
        system = reader.attr(c, "coordinateSystem", "entity")
        if system == "world":
            system = "entity"  # the heading in the world frame, as "entity" (esmini reads "world" so)
        if system not in _SYSTEMS:
            known = ", ".join((*_SYSTEMS, "world"))
            raise reader.fail(f"coordinateSystem={system!r}: expected one of {known}", c)
        return m.AngleCondition(
            angle_type=angle_type,  # type: ignore[arg-type]
            angle=reader.num(c, "angle"),
            tolerance=tolerance,
            coordinate_system=system,
        )
    raise reader.fail(f"EntityCondition/{tag} is not supported", c)
