"""OpenSCENARIO XML (1.0–1.3) → the object model, with parameters resolved.

Scenario files are untrusted: parsed with defusedxml (no entities, no external references), bounded in
size, and every problem raised as `BadInput` naming the file and the element path.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import defusedxml.ElementTree as SafeET
from defusedxml import DefusedXmlException

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario.parameters import Declaration, ParameterError, ParamValue, declare, resolve

MAX_SCENARIO_BYTES = 32 * 1024 * 1024
T = TypeVar("T")


def read_xml(path: Path, *, what: str, max_bytes: int = MAX_SCENARIO_BYTES) -> ET.Element:
    """Parse an untrusted XML file safely; errors name the file."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise BadInput(f"{what} not found", file=str(path)) from None
    if size > max_bytes:
        raise BadInput(f"{what} is {size} bytes; at most {max_bytes} are allowed", file=str(path))
    try:
        return SafeET.parse(str(path)).getroot()
    except DefusedXmlException as exc:
        raise BadInput(
            f"{what} uses forbidden XML constructs ({type(exc).__name__})", file=str(path)
        ) from None
    except ET.ParseError as exc:
        raise BadInput(f"{what} is not well-formed XML: {exc}", file=str(path)) from None


class _Reader:
    """Walks the XML with a stack of parameter scopes; `attr` resolves `$name` and `${…}`."""

    def __init__(self, path: Path, overrides: Mapping[str, ParamValue]) -> None:
        self.path = path
        self.overrides = dict(overrides)
        self.scopes: list[dict[str, ParamValue]] = [{}]
        self.where: list[str] = []

    # -- errors and scopes --
    def fail(self, message: str, element: ET.Element | None = None) -> BadInput:
        where = "/".join(self.where + ([element.tag] if element is not None else []))
        return BadInput(message, file=str(self.path), field=where or None)

    @property
    def values(self) -> dict[str, ParamValue]:
        return self.scopes[-1]

    def push_declarations(
        self, element: ET.Element, overrides: Mapping[str, ParamValue] | None = None
    ) -> None:
        declarations = []
        block = element.find("ParameterDeclarations")
        if block is not None:
            for item in block.findall("ParameterDeclaration"):
                name = item.get("name")
                if not name:
                    raise self.fail("ParameterDeclaration without a name", item)
                declarations.append(
                    Declaration(
                        name=name, type=item.get("parameterType", "string"), value=item.get("value", "")
                    )
                )
        try:
            self.scopes.append(declare(declarations, self.values, overrides))
        except ParameterError as exc:
            raise self.fail(str(exc), block) from None

    def pop(self) -> None:
        self.scopes.pop()

    # -- attributes --
    def attr(self, element: ET.Element, name: str, default: str | None = None) -> str:
        raw = element.get(name)
        if raw is None:
            if default is None:
                raise self.fail(f"attribute {name!r} is required", element)
            return default
        try:
            return resolve(raw, self.values)
        except ParameterError as exc:
            raise self.fail(f"{name}={raw!r}: {exc}", element) from None

    def num(self, element: ET.Element, name: str, default: float | None = None) -> float:
        raw = self.attr(element, name, None if default is None else repr(default))
        try:
            value = float(raw)
        except ValueError:
            raise self.fail(f"{name}={raw!r} is not a number", element) from None
        if not math.isfinite(value):
            raise self.fail(f"{name}={raw!r} is not finite", element)
        return value

    def opt_num(self, element: ET.Element, name: str) -> float | None:
        return None if element.get(name) is None else self.num(element, name)

    def integer(self, element: ET.Element, name: str, default: int | None = None) -> int:
        value = self.num(element, name, None if default is None else float(default))
        if value != int(value):
            raise self.fail(f"{name}={value!r} is not an integer", element)
        return int(value)

    def boolean(self, element: ET.Element, name: str, default: bool | None = None) -> bool:
        raw = self.attr(element, name, None if default is None else ("true" if default else "false"))
        if raw.lower() in ("true", "1"):
            return True
        if raw.lower() in ("false", "0"):
            return False
        raise self.fail(f"{name}={raw!r} is not true or false", element)

    def child(self, element: ET.Element, tag: str) -> ET.Element:
        found = element.find(tag)
        if found is None:
            raise self.fail(f"element <{tag}> is required", element)
        return found

    def only_child(self, element: ET.Element) -> ET.Element:
        children = [c for c in element if isinstance(c.tag, str)]
        if len(children) != 1:
            raise self.fail(f"expected exactly one child element, found {len(children)}", element)
        return children[0]

    def within(self, element: ET.Element, label: str | None, fn: Callable[..., T], *args: Any) -> T:
        """`fn(*args)` with `element` on the path that error messages name."""
        self.where.append(f"{element.tag}[{label}]" if label else element.tag)
        try:
            return fn(*args)
        finally:
            self.where.pop()


