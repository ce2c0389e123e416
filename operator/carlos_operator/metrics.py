"""Prometheus metrics of the operator (served on `--metrics-port`, default 9090, path /metrics)."""

from __future__ import annotations

import threading

from prometheus_client import Counter, Gauge, Histogram

RUNS = Gauge("carlos_simulationruns", "SimulationRuns known to the operator, by phase", ["phase"])
RECONCILE_SECONDS = Histogram(
    "carlos_reconcile_seconds",
    "Time of one reconciliation of a SimulationRun",
    buckets=(0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30),
)
ERRORS = Counter("carlos_reconcile_errors_total", "Reconciliations that raised, by exception type", ["kind"])
JOBS_CREATED = Counter("carlos_jobs_created_total", "Indexed Jobs created")

_lock = threading.Lock()
_phases: dict[str, str] = {}


def set_phase(uid: str, phase: str) -> None:
    """Record the phase of one run (by uid) and update the per-phase gauge."""
    with _lock:
        before = _phases.get(uid)
        if before == phase:
            return
        if before is not None:
            RUNS.labels(phase=before).dec()
        _phases[uid] = phase
        RUNS.labels(phase=phase).inc()


def forget(uid: str) -> None:
    with _lock:
        before = _phases.pop(uid, None)
        if before is not None:
            RUNS.labels(phase=before).dec()
