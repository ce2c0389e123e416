"""Parsing OpenDRIVE XML into the road model (`simcore.world.road_model`), safely: files are untrusted.

XML is parsed with :mod:`defusedxml` (no external entities), files over 64 MiB and files with more than
`MAX_GEOMETRIES` planView records are refused, and every problem in the input is reported as one
:class:`OpenDriveError` naming the file and the element (e.g. ``road id=3: laneSection 0: lane id=-1: ...``).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from xml.etree.ElementTree import Element

import defusedxml.ElementTree as DET
from defusedxml import DefusedXmlException

from simcore.world.road_geometry import Arc, Geometry, Line, ParamPoly3, Spiral
from simcore.world.road_model import Junction, JunctionConnection, Lane, LaneSection, Poly3, Road, RoadLink

__all__ = ["MAX_FILE_BYTES", "MAX_GEOMETRIES", "OpenDriveError", "parse_network", "read_bounded"]

MAX_FILE_BYTES = 64 * 1024 * 1024
"""Files (and strings) larger than this are refused."""

MAX_GEOMETRIES = 100_000
"""planView geometry records per file; more are refused before parsing (netconvert would take minutes and
gigabytes on them, then silently make an empty network). Large real maps have a few ten thousand."""


class OpenDriveError(ValueError):
    """A malformed, unsupported or unsafe OpenDRIVE input, or a query on something the file does not have."""


def read_bounded(p: Path) -> bytes:
    """The bytes of the road file `p`, refused (OpenDriveError) if unreadable or larger than 64 MiB."""
    try:
        size = p.stat().st_size
    except OSError as e:
        raise OpenDriveError(f"{p}: cannot read: {e.strerror or e}") from None
    if size > MAX_FILE_BYTES:
        raise OpenDriveError(f"{p}: file is {size} bytes, larger than the {MAX_FILE_BYTES} byte limit")
    with p.open("rb") as fh:
        data = fh.read(MAX_FILE_BYTES + 1)
    if len(data) > MAX_FILE_BYTES:
        raise OpenDriveError(f"{p}: file is larger than the {MAX_FILE_BYTES} byte limit")
    return data


def parse_network(data: bytes, name: str) -> tuple[dict[str, Road], dict[str, Junction], dict[str, str]]:
    """The roads and junctions (by id) of the OpenDRIVE XML `data` and its traffic signals (``<signal>`` id →
    name); `name` (the file) is used in error messages."""
    geometries = data.count(b"<geometry")
    if geometries > MAX_GEOMETRIES:
        raise OpenDriveError(
            f"{name}: {geometries} <geometry> records, more than the {MAX_GEOMETRIES} allowed: "
            "split the road network"
        )
    try:
        root = DET.fromstring(data, forbid_dtd=False, forbid_entities=True, forbid_external=True)
    except DefusedXmlException as e:
        raise OpenDriveError(f"{name}: unsafe XML rejected: {e}") from None
    except Exception as e:  # xml.etree.ElementTree.ParseError and friends
        raise OpenDriveError(f"{name}: not well-formed XML: {e}") from None
    if root.tag != "OpenDRIVE":
        raise OpenDriveError(f"{name}: root element is <{root.tag}>, expected <OpenDRIVE>")
    ctx = _Ctx(name)
    roads: dict[str, Road] = {}
    for el in root.findall("road"):
        road = _parse_road(ctx, el)
        if road.id in roads:
            raise OpenDriveError(f"{name}: road id={road.id}: duplicate road id")
        roads[road.id] = road
    junctions: dict[str, Junction] = {}
    for el in root.findall("junction"):
        j = _parse_junction(ctx, el)
        junctions[j.id] = j
    if not roads:
        raise OpenDriveError(f"{name}: no <road> elements")
    signals: dict[str, str] = {}
    for road_el in root.findall("road"):
        for signal in road_el.iterfind("signals/signal"):
            signals[signal.get("id", "")] = signal.get("name", "")
    return roads, junctions, signals


class _Ctx:
    """Error-message context: file name plus a path of element descriptions."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.parts: list[str] = []

    def error(self, msg: str) -> OpenDriveError:
        return OpenDriveError(": ".join([self.name, *self.parts, msg]))

    def num(self, el: Element, attr: str, default: float | None = None) -> float:
        raw = el.get(attr)
        if raw is None:
            if default is not None:
                return default
            raise self.error(f"<{el.tag}> is missing attribute '{attr}'")
        try:
            val = float(raw)
        except ValueError:
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not a number") from None
        if not math.isfinite(val):
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not finite")
        return val

    def integer(self, el: Element, attr: str) -> int:
        raw = el.get(attr)
        if raw is None:
            raise self.error(f"<{el.tag}> is missing attribute '{attr}'")
        try:
            f = float(raw)
        except ValueError:
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not an integer") from None
        if not f.is_integer():
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not an integer")
        return int(f)

    def string(self, el: Element, attr: str) -> str:
        raw = el.get(attr)
        if raw is None:
            raise self.error(f"<{el.tag}> is missing attribute '{attr}'")
        return raw.strip()

    def poly(self, el: Element, s_attr: str) -> Poly3:
        return Poly3(
            self.num(el, s_attr),
            self.num(el, "a", 0.0),
            self.num(el, "b", 0.0),
            self.num(el, "c", 0.0),
            self.num(el, "d", 0.0),
        )