def load_scenario(path: str | Path, overrides: Mapping[str, ParamValue] | None = None) -> m.Scenario:
    """Parse an OpenSCENARIO file. `overrides` replace declared parameter defaults; a name the file does not
    declare is bad input (a typo in a sweep must not silently do nothing)."""
    path = Path(path)
    root = read_xml(path, what="OpenSCENARIO file")
    if root.tag != "OpenSCENARIO":
        raise BadInput(f"root element is <{root.tag}>, expected <OpenSCENARIO>", file=str(path))
    reader = _Reader(path, overrides or {})
    header = root.find("FileHeader")
    version = "1.0"
    description = ""
    if header is not None:
        version = f"{header.get('revMajor', '1')}.{header.get('revMinor', '0')}"
        description = header.get("description", "")
    declared = _declared_names(root)
    unknown = sorted(set(reader.overrides) - declared)
    if unknown:
        listed = ", ".join(unknown)
        known = ", ".join(sorted(declared)) or "none"
        raise BadInput(
            f"parameter(s) {listed} not declared in the scenario (declared: {known})",
            file=str(path),
            field="ParameterDeclarations",
        )
    if root.find("Storyboard") is None:
        if root.find("ParameterValueDistribution") is not None:
            raise BadInput("this is a ParameterValueDistribution, not a scenario", file=str(path))
        raise BadInput("no <Storyboard>: not an OpenSCENARIO scenario", file=str(path))
    reader.push_declarations(root, reader.overrides)
    catalogs = _catalog_dirs(reader, root)
    road_file = None
    network = root.find("RoadNetwork")
    if network is not None:
        logic = network.find("LogicFile")
        if logic is not None:
            road_file = (path.parent / reader.attr(logic, "filepath")).resolve()
    entities = tuple(_entities(reader, reader.child(root, "Entities"), catalogs))
    names = {e.name for e in entities}
    storyboard = reader.child(root, "Storyboard")
    init = tuple(_init(reader, reader.child(storyboard, "Init")))
    stories = tuple(reader.within(s, s.get("name"), _story, reader, s) for s in storyboard.findall("Story"))
    stop = storyboard.find("StopTrigger")
    scenario = m.Scenario(
        path=path,
        version=version,
        description=description,
        road_file=road_file,
        entities=entities,
        init=init,
        stories=stories,
        stop_trigger=_trigger(reader, stop) if stop is not None else None,
        parameters=dict(reader.scopes[1]),
    )
    _check_references(scenario, names)
    return scenario


def declared_parameters(path: str | Path) -> dict[str, str]:
    """The scenario's top-level parameter names and their declared default values (as written)."""
    root = read_xml(Path(path), what="OpenSCENARIO file")
    block = root.find("ParameterDeclarations")
    if block is None:
        return {}
    return {d.get("name", ""): d.get("value", "") for d in block.findall("ParameterDeclaration")}


def _declared_names(root: ET.Element) -> set[str]:
    block = root.find("ParameterDeclarations")
    if block is None:
        return set()
    return {d.get("name", "") for d in block.findall("ParameterDeclaration")}


def _check_references(scenario: m.Scenario, names: set[str]) -> None:
    def check(name: str, where: str) -> None:
        if name not in names:
            raise BadInput(
                f"entity {name!r} is not declared in <Entities>", file=str(scenario.path), field=where
            )

    for item in scenario.init:
        check(item.entity, "Storyboard/Init")
    for story in scenario.stories:
        for act in story.acts:
            for group in act.groups:
                for actor in group.actors:
                    check(actor, f"Story[{story.name}]/Act[{act.name}]/ManeuverGroup[{group.name}]/Actors")


