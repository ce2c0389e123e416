"""OpenSCENARIO XML (1.0–1.3) → the object model, with parameters resolved.

Scenario files are untrusted: parsed with defusedxml (no entities, no external references), bounded in
size, and every problem raised as `BadInput` naming the file and the element path.
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

import defusedxml.ElementTree as SafeET
from defusedxml import DefusedXmlException

from simcore.errors import BadInput
from simcore.file_version import FileVersion, file_version
from simcore.scenario import model as m
from simcore.scenario.parameters import Declaration, ParameterError, ParamValue, convert, declare, resolve

MAX_SCENARIO_BYTES = 32 * 1024 * 1024
# Structure bounds checked while parsing, before anything else (the XSD check, the reader) walks the tree:
# OpenSCENARIO elements have at most a dozen attributes and real scenarios nest a few dozen levels deep.
MAX_XML_DEPTH = 256
MAX_XML_ATTRIBUTES = 256  # on one element
MAX_XML_ELEMENTS = 1_000_000
T = TypeVar("T")


class XmlLimitExceeded(Exception):
    """The XML is deeper, wider or larger than MAX_XML_*: raised by the builder, reported as BadInput."""


class _LineBuilder(ET.TreeBuilder):
    """A tree builder that enforces the structure bounds and (with `lines`) remembers the source line of every
    element (for warnings and errors)."""

    def __init__(self, lines: dict[int, int] | None) -> None:
        super().__init__()
        self.lines = lines
        self.parser: Any = None
        self.depth = 0
        self.elements = 0

    def start(self, tag: Any, attrs: Any) -> ET.Element:
        self.depth += 1
        self.elements += 1
        if self.depth > MAX_XML_DEPTH:
            raise XmlLimitExceeded(f"elements nested more than {MAX_XML_DEPTH} deep")
        if len(attrs) > MAX_XML_ATTRIBUTES:
            raise XmlLimitExceeded(f"an element with {len(attrs)} attributes (at most {MAX_XML_ATTRIBUTES})")
        if self.elements > MAX_XML_ELEMENTS:
            raise XmlLimitExceeded(f"more than {MAX_XML_ELEMENTS} elements")
        element = super().start(tag, attrs)
        if self.parser is not None and self.lines is not None:
            self.lines[id(element)] = int(self.parser.parser.CurrentLineNumber)
        return element

    def end(self, tag: Any) -> ET.Element:
        self.depth -= 1
        return super().end(tag)


def read_xml(
    path: Path, *, what: str, max_bytes: int = MAX_SCENARIO_BYTES, lines: dict[int, int] | None = None
) -> ET.Element:
    """Parse an untrusted XML file safely; errors name the file. `lines` (given): element id → line."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise BadInput(f"{what} not found", file=str(path)) from None
    if size > max_bytes:
        raise BadInput(f"{what} is {size} bytes; at most {max_bytes} are allowed", file=str(path))
    try:
        builder = _LineBuilder(lines)
        parser = SafeET.DefusedXMLParser(target=builder)
        builder.parser = parser
        parser.feed(path.read_bytes())
        root: ET.Element = parser.close()
        return root
    except XmlLimitExceeded as exc:
        line = builder.parser.parser.CurrentLineNumber if builder.parser is not None else "?"
        raise BadInput(f"{what} is too complex at line {line}: {exc}", file=str(path)) from None
    except DefusedXmlException as exc:
        raise BadInput(
            f"{what} uses forbidden XML constructs ({type(exc).__name__})", file=str(path)
        ) from None
    except ET.ParseError as exc:
        raise BadInput(f"{what} is not well-formed XML: {exc}", file=str(path)) from None
    except LookupError as exc:  # <?xml encoding="…"?> naming no known codec
        raise BadInput(f"{what} declares an unknown encoding: {exc}", file=str(path)) from None


