"""Criteria against a run's metrics, and the run's verdict.

- A criterion on a metric that is absent from the metrics fails, with a message saying why the metric is
  absent (see `simcore.evaluation.metrics.METRICS`) or that the name is unknown.
- `==` and `!=` compare with a tolerance of `EQUALITY_TOLERANCE` (absolute and relative), so that
  `simSeconds == 10` holds after 200 steps of 0.05 s; the ordering operators compare exactly.
- A NaN metric fails every criterion.
"""

from __future__ import annotations

import math
import operator
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from simcore.evaluation.metrics import KNOWN_METRICS, METRICS
from simcore.spec import CriterionModel
from simcore.units import spoken

Status = Literal["passed", "failed", "error"]

#: Absolute and relative tolerance of `==` and `!=`.
EQUALITY_TOLERANCE = 1e-9


def _equal(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=EQUALITY_TOLERANCE, abs_tol=EQUALITY_TOLERANCE)


_OPERATORS: dict[str, Callable[[float, float], bool]] = {
    ">=": operator.ge,
    ">": operator.gt,
    "<=": operator.le,
    "<": operator.lt,
    "==": _equal,
    "!=": lambda a, b: not _equal(a, b),
}


def format_number(value: float) -> str:
    """Shortest faithful text of a number: `2` for 2.0, `0.1` for 0.1, `1e+20` for 1e20."""
    if math.isfinite(value) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(float(value))


def format_measured(value: float, threshold: float | None = None, digits: int = 4) -> str:
    """A measured value to `digits` significant digits (`0.9705` for 0.9705480511215439, `12.35` for
    12.3456), exact integers as they are; with more digits when the short form would read as the `threshold`
    it is compared with (1.99996 against `>= 2` shows `1.99996`, not `2`)."""
    value = float(value)
    if not math.isfinite(value) or (value.is_integer() and abs(value) < 1e15):
        return format_number(value)
    for precision in range(digits, 18):
        text = f"{value:.{precision}g}"
        if threshold is None or float(text) != threshold or value == threshold:
            return text
    return repr(value)


@dataclass(frozen=True, slots=True)
class CriterionResult:
    """One criterion's outcome. `expected` is the operator and threshold (`>= 2`); `actual` is the
    metric's value, None when the metric was absent."""

    name: str
    metric: str
    expected: str
    actual: float | None
    passed: bool
    optional: bool
    message: str


def _evaluate_one(criterion: CriterionModel, metrics: Mapping[str, float]) -> CriterionResult:
    expected = f"{criterion.operator} {format_number(criterion.value)}"
    metric = criterion.metric
    actual = metrics.get(metric)
    if actual is None:
        if metric in KNOWN_METRICS:
            message = (
                f"metric {metric!r} was not measured in this run ({METRICS[metric]}): {expected} cannot hold"
            )
        else:
            message = (
                f"unknown metric {metric!r}: it is not among this run's metrics "
                f"({', '.join(sorted(metrics)) or 'none'}) nor the known ones ({', '.join(sorted(KNOWN_METRICS))})"
            )
        passed = False
    else:
        actual = float(actual)
        if math.isnan(actual):
            passed = False
            message = f"{metric} is NaN, expected {expected}"
        else:
            passed = _OPERATORS[criterion.operator](actual, criterion.value)
            verb = "holds" if passed else "does not hold"
            u = f" {spoken(metric)}" if spoken(metric) else ""
            message = f"{metric} = {format_measured(actual, criterion.value)}{u}: {expected}{u} {verb}"
    return CriterionResult(
        name=criterion.label,
        metric=metric,
        expected=expected,
        actual=actual,
        passed=passed,
        optional=criterion.optional,
        message=message,
    )


def ranges_of(metrics: Iterable[str], prefix: str = "detection") -> list[float]:
    """The distances r of the metric names `<prefix>[.…].0-<r>m` (criteria such as `… within 50 m`)."""
    pattern = re.compile(rf"^{re.escape(prefix)}(?:\.[A-Za-z0-9_.]*?)?\.0-([0-9.]+)m$")
    out = set()
    for name in metrics:
        match = pattern.match(name)
        if match:
            try:
                out.add(float(match.group(1)))
            except ValueError:
                continue
    return sorted(out)


def evaluate(criteria: Iterable[CriterionModel], metrics: Mapping[str, float]) -> list[CriterionResult]:
    """Every criterion against the metrics, in the criteria's order."""
    return [_evaluate_one(criterion, metrics) for criterion in criteria]


def verdict(results: Sequence[CriterionResult], error: str | None) -> Status:
    """`error` when `error` is set; else `failed` when a non-optional criterion failed; else `passed`."""
    if error is not None:
        return "error"
    if any(not r.passed and not r.optional for r in results):
        return "failed"
    return "passed"