# --- catalogs and entities --------------------------------------------------------------------------------


def _catalog_dirs(reader: _Reader, root: ET.Element) -> dict[str, Path]:
    dirs: dict[str, Path] = {}
    block = root.find("CatalogLocations")
    if block is None:
        return dirs
    for location in block:
        directory = location.find("Directory")
        if directory is not None:
            dirs[location.tag.removesuffix("Catalog")] = (
                reader.path.parent / reader.attr(directory, "path")
            ).resolve()
    return dirs


def _catalog_entry(
    reader: _Reader, ref: ET.Element, catalogs: dict[str, Path], kind: str
) -> tuple[ET.Element, dict[str, ParamValue]]:
    catalog_name = reader.attr(ref, "catalogName")
    entry_name = reader.attr(ref, "entryName")
    directory = catalogs.get(kind)
    if directory is None:
        raise reader.fail(
            f"CatalogReference to {catalog_name}/{entry_name} but no {kind}Catalog location", ref
        )
    assignments: dict[str, ParamValue] = {}
    block = ref.find("ParameterAssignments")
    if block is not None:
        for item in block.findall("ParameterAssignment"):
            assignments[reader.attr(item, "parameterRef").lstrip("$")] = reader.attr(item, "value")
    files = sorted(directory.glob("*.xosc")) if directory.is_dir() else []
    for file in files:
        root = read_xml(file, what="catalog")
        catalog = root.find("Catalog")
        if catalog is None or catalog.get("name") != catalog_name:
            continue
        for entry in catalog:
            if entry.get("name") == entry_name:
                return entry, assignments
    raise reader.fail(f"catalog entry {catalog_name}/{entry_name} not found under {directory}", ref)


def _entities(reader: _Reader, element: ET.Element, catalogs: dict[str, Path]) -> list[m.Entity]:
    entities = []
    for obj in element.findall("ScenarioObject"):
        name = reader.attr(obj, "name")
        entities.append(reader.within(obj, name, _entity, reader, obj, name, catalogs))
    if element.find("EntitySelection") is not None:
        raise reader.fail("EntitySelection is not supported yet", element)
    return entities


def _entity(reader: _Reader, obj: ET.Element, name: str, catalogs: dict[str, Path]) -> m.Entity:
    body = next(
        (c for c in obj if c.tag in ("Vehicle", "Pedestrian", "MiscObject", "CatalogReference")), None
    )
    if body is None:
        raise reader.fail("a ScenarioObject needs a Vehicle, Pedestrian, MiscObject or CatalogReference", obj)
    pushed = False
    if body.tag == "CatalogReference":
        entry, assignments = _catalog_entry(reader, body, catalogs, "Vehicle")
        if entry.tag not in ("Vehicle", "Pedestrian", "MiscObject"):
            entry2, assignments = _catalog_entry(reader, body, catalogs, entry.tag)
            entry = entry2
        reader.push_declarations(entry, assignments)
        pushed = True
        body = entry
    try:
        object_type = {"Vehicle": "vehicle", "Pedestrian": "pedestrian", "MiscObject": "miscObject"}[body.tag]
        category = reader.attr(
            body,
            {
                "Vehicle": "vehicleCategory",
                "Pedestrian": "pedestrianCategory",
                "MiscObject": "miscObjectCategory",
            }[body.tag],
            "car" if body.tag == "Vehicle" else "pedestrian" if body.tag == "Pedestrian" else "obstacle",
        )
        bbox = reader.child(body, "BoundingBox")
        center = reader.child(bbox, "Center")
        dims = reader.child(bbox, "Dimensions")
        box = m.Box(
            center_x=reader.num(center, "x"),
            center_y=reader.num(center, "y"),
            center_z=reader.num(center, "z"),
            length=reader.num(dims, "length"),
            width=reader.num(dims, "width"),
            height=reader.num(dims, "height"),
        )
        if min(box.length, box.width, box.height) < 0:
            raise reader.fail("BoundingBox dimensions must not be negative", dims)
        perf_el = body.find("Performance")
        performance = (
            m.Performance(
                max_speed=reader.num(perf_el, "maxSpeed"),
                max_acceleration=reader.num(perf_el, "maxAcceleration"),
                max_deceleration=reader.num(perf_el, "maxDeceleration"),
            )
            if perf_el is not None
            else m.Performance()
        )
        properties = _properties(reader, body)
    finally:
        if pushed:
            reader.pop()
    controller: dict[str, str] = {}
    oc = obj.find("ObjectController")
    if oc is not None:
        ctrl = oc.find("Controller")
        if ctrl is not None:
            controller = _properties(reader, ctrl)
            controller.setdefault("name", reader.attr(ctrl, "name", ""))
    return m.Entity(
        name=name,
        object_type=object_type,  # type: ignore[arg-type]
        category=category,
        box=box,
        performance=performance,
        properties=properties,
        controller=controller,
    )