class _Reader:
    """Walks the XML with a stack of parameter scopes; `attr` resolves `$name` and `${…}`."""

    def __init__(self, path: Path, overrides: Mapping[str, ParamValue]) -> None:
        self.path = path
        self.overrides = dict(overrides)
        self.scopes: list[dict[str, ParamValue]] = [{}]
        self.where: list[str] = []
        self.lines: dict[int, int] = {}
        self.files: dict[int, Path] = {}  # element id → the catalog file it comes from (others: self.path)
        self.warnings: list[str] = []
        self.catalogs: dict[str, Path] = {}
        self.catalog_origins: dict[str, str] = {}  # catalog kind → where its directory is declared
        self._catalog_files: dict[Path, ET.Element | None] = {}
        self._catalog_roots: list[ET.Element] = []
        self.variables: dict[str, ParamValue] = {}
        # inline trailers met while reading an entity: (their entity name, the Trailer element defining them)
        self.inline_trailers: list[tuple[str, ET.Element]] = []

    def line(self, element: ET.Element | None) -> int | None:
        return None if element is None else self.lines.get(id(element))

    def source(self, element: ET.Element | None) -> str:
        """The "file:line" of an element (in the scenario, or in the catalog it comes from)."""
        file = self.files.get(id(element), self.path) if element is not None else self.path
        line = self.line(element)
        return f"{file}:{line}" if line else str(file)

    def warn(self, message: str, element: ET.Element | None = None) -> None:
        """An unsupported element that does not change motion: the run goes on, the warning names it."""
        where = "/".join(self.where + ([element.tag] if element is not None else []))
        text = f"{self.source(element)}: {where}: {message}"
        if text not in self.warnings:
            self.warnings.append(text)

    # -- errors and scopes --
    def fail(self, message: str, element: ET.Element | None = None) -> BadInput:
        where = "/".join(self.where + ([element.tag] if element is not None else []))
        return BadInput(message, file=self.source(element), field=where or None)

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
                name = (item.get("name") or "").lstrip("$")  # "$Speed" declares Speed (as esmini reads it)
                if not name:
                    raise self.fail("ParameterDeclaration without a name", item)
                kind = item.get("parameterType", "string")
                value = item.get("value", "")
                if kind in ("double", "integer", "int", "unsignedInt", "unsignedShort") and value[:1] != "$":
                    try:
                        number = float(value)
                    except ValueError:
                        self.warn(
                            f"parameter {name!r} is declared {kind} but its value {value!r} is not a number: kept as a string",
                            item,
                        )
                        kind = "string"
                    else:
                        if kind != "double" and math.isfinite(number) and number != int(number):
                            # generators write decimals into integer parameters; esmini reads the number
                            # (`carlos validate --schema` reports it)
                            self.warn(
                                f"parameter {name!r} is declared {kind} but its value {value!r} is not an "
                                "integer: read as the number, as esmini does",
                                item,
                            )
                            kind = "double"
                declarations.append(Declaration(name=name, type=kind, value=value))
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
            if name in ("name", "storyboardElementRef") and raw.startswith("${"):
                # a name built by string concatenation (esmini's extension): parameters substituted, joined
                parts = [p.strip() for p in raw[2:-1].split("+")]
                out = []
                for part in parts:
                    try:
                        out.append(resolve(part, self.values))
                    except ParameterError:
                        out.append(part)
                return " ".join(out)
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


#: parsed scenario files (the XML tree and its element lines, which no parameter changes) by path and file
#: identity (size, mtime, ctime, inode): a sweep's points load the same file with other parameter values
_PARSED: dict[FileVersion, tuple[ET.Element, dict[int, int]]] = {}
_PARSED_MAX = 8


def _parsed_scenario(path: Path) -> tuple[ET.Element, dict[int, int]]:
    """The XML tree of a scenario file and the source line of each element, parsed once per file version.
    The tree is shared between loads and only read (`_Reader` never changes it); an entry is replaced when
    the file's size, modification or status-change time or inode changes (an edit, an atomic replace)."""
    lines: dict[int, int] = {}
    key = file_version(path)
    if key is None:  # read_xml says what is wrong
        return read_xml(path, what="OpenSCENARIO file", lines=lines), lines
    hit = _PARSED.get(key)
    if hit is None:
        hit = (read_xml(path, what="OpenSCENARIO file", lines=lines), lines)
        if len(_PARSED) >= _PARSED_MAX:
            _PARSED.pop(next(iter(_PARSED)))
        _PARSED[key] = hit
    return hit


