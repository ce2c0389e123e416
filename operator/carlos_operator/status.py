"""Status aggregation (pure): Job status + per-index verdicts → the SimulationRun's `status`.

Scales to 50,000 indexes without expanding them: the Job reports finished indexes as interval strings
(`completedIndexes: "0-4,7"`, `failedIndexes`), which are counted and diffed as intervals; per-index
verdicts live in a `Tally`, one byte per index (50 kB for 50,000), filled incrementally from the
per-index `summary.json` files the operator reads only once each.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from simcore.spec import API_GROUP
from simcore.wording import plural

UNKNOWN, PASSED, FAILED, ERROR = 0, 1, 2, 3
_VERDICTS = {"passed": PASSED, "failed": FAILED, "error": ERROR}
MAX_FAILURES = 20
TERMINAL_PHASES = ("Succeeded", "Failed")
#: the Job's annotations of its slicing (set by carlos_operator.builders): runs per pod, runs of the Job
RUNS_PER_POD_ANNOTATION = f"{API_GROUP}/runs-per-pod"
RUNS_ANNOTATION = f"{API_GROUP}/runs"


def parse_intervals(text: str | None) -> list[tuple[int, int]]:
    """`"0-4,7"` → [(0, 4), (7, 7)] (inclusive), as the Job API writes completed/failed indexes."""
    out: list[tuple[int, int]] = []
    if not text:
        return out
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        first, _, last = part.partition("-")
        out.append((int(first), int(last or first)))
    return out


def count_intervals(text: str | None) -> int:
    return sum(last - first + 1 for first, last in parse_intervals(text))


def iter_intervals(text: str | None) -> Iterator[int]:
    for first, last in parse_intervals(text):
        yield from range(first, last + 1)


def format_intervals(indexes: list[int]) -> str:
    """The inverse of `parse_intervals` for a sorted list."""
    parts: list[str] = []
    start = prev = None
    for i in indexes:
        if start is None:
            start = prev = i
        elif i == prev + 1:  # type: ignore[operator]
            prev = i
        else:
            parts.append(f"{start}" if start == prev else f"{start}-{prev}")
            start = prev = i
    if start is not None:
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
    return ",".join(parts)


@dataclass
class Tally:
    """Per-index verdicts of one run (one byte each) and the first failures with their reasons."""

    total: int
    verdicts: bytearray = field(init=False)
    counts: dict[int, int] = field(default_factory=lambda: {PASSED: 0, FAILED: 0, ERROR: 0})
    failures: list[dict[str, Any]] = field(default_factory=list)  # sorted by index, at most MAX_FAILURES
    required_failures: int = 0  # failed/error indexes of required (non-optional) scenarios
    finalized: bool = False

    def __post_init__(self) -> None:
        self.verdicts = bytearray(self.total)

    def known(self, index: int) -> bool:
        return self.verdicts[index] != UNKNOWN

    def record(self, summary: Mapping[str, Any]) -> None:
        """Count one index's summary (idempotent: a known index is ignored)."""
        index = int(summary["index"])
        if not 0 <= index < self.total or self.verdicts[index] != UNKNOWN:
            return
        verdict = _VERDICTS.get(str(summary.get("status")), ERROR)
        self.verdicts[index] = verdict
        self.counts[verdict] += 1
        if verdict == PASSED:
            return
        if not summary.get("optional"):
            self.required_failures += 1
        if verdict == ERROR:
            reason = str(summary.get("error") or "error")
        else:
            failing = [
                c.get("name", "?")
                for c in summary.get("criteria", [])
                if not c.get("passed") and not c.get("optional")
            ]
            reason = "criteria failed: " + ", ".join(failing) if failing else "test failed"
        entry = {
            "index": index,
            "scenario": summary.get("scenario"),
            "status": "error" if verdict == ERROR else "failed",
            "reason": reason[:500],
        }
        keys = [f["index"] for f in self.failures]
        position = bisect.bisect_left(keys, index)
        if position < MAX_FAILURES:
            self.failures.insert(position, entry)
            del self.failures[MAX_FAILURES:]

    def unknown_among(self, intervals: str | None, limit: int) -> list[int]:
        """Up to `limit` indexes of `intervals` whose verdict is not known yet."""
        out: list[int] = []
        verdicts = self.verdicts
        for first, last in parse_intervals(intervals):
            if first < 0 or last >= self.total:
                continue
            chunk = verdicts[first : last + 1]
            if chunk.count(UNKNOWN) == 0:
                continue
            start = 0
            while len(out) < limit:
                found = chunk.find(UNKNOWN, start)
                if found < 0:
                    break
                out.append(first + found)
                start = found + 1
            if len(out) >= limit:
                break
        return out

    @property
    def known_count(self) -> int:
        return self.counts[PASSED] + self.counts[FAILED] + self.counts[ERROR]


def condition(
    previous: Mapping[str, Mapping[str, Any]], kind: str, status: bool, reason: str, message: str, now: str
) -> dict[str, Any]:
    value = "True" if status else "False"
    old = previous.get(kind)
    since = old.get("lastTransitionTime") if old and old.get("status") == value else None
    return {
        "type": kind,
        "status": value,
        "reason": reason,
        "message": message,
        "lastTransitionTime": since or now,
    }