def _properties(reader: _Reader, element: ET.Element) -> dict[str, str]:
    block = element.find("Properties")
    if block is None:
        return {}
    return {reader.attr(p, "name"): reader.attr(p, "value") for p in block.findall("Property")}


# --- storyboard ---------------------------------------------------------------------------------------------


def _init(reader: _Reader, init: ET.Element) -> list[m.InitAction]:
    out: list[m.InitAction] = []
    actions = init.find("Actions")
    if actions is None:
        return out
    for private in actions.findall("Private"):
        entity = reader.attr(private, "entityRef")
        for action in private.findall("PrivateAction"):
            out.append(
                m.InitAction(entity=entity, action=reader.within(private, entity, _private, reader, action))
            )
    for other in actions:
        if other.tag == "GlobalAction":
            raise reader.fail("GlobalAction in Init is not supported yet", other)
    return out


def _story(reader: _Reader, story: ET.Element) -> m.Story:
    reader.push_declarations(story)
    try:
        acts = tuple(reader.within(a, a.get("name"), _act, reader, a) for a in story.findall("Act"))
    finally:
        reader.pop()
    return m.Story(name=reader.attr(story, "name"), acts=acts)


def _act(reader: _Reader, act: ET.Element) -> m.Act:
    start = act.find("StartTrigger")
    stop = act.find("StopTrigger")
    return m.Act(
        name=reader.attr(act, "name"),
        groups=tuple(
            reader.within(g, g.get("name"), _group, reader, g) for g in act.findall("ManeuverGroup")
        ),
        start_trigger=_trigger(reader, start) if start is not None else None,
        stop_trigger=_trigger(reader, stop) if stop is not None else None,
    )


def _group(reader: _Reader, group: ET.Element) -> m.ManeuverGroup:
    actors_el = group.find("Actors")
    actors: tuple[str, ...] = ()
    select = False
    if actors_el is not None:
        select = reader.boolean(actors_el, "selectTriggeringEntities", False)
        actors = tuple(reader.attr(r, "entityRef") for r in actors_el.findall("EntityRef"))
    if group.find("CatalogReference") is not None:
        raise reader.fail("Maneuver catalog references are not supported yet", group)
    return m.ManeuverGroup(
        name=reader.attr(group, "name"),
        maximum_execution_count=reader.integer(group, "maximumExecutionCount", 1),
        actors=actors,
        select_triggering_entities=select,
        maneuvers=tuple(
            reader.within(mv, mv.get("name"), _maneuver, reader, mv) for mv in group.findall("Maneuver")
        ),
    )


def _maneuver(reader: _Reader, maneuver: ET.Element) -> m.Maneuver:
    reader.push_declarations(maneuver)
    try:
        events = tuple(reader.within(e, e.get("name"), _event, reader, e) for e in maneuver.findall("Event"))
    finally:
        reader.pop()
    return m.Maneuver(name=reader.attr(maneuver, "name"), events=events)


