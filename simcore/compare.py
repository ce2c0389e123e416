"""Compare two runs' results (`carlos compare BASELINE CANDIDATE`): pure functions from index summaries to
verdicts, and their Markdown and JUnit renderings.

Runs are matched by scenario, parameters (names and values, order aside) and seed; runs sharing all three
(repeats) are paired in index order. Each candidate run gets one verdict:

- `new failure`: passed in the baseline, failed or errored in the candidate;
- `fixed`: failed or errored in the baseline, passed in the candidate;
- `still failing`, `still passing`: the same outcome in both;
- `added`: no baseline run matches it; `removed`: a baseline run no candidate run matches.

Metric changes: a metric both runs measured whose values differ by more than
`max(tolerance * |baseline|, absolute)` (relative 0.05 and absolute 0.01 in the metric's unit by default:
near-zero noise, 0.0254 → 0.0289 m/s², is not a change). The exit code is 1 when a required (non-optional)
candidate run is a new failure, else 0. What differs between the two specs (simcore.spec_diff) comes first
in every rendering: a changed threshold is not a regression of the software.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import defaultdict, deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from simcore.evaluation.report import testcase_name
from simcore.units import change_with_unit, with_unit
from simcore.wording import plural

Verdict = Literal["new failure", "fixed", "still failing", "still passing", "added", "removed"]
VERDICTS: tuple[Verdict, ...] = ("new failure", "fixed", "still failing", "still passing", "added", "removed")

#: key of the comparison next to the candidate's summary.json (read by its report.html)
COMPARISON_KEY = "comparison.json"
#: default tolerances of a metric change: a share of the baseline's value, and in the metric's unit
TOLERANCE = 0.05
ABSOLUTE_TOLERANCE = 0.01
MATCHED: tuple[Verdict, ...] = ("new failure", "fixed", "still failing", "still passing")


def verdict_count(count: int, verdict: str) -> str:
    """`1 new failure`, `3 new failures`, `2 still failing` (pure)."""
    return plural(count, verdict) if verdict == "new failure" else f"{count} {verdict}"


@dataclass(frozen=True)
class MetricChange:
    metric: str
    baseline: float
    candidate: float

    @property
    def delta(self) -> float:
        return self.candidate - self.baseline


@dataclass(frozen=True)
class RunVerdict:
    """One run's verdict; `baseline`/`candidate` are its index summaries (None when added/removed)."""

    verdict: Verdict
    baseline: Mapping[str, Any] | None
    candidate: Mapping[str, Any] | None
    metric_changes: tuple[MetricChange, ...] = ()

    @property
    def run(self) -> Mapping[str, Any]:
        summary = self.candidate if self.candidate is not None else self.baseline
        assert summary is not None
        return summary

    @property
    def name(self) -> str:
        """The run's test name (the candidate's index, else the baseline's)."""
        return testcase_name(self.run, 4)

    @property
    def optional(self) -> bool:
        return bool(self.run.get("optional", False))


@dataclass(frozen=True)
class Comparison:
    baseline: str
    candidate: str
    tolerance: float
    runs: tuple[RunVerdict, ...] = field(default_factory=tuple)
    absolute: float = ABSOLUTE_TOLERANCE
    spec_differences: tuple[str, ...] = ()

    def of(self, verdict: Verdict) -> list[RunVerdict]:
        return [r for r in self.runs if r.verdict == verdict]

    @property
    def counts(self) -> dict[str, int]:
        return {v: sum(r.verdict == v for r in self.runs) for v in VERDICTS}

    @property
    def matched(self) -> int:
        """Candidate runs that have a baseline run to compare with."""
        return sum(r.verdict in MATCHED for r in self.runs)

    def counts_line(self) -> str:
        """`1 new failure · 0 fixed · … · 2 with metric changes` (pure)."""
        counts = self.counts
        return (
            " · ".join(verdict_count(counts[v], v) for v in VERDICTS)
            + f" · {len(self.changed_metrics)} with metric changes"
        )

    @property
    def changed_metrics(self) -> list[RunVerdict]:
        return [r for r in self.runs if r.metric_changes]

    @property
    def exit_code(self) -> int:
        return 1 if any(not r.optional for r in self.of("new failure")) else 0

    def as_dict(self) -> dict[str, Any]:
        """JSON form (comparison.json): counts, and per run its verdict, indexes, statuses and changes."""
        return {
            "baseline": self.baseline,
            "candidate": self.candidate,
            "tolerance": self.tolerance,
            "absoluteTolerance": self.absolute,
            "specDifferences": list(self.spec_differences),
            "exitCode": self.exit_code,
            "counts": self.counts,
            "runs": [
                {
                    "name": r.name,
                    "verdict": r.verdict,
                    "optional": r.optional,
                    "baselineIndex": None if r.baseline is None else r.baseline["index"],
                    "candidateIndex": None if r.candidate is None else r.candidate["index"],
                    "baselineStatus": None if r.baseline is None else r.baseline["status"],
                    "candidateStatus": None if r.candidate is None else r.candidate["status"],
                    "metricChanges": [
                        {"metric": c.metric, "baseline": c.baseline, "candidate": c.candidate}
                        for c in r.metric_changes
                    ],
                }
                for r in self.runs
            ],
        }


