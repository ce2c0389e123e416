"""A run's state for `carlos get` / `carlos watch`: from its results (file:// or s3://) or from the
SimulationRun's status on a cluster. Pure functions but for the two readers at the end."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from typing import Any

from simcore.results import RunResults
from simcore.workflow.terminal import duration, eta_seconds, failure_lines


@dataclass
class RunState:
    name: str
    phase: str
    done: int
    total: int
    passed: int
    failed: int
    errors: int
    elapsed: float | None = None
    failures: list[str] = field(default_factory=list)
    results_url: str | None = None
    search: str | None = None  # a search on a cluster: "rounds 1/4 · best 0.31"

    @property
    def finished(self) -> bool:
        return self.phase in ("Succeeded", "Failed")

    def line(self) -> str:
        eta = (
            None
            if self.elapsed is None or self.finished
            else eta_seconds(self.done, self.total, self.elapsed)
        )
        finished = (
            f"{self.done} finished" if self.done >= self.total else f"{self.done} of {self.total} finished"
        )
        counts = [f"{self.passed} passed"] + [
            f"{n} {word}"
            for n, word in ((self.failed, "failed"), (self.errors, "errors" if self.errors != 1 else "error"))
            if n
        ]
        text = f"{self.name}: {self.phase} · {finished} · {' · '.join(counts)}"
        if self.search:
            text += f" · {self.search}"
        return text + ("" if eta is None else f" · ETA {duration(eta)}")


def state_of_results(results: RunResults, total: int | None = None) -> RunState:
    """From the store: finished when the run-level summary.json exists."""
    counts = {"passed": 0, "failed": 0, "error": 0}
    for s in results.indexes:
        counts[s["status"] if s["status"] in counts else "error"] += 1
    summary = results.summary
    if summary is not None:
        phase = "Succeeded" if summary["status"] == "passed" else "Failed"
        total = int(summary["counts"]["total"])
    else:
        phase = "Running"
        if total is None and results.spec is not None:
            from simcore.plan import Plan

            try:
                total = len(Plan(results.spec.spec))
            except Exception:  # a distribution file not readable here
                total = None
    return RunState(
        name=results.name,
        phase=phase,
        done=len(results.indexes),
        total=total if total is not None else len(results.indexes),
        passed=counts["passed"],
        failed=counts["failed"],
        errors=counts["error"],
        failures=failure_lines(results.indexes, limit=5),
        results_url=results.url,
    )


def _since(timestamp: str | None, now: dt.datetime) -> float | None:
    if not timestamp:
        return None
    try:
        start = dt.datetime.fromisoformat(timestamp.replace("Z", "+00:00"))
    except ValueError:
        return None
    return max(0.0, (now - start).total_seconds())


def state_of_object(obj: dict[str, Any], now: dt.datetime | None = None) -> RunState:
    """From a SimulationRun object of the cluster (its status as the operator writes it)."""
    st = obj.get("status") or {}
    now = now or dt.datetime.now(dt.UTC)
    failures = []
    for f in (st.get("failures") or [])[:5]:
        detail = f.get("message") or f.get("error") or f.get("status") or ""
        failures.append(f"{f.get('status', 'failed')} {f.get('scenario', '')}[{f.get('index')}]: {detail}")
    done = int(st.get("succeeded", 0)) + int(st.get("failed", 0))
    search = st.get("search") or {}
    rounds = None
    if search.get("rounds"):
        best = search.get("bestObjective")
        rounds = f"rounds {search['rounds']}" + ("" if best is None else f" · best {float(best):.3g}")
    return RunState(
        search=rounds,
        name=obj["metadata"]["name"],
        phase=str(st.get("phase") or "Pending"),
        done=done,
        total=int(st.get("total") or 0),
        passed=int(st.get("passed", 0)),
        failed=int(st.get("testFailures", 0)),
        errors=int(st.get("errors", 0)),
        elapsed=_since(st.get("startTime"), now),
        failures=failures,
        results_url=st.get("resultsURL"),
    )


def cluster_runs(namespace: str, name: str | None = None) -> list[dict[str, Any]]:
    """SimulationRun objects of `namespace` (or the one named); Kubernetes errors as CarlosErrors."""
    from kubernetes.client.exceptions import ApiException

    from simcore.errors import BadInput, SimulationError
    from simcore.workflow.submit import GROUP, PLURAL, VERSION, kube_clients

    custom, _ = kube_clients()
    try:
        if name is not None:
            return [dict(custom.get_namespaced_custom_object(GROUP, VERSION, namespace, PLURAL, name))]
        listed: Any = custom.list_namespaced_custom_object(GROUP, VERSION, namespace, PLURAL)
        return list(listed.get("items", []))
    except ApiException as exc:
        if exc.status == 404:
            raise BadInput(f"no SimulationRun {name!r} in namespace {namespace!r}", field="RUN") from None
        raise SimulationError(f"Kubernetes API: {exc.status} {exc.reason}") from None
    except Exception as exc:  # urllib3's connection errors
        raise SimulationError(f"Kubernetes API unreachable: {type(exc).__name__}: {exc}") from None
