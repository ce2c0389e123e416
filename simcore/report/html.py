"""`report.html`: one self-contained page per run (inline CSS and SVG, no script, nothing fetched at view
time) — verdict, criteria table, failures, pass/fail heat map, metric distributions, bird's-eye plots of
the worst indexes and the table of every index with links to its recording."""

from __future__ import annotations

import datetime as dt
import html
from collections.abc import Mapping, Sequence
from typing import Any

from simcore.evaluation.report import testcase_name
from simcore.report import plots
from simcore.report.trajectories import RoadOutline, read_recording, road_outline
from simcore.results import PrefixedStore, RunResults
from simcore.spec import SimulationRun
from simcore.store import Store, StoreError

#: name of the report next to the run-level summary.json
REPORT_KEY = "report.html"

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px auto;max-width:1100px;
color:#212121;padding:0 16px}
h1{margin-bottom:4px}h2{margin-top:32px;border-bottom:1px solid #ddd;padding-bottom:4px}
table{border-collapse:collapse;font-size:13px;margin:8px 0}
th,td{border:1px solid #ddd;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f5f5f5}td.num{text-align:right;font-variant-numeric:tabular-nums}
.badge{display:inline-block;padding:2px 10px;border-radius:10px;color:#fff;font-weight:600}
.passed{background:#2e7d32}.failed{background:#c62828}.error{background:#6a1b9a}.optional{background:#757575}
.muted{color:#757575}svg.plot{max-width:100%;height:auto;display:block;margin:8px 0}
"""


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _badge(status: str) -> str:
    return f'<span class="badge {_e(status)}">{_e(status)}</span>'


def _short(value: float) -> str:
    return f"{value:.4g}"


def _number(value: Any) -> str:
    return (
        _short(float(value)) if isinstance(value, int | float) else "absent" if value is None else _e(value)
    )


def criteria_rows(indexes: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per scenario and criterion: threshold, passed and failed counts, the measured range and
    whether it is optional (pure; the order of first appearance)."""
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for summary in indexes:
        for c in summary.get("criteria", []):
            row = rows.setdefault(
                (summary["scenario"], c["name"]),
                {
                    "scenario": summary["scenario"],
                    "criterion": c["name"],
                    "expected": c["expected"],
                    "optional": bool(c.get("optional")) or bool(summary.get("optional")),
                    "passed": 0,
                    "failed": 0,
                    "values": [],
                },
            )
            row["passed" if c["passed"] else "failed"] += 1
            if c.get("actual") is not None:
                row["values"].append(float(c["actual"]))
    return list(rows.values())


def worst_indexes(indexes: Sequence[Mapping[str, Any]], count: int) -> list[Mapping[str, Any]]:
    """The `count` most interesting indexes: errors, then failures, then collisions, then the smallest
    minDistance (pure)."""
    rank = {"error": 0, "failed": 1, "passed": 2}

    def key(s: Mapping[str, Any]) -> tuple[int, float, float, int]:
        metrics = s.get("metrics", {})
        return (
            rank.get(s["status"], 0),
            -float(metrics.get("collision", 0.0)),
            float(metrics.get("minDistance", float("inf"))),
            int(s["index"]),
        )

    return sorted(indexes, key=key)[:count]


def swept_parameters(indexes: Sequence[Mapping[str, Any]]) -> list[str]:
    """Numeric parameters that take more than one value across the indexes, most values first (pure)."""
    values: dict[str, set[float]] = {}
    for s in indexes:
        for name, value in (s.get("parameters") or {}).items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                values.setdefault(name, set()).add(float(value))
    swept = [name for name, seen in values.items() if len(seen) > 1]
    return sorted(swept, key=lambda n: -len(values[n]))


def _link(results: RunResults, key: str, relative: bool) -> str | None:
    if not results.store.exists(key):
        return None
    return key if relative else results.store.url_for(key)


def _verdict(results: RunResults) -> str:
    summary = results.summary
    if summary is None:
        counts = {"passed": sum(s["status"] == "passed" for s in results.indexes)}
        return (
            f"<p>{_badge('optional')} running or interrupted: {len(results.indexes)} indexes complete, "
            f"{counts['passed']} passed</p>"
        )
    c = summary["counts"]
    parts = [f"{c['total']} runs", f"{c['passed']} passed", f"{c['failed']} failed", f"{c['errors']} errors"]
    if c.get("optionalFailed"):
        parts.append(f"{c['optionalFailed']} optional failed")
    if c.get("missing"):
        parts.append(f"{c['missing']} missing")
    return f"<p>{_badge(summary['status'])} exit code {summary['exitCode']} · {' · '.join(parts)}</p>"


def _criteria_table(results: RunResults) -> str:
    rows = criteria_rows(results.indexes)
    if not rows:
        return '<p class="muted">No criteria: every run that completes passes.</p>'
    out = [
        "<table><tr><th>scenario</th><th>criterion</th><th>threshold</th><th>result</th>"
        "<th>passed</th><th>failed</th><th>measured (min … max)</th></tr>"
    ]
    for r in rows:
        status = "optional" if r["optional"] and r["failed"] else "failed" if r["failed"] else "passed"
        measured = (
            f"{_short(min(r['values']))} … {_short(max(r['values']))}"
            if len(set(r["values"])) > 1
            else _short(r["values"][0])
            if r["values"]
            else "absent"
        )
        out.append(
            f"<tr><td>{_e(r['scenario'])}</td><td>{_e(r['criterion'])}</td><td>{_e(r['expected'])}</td>"
            f"<td>{_badge(status)}</td><td class=num>{r['passed']}</td><td class=num>{r['failed']}</td>"
            f"<td class=num>{_e(measured)}</td></tr>"
        )
    out.append("</table>")
    return "".join(out)


def _failures(results: RunResults, limit: int = 50) -> str:
    failed = [s for s in results.indexes if s["status"] != "passed"]
    if not failed:
        return '<p class="muted">None.</p>'
    out = ["<table><tr><th>index</th><th>status</th><th>criterion</th><th>value</th><th>message</th></tr>"]
    for s in failed[:limit]:
        status = "optional" if s.get("optional") else s["status"]
        if s["status"] == "error":
            out.append(
                f"<tr><td>{_e(testcase_name(s))}</td><td>{_badge(status)}</td><td></td><td></td>"
                f"<td>{_e(s.get('error'))}</td></tr>"
            )
            continue
        for c in s.get("criteria", []):
            if not c["passed"]:
                out.append(
                    f"<tr><td>{_e(testcase_name(s))}</td><td>{_badge(status)}</td><td>{_e(c['name'])}</td>"
                    f"<td class=num>{_number(c.get('actual'))}</td><td>{_e(c.get('message'))}</td></tr>"
                )
    out.append("</table>")
    if len(failed) > limit:
        out.append(f'<p class="muted">… and {len(failed) - limit} more.</p>')
    return "".join(out)


def _heat_map(results: RunResults) -> str:
    swept = swept_parameters(results.indexes)
    if len(swept) < 2:
        return ""
    x_name, y_name = swept[1], swept[0]
    points = [
        (float(s["parameters"][x_name]), float(s["parameters"][y_name]), s["status"] == "passed")
        for s in results.indexes
        if x_name in s.get("parameters", {}) and y_name in s.get("parameters", {})
    ]
    return "<h2>Pass/fail over the sweep</h2>" + plots.heat_map(x_name, y_name, points)


def _distributions(results: RunResults, limit: int = 16) -> str:
    values: dict[str, list[float]] = {}
    for s in results.indexes:
        for name, value in s.get("metrics", {}).items():
            values.setdefault(name, []).append(float(value))
    values = {n: v for n, v in values.items() if len(v) > 1 and min(v) != max(v)}
    if not values:
        return ""
    return "<h2>Metric distributions</h2>" + plots.distributions(dict(list(values.items())[:limit]))


def _birds_eye(results: RunResults, worst: int) -> str:
    ego = results.spec.spec.simulation.ego if results.spec is not None else None
    roads: dict[str, RoadOutline | None] = {}
    figures = []
    for s in worst_indexes(results.indexes, worst):
        key = f"{s['index']}/recording.mcap"
        try:
            data = results.store.get_bytes(key) if results.store.exists(key) else None
        except StoreError:
            data = None
        if data is None:
            continue
        recording = read_recording(data, ego)
        if not recording.trajectories:
            continue
        source = recording.scenario_file or ""
        if source not in roads:
            roads[source] = road_outline(recording.scenario_file)
        title = f"{testcase_name(s)} · {s['status']}"
        figures.append(plots.birds_eye(recording, roads[source], title))
    if not figures:
        return ""
    note = (
        ""
        if any(roads.values())
        else '<p class="muted">Road outline unavailable: the scenario files of the recordings are not on '
        "this machine.</p>"
    )
    return (
        f"<h2>Bird's-eye view of the {len(figures)} worst runs</h2>{note}"
        "<p class=muted>Dots: start of each trajectory; dashed: the closest approach to the ego; "
        "red crosses: collisions.</p>" + "".join(figures)
    )


def _index_table(results: RunResults, relative: bool, metric_limit: int = 8) -> str:
    metric_names: list[str] = []
    for s in results.indexes:
        for name in s.get("metrics", {}):
            if name not in metric_names:
                metric_names.append(name)
    metric_names = metric_names[:metric_limit]
    head = "".join(f"<th>{_e(n)}</th>" for n in metric_names)
    out = [
        f"<table><tr><th>index</th><th>scenario</th><th>status</th><th>parameters</th><th>seed</th>{head}"
        "<th>files</th></tr>"
    ]
    for s in results.indexes:
        i = s["index"]
        params = ", ".join(f"{k}={v}" for k, v in (s.get("parameters") or {}).items())
        cells = "".join(
            f"<td class=num>{_short(float(s['metrics'][n])) if n in s.get('metrics', {}) else '—'}</td>"
            for n in metric_names
        )
        links = []
        for label, key in (("MCAP", f"{i}/recording.mcap"), ("log", f"{i}/log.txt")):
            href = _link(results, key, relative)
            if href is not None:
                links.append(f'<a href="{_e(href)}">{label}</a>')
        out.append(
            f"<tr><td class=num>{i}</td><td>{_e(s['scenario'])}</td><td>{_badge(s['status'])}</td>"
            f"<td>{_e(params)}</td><td class=num>{_e(s.get('seed'))}</td>{cells}"
            f"<td>{' '.join(links)}</td></tr>"
        )
    out.append("</table>")
    return "".join(out)


def render(results: RunResults, *, worst: int = 6, relative_links: bool = False, omitted: int = 0) -> str:
    """The whole page. `relative_links`: the page is stored next to the run's summary.json, so the links
    to recordings and logs are relative to it; else they are the store's URLs. `omitted`: index summaries
    left out of `results.indexes` (a large run: the verdict's counts stay those of summary.json)."""
    now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    body = [
        f"<h1>SimulationRun {_e(results.name)}</h1>",
        f'<p class="muted">{_e(results.url)} · report generated {now}</p>',
        _verdict(results),
        "<h2>Criteria</h2>",
        _criteria_table(results),
        "<h2>Failed and errored runs</h2>",
        _failures(results),
        _heat_map(results),
        _distributions(results),
        _birds_eye(results, worst),
        "<h2>Runs</h2>",
        (
            f'<p class="muted">{len(results.indexes):,} of {len(results.indexes) + omitted:,} indexes shown '
            "(failed and errored first); the counts above are the whole run's (summary.json), the tables "
            "and plots are of the indexes shown.</p>"
            if omitted
            else ""
        ),
        _index_table(results, relative_links),
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>CARLOS report: {_e(results.name)}</title><style>{_CSS}</style></head><body>"
        + "\n".join(part for part in body if part)
        + "</body></html>\n"
    )


def write_next_to_summary(results: RunResults, *, worst: int = 6, omitted: int = 0) -> str:
    """Render the report and store it as `<run>/report.html`; returns its URL."""
    page = render(results, worst=worst, relative_links=True, omitted=omitted)
    results.store.put_bytes(REPORT_KEY, page.encode())
    return results.store.url_for(REPORT_KEY)


class ReportSample:
    """At most `limit` index summaries for a report of a run too large to hold every summary: the failed
    and errored ones first, then passed ones, in index order. Fed one summary at a time (a stream)."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.seen = 0
        self._bad: list[dict[str, Any]] = []
        self._good: list[dict[str, Any]] = []

    def add(self, summary: Mapping[str, Any]) -> None:
        self.seen += 1
        kept = self._bad if summary.get("status") != "passed" else self._good
        if len(kept) < self.limit:
            kept.append(dict(summary))

    def summaries(self) -> list[dict[str, Any]]:
        chosen = self._bad + self._good[: max(0, self.limit - len(self._bad))]
        return sorted(chosen, key=lambda s: int(s["index"]))

    @property
    def omitted(self) -> int:
        return self.seen - len(self.summaries())


def write_after_run(
    store: Store,
    run: SimulationRun,
    summary: dict[str, Any],
    index_summaries: Sequence[dict[str, Any]],
    *,
    omitted: int = 0,
    worst: int = 6,
) -> str:
    """Store `<run>/report.html` at the end of a run (`carlos run`, the operator) from the summaries at
    hand (`omitted`: how many more the run has); its URL."""
    results = RunResults(
        url=store.url_for(run.name),
        store=PrefixedStore(store, run.name),
        name=run.name,
        spec=run,
        summary=summary,
        indexes=sorted(index_summaries, key=lambda s: int(s["index"])),
    )
    return write_next_to_summary(results, worst=worst, omitted=omitted)
