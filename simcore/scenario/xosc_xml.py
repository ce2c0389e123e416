"""Safe reading of untrusted XML files: OpenSCENARIO scenarios and catalogs (for the parser, `xosc.py`),
OpenDRIVE roads and parameter distributions (for their readers).

Parsed with defusedxml (no entities, no external references), bounded in size, depth, width and element
count while parsing (before anything walks the tree), every problem raised as `BadInput` naming the file;
with `lines`, the source line of every element is remembered for warnings and errors.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import defusedxml.ElementTree as SafeET
from defusedxml import DefusedXmlException

from simcore.errors import BadInput
from simcore.file_version import BoundedCache, ContentKey, content_key

MAX_SCENARIO_BYTES = 32 * 1024 * 1024
# Structure bounds checked while parsing, before anything else (the XSD check, the reader) walks the tree:
# OpenSCENARIO elements have at most a dozen attributes and real scenarios nest a few dozen levels deep.
MAX_XML_DEPTH = 256
MAX_XML_ATTRIBUTES = 256  # on one element
MAX_XML_ELEMENTS = 1_000_000
#: files parsed once per process (`parsed_xml`): at most this many, each at most this large
PARSED_FILES_MAX = 32
PARSED_FILE_MAX_BYTES = 1024 * 1024  # a parsed tree takes some 10× its file in memory: at most ~0.3 GB in all


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
    return parse_xml(read_xml_bytes(path, what=what, max_bytes=max_bytes), path, what=what, lines=lines)


def read_xml_bytes(path: Path, *, what: str, max_bytes: int = MAX_SCENARIO_BYTES) -> bytes:
    """The bytes of an untrusted XML file, refused when larger than `max_bytes` (before reading it)."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise BadInput(f"{what} not found", file=str(path)) from None
    if size > max_bytes:
        raise BadInput(f"{what} is {size} bytes; at most {max_bytes} are allowed", file=str(path))
    try:
        data = path.read_bytes()
    except FileNotFoundError:  # removed in between
        raise BadInput(f"{what} not found", file=str(path)) from None
    if len(data) > max_bytes:  # grown in between
        raise BadInput(f"{what} is {len(data)} bytes; at most {max_bytes} are allowed", file=str(path))
    return data


def parse_xml(data: bytes, path: Path, *, what: str, lines: dict[int, int] | None = None) -> ET.Element:
    """Parse the bytes of the untrusted XML file `path` safely (`read_xml`, on bytes already read)."""
    builder = _LineBuilder(lines)
    try:
        parser = SafeET.DefusedXMLParser(target=builder)
        builder.parser = parser
        parser.feed(data)
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


@dataclass(frozen=True)
class ParsedXml:
    """A parsed XML file, shared by every load of the same bytes: only read, never changed."""

    root: ET.Element
    lines: Mapping[int, int]  # element id → source line
    ids: tuple[int, ...]  # the id of every element (the entry keeps them alive, so ids stay unique)


_PARSED: BoundedCache[ContentKey, ParsedXml] = BoundedCache(PARSED_FILES_MAX)


def parsed_xml(path: Path, *, what: str, max_bytes: int = MAX_SCENARIO_BYTES) -> ParsedXml:
    """`read_xml` once per process for the same file content (a sweep's points load one scenario and its
    catalogs with other parameter values): keyed by the path and the bytes' hash, so a changed file is parsed
    again, whatever its size and times. Files larger than PARSED_FILE_MAX_BYTES are parsed every time."""
    data = read_xml_bytes(path, what=what, max_bytes=max_bytes)
    key = content_key(path, data)
    hit = _PARSED.get(key)
    if hit is None:
        lines: dict[int, int] = {}
        root = parse_xml(data, path, what=what, lines=lines)
        hit = ParsedXml(root, lines, tuple(id(element) for element in root.iter()))
        if len(data) <= PARSED_FILE_MAX_BYTES:
            _PARSED.put(key, hit)
    return hit