def runs_view(job: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """The Job with its finished completion indexes (`completedIndexes`, `failedIndexes`: pods, each a slice
    of runs) expressed as the Job's run positions (simcore.shards; the builders annotate runs per pod and
    runs), so that everything downstream counts runs, not pods. `active` stays pods."""
    from simcore.shards import positions_of_pods

    if job is None:
        return None
    annotations = (job.get("metadata") or {}).get("annotations") or {}
    per_pod = int(annotations.get(RUNS_PER_POD_ANNOTATION) or 1)
    status = dict(job.get("status") or {})
    if per_pod == 1 or not status:
        return dict(job)
    runs = int(annotations.get(RUNS_ANNOTATION) or 0)
    for key in ("completedIndexes", "failedIndexes"):
        if status.get(key):
            status[key] = positions_of_pods(status[key], per_pod, runs)
    return {**job, "status": status}


def job_finished(job: Mapping[str, Any] | None) -> str | None:
    """ "Complete" or "Failed" when the Job has that condition, else None."""
    if not job:
        return None
    for condition in job.get("status", {}).get("conditions") or []:
        if condition.get("status") == "True" and condition.get("type") in ("Complete", "Failed"):
            return str(condition["type"])
    return None


def _job_failure_reason(job: Mapping[str, Any]) -> tuple[str, str]:
    for condition in job.get("status", {}).get("conditions") or []:
        if condition.get("type") == "Failed" and condition.get("status") == "True":
            return str(condition.get("reason") or "JobFailed"), str(condition.get("message") or "")
    return "JobFailed", ""


def verdict_fields(tally: Tally, results_url: str) -> dict[str, Any]:
    """The status fields every run shows of its verdicts: counts, where the results are, the first failures."""
    return {
        "passed": tally.counts[PASSED],
        "testFailures": tally.counts[FAILED],
        "errors": tally.counts[ERROR],
        "resultsURL": results_url,
        "failures": list(tally.failures),
    }


def aggregate(
    *,
    total: int,
    job: Mapping[str, Any] | None,
    tally: Tally,
    results_url: str,
    now: str,
    previous: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The SimulationRun status from its Job (or None before it exists) and the verdicts read so far."""
    previous = previous or {}
    conditions_before = {c.get("type"): c for c in previous.get("conditions") or []}
    job_status: Mapping[str, Any] = (job or {}).get("status") or {}
    job_spec: Mapping[str, Any] = (job or {}).get("spec") or {}
    succeeded = count_intervals(job_status.get("completedIndexes"))
    failed = count_intervals(job_status.get("failedIndexes"))
    active = int(job_status.get("active") or 0)
    finished = job_finished(job)
    done = succeeded + failed
    conditions = [
        condition(conditions_before, "Accepted", True, "Valid", "the spec is valid; the Job is created", now)
    ]
    if job is None:
        phase = "Pending"
    elif finished and (tally.known_count >= done or tally.finalized):
        if finished == "Failed" and done < total:
            phase = "Failed"
        else:
            phase = "Failed" if tally.required_failures else "Succeeded"
    elif job_spec.get("suspend") and active == 0 and not finished:
        phase = "Suspended"
    elif active or done or job_status.get("startTime"):
        phase = "Running"
    else:
        phase = "Pending"
    running = phase == "Running"
    conditions.append(
        condition(
            conditions_before,
            "Running",
            running,
            "PodsActive" if active else ("Aggregating" if running and finished else phase),
            f"{active} pods active, {done}/{total} runs finished",
            now,
        )
    )
    complete = phase in TERMINAL_PHASES
    conditions.append(
        condition(
            conditions_before,
            "Complete",
            complete,
            "AllRunsFinished" if complete else "InProgress",
            f"{tally.counts[PASSED]} passed, {tally.counts[FAILED]} failed, {tally.counts[ERROR]} errors"
            if complete
            else f"{done}/{total} runs finished",
            now,
        )
    )
    if phase == "Failed":
        if job is not None and finished == "Failed" and done < total:
            reason, message = _job_failure_reason(job)
        elif tally.counts[ERROR] and not tally.counts[FAILED]:
            reason, message = "RunErrors", f"{plural(tally.counts[ERROR], 'run')} ended in an error"
        else:
            reason = "TestFailures"
            failed = tally.counts[FAILED]
            message = (
                f"{plural(failed, 'run')} failed {'its' if failed == 1 else 'their'} criteria, "
                f"{plural(tally.counts[ERROR], 'error')}"
            )
        conditions.append(condition(conditions_before, "Failed", True, reason, message, now))
    else:
        conditions.append(condition(conditions_before, "Failed", False, "NoFailure", "", now))
    status: dict[str, Any] = {
        "phase": phase,
        "progress": f"{done}/{total}",
        "total": total,
        "active": active,
        "succeeded": succeeded,
        "failed": failed,
        **verdict_fields(tally, results_url),
        "conditions": conditions,
    }
    start = job_status.get("startTime") or previous.get("startTime")
    if start:
        status["startTime"] = start
    if complete:
        status["completionTime"] = previous.get("completionTime") or job_status.get("completionTime") or now
    return status
