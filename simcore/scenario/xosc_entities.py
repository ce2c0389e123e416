"""Entities for the OpenSCENARIO parser: each ScenarioObject (a Vehicle, Pedestrian or MiscObject, inline or
from a catalog; an inline trailer as an entity of its own) with its bounding box, performance, axles,
trailer, properties and controller (ObjectController, also read for AssignControllerAction).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from simcore.scenario import model as m
from simcore.scenario.xosc_catalogs import _catalog_entry
from simcore.scenario.xosc_reader import _Reader


def _entities(reader: _Reader, element: ET.Element, catalogs: dict[str, Path]) -> list[m.Entity]:
    entities = []
    for obj in element.findall("ScenarioObject"):
        name = reader.attr(obj, "name")
        entities.append(reader.within(obj, name, _entity, reader, obj, name, catalogs))
        # a trailer defined inline is an entity of its own, named after its tow vehicle with a "+" (as esmini
        # names it; a trailer's own inline trailer gets another "+")
        while reader.inline_trailers:
            trailer_name, trailer = reader.inline_trailers.pop(0)
            entities.append(
                reader.within(trailer, trailer_name, _entity, reader, trailer, trailer_name, catalogs)
            )
    selection = element.find("EntitySelection")
    if selection is not None:  # its own line, not its <Entities>'
        raise reader.fail("EntitySelection is not supported yet", selection)
    return entities


def _entity(reader: _Reader, obj: ET.Element, name: str, catalogs: dict[str, Path]) -> m.Entity:
    body = next(
        (c for c in obj if c.tag in ("Vehicle", "Pedestrian", "MiscObject", "CatalogReference")), None
    )
    if body is None:
        raise reader.fail("a ScenarioObject needs a Vehicle, Pedestrian, MiscObject or CatalogReference", obj)
    pushed = False
    if body.tag == "CatalogReference":
        entry, assignments = _catalog_entry(reader, body, catalogs, ("Vehicle", "Pedestrian", "MiscObject"))
        if entry.tag not in ("Vehicle", "Pedestrian", "MiscObject"):
            raise reader.fail(
                f"catalog entry is a {entry.tag}, not a Vehicle, Pedestrian or MiscObject", body
            )
        reader.push_declarations(entry, assignments)
        pushed = True
        body = entry
    elif body.find("ParameterDeclarations") is not None:
        # an inline Vehicle (Pedestrian, MiscObject) may declare parameters of its own, as a catalog entry does
        reader.push_declarations(body)
        pushed = True
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
        wheelbase, max_steering = _axles(reader, body)
        hitch, coupler, trailer = _trailer(reader, body, name)
    finally:
        if pushed:
            reader.pop()
    controllers = []
    for oc in obj.findall("ObjectController"):
        properties = _controller(reader, oc)
        if properties and oc.get("name"):
            # an ActivateControllerAction's objectControllerRef names the ObjectController (OpenSCENARIO 1.3)
            properties[m.OBJECT_CONTROLLER] = reader.attr(oc, "name", "")
        if properties:
            controllers.append(properties)
    controller: dict[str, str] = controllers[-1] if controllers else {}
    return m.Entity(
        source=reader.source(obj),
        name=name,
        object_type=object_type,  # type: ignore[arg-type]
        category=category,
        box=box,
        performance=performance,
        properties=properties,
        controller=controller,
        controllers=tuple(controllers),
        wheelbase=wheelbase,
        max_steering=max_steering,
        trailer_hitch=hitch,
        trailer_coupler=coupler,
        trailer=trailer,
    )


def _trailer(reader: _Reader, body: ET.Element, owner: str) -> tuple[float | None, float | None, str | None]:
    """A vehicle's TrailerHitch dx, TrailerCoupler dx and the entity it tows from the start (Trailer/TrailerRef,
    OpenSCENARIO 1.3; an empty reference tows nothing). A trailer defined inline (Trailer/Trailer with its
    Vehicle or CatalogReference) becomes the entity `<owner>+`, read after the owner."""
    hitch_el, coupler_el = body.find("TrailerHitch"), body.find("TrailerCoupler")
    hitch = reader.num(hitch_el, "dx", 0.0) if hitch_el is not None else None
    coupler = reader.num(coupler_el, "dx", 0.0) if coupler_el is not None else None
    trailer = None
    towed = body.find("Trailer")
    if towed is not None:
        ref = towed.find("TrailerRef")
        inline = towed.find("Trailer")
        if ref is not None:
            trailer = reader.attr(ref, "entityRef", "") or None
        elif inline is not None:
            trailer = f"{owner}+"
            reader.inline_trailers.append((trailer, inline))
    return hitch, coupler, trailer


def _axles(reader: _Reader, body: ET.Element) -> tuple[float | None, float | None]:
    """A vehicle's wheelbase and front-wheel steering limit (Axles), when it has both axles."""
    axles = body.find("Axles")
    if axles is None:
        return None, None
    front, rear = axles.find("FrontAxle"), axles.find("RearAxle")
    if front is None or rear is None:
        return None, None
    wheelbase = reader.num(front, "positionX", 0.0) - reader.num(rear, "positionX", 0.0)
    max_steering = abs(reader.num(front, "maxSteering", 0.0))
    return (wheelbase if wheelbase > 0 else None), (max_steering if max_steering > 0 else None)


