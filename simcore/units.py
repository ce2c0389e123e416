"""Units of the metrics, and numbers with their unit for everything a person reads (terminal tables,
`carlos get`, criteria, `carlos compare`, the report). Pure."""

from __future__ import annotations

#: units of the built-in metrics (simcore.evaluation.metrics.METRICS); "0/1" marks a yes/no metric
UNITS: dict[str, str] = {
    "collision": "0/1",
    "collisionTime": "s",
    "minDistance": "m",
    "minTimeHeadway": "s",
    "minTimeToCollision": "s",
    "minLateralDistance": "m",
    "maxDeceleration": "m/s²",
    "maxAcceleration": "m/s²",
    "maxSpeed": "m/s",
    "meanSpeed": "m/s",
    "egoDistance": "m",
    "simSeconds": "s",
    "stopTriggered": "0/1",
    "detection.meanCenterError": "m",
    "v2x.hazardToFirstDenm": "s",
}
#: metric families by prefix (the first that matches): per-sender, per-band and per-class variants
PREFIX_UNITS: tuple[tuple[str, str], ...] = (
    ("v2x.ageOfInformation.", "s"),
    ("detection.meanCenterError.", "m"),
)


def spoken(metric: str) -> str:
    """The unit after a number in a sentence: "" for yes/no metrics (`collision = 1`)."""
    u = unit(metric)
    return "" if u == "0/1" else u


def unit(metric: str) -> str:
    """The unit of a metric ("" for counts, shares and unknown metrics; "0/1" for yes/no ones)."""
    if metric in UNITS:
        return UNITS[metric]
    return next((u for prefix, u in PREFIX_UNITS if metric.startswith(prefix)), "")


def with_unit(metric: str, value: float | None, digits: int = 4) -> str:
    """`0.9705 s`, `12.35 m/s²`, `1` (yes/no and unitless metrics as bare numbers), `absent` for None."""
    from simcore.evaluation.criteria import format_measured

    if value is None:
        return "absent"
    text = format_measured(float(value), digits=digits)
    u = unit(metric)
    return f"{text} {u}" if u and u != "0/1" else text


def change_with_unit(metric: str, delta: float) -> str:
    """A signed change: `+0.0035 m/s²`."""
    from simcore.evaluation.criteria import format_measured

    text = format_measured(abs(float(delta)))
    sign = "+" if delta >= 0 else "-"
    u = unit(metric)
    return f"{sign}{text} {u}" if u and u != "0/1" else f"{sign}{text}"