def _parse_geometry(ctx: _Ctx, el: Element) -> Geometry:
    s, x, y = ctx.num(el, "s"), ctx.num(el, "x"), ctx.num(el, "y")
    hdg, length = ctx.num(el, "hdg"), ctx.num(el, "length")
    if length < 0:
        raise ctx.error(f"negative length {length}")
    kids = list(el)
    if not kids:
        raise ctx.error("no geometry type (expected line, arc, spiral, poly3 or paramPoly3)")
    g = kids[0]
    if g.tag == "line":
        return Line(s, x, y, hdg, length)
    if g.tag == "arc":
        return Arc(s, x, y, hdg, length, ctx.num(g, "curvature"))
    if g.tag == "spiral":
        return Spiral(s, x, y, hdg, length, ctx.num(g, "curvStart"), ctx.num(g, "curvEnd"))
    if g.tag == "poly3":
        v = (ctx.num(g, "a"), ctx.num(g, "b"), ctx.num(g, "c"), ctx.num(g, "d"))
        return ParamPoly3(s, x, y, hdg, length, (0.0, 1.0, 0.0, 0.0), v, None)
    if g.tag == "paramPoly3":
        u = (ctx.num(g, "aU"), ctx.num(g, "bU"), ctx.num(g, "cU"), ctx.num(g, "dU"))
        v = (ctx.num(g, "aV"), ctx.num(g, "bV"), ctx.num(g, "cV"), ctx.num(g, "dV"))
        prange = (g.get("pRange") or "normalized").strip()
        if prange == "arcLength":
            p_max = length
        elif prange == "normalized":
            p_max = 1.0
        else:
            raise ctx.error(f"paramPoly3 has unsupported pRange {prange!r}")
        return ParamPoly3(s, x, y, hdg, length, u, v, p_max)
    raise ctx.error(f"unsupported type {g.tag!r}")


def _parse_link(ctx: _Ctx, el: Element | None) -> RoadLink | None:
    if el is None:
        return None
    etype = ctx.string(el, "elementType")
    if etype not in ("road", "junction"):
        raise ctx.error(f"<{el.tag}> has unsupported elementType {etype!r}")
    cp = el.get("contactPoint")
    if etype == "road":
        if cp not in ("start", "end"):
            raise ctx.error(
                f"<{el.tag}> to road {el.get('elementId')!r} needs contactPoint start/end, got {cp!r}"
            )
    else:
        cp = None
    return RoadLink(etype, ctx.string(el, "elementId"), cp)


def _parse_lane(ctx: _Ctx, el: Element) -> Lane:
    lane_id = ctx.integer(el, "id")
    ctx.parts.append(f"lane id={lane_id}")
    widths = []
    for i, w in enumerate(el.findall("width")):
        ctx.parts.append(f"width {i}")
        widths.append(ctx.poly(w, "sOffset"))
        ctx.parts.pop()
    borders = []
    for i, b in enumerate(el.findall("border")):
        ctx.parts.append(f"border {i}")
        borders.append(ctx.poly(b, "sOffset"))
        ctx.parts.pop()
    pred = succ = None
    link = el.find("link")
    if link is not None:
        p = link.find("predecessor")
        if p is not None:
            pred = ctx.integer(p, "id")
        q = link.find("successor")
        if q is not None:
            succ = ctx.integer(q, "id")
    level = (el.get("level") or "false").strip().lower() in ("true", "1")
    ctx.parts.pop()
    return Lane(lane_id, (el.get("type") or "none").strip(), widths, borders, pred, succ, level)