def load_scenario(path: str | Path, overrides: Mapping[str, ParamValue] | None = None) -> m.Scenario:
    """Parse an OpenSCENARIO file. `overrides` replace declared parameter defaults; a name the file does not
    declare is bad input (a typo in a sweep must not silently do nothing)."""
    path = Path(path)
    root, lines = _parsed_scenario(path)
    if root.tag != "OpenSCENARIO":
        raise BadInput(f"root element is <{root.tag}>, expected <OpenSCENARIO>", file=str(path))
    reader = _Reader(path, overrides or {})
    reader.lines = dict(lines)  # catalogs read while loading add their elements' lines
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
    root = read_xml(Path(path), what="OpenSCENARIO file")
    block = root.find("ParameterDeclarations")
    if block is None:
        return {}
    return {d.get("name", ""): d.get("value", "") for d in block.findall("ParameterDeclaration")}


def parameter_declarations(path: str | Path) -> dict[str, Declaration]:
    """The scenario's top-level parameter declarations by name (type and default as written)."""
    root = read_xml(Path(path), what="OpenSCENARIO file")
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


# --- catalogs and entities --------------------------------------------------------------------------------


def _catalog_dirs(reader: _Reader, root: ET.Element) -> dict[str, Path]:
    dirs: dict[str, Path] = {}
    block = root.find("CatalogLocations")
    if block is None:
        return dirs
    for location in block:
        directory = location.find("Directory")
        if directory is not None:
            raw = reader.attr(directory, "path")
            kind = location.tag.removesuffix("Catalog")
            dirs[kind] = (reader.path.parent / raw).resolve()
            line = reader.line(directory)
            reader.catalog_origins[kind] = f"CatalogLocations/{location.tag}/Directory path={raw!r}" + (
                f" (line {line})" if line else ""
            )
    return dirs


def _catalog_entry(
    reader: _Reader, ref: ET.Element, catalogs: dict[str, Path], kind: str | tuple[str, ...]
) -> tuple[ET.Element, dict[str, ParamValue]]:
    """The catalog entry a CatalogReference names (searched in the catalog locations of `kind`, then in all
    locations), with its parameter assignments."""
    catalog_name = reader.attr(ref, "catalogName")
    entry_name = reader.attr(ref, "entryName")
    kinds = (kind,) if isinstance(kind, str) else kind
    assignments: dict[str, ParamValue] = {}
    block = ref.find("ParameterAssignments")
    if block is not None:
        for item in block.findall("ParameterAssignment"):
            name = item.get("parameterRef") or ""
            if not name:
                raise reader.fail("ParameterAssignment without parameterRef", item)
            assignments[name.lstrip("$")] = reader.attr(item, "value")
    directories = [catalogs[k] for k in kinds if k in catalogs]
    directories += [d for k, d in catalogs.items() if k not in kinds]
    if not directories:
        raise reader.fail(
            f"CatalogReference to {catalog_name}/{entry_name} but no {kinds[0]}Catalog location", ref
        )
    for directory in dict.fromkeys(directories):
        # a directory of catalog files, or (as esmini accepts) the path of one catalog file
        files = sorted(directory.glob("*.xosc")) if directory.is_dir() else []
        if not files and directory.suffix == ".xosc" and directory.is_file():
            files = [directory]
        for file in files:
            if file not in reader._catalog_files:
                root = read_xml(file, what="catalog", lines=reader.lines)
                reader._catalog_files[file] = root.find("Catalog")
                reader._catalog_roots.append(root)  # alive while loading: element ids stay unique
                for element in root.iter():
                    reader.files[id(element)] = file
            catalog = reader._catalog_files[file]
            # by the catalog's name, or by its file name (esmini accepts both)
            if catalog is None or catalog_name not in (catalog.get("name"), file.stem):
                continue
            for entry in catalog:
                if entry.get("name") == entry_name:
                    return entry, assignments
    searched = []
    for k, d in catalogs.items():
        origin = reader.catalog_origins.get(k, f"{k}Catalog")
        state = "" if d.is_dir() else ": no such directory"
        searched.append(f"{d} ({origin}{state})")
    raise reader.fail(
        f"catalog entry {catalog_name}/{entry_name} not found: no catalog named {catalog_name!r} with an entry "
        f"{entry_name!r} in {'; '.join(searched)}. Add the catalog file or correct CatalogLocations",
        ref,
    )


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
    controller: dict[str, str] = {}
    oc = obj.find("ObjectController")
    if oc is not None:
        controller = _controller(reader, oc)
    return m.Entity(
        source=reader.source(obj),
        name=name,
        object_type=object_type,  # type: ignore[arg-type]
        category=category,
        box=box,
        performance=performance,
        properties=properties,
        controller=controller,
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
    for other in actions.findall("GlobalAction"):
        g = reader.within(other, None, _global, reader, other)
        out.append(m.InitAction(entity="", action=g))
    for other in actions.findall("UserDefinedAction"):
        reader.warn("UserDefinedAction is ignored", other)
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
        start_trigger=_start_trigger(reader, start),
        stop_trigger=_trigger(reader, stop) if stop is not None else None,
    )