def run_key(summary: Mapping[str, Any]) -> str:
    """What matches a run across builds: scenario, parameters (sorted by name) and seed (pure)."""
    parameters = summary.get("parameters") or {}
    return json.dumps(
        [summary["scenario"], sorted(parameters.items()), summary.get("seed")], sort_keys=True, default=str
    )


def classify(baseline_status: str | None, candidate_status: str | None) -> Verdict:
    """The verdict of one matched pair of statuses (None: no run on that side) (pure)."""
    if baseline_status is None:
        return "added"
    if candidate_status is None:
        return "removed"
    before, after = baseline_status == "passed", candidate_status == "passed"
    if before and not after:
        return "new failure"
    if after and not before:
        return "fixed"
    return "still passing" if after else "still failing"


def metric_changes(
    baseline: Mapping[str, float],
    candidate: Mapping[str, float],
    tolerance: float = TOLERANCE,
    absolute: float = ABSOLUTE_TOLERANCE,
) -> tuple[MetricChange, ...]:
    """Metrics measured on both sides that differ by more than `max(tolerance·|baseline|, absolute)`, by
    the candidate's metric order (pure)."""
    changes = []
    for name, value in candidate.items():
        if name not in baseline:
            continue
        before, after = float(baseline[name]), float(value)
        if abs(after - before) > max(tolerance * abs(before), absolute):
            changes.append(MetricChange(name, before, after))
    return tuple(changes)


def compare(
    baseline: Sequence[Mapping[str, Any]],
    candidate: Sequence[Mapping[str, Any]],
    *,
    tolerance: float = TOLERANCE,
    absolute: float = ABSOLUTE_TOLERANCE,
    baseline_name: str = "baseline",
    candidate_name: str = "candidate",
    spec_differences: Sequence[str] = (),
) -> Comparison:
    """Every candidate run's verdict (by candidate index), then the removed baseline runs (by baseline
    index) (pure)."""
    waiting: dict[str, deque[Mapping[str, Any]]] = defaultdict(deque)
    for summary in sorted(baseline, key=lambda s: int(s["index"])):
        waiting[run_key(summary)].append(summary)
    runs: list[RunVerdict] = []
    for summary in sorted(candidate, key=lambda s: int(s["index"])):
        queue = waiting.get(run_key(summary))
        before = queue.popleft() if queue else None
        verdict = classify(None if before is None else before["status"], summary["status"])
        changes = (
            metric_changes(before.get("metrics", {}), summary.get("metrics", {}), tolerance, absolute)
            if before is not None
            else ()
        )
        runs.append(RunVerdict(verdict, before, summary, changes))
    removed = sorted((s for queue in waiting.values() for s in queue), key=lambda s: int(s["index"]))
    runs.extend(RunVerdict("removed", s, None) for s in removed)
    return Comparison(
        baseline_name, candidate_name, tolerance, tuple(runs), absolute, tuple(spec_differences)
    )


def failure_text(summary: Mapping[str, Any] | None) -> str:
    """The failed criteria (or the error) of a run in one line (pure)."""
    if summary is None or summary["status"] == "passed":
        return ""
    if summary["status"] == "error":
        return str(summary.get("error") or "error")
    parts = [
        f"{c['name']}: " + with_unit(str(c.get("metric", "")), c.get("actual"))
        for c in summary.get("criteria", [])
        if not c["passed"]
    ]
    return "; ".join(parts) or "failed"


