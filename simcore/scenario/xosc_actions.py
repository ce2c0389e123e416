"""Actions for the OpenSCENARIO parser: private actions (speed, lane change and lane offset with their
dynamics, longitudinal and lateral distance, speed profile, synchronize, routing and trajectories, teleport,
trailers, controllers; those that change no motion recorded with a warning) and global actions (parameters
and variables, entities, traffic signals).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Literal

from simcore.scenario import model as m
from simcore.scenario.xosc_entities import _controller
from simcore.scenario.xosc_positions import _position, _route_or_ref, _trajectory_or_ref
from simcore.scenario.xosc_reader import _freespace, _Reader

_NO_MOTION = {
    "VisibilityAction": "changes what sensors see, not motion",
    "AppearanceAction": "lights and animations change no motion here",
    "LightStateAction": "lights change no motion here",
    "AnimationAction": "animations change no motion here",
}


def _private(reader: _Reader, element: ET.Element) -> m.PrivateAction:
    inner = reader.only_child(element)
    tag = inner.tag
    if tag == "TeleportAction":
        return m.TeleportAction(position=_position(reader, reader.child(inner, "Position")))
    if tag == "TrailerAction":
        action = reader.only_child(inner)
        if action.tag == "ConnectTrailerAction":
            return m.TrailerAction(trailer=reader.attr(action, "trailerRef"))
        if action.tag == "DisconnectTrailerAction":
            return m.TrailerAction(trailer=None)
        raise reader.fail(f"TrailerAction/{action.tag} is not supported", action)
    if tag == "LongitudinalAction":
        action = reader.only_child(inner)
        if action.tag == "SpeedAction":
            return _speed_action(reader, action)
        if action.tag == "LongitudinalDistanceAction":
            return _longitudinal_distance(reader, action)
        if action.tag == "SpeedProfileAction":
            return _speed_profile(reader, action)
        raise reader.fail(f"LongitudinalAction/{action.tag} is not supported", action)
    if tag == "LateralAction":
        action = reader.only_child(inner)
        if action.tag == "LaneChangeAction":
            return _lane_change(reader, action)
        if action.tag == "LaneOffsetAction":
            return _lane_offset(reader, action)
        if action.tag == "LateralDistanceAction":
            return m.LateralDistanceAction(
                entity=reader.attr(action, "entityRef"),
                distance=reader.num(action, "distance", 0.0),
                freespace=_freespace(reader, action),
                continuous=reader.boolean(action, "continuous", False),
                # without the attribute the entity goes to the left of the other (esmini's default)
                displacement=reader.attr(action, "displacement", "leftToReferencedEntity"),
                constraints=_constraints(reader, action.find("DynamicConstraints")),
                coordinate_system=reader.attr(action, "coordinateSystem", "entity"),
            )
        raise reader.fail(f"LateralAction/{action.tag} is not supported", action)
    if tag == "RoutingAction":
        action = reader.only_child(inner)
        if action.tag == "RandomRouteAction":
            # 1.3: a random route from where the entity is; it follows its lane and takes the default way at
            # junctions (as it does without a route; esmini's choice there is random too)
            reader.warn("RandomRouteAction: no route is drawn; the entity follows its lane", action)
            return m.NoMotionAction("RandomRouteAction")
        if action.tag == "AssignRouteAction":
            return m.AssignRouteAction(route=_route_or_ref(reader, action))
        if action.tag == "FollowTrajectoryAction":
            return _follow_trajectory(reader, action)
        if action.tag == "AcquirePositionAction":
            return m.AcquirePositionAction(position=_position(reader, reader.child(action, "Position")))
        raise reader.fail(f"RoutingAction/{action.tag} is not supported", action)
    if tag == "SynchronizeAction":
        return _synchronize(reader, inner)
    if tag in ("ControllerAction", "ActivateControllerAction"):
        return _controller_action(reader, inner)
    if tag in _NO_MOTION:
        detail = reader.only_child(inner).tag if len(inner) and tag != "VisibilityAction" else ""
        kind = f"{tag}/{detail}" if detail else tag
        reader.warn(f"{kind} is recorded only: {_NO_MOTION[tag]}", inner)
        return m.NoMotionAction(kind)
    raise reader.fail(f"{tag} is not supported", inner)


def _controller_action(reader: _Reader, inner: ET.Element) -> m.PrivateAction:
    """ActivateControllerAction (1.0: a PrivateAction of its own; 1.1+: inside ControllerAction) and
    AssignControllerAction (its activate* attributes, 1.2+)."""

    def flag(element: ET.Element, name: str) -> bool | None:
        raw = reader.attr(element, name, "")
        if raw == "":
            return None
        if raw.lower() not in ("true", "false", "1", "0"):
            raise reader.fail(f"{name}={raw!r} is not a boolean", element)
        return raw.lower() in ("true", "1")

    def ref(activate: ET.Element) -> str | None:
        return activate.get("objectControllerRef") or activate.get("controllerRef") or None

    if inner.tag == "ActivateControllerAction":
        return m.ControllerAction(
            longitudinal=flag(inner, "longitudinal"), lateral=flag(inner, "lateral"), ref=ref(inner)
        )
    assign: str | None = None
    longitudinal: bool | None = None
    lateral: bool | None = None
    controller: tuple[tuple[str, str], ...] = ()
    activated: str | None = None
    for child in inner:
        if child.tag == "AssignControllerAction":
            properties = _controller(reader, child)
            driver = properties.get("carlos.driver")
            if driver == "sumo":
                raise reader.fail(
                    "the SUMO driver can only be given in the entity's ObjectController, not assigned later",
                    child,
                )
            external = driver == "external" or m.controller_type(properties) in m.EXTERNAL_CONTROLLERS
            assign = "external" if external else "scenario"
            controller = tuple(properties.items())
            longitudinal = flag(child, "activateLongitudinal")
            lateral = flag(child, "activateLateral")
        elif child.tag == "ActivateControllerAction":
            longitudinal = flag(child, "longitudinal")
            lateral = flag(child, "lateral")
            activated = ref(child)
        elif child.tag.startswith("Override"):
            reader.warn(f"{child.tag} is ignored (no driver model to override)", child)
    return m.ControllerAction(
        assign=assign, longitudinal=longitudinal, lateral=lateral, controller=controller, ref=activated
    )


_MODIFY_RULES: dict[str, Literal["add", "multiply"]] = {"AddValue": "add", "MultiplyByValue": "multiply"}


def _global(reader: _Reader, element: ET.Element) -> m.GlobalAction:
    inner = reader.only_child(element)
    tag = inner.tag
    if tag in ("ParameterAction", "VariableAction"):
        variable = tag == "VariableAction"
        name = (inner.get("variableRef") if variable else inner.get("parameterRef")) or ""
        if not name:
            raise reader.fail("parameterRef/variableRef is required", inner)
        body = reader.only_child(inner)
        if body.tag == "SetAction":
            return m.ParameterSetAction(
                name=name.lstrip("$"), value=reader.attr(body, "value"), variable=variable
            )
        if body.tag == "ModifyAction":
            rule = reader.only_child(reader.child(body, "Rule"))
            kinds = _MODIFY_RULES
            if rule.tag not in kinds:
                raise reader.fail(f"unknown modify rule <{rule.tag}>", rule)
            return m.ParameterModifyAction(
                name=name.lstrip("$"),
                rule=kinds[rule.tag],
                value=reader.num(rule, "value"),
                variable=variable,
            )
        raise reader.fail(f"unknown {tag} <{body.tag}>", body)
    if tag in ("ParameterSetAction", "VariableSetAction"):
        variable = tag == "VariableSetAction"
        name = (inner.get("variableRef") if variable else inner.get("parameterRef")) or ""
        return m.ParameterSetAction(
            name=name.lstrip("$"), value=reader.attr(inner, "value"), variable=variable
        )
    if tag in ("ParameterModifyAction", "VariableModifyAction"):
        variable = tag == "VariableModifyAction"
        name = (inner.get("variableRef") if variable else inner.get("parameterRef")) or ""
        rule = reader.only_child(reader.child(inner, "Rule"))
        kinds = _MODIFY_RULES
        if rule.tag not in kinds:
            raise reader.fail(f"unknown modify rule <{rule.tag}>", rule)
        return m.ParameterModifyAction(
            name=name.lstrip("$"),
            rule=kinds[rule.tag],
            value=reader.num(rule, "value"),
            variable=variable,
        )
    if tag == "EntityAction":
        entity = reader.attr(inner, "entityRef")
        body = reader.only_child(inner)
        if body.tag == "AddEntityAction":
            return m.AddEntityAction(
                entity=entity, position=_position(reader, reader.child(body, "Position"))
            )
        if body.tag == "DeleteEntityAction":
            return m.DeleteEntityAction(entity=entity)
        raise reader.fail(f"unknown EntityAction <{body.tag}>", body)
    if tag == "InfrastructureAction":
        signal = reader.only_child(reader.child(inner, "TrafficSignalAction"))
        if signal.tag == "TrafficSignalStateAction":
            return m.TrafficSignalStateAction(
                name=reader.attr(signal, "name"), state=reader.attr(signal, "state")
            )
        if signal.tag == "TrafficSignalControllerAction":
            return m.TrafficSignalControllerAction(
                controller=reader.attr(signal, "trafficSignalControllerRef"),
                phase=reader.attr(signal, "phase"),
            )
        raise reader.fail(f"TrafficSignalAction/{signal.tag} is not supported", signal)
    if tag == "EnvironmentAction":
        reader.warn(
            "EnvironmentAction is recorded only (weather and time of day change no motion here)", inner
        )
        return m.NoMotionGlobalAction(tag)
    detail = reader.only_child(inner).tag if len(inner) else ""
    kind = f"{tag}/{detail}" if detail else tag
    if tag in ("TrafficAction", "SetMonitorAction"):
        reader.warn(f"{kind} is not modelled: ignored (it moves no scripted entity)", inner)
        return m.NoMotionGlobalAction(kind)
    raise reader.fail(f"GlobalAction/{kind} is not supported", inner)


def _constraints(reader: _Reader, element: ET.Element | None) -> m.DynamicConstraints | None:
    if element is None:
        return None
    return m.DynamicConstraints(
        max_acceleration=reader.opt_num(element, "maxAcceleration"),
        max_deceleration=reader.opt_num(element, "maxDeceleration"),
        max_speed=reader.opt_num(element, "maxSpeed"),
        max_acceleration_rate=reader.opt_num(element, "maxAccelerationRate"),
        max_deceleration_rate=reader.opt_num(element, "maxDecelerationRate"),
    )


def _longitudinal_distance(reader: _Reader, action: ET.Element) -> m.LongitudinalDistanceAction:
    distance = reader.opt_num(action, "distance")
    time_gap = reader.opt_num(action, "timeGap")
    if (distance is None) == (time_gap is None):
        raise reader.fail("give exactly one of distance and timeGap", action)
    return m.LongitudinalDistanceAction(
        entity=reader.attr(action, "entityRef"),
        distance=distance,
        time_gap=time_gap,
        freespace=_freespace(reader, action),
        continuous=reader.boolean(action, "continuous", False),
        displacement=reader.attr(action, "displacement", "trailingReferencedEntity"),
        constraints=_constraints(reader, action.find("DynamicConstraints")),
        coordinate_system=reader.attr(action, "coordinateSystem", "entity"),
    )


def _speed_profile(reader: _Reader, action: ET.Element) -> m.SpeedProfileAction:
    entries = tuple(
        m.SpeedProfileEntry(speed=reader.num(e, "speed"), time=reader.opt_num(e, "time"))
        for e in action.findall("SpeedProfileEntry")
    )
    if not entries:
        raise reader.fail("SpeedProfileAction needs at least one SpeedProfileEntry", action)
    dc = action.find("DynamicConstraints")
    return m.SpeedProfileAction(
        entity=action.get("entityRef") and reader.attr(action, "entityRef"),
        following_mode=reader.attr(action, "followingMode", "follow"),
        entries=entries,
        constraints=_constraints(reader, dc),
        max_jerk=None if dc is None else reader.opt_num(dc, "maxAccelerationRate"),
    )


def _lane_offset(reader: _Reader, action: ET.Element) -> m.LaneOffsetAction:
    dyn = reader.child(action, "LaneOffsetActionDynamics")
    shape = reader.attr(dyn, "dynamicsShape", "linear")
    if shape not in ("linear", "cubic", "sinusoidal", "step"):
        raise reader.fail(f"dynamicsShape={shape!r}: expected linear, cubic, sinusoidal or step", dyn)
    target = reader.only_child(reader.child(action, "LaneOffsetTarget"))
    entity = None
    if target.tag == "RelativeTargetLaneOffset":
        entity = reader.attr(target, "entityRef")
    elif target.tag != "AbsoluteTargetLaneOffset":
        raise reader.fail(f"unknown lane offset target <{target.tag}>", target)
    return m.LaneOffsetAction(
        shape=shape,  # type: ignore[arg-type]
        max_lateral_acc=reader.opt_num(dyn, "maxLateralAcc"),
        offset=reader.num(target, "value"),
        entity=entity,
        continuous=reader.boolean(action, "continuous", False),
    )


def _synchronize(reader: _Reader, action: ET.Element) -> m.SynchronizeAction:
    final_speed = None
    final_relative = None
    steady_distance = steady_time = None
    fs = action.find("FinalSpeed")
    if fs is not None:
        body = reader.only_child(fs)
        sd = body.find("TargetDistanceSteadyState")
        st = body.find("TargetTimeSteadyState")
        steady_distance = reader.num(sd, "distance") if sd is not None else None
        steady_time = reader.num(st, "time") if st is not None else None
        if body.tag == "AbsoluteSpeed":
            final_speed = reader.num(body, "value")
        elif body.tag == "RelativeSpeedToMaster":
            final_relative = (
                reader.attr(action, "masterEntityRef"),
                reader.num(body, "value"),
                reader.attr(body, "speedTargetValueType", "delta"),
            )
        else:
            raise reader.fail(f"unknown final speed <{body.tag}>", body)
    return m.SynchronizeAction(
        master=reader.attr(action, "masterEntityRef"),
        master_position=_position(reader, reader.child(action, "TargetPositionMaster")),
        position=_position(reader, reader.child(action, "TargetPosition")),
        master_tolerance=reader.num(action, "targetToleranceMaster", 0.0),
        tolerance=reader.num(action, "targetTolerance", 0.0),
        final_speed=final_speed,
        final_relative=final_relative,
        steady_distance=steady_distance,
        steady_time=steady_time,
    )


def _follow_trajectory(reader: _Reader, action: ET.Element) -> m.FollowTrajectoryAction:
    trajectory = _trajectory_or_ref(reader, action)
    timing: str = "none"
    scale, offset = 1.0, 0.0
    ref = action.find("TimeReference")
    if ref is not None:
        body = reader.only_child(ref)
        if body.tag == "Timing":
            timing = reader.attr(body, "domainAbsoluteRelative")
            if timing not in ("absolute", "relative"):
                raise reader.fail(f"domainAbsoluteRelative={timing!r}: expected absolute or relative", body)
            scale = reader.num(body, "scale", 1.0)
            offset = reader.num(body, "offset", 0.0)
    mode_el = action.find("TrajectoryFollowingMode")
    mode = reader.attr(mode_el, "followingMode", "position") if mode_el is not None else "position"
    if mode == "follow":
        reader.warn("followingMode=follow is run as position (no steering model): motion is exact", mode_el)
    return m.FollowTrajectoryAction(
        trajectory=trajectory,
        timing=timing,  # type: ignore[arg-type]
        scale=scale,
        offset=offset,
        initial_distance_offset=reader.num(action, "initialDistanceOffset", 0.0),
        following_mode=mode,
    )


def _dynamics(reader: _Reader, element: ET.Element) -> m.TransitionDynamics:
    shape = reader.attr(element, "dynamicsShape")
    dimension = reader.attr(element, "dynamicsDimension")
    if shape not in ("linear", "cubic", "sinusoidal", "step"):
        raise reader.fail(f"dynamicsShape={shape!r}: expected linear, cubic, sinusoidal or step", element)
    if dimension not in ("time", "distance", "rate"):
        raise reader.fail(f"dynamicsDimension={dimension!r}: expected time, distance or rate", element)
    value = reader.num(element, "value")
    if value < 0:
        reader.warn(f"value={value} is negative: its magnitude is used", element)
        value = -value
    return m.TransitionDynamics(shape=shape, dimension=dimension, value=value)  # type: ignore[arg-type]


def _speed_action(reader: _Reader, action: ET.Element) -> m.SpeedAction:
    target_el = reader.only_child(reader.child(action, "SpeedActionTarget"))
    target: m.AbsoluteTargetSpeed | m.RelativeTargetSpeed
    if target_el.tag == "AbsoluteTargetSpeed":
        target = m.AbsoluteTargetSpeed(value=reader.num(target_el, "value"))
    elif target_el.tag == "RelativeTargetSpeed":
        value_type = reader.attr(target_el, "speedTargetValueType")
        if value_type not in ("delta", "factor"):
            raise reader.fail(f"speedTargetValueType={value_type!r}: expected delta or factor", target_el)
        target = m.RelativeTargetSpeed(
            entity=reader.attr(target_el, "entityRef"),
            value=reader.num(target_el, "value"),
            value_type=value_type,  # type: ignore[arg-type]
            continuous=reader.boolean(target_el, "continuous", False),
        )
    else:
        raise reader.fail(f"unknown speed target <{target_el.tag}>", target_el)
    return m.SpeedAction(
        dynamics=_dynamics(reader, reader.child(action, "SpeedActionDynamics")), target=target
    )


def _lane_change(reader: _Reader, action: ET.Element) -> m.LaneChangeAction:
    target_el = reader.only_child(reader.child(action, "LaneChangeTarget"))
    target: m.AbsoluteTargetLane | m.RelativeTargetLane
    if target_el.tag == "AbsoluteTargetLane":
        target = m.AbsoluteTargetLane(lane_id=reader.integer(target_el, "value"))
    elif target_el.tag == "RelativeTargetLane":
        target = m.RelativeTargetLane(
            entity=reader.attr(target_el, "entityRef"), value=reader.integer(target_el, "value")
        )
    else:
        raise reader.fail(f"unknown lane target <{target_el.tag}>", target_el)
    return m.LaneChangeAction(
        dynamics=_dynamics(reader, reader.child(action, "LaneChangeActionDynamics")),
        target=target,
        target_lane_offset=reader.num(action, "targetLaneOffset", 0.0),
    )