def _parse_road(ctx: _Ctx, el: Element) -> Road:
    rid = ctx.string(el, "id")
    ctx.parts.append(f"road id={rid}")
    length = ctx.num(el, "length")
    if length <= 0:
        raise ctx.error(f"non-positive length {length}")
    junction = (el.get("junction") or "-1").strip()
    plan = el.find("planView")
    if plan is None:
        raise ctx.error("no <planView>")
    geoms = []
    for i, g in enumerate(plan.findall("geometry")):
        ctx.parts.append(f"geometry {i}")
        geoms.append(_parse_geometry(ctx, g))
        ctx.parts.pop()
    if not geoms:
        raise ctx.error("<planView> has no <geometry>")
    geoms.sort(key=lambda g: g.s)
    elevs = []
    ep = el.find("elevationProfile")
    if ep is not None:
        for i, e in enumerate(ep.findall("elevation")):
            ctx.parts.append(f"elevation {i}")
            elevs.append(ctx.poly(e, "s"))
            ctx.parts.pop()
    elevs.sort(key=lambda p: p.s0)
    supers = []
    lp = el.find("lateralProfile")
    if lp is not None:
        for i, e in enumerate(lp.findall("superelevation")):
            ctx.parts.append(f"superelevation {i}")
            supers.append(ctx.poly(e, "s"))
            ctx.parts.pop()
    supers.sort(key=lambda p: p.s0)
    lanes_el = el.find("lanes")
    if lanes_el is None:
        raise ctx.error("no <lanes>")
    offsets = []
    for i, o in enumerate(lanes_el.findall("laneOffset")):
        ctx.parts.append(f"laneOffset {i}")
        offsets.append(ctx.poly(o, "s"))
        ctx.parts.pop()
    offsets.sort(key=lambda p: p.s0)
    sections: list[LaneSection] = []
    sec_els = lanes_el.findall("laneSection")
    if not sec_els:
        raise ctx.error("<lanes> has no <laneSection>")
    for i, sec in enumerate(sec_els):
        ctx.parts.append(f"laneSection {i}")
        s0 = ctx.num(sec, "s")
        single = (sec.get("singleSide") or "false").strip().lower() in ("true", "1")
        left: list[Lane] = []
        right: list[Lane] = []
        center: Lane | None = None
        for side_name in ("left", "center", "right"):
            side_el = sec.find(side_name)
            if side_el is None:
                continue
            for lane_el in side_el.findall("lane"):
                lane = _parse_lane(ctx, lane_el)
                if side_name == "left" and lane.id > 0:
                    left.append(lane)
                elif side_name == "right" and lane.id < 0:
                    right.append(lane)
                elif side_name == "center" and lane.id == 0:
                    center = lane
                else:
                    raise ctx.error(f"lane id={lane.id} does not belong in <{side_name}>")
        left.sort(key=lambda ln: ln.id)
        right.sort(key=lambda ln: -ln.id)
        for side_lanes, sign in ((left, 1), (right, -1)):
            if [ln.id for ln in side_lanes] != [sign * (k + 1) for k in range(len(side_lanes))]:
                raise ctx.error(f"lane ids {[ln.id for ln in side_lanes]} are not consecutive from {sign}")
        sections.append(LaneSection(s0, length, left, right, center, single))
        ctx.parts.pop()
    sections.sort(key=lambda sc: sc.s)
    for a, b in itertools.pairwise(sections):
        a.end = b.s
    link = el.find("link")
    pred = succ = None
    if link is not None:
        ctx.parts.append("link")
        pred = _parse_link(ctx, link.find("predecessor"))
        succ = _parse_link(ctx, link.find("successor"))
        ctx.parts.pop()
    ctx.parts.pop()
    rule = (el.get("rule") or "RHT").strip().upper()
    speeds = []
    for kind in el.findall("type"):
        record = kind.find("speed")
        if record is None or record.get("max") in (None, "", "no limit", "undefined"):
            continue
        scale = _SPEED_UNITS.get((record.get("unit") or "m/s").strip(), 1.0)
        try:
            speeds.append((ctx.num(kind, "s", 0.0), float(record.get("max", "")) * scale))
        except ValueError:
            continue  # a speed record that is not a number: no limit from it
    road = Road(
        rid,
        el.get("name") or "",
        length,
        junction,
        geoms,
        elevs,
        offsets,
        sections,
        pred,
        succ,
        supers,
        "LHT" if rule == "LHT" else "RHT",
    )
    road.speeds = sorted(speeds)
    return road


_SPEED_UNITS = {"m/s": 1.0, "km/h": 1 / 3.6, "mph": 0.44704}


def _parse_junction(ctx: _Ctx, el: Element) -> Junction:
    jid = ctx.string(el, "id")
    ctx.parts.append(f"junction id={jid}")
    conns = []
    for i, c in enumerate(el.findall("connection")):
        ctx.parts.append(f"connection {c.get('id', i)}")
        links = tuple((ctx.integer(ll, "from"), ctx.integer(ll, "to")) for ll in c.findall("laneLink"))
        cp = (c.get("contactPoint") or "start").strip()
        if cp not in ("start", "end"):
            raise ctx.error(f"unsupported contactPoint {cp!r}")
        conns.append(
            JunctionConnection(
                (c.get("id") or str(i)).strip(),
                ctx.string(c, "incomingRoad"),
                ctx.string(
                    c,
                    "linkedRoad"
                    if c.get("connectingRoad") is None and c.get("linkedRoad")
                    else "connectingRoad",
                ),
                cp,
                links,
            )
        )
        ctx.parts.pop()
    ctx.parts.pop()
    return Junction(jid, el.get("name") or "", conns)
