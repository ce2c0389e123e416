"""Shards: contiguous slices of a run's indexes, one slice per pod of the cluster's Indexed Job (pure).

Mapping (docs/design.md, "Shards"): a Job over `runs` indexes with `runs_per_pod` R has
`ceil(runs / R)` completions; completion index k (the pod's `JOB_COMPLETION_INDEX`) runs the Job's
positions k·R … min((k+1)·R, runs) − 1, i.e. the run's indexes offset + those positions (a search
round's Job has an offset; a sweep's is 0). R = 1 is one pod per run.

The default R keeps a pod working for minutes, not milliseconds, and a Job at most `MAX_PODS_PER_JOB`
completions: `default_runs_per_pod` estimates one run's cost from the plan (simulated seconds, sensors)
or, for a search round, from earlier rounds' measured wall seconds.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

#: a Job gets at most this many completions unless `execution.runsPerPod` asks for smaller shards
MAX_PODS_PER_JOB = 1_000
#: what one pod should work for (wall seconds), so its start-up is paid once per minutes of work
TARGET_POD_SECONDS = 300.0
#: estimated wall seconds per simulated second (of `simulation.maxSeconds`, which most scenarios' stop
#: triggers cut short): the scenario engine (cut-in: ~0.035 s CPU per run), and each sensor (a 64-channel
#: lidar: ~1.3 s per cut-in run) — measured with bench/cluster.py
_ENGINE_COST = 0.005
_SENSOR_COST = 0.05


def pods_for(runs: int, runs_per_pod: int) -> int:
    """Completions of a Job over `runs` indexes in slices of `runs_per_pod`."""
    return max(1, math.ceil(runs / max(1, runs_per_pod)))


def slice_of(completion: int, runs_per_pod: int, runs: int) -> range:
    """The Job positions (0-based) completion index `completion` runs."""
    first = completion * runs_per_pod
    return range(min(first, runs), min(first + runs_per_pod, runs))


def pod_of(position: int, runs_per_pod: int) -> int:
    """The completion index whose pod runs Job position `position`."""
    return position // max(1, runs_per_pod)


def estimate_run_seconds(max_seconds: float, sensors: int, measured: Sequence[float] = ()) -> float:
    """Wall seconds of one run: the mean of `measured` runs (a search's earlier rounds) when there are any,
    else a conservative estimate from the simulated time and the number of sensors."""
    if measured:
        return max(1e-3, sum(measured) / len(measured))
    return max(1e-3, max_seconds * (_ENGINE_COST + _SENSOR_COST * sensors))


def default_runs_per_pod(runs: int, run_seconds: float) -> int:
    """Runs per pod when the spec does not say: enough for `TARGET_POD_SECONDS` of work, and enough that
    the Job has at most `MAX_PODS_PER_JOB` completions; never more than the runs there are."""
    if runs <= 0:
        return 1
    by_time = max(1, int(TARGET_POD_SECONDS // max(run_seconds, 1e-3)))
    by_count = math.ceil(runs / MAX_PODS_PER_JOB)
    return max(1, min(runs, max(by_time, by_count)))


def _merge(intervals: Iterable[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for first, last in intervals:
        if out and first <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], last))
        else:
            out.append((first, last))
    return out


def positions_of_pods(intervals: str | None, runs_per_pod: int, runs: int) -> str:
    """Completion-index intervals (`"0-4,7"`, as a Job's completedIndexes) → the Job positions those pods
    ran, in the same notation; one pass over the intervals, never over the indexes."""
    if not intervals or runs_per_pod == 1:
        return intervals or ""
    spans: list[tuple[int, int]] = []
    for part in intervals.split(","):
        part = part.strip()
        if not part:
            continue
        first, _, last = part.partition("-")
        lo = int(first) * runs_per_pod
        hi = min((int(last or first) + 1) * runs_per_pod, runs) - 1
        if lo <= hi:
            spans.append((lo, hi))
    return ",".join(f"{a}" if a == b else f"{a}-{b}" for a, b in _merge(spans))