def _event(reader: _Reader, event: ET.Element) -> m.Event:
    priority = reader.attr(event, "priority", "override")
    if priority not in ("override", "overwrite", "skip", "parallel"):
        raise reader.fail(f"priority={priority!r}: expected override, overwrite, skip or parallel", event)
    start = event.find("StartTrigger")
    actions = []
    for action in event.findall("Action"):
        name = reader.attr(action, "name")
        private = action.find("PrivateAction")
        if private is None:
            inner = reader.only_child(action)
            raise reader.fail(
                f"action {name!r}: {inner.tag}/{reader.only_child(inner).tag} is not supported yet", action
            )
        actions.append(m.Action(name=name, private=reader.within(action, name, _private, reader, private)))
    return m.Event(
        name=reader.attr(event, "name"),
        priority=priority,  # type: ignore[arg-type]
        maximum_execution_count=reader.integer(event, "maximumExecutionCount", 1),
        actions=tuple(actions),
        start_trigger=_trigger(reader, start) if start is not None else None,
    )


# --- actions ----------------------------------------------------------------------------------------------


def _private(reader: _Reader, element: ET.Element) -> m.PrivateAction:
    inner = reader.only_child(element)
    if inner.tag == "TeleportAction":
        return m.TeleportAction(position=_position(reader, reader.child(inner, "Position")))
    if inner.tag == "LongitudinalAction":
        action = reader.only_child(inner)
        if action.tag == "SpeedAction":
            return _speed_action(reader, action)
        raise reader.fail(f"LongitudinalAction/{action.tag} is not supported yet", action)
    if inner.tag == "LateralAction":
        action = reader.only_child(inner)
        if action.tag == "LaneChangeAction":
            return _lane_change(reader, action)
        raise reader.fail(f"LateralAction/{action.tag} is not supported yet", action)
    detail = reader.only_child(inner).tag if len(inner) else ""
    raise reader.fail(f"{inner.tag}{'/' + detail if detail else ''} is not supported yet", inner)


def _dynamics(reader: _Reader, element: ET.Element) -> m.TransitionDynamics:
    shape = reader.attr(element, "dynamicsShape")
    dimension = reader.attr(element, "dynamicsDimension")
    if shape not in ("linear", "cubic", "sinusoidal", "step"):
        raise reader.fail(f"dynamicsShape={shape!r}: expected linear, cubic, sinusoidal or step", element)
    if dimension not in ("time", "distance", "rate"):
        raise reader.fail(f"dynamicsDimension={dimension!r}: expected time, distance or rate", element)
    value = reader.num(element, "value")
    if value < 0:
        raise reader.fail(f"value={value} must not be negative", element)
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


# --- positions --------------------------------------------------------------------------------------------


def _orientation(reader: _Reader, element: ET.Element) -> m.Orientation | None:
    o = element.find("Orientation")
    if o is None:
        return None
    kind = reader.attr(o, "type", "absolute")
    if kind not in ("relative", "absolute"):
        raise reader.fail(f"type={kind!r}: expected relative or absolute", o)
    return m.Orientation(
        type=kind,  # type: ignore[arg-type]
        h=reader.num(o, "h", 0.0),
        p=reader.num(o, "p", 0.0),
        r=reader.num(o, "r", 0.0),
    )


