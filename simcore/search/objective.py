"""A run's objective value from its index summary (pure functions).

The criteria margin is how far a run is from violating its required criteria: per criterion the signed
distance to the threshold in the passing direction (`metric >= v`: metric - v; `metric <= v`: v - metric;
`==`: -|metric - v|, no margin while it holds; `!=`: |metric - v|), negative when violated; a criterion
whose metric is absent counts as violated by 1. The run's margin is the smallest over its required
criteria (0 when only holding `==` criteria remain).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from simcore.evaluation.criteria import EQUALITY_TOLERANCE
from simcore.spec import CriterionModel, SearchObjective

MARGIN = "margin"


def criterion_margin(criterion: CriterionModel, metrics: Mapping[str, float]) -> float | None:
    actual = metrics.get(criterion.metric)
    if actual is None or math.isnan(actual):
        return -1.0
    difference = float(actual) - criterion.value
    if criterion.operator in (">=", ">"):
        return difference
    if criterion.operator in ("<=", "<"):
        return -difference
    if criterion.operator == "==":
        return -abs(difference) if abs(difference) > EQUALITY_TOLERANCE else None
    return abs(difference)


def margin(criteria: list[CriterionModel], metrics: Mapping[str, float]) -> float | None:
    """The smallest margin of the required criteria (None without any)."""
    required = [c for c in criteria if not c.optional]
    margins = [m for m in (criterion_margin(c, metrics) for c in required) if m is not None]
    return min(margins) if margins else (0.0 if required else None)


def raw_value(
    objective: SearchObjective, criteria: list[CriterionModel], summary: Mapping[str, Any]
) -> float | None:
    """The objective's metric of a finished run, as measured (None: the run errored or lacks the metric)."""
    if summary.get("status") == "error":
        return None
    metrics: Mapping[str, float] = summary.get("metrics", {})
    if objective.metric == MARGIN:
        return margin(criteria, metrics)
    value = metrics.get(objective.metric)
    return float(value) if value is not None and math.isfinite(value) else None


def loss(raw: float, objective: SearchObjective, *, boundary: bool) -> float:
    """What the sampler minimises: the metric (negated to maximise), or its distance to 0 on the boundary."""
    if boundary:
        return abs(raw)
    return raw if objective.direction == "minimize" else -raw
