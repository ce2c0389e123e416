"""OpenSCENARIO XML (1.0–1.3) → the object model, with parameters resolved: `load_scenario`, and the
scenario's top-level parameter declarations (`declared_parameters`, `parameter_declarations`).

Scenario files are untrusted: parsed with defusedxml (no entities, no external references), bounded in
size, and every problem raised as `BadInput` naming the file and the element path.

This module reads the file and assembles the scenario (header, parameters and variables, road network and
traffic signal controllers, the entity references check); its parts, bottom up: `xosc_xml` (safe XML
reading, `read_xml`), `xosc_reader` (the reading context: parameter scopes, attributes, errors),
`xosc_catalogs`, `xosc_positions` (with routes and trajectories), `xosc_entities`, `xosc_conditions`,
`xosc_actions`, `xosc_storyboard`.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario.parameters import Declaration, ParameterError, ParamValue, convert
from simcore.scenario.xosc_catalogs import _catalog_dirs
from simcore.scenario.xosc_conditions import _trigger
from simcore.scenario.xosc_entities import _entities
from simcore.scenario.xosc_reader import _Reader
from simcore.scenario.xosc_storyboard import _init, _story
from simcore.scenario.xosc_xml import parsed_xml, read_xml

__all__ = ["declared_parameters", "load_scenario", "parameter_declarations", "read_xml"]


def load_scenario(path: str | Path, overrides: Mapping[str, ParamValue] | None = None) -> m.Scenario:
    """Parse an OpenSCENARIO file. `overrides` replace declared parameter defaults; a name the file does not
    declare is bad input (a typo in a sweep must not silently do nothing)."""
    path = Path(path)
    parsed = parsed_xml(path, what="OpenSCENARIO file")
    root = parsed.root
    if root.tag != "OpenSCENARIO":
        raise BadInput(f"root element is <{root.tag}>, expected <OpenSCENARIO>", file=str(path))
    reader = _Reader(path, overrides or {})
    reader.lines = dict(parsed.lines)  # catalogs read while loading add their elements' lines
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
    _variables(reader, root)
    catalogs = _catalog_dirs(reader, root)
    reader.catalogs = catalogs
    road_file = None
    signal_controllers: tuple[m.SignalController, ...] = ()
    network = root.find("RoadNetwork")
    if network is not None:
        logic = network.find("LogicFile")
        if logic is not None:
            road_file = (path.parent / reader.attr(logic, "filepath")).resolve()
        signals = network.find("TrafficSignals")
        if signals is not None:
            signal_controllers = reader.within(network, None, _signal_controllers, reader, signals)
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
        variables=dict(reader.variables),
        signal_controllers=signal_controllers,
        warnings=tuple(reader.warnings),
    )
    _check_references(scenario, names)
    return scenario


def _signal_controllers(reader: _Reader, signals: ET.Element) -> tuple[m.SignalController, ...]:
    out = []
    for ctrl in signals.findall("TrafficSignalController"):
        phases = []
        for phase in ctrl.findall("Phase"):
            duration = reader.num(phase, "duration")
            if duration < 0:
                raise reader.fail(f"duration={duration:g} is negative", phase)
            states = tuple(
                (reader.attr(state, "trafficSignalId"), reader.attr(state, "state"))
                for state in phase.findall("TrafficSignalState")
            )
            phases.append(m.SignalPhase(name=reader.attr(phase, "name"), duration=duration, states=states))
        out.append(
            m.SignalController(
                name=reader.attr(ctrl, "name"),
                delay=reader.num(ctrl, "delay", 0.0),
                reference=reader.attr(ctrl, "reference") if ctrl.get("reference") else None,
                phases=tuple(phases),
            )
        )
    names = {c.name for c in out}
    for c in out:
        if c.reference is not None and c.reference not in names:
            raise reader.fail(f"TrafficSignalController {c.name!r}: reference {c.reference!r} does not exist")
    return tuple(out)


def declared_parameters(path: str | Path) -> dict[str, str]:
    """The scenario's top-level parameter names and their declared default values (as written)."""
    root = parsed_xml(Path(path), what="OpenSCENARIO file").root
    block = root.find("ParameterDeclarations")
    if block is None:
        return {}
    return {d.get("name", ""): d.get("value", "") for d in block.findall("ParameterDeclaration")}


def parameter_declarations(path: str | Path) -> dict[str, Declaration]:
    """The scenario's top-level parameter declarations by name (type and default as written)."""
    root = parsed_xml(Path(path), what="OpenSCENARIO file").root
    block = root.find("ParameterDeclarations")
    if block is None:
        return {}
    return {
        d.get("name", ""): Declaration(
            d.get("name", ""), d.get("parameterType", "string"), d.get("value", "")
        )
        for d in block.findall("ParameterDeclaration")
    }


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
        if item.entity:
            check(item.entity, "Storyboard/Init")
    for story in scenario.stories:
        for act in story.acts:
            for group in act.groups:
                for actor in group.actors:
                    check(actor, f"Story[{story.name}]/Act[{act.name}]/ManeuverGroup[{group.name}]/Actors")
    for story in scenario.stories:
        for owner, name in _entity_references(story):
            check(name, f"Story[{story.name}]: {owner}")
    if scenario.stop_trigger is not None:
        for owner, name in _entity_references(scenario.stop_trigger):
            check(name, f"StopTrigger: {owner}")


_ENTITY_FIELDS = ("entity", "entities", "triggering_entities", "actors")


def _entity_references(root: object) -> list[tuple[str, str]]:
    """(dataclass name, entity name) of every entity reference under a model object: the fields named in
    _ENTITY_FIELDS of every dataclass (conditions, actions, positions), found without recursion."""
    found: list[tuple[str, str]] = []
    stack: list[object] = [root]
    while stack:
        item = stack.pop()
        if isinstance(item, tuple | list):
            stack.extend(item)
            continue
        split = _reference_fields(type(item))
        if split is None:
            continue
        entity_fields, other_fields = split
        for name in entity_fields:
            value = getattr(item, name)
            names = value if isinstance(value, tuple | list) else (value,)
            found.extend((type(item).__name__, n) for n in names if isinstance(n, str) and n)
        for name in other_fields:
            value = getattr(item, name)
            if value is not None and type(value) not in _SCALARS:
                stack.append(value)  # (anything but a dataclass, tuple or list is skipped when popped)
    return found


_SCALARS = (str, float, int, bool)


_REFERENCE_FIELDS: dict[type, tuple[tuple[str, ...], tuple[str, ...]] | None] = {}


def _reference_fields(cls: type) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
    """A dataclass's fields naming entities (_ENTITY_FIELDS) and its other fields, in declaration order
    (None for anything else); found once per class."""
    try:
        return _REFERENCE_FIELDS[cls]
    except KeyError:
        pass
    split = None
    if dataclasses.is_dataclass(cls):
        names = [f.name for f in dataclasses.fields(cls)]
        split = (
            tuple(n for n in names if n in _ENTITY_FIELDS),
            tuple(n for n in names if n not in _ENTITY_FIELDS),
        )
    _REFERENCE_FIELDS[cls] = split
    return split


def _variables(reader: _Reader, root: ET.Element) -> None:
    block = root.find("VariableDeclarations")
    if block is None:
        return
    for item in block.findall("VariableDeclaration"):
        name = (item.get("name") or "").lstrip("$")
        if not name:
            raise reader.fail("VariableDeclaration without a name", item)
        try:
            reader.variables[name] = convert(
                reader.attr(item, "value"), item.get("variableType", "string"), name=name
            )
        except ParameterError as exc:
            raise reader.fail(str(exc), item) from None