def _md(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _md_table(head: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines.extend("| " + " | ".join(_md(c) for c in row) + " |" for row in rows)
    return lines


def markdown(comparison: Comparison, limit: int = 50) -> str:
    """A pull-request comment: the verdict, the counts, then new failures, fixed, metric changes,
    added/removed and (folded) the runs still failing."""
    counts = comparison.counts
    new = comparison.of("new failure")
    head = f"❌ {verdict_count(len(new), 'new failure')}" if comparison.exit_code else "✅ no new failures"
    lines = [
        f"### CARLOS compare: {head}",
        "",
        f"Baseline `{comparison.baseline}` → candidate `{comparison.candidate}`",
    ]
    if comparison.spec_differences:
        lines += [
            "",
            f"#### The specs differ ({len(comparison.spec_differences)})",
            "",
            "A changed criterion, parameter or scenario file changes verdicts by itself:",
            "",
            *(f"- {_md(d)}" for d in comparison.spec_differences),
        ]
    lines += ["", *_md_table(["verdict", "runs"], [(v, counts[v]) for v in VERDICTS])]

    def section(title: str, rows: list[RunVerdict], folded: bool = False) -> None:
        if not rows:
            return
        table = _md_table(
            ["run", "baseline", "candidate", "failure"],
            [
                (
                    r.name + (" (optional)" if r.optional else ""),
                    "—" if r.baseline is None else r.baseline["status"],
                    "—" if r.candidate is None else r.candidate["status"],
                    failure_text(r.candidate if r.candidate is not None else r.baseline),
                )
                for r in rows[:limit]
            ],
        )
        more = [f"… and {len(rows) - limit} more"] if len(rows) > limit else []
        if folded:
            lines.extend(
                [
                    "",
                    f"<details><summary>{title} ({len(rows)})</summary>",
                    "",
                    *table,
                    *more,
                    "",
                    "</details>",
                ]
            )
        else:
            lines.extend(["", f"#### {title} ({len(rows)})", "", *table, *more])

    section("New failures", new)
    section("Fixed", comparison.of("fixed"))
    changed = comparison.changed_metrics
    if changed:
        rows = [
            (
                r.name,
                c.metric,
                with_unit(c.metric, c.baseline),
                with_unit(c.metric, c.candidate),
                change_with_unit(c.metric, c.delta),
            )
            for r in changed
            for c in r.metric_changes
        ]
        lines.extend(
            [
                "",
                f"#### Metric changes beyond {comparison.tolerance:g} × \\|baseline\\| and "
                f"{comparison.absolute:g} in the metric's unit ({len(rows)})",
                "",
                *_md_table(["run", "metric", "baseline", "candidate", "change"], rows[:limit]),
            ]
        )
        if len(rows) > limit:
            lines.append(f"… and {len(rows) - limit} more")
    section("Added runs", comparison.of("added"))
    section("Removed runs", comparison.of("removed"))
    section("Still failing", comparison.of("still failing"), folded=True)
    return "\n".join(lines) + "\n"


def junit_xml(comparison: Comparison) -> str:
    """JUnit XML of the regressions: one testcase per candidate run (name `testcase_name`, classname
    `carlos.compare.<scenario>`): a new failure is a `<failure>`; a run still failing is `<skipped>` (a
    known failure, not this change's); added and fixed runs pass; removed runs are `<skipped>`."""
    suites: dict[str, list[RunVerdict]] = {}
    for r in comparison.runs:
        suites.setdefault(str(r.run["scenario"]), []).append(r)
    root = ET.Element(
        "testsuites",
        name=f"carlos compare {comparison.baseline} {comparison.candidate}",
        tests=str(len(comparison.runs)),
        failures=str(sum(r.verdict == "new failure" for r in comparison.runs)),
    )
    for scenario, rows in suites.items():
        suite = ET.SubElement(
            root,
            "testsuite",
            name=scenario,
            tests=str(len(rows)),
            failures=str(sum(r.verdict == "new failure" for r in rows)),
            skipped=str(sum(r.verdict in ("still failing", "removed") for r in rows)),
        )
        for r in rows:
            case = ET.SubElement(
                suite, "testcase", name=testcase_name(r.run), classname=f"carlos.compare.{scenario}"
            )
            if r.verdict == "new failure":
                text = failure_text(r.candidate)
                ET.SubElement(case, "failure", message=f"new failure: {text}", type="newFailure").text = text
            elif r.verdict == "still failing":
                ET.SubElement(
                    case, "skipped", message=f"failing in the baseline too: {failure_text(r.candidate)}"
                )
            elif r.verdict == "removed":
                ET.SubElement(case, "skipped", message="removed: no candidate run matches this baseline run")
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
