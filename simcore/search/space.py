"""The search space: `spec.search.parameters` completed from the scenario's ParameterDeclarations.

A parameter listed without `min`/`max` (and every declared parameter with a range, when none is listed)
takes its range from the declaration's ConstraintGroups: `ValueConstraint` rules greaterThan/greaterOrEqual
give the lower bound, lessThan/lessOrEqual the upper one, a `Range lowerLimit/upperLimit` both; several
groups (alternatives) span their union. Integer declarations (int, unsignedInt, unsignedShort) search whole
numbers.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from simcore.errors import BadInput
from simcore.spec import ParameterValue, Search

_INTEGER_TYPES = frozenset({"int", "integer", "unsignedInt", "unsignedShort"})
_LOWER = frozenset({"greaterThan", "greaterOrEqual"})
_UPPER = frozenset({"lessThan", "lessOrEqual"})


@dataclass(frozen=True, slots=True)
class Dimension:
    """One searched parameter: a range [low, high] (whole numbers when `integer`) or `choices`."""

    name: str
    low: float = 0.0
    high: float = 0.0
    integer: bool = False
    choices: tuple[ParameterValue, ...] | None = None

    def contains(self, value: ParameterValue) -> bool:
        if self.choices is not None:
            return value in self.choices
        return isinstance(value, int | float) and self.low <= float(value) <= self.high


@dataclass(frozen=True, slots=True)
class Declaration:
    """A top-level ParameterDeclaration: its type and the range its constraints allow (None: unbounded)."""

    name: str
    type: str
    low: float | None
    high: float | None


def _number(element: ET.Element, attribute: str) -> float | None:
    try:
        value = float(element.get(attribute, ""))
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _group_range(group: ET.Element) -> tuple[float | None, float | None]:
    low: float | None = None
    high: float | None = None
    for element in group.iter():
        if element.tag == "ValueConstraint":
            rule, value = element.get("rule", ""), _number(element, "value")
            if value is None:
                continue
            if rule in _LOWER:
                low = value if low is None else max(low, value)
            elif rule in _UPPER:
                high = value if high is None else min(high, value)
        elif element.tag == "Range":
            lower, upper = _number(element, "lowerLimit"), _number(element, "upperLimit")
            low = lower if lower is not None else low
            high = upper if upper is not None else high
    return low, high


def declarations(root: ET.Element) -> dict[str, Declaration]:
    """The scenario's top-level ParameterDeclarations with the range of their constraints."""
    block = root.find("ParameterDeclarations")
    out: dict[str, Declaration] = {}
    for item in block.findall("ParameterDeclaration") if block is not None else ():
        name = item.get("name", "").lstrip("$")
        ranges = [_group_range(g) for g in item.findall("ConstraintGroup")]
        if item.find("Range") is not None:
            ranges.append(_group_range(item))
        bounded = [(lo, hi) for lo, hi in ranges if lo is not None and hi is not None]
        low = min(lo for lo, _ in bounded) if bounded else None
        high = max(hi for _, hi in bounded) if bounded else None
        out[name] = Declaration(name, item.get("parameterType", "string"), low, high)
    return out


def read_declarations(path: Path) -> dict[str, Declaration]:
    from simcore.scenario.xosc_xml import read_xml

    return declarations(read_xml(path, what="OpenSCENARIO file"))


def dimensions(search: Search, declared: dict[str, Declaration], *, source: str) -> list[Dimension]:
    """The search space; a parameter the scenario does not declare, or one without a range, is bad input."""
    wanted = search.parameters
    if not wanted:
        out = [
            Dimension(d.name, d.low, d.high, integer=d.type in _INTEGER_TYPES)
            for d in declared.values()
            if d.low is not None and d.high is not None and d.low < d.high
        ]
        if not out:
            raise BadInput(
                f"no parameter of {source} declares a range (ValueConstraints): list the parameters to "
                "search with min and max",
                field="spec.search.parameters",
            )
        return out
    out = []
    for position, parameter in enumerate(wanted):
        field = f"spec.search.parameters[{position}]"
        declaration = declared.get(parameter.name)
        if declaration is None:
            raise BadInput(
                f"parameter {parameter.name!r} is not declared in {source} "
                f"(declared: {', '.join(sorted(declared)) or 'none'})",
                field=f"{field}.name",
            )
        if parameter.values is not None:
            out.append(Dimension(parameter.name, choices=tuple(parameter.values)))
            continue
        low = parameter.min if parameter.min is not None else declaration.low
        high = parameter.max if parameter.max is not None else declaration.high
        if low is None or high is None:
            raise BadInput(
                f"parameter {parameter.name!r} has no range: give min and max (its declaration has no "
                "ValueConstraints)",
                field=field,
            )
        integer = parameter.integer or declaration.type in _INTEGER_TYPES
        if not low < high or (integer and math.floor(high) < math.ceil(low)):
            raise BadInput(
                f"parameter {parameter.name!r}: the range [{low:g}, {high:g}] is empty", field=field
            )
        out.append(Dimension(parameter.name, low, high, integer=integer))
    return out