def _controller(reader: _Reader, parent: ET.Element) -> dict[str, str]:
    """The properties of the Controller (inline or from a catalog) under `parent`; a controller CARLOS does
    not model is warned about (the entity then follows the scenario's actions, as under the default one)."""
    ctrl = parent.find("Controller")
    pushed = False
    if ctrl is None:
        ref = parent.find("CatalogReference")
        if ref is None:
            return {}
        ctrl, assignments = _catalog_entry(reader, ref, reader.catalogs, "Controller")
        reader.push_declarations(ctrl, assignments)
        pushed = True
    try:
        properties = _properties(reader, ctrl)
        properties.setdefault("name", reader.attr(ctrl, "name", ""))
    finally:
        if pushed:
            reader.pop()
    if properties.get("carlos.driver", "scenario") not in ("scenario", "sumo", "external"):
        raise reader.fail(
            f"controller property carlos.driver={properties['carlos.driver']!r}: use scenario, sumo or external",
            ctrl,
        )
    kind = m.controller_type(properties)
    known = properties.get("carlos.driver") in ("sumo", "external") or kind in m.EXTERNAL_CONTROLLERS
    if kind in m.ACC_CONTROLLERS:
        known = True  # runs as esmini's ACC controller (simcore.scenario.actions.AccDriver)
    if kind in m.VEHICLE_CONTROLLERS:
        known = True  # drives a vehicle model of its own as esmini's (simcore.scenario.drivers)
    if kind in m.NATURAL_DRIVER_CONTROLLERS:
        known = True  # esmini's IDM driver with lane changes (simcore.scenario.drivers.NaturalDriver)
    if kind in m.FOLLOW_GHOST_CONTROLLERS:
        known = True  # a ghost runs the actions ahead, the entity follows it (simcore.scenario.ghost)
    if kind in m.REGISTERED_CONTROLLERS:
        known = True  # runs as esmini's (simcore.scenario.controllers)
    if m.partly_modelled(properties):
        reader.warn(
            f"controller {kind!r} in override mode: its steering (esmini's near and far points) is not "
            "modelled, only its speed; the entity keeps to its lane and is not compared in conformance",
            parent,
        )
    if not known and kind not in ("", "DefaultController"):
        reader.warn(
            f"controller {kind!r} is not modelled: the entity follows the scenario's actions "
            "(default controller)",
            parent,
        )
    return properties


def _properties(reader: _Reader, element: ET.Element) -> dict[str, str]:
    block = element.find("Properties")
    if block is None:
        return {}
    return {reader.attr(p, "name"): reader.attr(p, "value") for p in block.findall("Property")}
