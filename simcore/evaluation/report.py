"""Per-index and run-level summaries (summary.json) and the JUnit report (junit.xml); pure functions.

Run-level counting (every index lands in exactly one bucket, so
`passed + failed + errors + optionalFailed + missing == total`):

- `passed`: indexes with status `passed` (required or optional scenario);
- `failed`, `errors`: indexes of required scenarios with status `failed`, `error`;
- `optionalFailed`: indexes of optional scenarios with status `failed` or `error`;
- `missing`: indexes in `0 … total-1` without a summary.

The run's `status` is `passed` when `failed == errors == missing == 0`, else `failed`. Its `exitCode`
(DESIGN.md): 1 when a required index failed (a test failure wins over everything else, because a retry
cannot fix it), else 2 when a required index errored on bad input (its summary has `badInput: true`: a
retry cannot fix that either), else 3 when a required index errored or an index is missing
(infrastructure), else 0.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import IO, Any, Literal

from simcore.evaluation.criteria import CriterionResult, format_measured, verdict

EndReason = Literal["stopTrigger", "maxSeconds", "error"]
END_REASONS: tuple[str, ...] = ("stopTrigger", "maxSeconds", "error")
STATUSES: tuple[str, ...] = ("passed", "failed", "error")

EXIT_PASSED = 0
EXIT_TEST_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INFRASTRUCTURE = 3


def _finite(name: str, value: float) -> float:
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} is {number!r}: summary.json holds finite numbers only")
    return number


def index_summary(
    *,
    index: int,
    scenario: str,
    parameters: Mapping[str, Any],
    seed: int,
    optional: bool,
    sim_seconds: float,
    wall_seconds: float,
    metrics: Mapping[str, float],
    results: Sequence[CriterionResult],
    error: str | None,
    end_reason: EndReason,
    attempts: int = 1,
    scenario_time_offset: float = 0.0,
) -> dict[str, Any]:
    """The per-index summary.json as a dict (DESIGN.md fields plus `endReason` and `attempts`).

    `status` is `verdict(results, error)`. `end_reason` is why the simulation ended; `error` (the message)
    must be set when it is `error`. Metric values must be finite."""
    if end_reason not in END_REASONS:
        raise ValueError(f"end_reason must be one of {', '.join(END_REASONS)}, not {end_reason!r}")
    if end_reason == "error" and error is None:
        raise ValueError("end_reason 'error' needs the error message")
    if index < 0:
        raise ValueError(f"index must be >= 0, not {index}")
    if attempts < 1:
        raise ValueError(f"attempts must be >= 1, not {attempts}")
    summary: dict[str, Any] = {
        "index": index,
        "scenario": scenario,
        "parameters": dict(parameters),
        "seed": seed,
        "status": verdict(results, error),
        "optional": optional,
        "simSeconds": _finite("simSeconds", sim_seconds),
        "wallSeconds": _finite("wallSeconds", wall_seconds),
        "metrics": {name: _finite(f"metric {name}", value) for name, value in metrics.items()},
        "criteria": [
            {
                "name": r.name,
                "metric": r.metric,
                "expected": r.expected,
                "actual": r.actual,
                "passed": r.passed,
                "optional": r.optional,
                "message": r.message,
            }
            for r in results
        ],
        "error": error,
        "endReason": end_reason,
        "attempts": attempts,
    }
    if scenario_time_offset:
        # scenario time = simSeconds' time axis + this (a FollowGhost's ghost starts before time 0)
        summary["scenarioTimeOffsetSeconds"] = _finite("scenarioTimeOffsetSeconds", scenario_time_offset)
    return summary


class _Aggregate:
    __slots__ = ("count", "max", "min", "total")

    def __init__(self) -> None:
        self.count = 0
        self.total = 0.0
        self.min = math.inf
        self.max = -math.inf

    def add(self, value: float) -> None:
        self.count += 1
        self.total += value
        self.min = min(self.min, value)
        self.max = max(self.max, value)

    def as_dict(self) -> dict[str, float | int]:
        return {"min": self.min, "mean": self.total / self.count, "max": self.max, "count": self.count}


def _new_counts() -> dict[str, int]:
    return {"runs": 0, "passed": 0, "failed": 0, "errors": 0, "optionalFailed": 0}


def run_summary(
    run_name: str,
    index_summaries: Iterable[Mapping[str, Any]],
    total: int,
    expected: Collection[int] | None = None,
) -> dict[str, Any]:
    """The run-level summary.json from the per-index summaries (streamed once; see the module docstring).

    Fields: `run`, `status`, `exitCode`, `counts` {total, passed, failed, errors, optionalFailed, missing},
    `scenarios` {name: {optional, counts {runs, passed, failed, errors, optionalFailed},
    metrics {metric: {min, mean, max, count}}}} in order of first appearance. A metric's `count` is the
    number of that scenario's indexes that had it (metrics can be absent). Raises ValueError for an index
    outside `0 … total-1`, a repeated index or an unknown status. `expected`: the selected indexes (e.g.
    `--index 4 --index 7`; `total` is then their count) instead of `0 … total-1`."""
    if total < 0:
        raise ValueError(f"total must be >= 0, not {total}")
    if expected is not None and len(set(expected)) != total:
        raise ValueError(f"total is {total} but {len(set(expected))} indexes are expected")
    counts = {"total": total, "passed": 0, "failed": 0, "errors": 0, "optionalFailed": 0, "missing": 0}
    scenarios: dict[str, dict[str, Any]] = {}
    aggregates: dict[str, dict[str, _Aggregate]] = {}
    seen: set[int] = set()
    bad_input = False
    for summary in index_summaries:
        index = summary["index"]
        if expected is not None and index not in expected:
            raise ValueError(f"index {index} is not among the selected indexes")
        if expected is None and not 0 <= index < total:
            raise ValueError(f"index {index} is outside 0…{total - 1}")
        if index in seen:
            raise ValueError(f"index {index} has two summaries")
        seen.add(index)
        status = summary["status"]
        if status not in STATUSES:
            raise ValueError(f"index {index}: status {status!r} is not one of {', '.join(STATUSES)}")
        optional = bool(summary.get("optional", False))
        name = summary["scenario"]
        scenario = scenarios.get(name)
        if scenario is None:
            scenario = scenarios[name] = {"optional": optional, "counts": _new_counts()}
            aggregates[name] = {}
        scenario["optional"] = scenario["optional"] or optional
        bucket = (
            "passed"
            if status == "passed"
            else "optionalFailed"
            if optional
            else "failed"
            if status == "failed"
            else "errors"
        )
        counts[bucket] += 1
        scenario["counts"][bucket] += 1
        scenario["counts"]["runs"] += 1
        metric_aggregates = aggregates[name]
        for metric, value in summary.get("metrics", {}).items():
            aggregate = metric_aggregates.get(metric)
            if aggregate is None:
                aggregate = metric_aggregates[metric] = _Aggregate()
            aggregate.add(float(value))
        if bucket == "errors" and summary.get("badInput"):
            bad_input = True
    counts["missing"] = total - len(seen)
    for name, scenario in scenarios.items():
        scenario["metrics"] = {metric: a.as_dict() for metric, a in aggregates[name].items()}

    if counts["failed"]:
        exit_code = EXIT_TEST_FAILED
    elif bad_input:
        exit_code = EXIT_BAD_INPUT
    elif counts["errors"] or counts["missing"]:
        exit_code = EXIT_INFRASTRUCTURE
    else:
        exit_code = EXIT_PASSED
    return {
        "run": run_name,
        "status": "passed" if exit_code == EXIT_PASSED else "failed",
        "exitCode": exit_code,
        "counts": counts,
        "scenarios": scenarios,
    }


# XML 1.0 cannot hold most control characters, lone surrogates or U+FFFE/U+FFFF, even escaped: the
# complement of XML's Char production, spelled out (the negated class of its ranges takes ~15 ms to compile).
_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def _xml_text(value: object) -> str:
    return _XML_INVALID.sub("\ufffd", str(value))


def _format_value(value: Any, digits: int | None = None) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if digits is not None and math.isfinite(value):
            return f"{value:.{digits}g}"
        short = f"{value:g}"
        return short if float(short) == value else repr(value)
    return str(value)


def testcase_name(summary: Mapping[str, Any], digits: int | None = None) -> str:
    """`cut-in[3] speed=30,gap=15` (parameters in their order; no suffix without parameters). JUnit names
    keep every digit (a search's 7.0720762150555725); what a person reads takes `digits` significant digits
    (`CutInGap=7.072`): the index names the run exactly."""
    parameters = summary.get("parameters") or {}
    name = f"{summary['scenario']}[{summary['index']}]"
    if parameters:
        name += " " + ",".join(f"{key}={_format_value(value, digits)}" for key, value in parameters.items())
    return name


def _threshold(criterion: Mapping[str, Any]) -> float | None:
    """The number of a criterion's `expected` (`>= 2` → 2.0), None when it has none."""
    try:
        return float(str(criterion.get("expected", "")).split()[-1])
    except (IndexError, ValueError):
        return None


def summary_json(summary: Mapping[str, Any]) -> bytes:
    """A summary.json's bytes: keys sorted (stable bytes), except a summary's `parameters`, which keep their
    order (the manifest's: spec, scenario, matrix), as in junit.xml's testcase names."""
    return (json.dumps(_sorted_except_parameters(summary), indent=2) + "\n").encode()


def _sorted_except_parameters(value: Any, key: str = "") -> Any:
    if isinstance(value, Mapping):
        items = value.items() if key == "parameters" else sorted(value.items())
        return {k: v if key == "parameters" else _sorted_except_parameters(v, k) for k, v in items}
    if isinstance(value, list):
        return [_sorted_except_parameters(v) for v in value]
    return value


def in_manifest_order(summary: dict[str, Any], order: Sequence[str]) -> dict[str, Any]:
    """`summary` with its `parameters` in `order` (the plan's, i.e. the manifest's) and any others after them
    as they were: summaries written before their order was kept have them sorted by name."""
    parameters = summary.get("parameters")
    if not isinstance(parameters, dict):
        return summary
    ordered = {name: parameters[name] for name in order if name in parameters}
    ordered.update((name, value) for name, value in parameters.items() if name not in ordered)
    if list(ordered) == list(parameters):
        return summary
    return {**summary, "parameters": ordered}


def _failure_message(summary: Mapping[str, Any]) -> tuple[str, str]:
    """(one-line message, detailed text) for a failed index: its failed required criteria."""
    failed = [c for c in summary.get("criteria", []) if not c["passed"] and not c.get("optional", False)]
    if not failed:
        return "failed", "failed without a failed required criterion"
    parts = []
    for c in failed:
        actual = "absent" if c["actual"] is None else format_measured(float(c["actual"]), _threshold(c))
        parts.append(f"{c['name']}: expected {c['expected']}, actual {actual}")
    message = f"{len(failed)} criteria failed: " + "; ".join(parts) if len(failed) > 1 else parts[0]
    text = "\n".join(c.get("message") or c["name"] for c in failed)
    return message, text


def junit_xml(run_name: str, index_summaries: Iterable[Mapping[str, Any]]) -> str:
    """JUnit XML: `<testsuites>` with one `<testsuite>` per scenario (in order of first appearance) and
    one `<testcase>` per index (by index): name `testcase_name`, classname `carlos.<run>.<scenario>`,
    time the wall seconds, `<properties>` with the parameters (`param.<name>`), `seed`, `attempts`,
    `endReason` and `flaky` (`true` on the runs of a point whose verdict changed between its repeats). A
    failed index gets `<failure>` listing its failed required criteria with expected and actual values, an
    errored one `<error>`; in an optional scenario either is `<skipped message="optional: …">` instead."""
    out = io.BytesIO()
    write_junit_xml(run_name, index_summaries, out)
    return out.getvalue().decode()


_JUNIT_COUNTS = ("tests", "failures", "errors", "skipped")


@dataclass
class _Suite:
    """One scenario's test cases while they stream in: their XML spooled to a file, what orders them."""

    spool: IO[bytes]
    cases: list[tuple[int, int, int, float]] = field(default_factory=list)  # index, offset, length, wall
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(_JUNIT_COUNTS, 0))