def _group(reader: _Reader, group: ET.Element) -> m.ManeuverGroup:
    actors_el = group.find("Actors")
    actors: tuple[str, ...] = ()
    select = False
    if actors_el is not None:
        select = reader.boolean(actors_el, "selectTriggeringEntities", False)
        actors = tuple(reader.attr(r, "entityRef") for r in actors_el.findall("EntityRef"))
    maneuvers = [reader.within(mv, mv.get("name"), _maneuver, reader, mv) for mv in group.findall("Maneuver")]
    for ref in group.findall("CatalogReference"):
        entry, assignments = _catalog_entry(reader, ref, reader.catalogs, "Maneuver")
        if entry.tag != "Maneuver":
            raise reader.fail(f"catalog entry is a {entry.tag}, not a Maneuver", ref)
        reader.push_declarations(entry, assignments)
        try:
            maneuvers.append(reader.within(entry, entry.get("name"), _maneuver, reader, entry, False))
        finally:
            reader.pop()
    return m.ManeuverGroup(
        name=reader.attr(group, "name"),
        maximum_execution_count=reader.integer(group, "maximumExecutionCount", 1),
        actors=actors,
        select_triggering_entities=select,
        maneuvers=tuple(maneuvers),
    )


def _maneuver(reader: _Reader, maneuver: ET.Element, declare: bool = True) -> m.Maneuver:
    if declare:
        reader.push_declarations(maneuver)
    try:
        events = tuple(reader.within(e, e.get("name"), _event, reader, e) for e in maneuver.findall("Event"))
    finally:
        if declare:
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
        if private is not None:
            actions.append(
                m.Action(name=name, private=reader.within(action, name, _private, reader, private))
            )
            continue
        if not any(isinstance(c.tag, str) for c in action):
            # an empty <Action/>: nothing to do, it ends at once (as esmini runs it)
            reader.within(action, name, reader.warn, "an empty Action does nothing", action)
            actions.append(m.Action(name=name, private=None))
            continue
        inner = reader.only_child(action)
        if inner.tag == "GlobalAction":
            g = reader.within(action, name, _global, reader, inner)
            actions.append(m.Action(name=name, private=None, global_action=g))
        else:
            reader.within(action, name, reader.warn, f"{inner.tag} is ignored", inner)
            actions.append(m.Action(name=name, private=None))
    return m.Event(
        name=reader.attr(event, "name"),
        priority=priority,  # type: ignore[arg-type]
        maximum_execution_count=reader.integer(event, "maximumExecutionCount", 1),
        actions=tuple(actions),
        start_trigger=_start_trigger(reader, start),
    )


# --- actions ----------------------------------------------------------------------------------------------


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

    if inner.tag == "ActivateControllerAction":
        return m.ControllerAction(longitudinal=flag(inner, "longitudinal"), lateral=flag(inner, "lateral"))
    assign: str | None = None
    longitudinal: bool | None = None
    lateral: bool | None = None
    controller: tuple[tuple[str, str], ...] = ()
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
        elif child.tag.startswith("Override"):
            reader.warn(f"{child.tag} is ignored (no driver model to override)", child)
    return m.ControllerAction(
        assign=assign, longitudinal=longitudinal, lateral=lateral, controller=controller
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


# --- positions --------------------------------------------------------------------------------------------


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