def _position(reader: _Reader, element: ET.Element) -> m.Position:
    p = reader.only_child(element)
    if p.tag == "WorldPosition":
        return m.WorldPosition(
            x=reader.num(p, "x"),
            y=reader.num(p, "y"),
            z=reader.opt_num(p, "z"),
            h=reader.opt_num(p, "h"),
            p=reader.num(p, "p", 0.0),
            r=reader.num(p, "r", 0.0),
        )
    if p.tag == "LanePosition":
        return m.LanePosition(
            road_id=reader.attr(p, "roadId"),
            lane_id=reader.integer(p, "laneId"),
            s=reader.num(p, "s"),
            offset=reader.num(p, "offset", 0.0),
            orientation=_orientation(reader, p),
        )
    if p.tag == "RoadPosition":
        return m.RoadPosition(
            road_id=reader.attr(p, "roadId"),
            s=reader.num(p, "s"),
            t=reader.num(p, "t"),
            orientation=_orientation(reader, p),
        )
    if p.tag == "RelativeLanePosition":
        ds = reader.opt_num(p, "ds")
        if ds is None:
            ds = reader.num(p, "dsLane", 0.0)
        return m.RelativeLanePosition(
            entity=reader.attr(p, "entityRef"),
            d_lane=reader.integer(p, "dLane"),
            ds=ds,
            offset=reader.num(p, "offset", 0.0),
            orientation=_orientation(reader, p),
        )
    if p.tag == "RelativeRoadPosition":
        return m.RelativeRoadPosition(
            entity=reader.attr(p, "entityRef"),
            ds=reader.num(p, "ds"),
            dt=reader.num(p, "dt"),
            orientation=_orientation(reader, p),
        )
    if p.tag in ("RelativeWorldPosition", "RelativeObjectPosition"):
        cls: Any = m.RelativeWorldPosition if p.tag == "RelativeWorldPosition" else m.RelativeObjectPosition
        return cls(
            entity=reader.attr(p, "entityRef"),
            dx=reader.num(p, "dx"),
            dy=reader.num(p, "dy"),
            dz=reader.num(p, "dz", 0.0),
            orientation=_orientation(reader, p),
        )
    raise reader.fail(f"position type <{p.tag}> is not supported yet", p)


# --- triggers and conditions -----------------------------------------------------------------------------

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


def _value_condition(reader: _Reader, c: ET.Element) -> m.ValueCondition:
    if c.tag == "SimulationTimeCondition":
        return m.SimulationTimeCondition(value=reader.num(c, "value"), rule=_rule(reader, c))
    if c.tag == "StoryboardElementStateCondition":
        return m.StoryboardElementStateCondition(
            element_type=reader.attr(c, "storyboardElementType"),
            element_ref=reader.attr(c, "storyboardElementRef"),
            state=reader.attr(c, "state"),
        )
    if c.tag == "ParameterCondition":
        return m.ParameterCondition(
            name=reader.attr(c, "parameterRef").lstrip("$"),
            value=reader.attr(c, "value"),
            rule=_rule(reader, c),
        )
    raise reader.fail(f"ByValueCondition/{c.tag} is not supported yet", c)


def _freespace(reader: _Reader, c: ET.Element) -> bool:
    return reader.boolean(c, "freespace", False)


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
        )
    if tag == "SpeedCondition":
        return m.SpeedCondition(value=reader.num(c, "value"), rule=_rule(reader, c))
    if tag == "RelativeSpeedCondition":
        return m.RelativeSpeedCondition(
            entity=reader.attr(c, "entityRef"), value=reader.num(c, "value"), rule=_rule(reader, c)
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
        return m.DistanceCondition(
            position=_position(reader, reader.child(c, "Position")),
            freespace=_freespace(reader, c),
            value=reader.num(c, "value"),
            rule=_rule(reader, c),
        )
    if tag in ("TimeHeadwayCondition", "TimeToCollisionCondition"):
        target = c
        entity = c.get("entityRef")
        if tag == "TimeToCollisionCondition":
            target_el = reader.only_child(reader.child(c, "TimeToCollisionConditionTarget"))
            if target_el.tag != "EntityRef":
                raise reader.fail("TimeToCollisionCondition to a position is not supported yet", target_el)
            entity = reader.attr(target_el, "entityRef")
        cls: Any = m.TimeHeadwayCondition if tag == "TimeHeadwayCondition" else m.TimeToCollisionCondition
        return cls(
            entity=entity if entity is not None else reader.attr(target, "entityRef"),
            freespace=_freespace(reader, c),
            value=reader.num(c, "value"),
            rule=_rule(reader, c),
        )
    if tag == "StandStillCondition":
        return m.StandStillCondition(duration=reader.num(c, "duration"))
    if tag == "EndOfRoadCondition":
        return m.EndOfRoadCondition(duration=reader.num(c, "duration"))
    if tag == "CollisionCondition":
        ref = c.find("EntityRef")
        return m.CollisionCondition(entity=reader.attr(ref, "entityRef") if ref is not None else None)
    raise reader.fail(f"EntityCondition/{tag} is not supported yet", c)