def write_junit_xml(run_name: str, index_summaries: Iterable[Mapping[str, Any]], out: IO[bytes]) -> None:
    """`junit_xml`, written to `out` (UTF-8) from a stream of summaries held one at a time: each test case's
    XML is spooled to a temporary file per scenario, so that a run of 50,000 indexes never holds their
    summaries or a document tree in memory."""
    with contextlib.ExitStack() as stack:
        suites: dict[str, _Suite] = {}
        for summary in index_summaries:
            scenario = summary["scenario"]
            suite = suites.get(scenario)
            if suite is None:
                suite = suites[scenario] = _Suite(stack.enter_context(tempfile.TemporaryFile()))
            case, kind = _testcase(run_name, scenario, summary)
            ET.indent(case, level=2)
            data = ET.tostring(case, encoding="unicode").encode()
            suite.cases.append((int(summary["index"]), suite.spool.tell(), len(data), _wall(summary)))
            suite.spool.write(data)
            suite.counts["tests"] += 1
            if kind:
                suite.counts[kind] += 1
        root = ET.Element("testsuites", name=_xml_text(run_name))
        totals = dict.fromkeys(_JUNIT_COUNTS, 0)
        total_time = 0.0
        for number, (scenario, suite) in enumerate(suites.items()):
            element = ET.SubElement(root, "testsuite", name=_xml_text(scenario))
            ET.SubElement(element, f"carlos-cases-{number}")  # where the spooled cases go
            suite.cases.sort(key=lambda spooled: spooled[0])
            suite_time = 0.0
            for _, _, _, wall in suite.cases:  # summed in index order, as the cases are written
                suite_time += wall
            for key, value in suite.counts.items():
                element.set(key, str(value))
                totals[key] += value
            element.set("time", f"{suite_time:.3f}")
            total_time += suite_time
        for key, value in totals.items():
            root.set(key, str(value))
        root.set("time", f"{total_time:.3f}")
        ET.indent(root)
        skeleton = (
            '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
        ).encode()
        for number, suite in enumerate(suites.values()):
            before, _, skeleton = skeleton.partition(f"<carlos-cases-{number} />".encode())
            out.write(before)
            for position, (_, offset, length, _) in enumerate(suite.cases):
                if position:
                    out.write(b"\n    ")
                suite.spool.seek(offset)
                out.write(suite.spool.read(length))
        out.write(skeleton)


