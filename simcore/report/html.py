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
from simcore.units import spoken, unit, with_unit
from simcore.wording import plural

#: name of the report next to the run-level summary.json
REPORT_KEY = "report.html"

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px auto;max-width:1100px;
color:#212121;padding:0 16px}
h1{margin-bottom:4px}h2{margin-top:32px;border-bottom:1px solid #ddd;padding-bottom:4px}
table{border-collapse:collapse;font-size:13px;margin:8px 0}
th,td{border:1px solid #ddd;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f5f5f5}td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.badge{display:inline-block;padding:2px 10px;border-radius:10px;color:#fff;font-weight:600}
.passed{background:#2e7d32}.failed{background:#c62828}.error{background:#6a1b9a}.optional{background:#757575}
.muted{color:#757575}svg.plot{max-width:100%;height:auto;display:block;margin:8px 0}
table.runs{width:100%;font-size:12px}table.runs td{overflow-wrap:break-word}div.wide{overflow-x:auto}
table.runs th{font-size:11px;white-space:nowrap;vertical-align:bottom}.unit{font-weight:400}
.badge{white-space:nowrap}
table.runs td:first-child{white-space:nowrap}p.links a{font-weight:600}

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
                    "metric": c.get("metric", ""),
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


def margin(expected: str, actual: float | None) -> float | None:
    """How far `actual` is inside (positive) or outside (negative) a criterion's `expected` (`>= 2`), as a
    share of the threshold's size (at least 1), so that criteria of different units rank together (pure;
    None when the criterion was not measured or `expected` is not `<op> <number>`)."""
    if actual is None:
        return None
    op, _, value = expected.partition(" ")
    try:
        threshold = float(value)
    except ValueError:
        return None
    distance = {
        ">=": actual - threshold,
        ">": actual - threshold,
        "<=": threshold - actual,
        "<": threshold - actual,
        "==": -abs(actual - threshold),
        "!=": abs(actual - threshold),
    }.get(op)
    return None if distance is None else distance / max(abs(threshold), 1.0)


#: metrics whose smallest value marks a near miss even without a criterion on them, tightest first
NEAR_MISS_METRICS = ("minTimeToCollision", "minTimeHeadway", "minDistance")


def worst_runs(indexes: Sequence[Mapping[str, Any]], count: int) -> list[tuple[Mapping[str, Any], str]]:
    """The `count` most telling runs and why each was chosen (pure): errors; failures, tightest margin to
    a threshold first; collisions; then for each criterion the passed run closest to its threshold and for each
    of minTimeToCollision, minTimeHeadway, minDistance the run with the smallest value; then the others by
    their smallest margin, time to collision, headway and distance."""
    chosen: dict[int, tuple[Mapping[str, Any], str]] = {}

    def pick(summary: Mapping[str, Any], reason: str) -> None:
        if len(chosen) < count and int(summary["index"]) not in chosen:
            chosen[int(summary["index"])] = (summary, reason)

    def margins(s: Mapping[str, Any]) -> list[tuple[float, str]]:
        out = []
        for c in s.get("criteria", []):
            m = margin(str(c.get("expected", "")), c.get("actual"))
            if m is not None:
                out.append((m + 0.0, str(c["name"])))  # + 0.0: never a "-0"
        return out

    def measured_text(s: Mapping[str, Any], name: str) -> str:
        """`minTimeToCollision = 0.9546 s`: what a reason says instead of an abstract margin."""
        c = next((c for c in s.get("criteria", []) if str(c["name"]) == name), None)
        if c is None or c.get("actual") is None:
            return ""
        metric = str(c.get("metric") or name)
        return f" ({metric} = {with_unit(metric, float(c['actual']))})"

    by_index = sorted(indexes, key=lambda s: int(s["index"]))
    for s in by_index:
        if s["status"] == "error":
            pick(s, "error")
    failed = [s for s in by_index if s["status"] == "failed"]
    for s in sorted(failed, key=lambda s: min((m for m, _ in margins(s)), default=0.0)):
        tightest = min(margins(s), default=None)
        pick(s, f"failed {tightest[1]}{measured_text(s, tightest[1])}" if tightest else "failed")
    for s in by_index:
        if float(s.get("metrics", {}).get("collision", 0.0)) > 0:
            pick(s, "collision")
    criteria: dict[str, list[tuple[float, int, Mapping[str, Any]]]] = {}
    for s in by_index:
        ordered = {
            str(c["name"]) for c in s.get("criteria", []) if str(c.get("expected", "")).startswith(("<", ">"))
        }
        for m, name in margins(s):
            # the failures are already chosen: the near misses that passed, of criteria with a side to
            # approach from (an equality that holds, `collision == 0`, is not close to anything)
            if m >= 0 and name in ordered:
                criteria.setdefault(name, []).append((m, int(s["index"]), s))
    for name, ranked in criteria.items():
        m, _, s = min(ranked, key=lambda r: (r[0], r[1]))
        pick(s, f"closest to {name}{measured_text(s, name)}")
    for metric in NEAR_MISS_METRICS:
        measured = [
            (float(s["metrics"][metric]), int(s["index"]), s)
            for s in by_index
            if metric in s.get("metrics", {})
        ]
        if measured:
            value, _, s = min(measured, key=lambda r: (r[0], r[1]))
            pick(s, f"smallest {metric} ({with_unit(metric, value)})")

    def tightness(s: Mapping[str, Any]) -> tuple[float, ...]:
        metrics = s.get("metrics", {})
        near = (float(metrics.get(m, float("inf"))) for m in NEAR_MISS_METRICS)
        return (min((m for m, _ in margins(s)), default=float("inf")), *near, float(s["index"]))

    for s in sorted(by_index, key=tightness):  # the remaining places: the next tightest runs
        pick(s, "next tightest")
    return list(chosen.values())


def constant_parameters(indexes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Parameters every run has with the same value, in the first run's order (pure; shown once in the
    report instead of in every row)."""
    if not indexes:
        return {}
    first = dict(indexes[0].get("parameters") or {})
    for s in indexes[1:]:
        params = s.get("parameters") or {}
        for name in list(first):
            if name not in params or params[name] != first[name]:
                del first[name]
    return first


def swept_parameters(indexes: Sequence[Mapping[str, Any]], order: Sequence[str] = ()) -> list[str]:
    """Numeric parameters that take more than one value across the indexes (pure): those named in `order`
    (the manifest's matrix keys) in that order, then the others in order of first appearance — the same
    for the same results, fresh or resumed."""
    values: dict[str, set[float]] = {}
    for s in indexes:
        for name, value in (s.get("parameters") or {}).items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                values.setdefault(name, set()).add(float(value))
    swept = [name for name, seen in values.items() if len(seen) > 1]
    rank = {name: k for k, name in enumerate(order)}
    return sorted(swept, key=lambda n: rank.get(n, len(rank)))


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
    parts = [
        plural(c["total"], "run"),
        f"{c['passed']} passed",
        f"{c['failed']} failed",
        f"{c['errors']} errors",
    ]
    if c.get("optionalFailed"):
        parts.append(f"{c['optionalFailed']} optional failed")
    if c.get("missing"):
        parts.append(f"{c['missing']} missing")
    return f"<p>{_badge(summary['status'])} exit code {summary['exitCode']} · {' · '.join(parts)}</p>"


def _with_spoken_unit(text: str, metric: str) -> str:
    """`>= 1.5 s` for a threshold `>= 1.5` of a metric in seconds."""
    u = spoken(metric)
    return f"{text} {u}" if u else text


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
        metric = str(r.get("metric", ""))
        measured = (
            f"{_short(min(r['values']))} … {with_unit(metric, max(r['values']))}"
            if len(set(r["values"])) > 1
            else with_unit(metric, r["values"][0])
            if r["values"]
            else "absent"
        )
        out.append(
            f"<tr><td>{_e(r['scenario'])}</td><td>{_e(r['criterion'])}</td>"
            f"<td>{_e(_with_spoken_unit(str(r['expected']), metric))}</td>"
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
    constant = constant_parameters(results.indexes)  # shown once in the header, not in every row
    for s in failed[:limit]:
        status = "optional" if s.get("optional") else s["status"]
        name = testcase_name(
            {**s, "parameters": {k: v for k, v in (s.get("parameters") or {}).items() if k not in constant}},
            4,
        )
        if s["status"] == "error":
            out.append(
                f"<tr><td>{_e(name)}</td><td>{_badge(status)}</td><td></td><td></td>"
                f"<td>{_e(s.get('error'))}</td></tr>"
            )
            continue
        for c in s.get("criteria", []):
            if not c["passed"]:
                out.append(
                    f"<tr><td>{_e(name)}</td><td>{_badge(status)}</td><td>{_e(c['name'])}</td>"
                    f"<td class=num>{_e(with_unit(str(c.get('metric', '')), c.get('actual')))}</td>"
                    f"<td>{_e(c.get('message'))}</td></tr>"
                )
    out.append("</table>")
    if len(failed) > limit:
        out.append(f'<p class="muted">… and {len(failed) - limit} more.</p>')
    return "".join(out)


def _manifest_order(results: RunResults) -> list[str]:
    if results.spec is None:
        return []
    spec = results.spec.spec
    return [*spec.sweep.matrix, *spec.parameters]


def _heat_map(results: RunResults) -> str:
    swept = swept_parameters(results.indexes, _manifest_order(results))
    if len(swept) < 2:
        return ""
    x_name, y_name = swept[0], swept[1]
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
    constant = constant_parameters(results.indexes)
    figures = []
    for s, reason in worst_runs(results.indexes, worst):
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
            # one sample per ~2 px of the plot's 600 px over the trajectories' extent (at least every 2 m)
            xs = [v for tr in recording.trajectories.values() for v in tr.x] or [0.0]
            ys = [v for tr in recording.trajectories.values() for v in tr.y] or [0.0]
            extent = max(max(xs) - min(xs), max(ys) - min(ys)) + 20.0
            roads[source] = road_outline(recording.scenario_file, step=min(max(extent / 300.0, 2.0), 10.0))
        varying = ",".join(
            f"{k}={_parameter(v)}" for k, v in (s.get("parameters") or {}).items() if k not in constant
        )
        title = f"{s['scenario']}[{s['index']}] {varying} · {s['status']}"
        figures.append(plots.birds_eye(recording, roads[source], title, reason))
    if not figures:
        if not results.indexes:
            return ""
        recording_off = results.spec is not None and not results.spec.spec.recording.enabled
        why = (
            "this run recorded nothing (<code>spec.recording.enabled: false</code>), and the plots are drawn "
            "from each run's recording.mcap: turn recording on to see them"
            if recording_off
            else "none of the chosen runs has a recording.mcap with trajectories in the results"
        )
        return f"<h2>Bird's-eye view</h2><p class=muted>Not drawn: {why}.</p>"
    note = (
        ""
        if any(roads.values())
        else '<p class="muted">Road outline unavailable: the scenario files of the recordings are not on '
        "this machine.</p>"
    )
    return (
        f"<h2>Bird's-eye view of the {len(figures)} worst runs</h2>{note}"
        "<p class=muted>Chosen in this order: errors, failures (tightest margin to a threshold first), "
        "collisions, then per criterion the run closest to its threshold and the smallest time to "
        "collision, time headway and distance; the reason is in each title.</p>"
        "<p class=muted>Dots: start of each trajectory; dashed: the closest approach to the ego; "
        "red crosses: collisions.</p>" + "".join(figures)
    )


#: the metric columns of every report's runs table, in this order (then the criteria's other metrics)
RUNS_TABLE_METRICS = ("collision", "minDistance", "minTimeHeadway", "minTimeToCollision", "maxDeceleration")


def runs_table_metrics(results: RunResults, extra_limit: int = 3) -> list[str]:
    """The same columns in every report: RUNS_TABLE_METRICS, then the metrics of the spec's criteria that are
    not among them (in the spec's order, at most `extra_limit`) (pure but for reading the spec)."""
    named: list[str] = []
    if results.spec is not None:
        spec = results.spec.spec
        criteria = [*spec.evaluation.criteria, *(c for sc in spec.scenarios for c in sc.criteria)]
        named = [c.metric for c in criteria]
    else:  # a spec of another version: the criteria the summaries name
        named = [str(c.get("metric")) for s in results.indexes for c in s.get("criteria", [])]
    extra = [m for m in dict.fromkeys(named) if m not in RUNS_TABLE_METRICS]
    return [*RUNS_TABLE_METRICS, *extra[:extra_limit]]


def _index_table(results: RunResults, relative: bool) -> str:
    metric_names = runs_table_metrics(results)
    constant = constant_parameters(results.indexes)
    flaky = _flaky_indexes(results)
    head = "".join(
        f"<th>{_e(n)}" + (f"<br><span class=unit>({_e(unit(n))})</span>" if unit(n) else "") + "</th>"
        for n in metric_names
    )
    out = [
        f"<div class=wide><table class=runs><tr><th>files</th><th>index</th><th>scenario</th><th>status</th>"
        f"<th>parameters</th><th>seed</th>{head}</tr>"
    ]
    for s in results.indexes:
        i = s["index"]
        params = ", ".join(
            f"{k}={_parameter(v)}" for k, v in (s.get("parameters") or {}).items() if k not in constant
        )
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
            f"<tr><td>{' '.join(links)}</td><td class=num>{i}</td><td>{_e(s['scenario'])}</td>"
            f"<td>{_badge(s['status'])}{' flaky' if i in flaky else ''}</td><td>{_e(params)}</td><td class=num>{_e(s.get('seed'))}</td>{cells}</tr>"
        )
    out.append("</table></div>")
    return "".join(out)


def _parameter(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _flaky_indexes(results: RunResults) -> set[int]:
    repeats = (results.summary or {}).get("repeats") or {}
    return {int(i) for p in repeats.get("flakyPoints", []) if p.get("flaky") for i in p["indexes"]}


def _repeats(results: RunResults) -> str:
    """Flaky points and the determinism check (summary.json `repeats`, execution.repeat > 1)."""
    repeats = (results.summary or {}).get("repeats")
    if not repeats:
        return ""
    checked = repeats.get("determinismChecked", 0)
    determinism = (
        f"{repeats['nondeterministic']} of {checked} points recorded different messages with the same seed"
        if checked
        else "determinism not checked (no two recordings of a point with the same seed)"
    )
    out = [
        "<h2>Repeats: flaky runs and determinism</h2>",
        f"<p>{_badge('failed' if repeats['flaky'] or repeats.get('nondeterministic') else 'passed')} "
        f"every point run {repeats['repeat']} times · {repeats['flaky']} of {repeats['points']} points flaky "
        f"(verdict changed between repeats) · {_e(determinism)}</p>",
    ]
    listed = repeats.get("flakyPoints", [])
    if listed:
        out.append(
            "<table><tr><th>indexes</th><th>statuses</th><th>seeds</th><th>flaky</th><th>same messages</th></tr>"
        )
        for p in listed:
            same = {True: "yes", False: "no", None: "not checked"}[p.get("deterministic")]
            out.append(
                f"<tr><td>{_e(', '.join(map(str, p['indexes'])))}</td><td>{_e(', '.join(p['statuses']))}</td>"
                f"<td>{_e(', '.join(map(str, p['seeds'])))}</td><td>{'yes' if p['flaky'] else 'no'}</td>"
                f"<td>{same}</td></tr>"
            )
        out.append("</table>")
    return "".join(out)


def _version() -> str:
    from simcore import version

    return version()


def _header(results: RunResults, relative: bool) -> str:
    """Links to the run's files first, then the CARLOS version, the runs' time and the constant
    parameters (shown once here, not in every row)."""
    links = []
    for label, key in (
        ("summary.json", "summary.json"),
        ("junit.xml", "junit.xml"),
        ("run.yaml", "run.yaml"),
        ("comparison.json", "comparison.json"),
    ):
        href = _link(results, key, relative)
        if href is not None:
            links.append(f'<a href="{_e(href)}">{label}</a>')
    walls = [float(s.get("wallSeconds") or 0.0) for s in results.indexes]
    timing = (
        f"{plural(len(walls), 'run')} took {sum(walls):.1f} s of wall time in all (longest {max(walls):.1f} s)"
        if walls
        else "no run finished"
    )
    parts = [
        f"<p class=links>{' · '.join(links)}</p>" if links else "",
        f'<p class="muted">CARLOS {_e(_version())} · {_e(timing)}</p>',
    ]
    constant = constant_parameters(results.indexes)
    if constant:
        values = ", ".join(f"{k}={v}" for k, v in constant.items())
        parts.append(f"<p><b>Parameters of every run:</b> {_e(values)}</p>")
    return "".join(parts)


def _comparison(results: RunResults, limit: int = 30) -> str:
    """The section `carlos compare --report` adds (from comparison.json next to the summary), when it was
    made for the summary.json that is there now."""
    import hashlib
    import json

    from simcore.compare import COMPARISON_KEY, VERDICTS

    try:
        if not results.store.exists(COMPARISON_KEY):
            return ""
        data = json.loads(results.store.get_bytes(COMPARISON_KEY))
        summary = results.store.get_bytes("summary.json") if results.store.exists("summary.json") else b""
    except (StoreError, ValueError):
        return ""
    if data.get("candidateSummarySha256") != hashlib.sha256(summary).hexdigest():
        return ""  # made for earlier results in this folder (the run was run again since)
    counts = data.get("counts", {})
    status = "failed" if data.get("exitCode") else "passed"
    out = [
        "<h2>Compared with the baseline</h2>",
        f"<p>{_badge(status)} baseline {_e(data.get('baseline'))} · "
        + " · ".join(f"{counts.get(v, 0)} {_e(v)}" for v in VERDICTS)
        + "</p>",
    ]
    shown = [r for r in data.get("runs", []) if r["verdict"] not in ("still passing",) or r["metricChanges"]]
    if shown:
        out.append(
            "<table><tr><th>run</th><th>verdict</th><th>baseline</th><th>candidate</th>"
            "<th>metric changes</th></tr>"
        )
        for r in shown[:limit]:
            changes = ", ".join(
                f"{c['metric']} {_short(c['baseline'])} → {_short(c['candidate'])}"
                for c in r["metricChanges"]
            )
            out.append(
                f"<tr><td>{_e(r['name'])}</td><td>{_e(r['verdict'])}</td>"
                f"<td>{_e(r['baselineStatus'] or '—')}</td><td>{_e(r['candidateStatus'] or '—')}</td>"
                f"<td>{_e(changes)}</td></tr>"
            )
        out.append("</table>")
        if len(shown) > limit:
            out.append(f'<p class="muted">… and {len(shown) - limit} more (comparison.json).</p>')
    return "".join(out)


def render(results: RunResults, *, worst: int = 6, relative_links: bool = False, omitted: int = 0) -> str:
    """The whole page. `relative_links`: the page is stored next to the run's summary.json, so the links
    to recordings and logs are relative to it; else they are the store's URLs. `omitted`: index summaries
    left out of `results.indexes` (a large run: the verdict's counts stay those of summary.json)."""
    now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    body = [
        f"<h1>SimulationRun {_e(results.name)}</h1>",
        f'<p class="muted">{_e(results.url)} · report generated {now}</p>',
        _header(results, relative_links),
        _verdict(results),
        _comparison(results),
        _repeats(results),
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
