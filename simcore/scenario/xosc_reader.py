"""The OpenSCENARIO parser's reading context (`_Reader`), under every other `xosc_*` module: the stack of
parameter scopes, attribute reading (`$name` and `${…}` resolved; numbers, integers, booleans), required
children, the element path and file:line that warnings and `BadInput` errors name.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from simcore.errors import BadInput
from simcore.scenario.parameters import Declaration, ParameterError, ParamValue, declare, resolve

T = TypeVar("T")


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
        # parameters declared numeric whose value is not a number ("None"): read as 0 where a number is needed
        self.not_numbers: set[str] = set()
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
                        # esmini converts it as C's strtod does (0) and keeps the text for string uses
                        self.warn(
                            f"parameter {name!r} is declared {kind} but its value {value!r} is not a number: "
                            "read as 0 where a number is needed, as esmini does",
                            item,
                        )
                        kind = "string"
                        self.not_numbers.add(name)
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
            text = element.get(name) or ""
            if text[:1] == "$" and text[1:].strip("{}") in self.not_numbers:
                return 0.0  # a numeric parameter whose value is no number (warned where it is declared)
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


def _freespace(reader: _Reader, c: ET.Element) -> bool:
    return reader.boolean(c, "freespace", False)