def _wall(summary: Mapping[str, Any]) -> float:
    return float(summary.get("wallSeconds") or 0.0)


def _testcase(run_name: str, scenario: str, summary: Mapping[str, Any]) -> tuple[ET.Element, str | None]:
    """One index's `<testcase>` and what it counts as beyond a test (failures, errors, skipped; None)."""
    case = ET.Element(
        "testcase",
        name=_xml_text(testcase_name(summary)),
        classname=_xml_text(f"carlos.{run_name}.{scenario}"),
        time=f"{_wall(summary):.3f}",
    )
    properties = ET.SubElement(case, "properties")
    for key, value in (summary.get("parameters") or {}).items():
        ET.SubElement(
            properties,
            "property",
            name=_xml_text(f"param.{key}"),
            value=_xml_text(_format_value(value)),
        )
    for key in ("seed", "attempts", "endReason", "flaky"):
        if summary.get(key) is not None:
            value = _format_value(summary[key])  # `flaky`: true
            ET.SubElement(properties, "property", name=key, value=_xml_text(value))
    status = summary["status"]
    if status == "passed":
        return case, None
    if status == "failed":
        message, text = _failure_message(summary)
        kind = "failure"
    else:
        message = str(summary.get("error") or "error")
        text = message
        kind = "error"
    if summary.get("optional", False):
        skipped = ET.SubElement(case, "skipped", message=_xml_text(f"optional: {message}"))
        skipped.text = _xml_text(text)
        return case, "skipped"
    if kind == "failure":
        element = ET.SubElement(case, "failure", message=_xml_text(message), type="CriterionFailed")
        element.text = _xml_text(text)
        return case, "failures"
    element = ET.SubElement(case, "error", message=_xml_text(message), type="SimulationError")
    element.text = _xml_text(text)
    return case, "errors"
