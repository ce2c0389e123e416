"""Positions for the OpenSCENARIO parser: every Position type with its Orientation, and the routes and
trajectories that positions (RoutePosition, TrajectoryPosition) and routing actions name, inline or from a
catalog.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

from simcore.scenario import model as m
from simcore.scenario.xosc_catalogs import _catalog_entry
from simcore.scenario.xosc_reader import _Reader


def _route_orientation(reader: _Reader, position: ET.Element, in_route: ET.Element) -> m.Orientation | None:
    """A RoutePosition's Orientation. The schema puts it before InRoutePosition; the reference player reads
    the children in order and places the position when it meets InRoutePosition, so an Orientation written
    after it changes nothing there: the same here, with a warning naming the element."""
    orientation = position.find("Orientation")
    if orientation is None:
        return None
    children = list(position)
    if children.index(orientation) > children.index(in_route):
        reader.warn(
            "Orientation after InRoutePosition (the schema puts it before): ignored, as the reference "
            "player does; move it before InRoutePosition to turn the entity",
            orientation,
        )
        return None
    return _orientation(reader, position)


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


def _road_id(raw: str) -> str:
    """A road id from a double parameter ("1.0") names road "1"."""
    if raw.endswith(".0") and raw[:-2].lstrip("-").isdigit():
        return raw[:-2]
    return raw


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
            road_id=_road_id(reader.attr(p, "roadId")),
            lane_id=reader.integer(p, "laneId"),
            s=reader.num(p, "s"),
            offset=reader.num(p, "offset", 0.0),
            orientation=_orientation(reader, p),
            source=reader.source(p),
        )
    if p.tag == "RoadPosition":
        return m.RoadPosition(
            road_id=_road_id(reader.attr(p, "roadId")),
            s=reader.num(p, "s"),
            t=reader.num(p, "t"),
            orientation=_orientation(reader, p),
        )
    if p.tag == "RelativeLanePosition":
        ds = reader.opt_num(p, "ds")
        along_lane = ds is None  # dsLane: along the lane, in its driving direction
        if ds is None:
            ds = reader.num(p, "dsLane", 0.0)
        return m.RelativeLanePosition(
            entity=reader.attr(p, "entityRef"),
            d_lane=reader.integer(p, "dLane"),
            ds=ds,
            along_lane=along_lane,
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
    if p.tag == "RoutePosition":
        ref = reader.child(p, "RouteRef")
        route = _route_or_ref(reader, ref)
        in_route_element = reader.child(p, "InRoutePosition")
        in_route = reader.only_child(in_route_element)
        orientation = _route_orientation(reader, p, in_route_element)
        if in_route.tag == "FromCurrentEntity":
            return m.RoutePosition(
                route=route, entity=reader.attr(in_route, "entityRef"), orientation=orientation
            )
        if in_route.tag == "FromRoadCoordinates":
            return m.RoutePosition(
                route=route,
                entity=None,
                path_s=reader.num(in_route, "pathS"),
                t=reader.num(in_route, "t", 0.0),
                orientation=orientation,
            )
        if in_route.tag == "FromLaneCoordinates":
            return m.RoutePosition(
                route=route,
                entity=None,
                path_s=reader.num(in_route, "pathS"),
                lane_id=reader.integer(in_route, "laneId"),
                lane_offset=reader.num(in_route, "laneOffset", 0.0),
                orientation=orientation,
            )
        raise reader.fail(f"unknown InRoutePosition <{in_route.tag}>", in_route)
    if p.tag == "TrajectoryPosition":
        return m.TrajectoryPosition(
            trajectory=_trajectory_or_ref(reader, reader.child(p, "TrajectoryRef")),
            s=reader.num(p, "s"),
            t=reader.num(p, "t", 0.0),
            orientation=_orientation(reader, p),
        )
    raise reader.fail(f"position type <{p.tag}> is not supported", p)


def _route_or_ref(reader: _Reader, parent: ET.Element) -> m.Route:
    route = parent.find("Route")
    if route is not None:
        return _route(reader, route)
    ref = parent.find("CatalogReference")
    if ref is None:
        raise reader.fail("a Route or a CatalogReference to one is required", parent)
    entry, assignments = _catalog_entry(reader, ref, reader.catalogs, "Route")
    if entry.tag != "Route":
        raise reader.fail(f"catalog entry is a {entry.tag}, not a Route", ref)
    reader.push_declarations(entry, assignments)
    try:
        return _route(reader, entry, False)
    finally:
        reader.pop()


def _route(reader: _Reader, route: ET.Element, declare: bool = True) -> m.Route:
    if declare:
        reader.push_declarations(route)
    try:
        waypoints = tuple(
            m.Waypoint(
                position=_position(reader, reader.child(w, "Position")),
                strategy=reader.attr(w, "routeStrategy", "shortest"),
            )
            for w in route.findall("Waypoint")
        )
        if len(waypoints) < 2:
            raise reader.fail("a Route needs at least two waypoints", route)
        return m.Route(
            name=reader.attr(route, "name", ""),
            closed=reader.boolean(route, "closed", False),
            waypoints=waypoints,
        )
    finally:
        if declare:
            reader.pop()


def _trajectory_or_ref(reader: _Reader, parent: ET.Element) -> m.Trajectory:
    holder = parent.find("TrajectoryRef")
    if holder is None:
        holder = parent  # OpenSCENARIO 1.0: Trajectory or CatalogReference directly
    trajectory = holder.find("Trajectory")
    if trajectory is not None:
        return _trajectory(reader, trajectory)
    ref = holder.find("CatalogReference")
    if ref is None:
        raise reader.fail("a Trajectory or a CatalogReference to one is required", parent)
    entry, assignments = _catalog_entry(reader, ref, reader.catalogs, "Trajectory")
    if entry.tag != "Trajectory":
        raise reader.fail(f"catalog entry is a {entry.tag}, not a Trajectory", ref)
    reader.push_declarations(entry, assignments)
    try:
        return _trajectory(reader, entry, False)
    finally:
        reader.pop()


def _trajectory(reader: _Reader, element: ET.Element, declare: bool = True) -> m.Trajectory:
    if declare:
        reader.push_declarations(element)
    try:
        shape_el = reader.only_child(reader.child(element, "Shape"))
        shape: m.TrajectoryShape
        if shape_el.tag == "Polyline":
            vertices = tuple(
                m.Vertex(
                    position=_position(reader, reader.child(v, "Position")), time=reader.opt_num(v, "time")
                )
                for v in shape_el.findall("Vertex")
            )
            if not vertices:
                raise reader.fail("a Polyline needs at least one Vertex", shape_el)
            shape = m.Polyline(vertices)
        elif shape_el.tag == "Clothoid":
            position = shape_el.find("Position")
            k = reader.num(shape_el, "curvature")
            k_dot = reader.opt_num(shape_el, "curvaturePrime")
            if k_dot is None:
                k_dot = reader.num(shape_el, "curvatureDot", 0.0)
            length = reader.num(shape_el, "length")
            shape = m.Clothoid(
                (
                    m.ClothoidSegment(
                        curvature_start=k,
                        curvature_end=k + k_dot * length,
                        length=length,
                        start=_position(reader, position) if position is not None else None,
                        time_start=reader.opt_num(shape_el, "startTime"),
                        time_end=reader.opt_num(shape_el, "stopTime"),
                    ),
                )
            )
        elif shape_el.tag == "ClothoidSpline":
            segments = []
            seg_els = shape_el.findall("ClothoidSplineSegment")
            time_end = reader.opt_num(shape_el, "timeEnd")
            for i, seg in enumerate(seg_els):
                start = seg.find("PositionStart")
                t0 = reader.opt_num(seg, "timeStart")
                t1 = reader.opt_num(seg_els[i + 1], "timeStart") if i + 1 < len(seg_els) else time_end
                segments.append(
                    m.ClothoidSegment(
                        curvature_start=reader.num(seg, "curvatureStart"),
                        curvature_end=reader.num(seg, "curvatureEnd"),
                        length=reader.num(seg, "length"),
                        start=_position(reader, start) if start is not None else None,
                        h_offset=reader.num(seg, "hOffset", 0.0),
                        time_start=t0,
                        time_end=t1,
                    )
                )
            if not segments:
                raise reader.fail("a ClothoidSpline needs at least one segment", shape_el)
            shape = m.Clothoid(tuple(segments))
        elif shape_el.tag == "Nurbs":
            points = tuple(
                m.ControlPoint(
                    position=_position(reader, reader.child(c, "Position")),
                    time=reader.opt_num(c, "time"),
                    weight=reader.num(c, "weight", 1.0),
                )
                for c in shape_el.findall("ControlPoint")
            )
            knots = tuple(reader.num(k, "value") for k in shape_el.findall("Knot"))
            order = reader.integer(shape_el, "order")
            if order < 1 or len(points) < order or len(knots) != len(points) + order:
                raise reader.fail(
                    f"Nurbs of order {order} with {len(points)} control points needs "
                    f"{len(points) + order} knots, has {len(knots)}",
                    shape_el,
                )
            shape = m.Nurbs(order=order, control_points=points, knots=knots)
        else:
            raise reader.fail(f"trajectory shape <{shape_el.tag}> is not supported", shape_el)
        return m.Trajectory(
            name=reader.attr(element, "name", ""),
            closed=reader.boolean(element, "closed", False),
            shape=shape,
        )
    finally:
        if declare:
            reader.pop()
