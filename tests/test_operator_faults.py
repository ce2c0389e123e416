"""The operator under faults, at every step of a run's life: killed (SIGKILL: the controller and everything it
held in memory are gone, a new one starts from what the API server and the object store kept) or answered
429 / 500 / 409 by the API server, before each single call it makes to Kubernetes or to the store. Whatever
the moment, the run ends with the verdict and results of an undisturbed run, and one Job is ever created."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest
from carlos_operator.builders import job_name
from carlos_operator.kube import Conflict
from kubernetes.client.rest import ApiException

from tests.test_operator_controller import (  # _scratch_removed: its controllers' scratch folders go too
    FakeKube,
    FakeStore,
    _scratch_removed,  # noqa: F401
    controller,
    run_body,
    summary,
)

N = 5
FAILED_INDEX = 3


class OperatorKilled(BaseException):
    """The operator's process ends here (SIGKILL): nothing after this call happens in it."""


class ApiServer(FakeKube):
    """FakeKube that keeps the run's status as the API server does (merge patches) and whose Jobs run at once:
    a created Job is complete, index FAILED_INDEX failed (a test failure, its summary written)."""

    def __init__(self) -> None:
        super().__init__()
        self.status: dict[str, Any] = {}
        self.created: list[str] = []

    def create_job(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        job = super().create_job(namespace, body)
        self.created.append(body["metadata"]["name"])
        job["status"] = {
            "completedIndexes": ",".join(str(i) for i in range(N) if i != FAILED_INDEX),
            "failedIndexes": str(FAILED_INDEX),
            "startTime": "2026-01-01T00:00:00Z",
            "conditions": [{"type": "Failed", "status": "True", "reason": "FailedIndexes"}],
        }
        return job

    def patch_run_status(self, namespace: str, name: str, status: dict[str, Any]) -> None:
        super().patch_run_status(namespace, name, status)
        self.status.update(json.loads(json.dumps(status)))


@dataclass
class Fault:
    """Raises `error()` before the call numbered `at` (counting every call to the API server and the store)."""

    at: int
    error: Callable[[], BaseException]
    calls: int = 0
    fired: bool = False

    def wrap(self, target: Any, names: tuple[str, ...]) -> Any:
        fault = self

        class Proxy:
            def __getattr__(self, name: str) -> Any:
                attribute = getattr(target, name)
                if name not in names:
                    return attribute

                def call(*args: Any, **kwargs: Any) -> Any:
                    fault.calls += 1
                    if fault.calls - 1 == fault.at and not fault.fired:
                        fault.fired = True
                        raise fault.error()
                    return attribute(*args, **kwargs)

                return call

        return Proxy()


KUBE_CALLS = (
    "create_configmap",
    "read_configmap",
    "create_job",
    "read_job",
    "patch_job",
    "patch_run_status",
    "read_secret_data",
    "delete",
    "list_pods",
    "event",
)
STORE_CALLS = ("exists", "get_bytes", "put_bytes")


def _prepared() -> tuple[ApiServer, FakeStore]:
    kube, store = ApiServer(), FakeStore()
    for i in range(N):  # what the run's pods wrote
        store.put_bytes(f"r/{i}/summary.json", summary(i, "failed" if i == FAILED_INDEX else "passed"))
    return kube, store


def _drive(kube: Any, store: Any, fault: Fault | None) -> tuple[ApiServer, FakeStore]:
    """One operator (with `fault` on its calls) until its queue is empty; a retryable error is retried as the
    work loop does. OperatorKilled propagates."""
    faulty_kube = fault.wrap(kube, KUBE_CALLS) if fault else kube
    faulty_store = fault.wrap(store, STORE_CALLS) if fault else store
    c = controller(faulty_kube, faulty_store)
    c.observe_run("ADDED", run_body("r", "uid-1", N, json.loads(json.dumps(kube.status))))
    for job in list(kube.jobs.values()):  # the Job watch lists what exists
        c.observe_job("ADDED", job)
    for _ in range(50):
        if not c._queue:
            return kube, store
        key = c._queue.pop(0)
        c._queued.discard(key)
        try:
            c.reconcile(key)
        except (ApiException, Conflict):
            c.enqueue(key)  # the work loop retries after its backoff
    raise AssertionError("the queue does not drain")


def _outcome(kube: ApiServer, store: FakeStore) -> dict[str, Any]:
    status = kube.status
    run_summary = json.loads(store.objects["r/summary.json"])
    run_summary.pop("finishedAt", None)
    return {
        "phase": status.get("phase"),
        "counts": {k: status.get(k) for k in ("passed", "testFailures", "errors", "total")},
        "failures": [(f["index"], f.get("reason")) for f in status.get("failures") or []],
        "jobs": kube.created,
        "objects": sorted(store.objects),
        "summary": run_summary,
        "junit": store.objects["r/junit.xml"].count(b"<testcase"),
    }


def _calls_of_an_undisturbed_run() -> tuple[int, dict[str, Any]]:
    counter = Fault(at=-1, error=lambda: OperatorKilled())
    kube, store = _drive(*_prepared(), counter)
    return counter.calls, _outcome(kube, store)


CALLS, UNDISTURBED = _calls_of_an_undisturbed_run()


def test_the_undisturbed_run_is_what_the_faulty_ones_must_reach() -> None:
    assert UNDISTURBED["phase"] == "Failed" and UNDISTURBED["jobs"] == [job_name("r")]
    assert UNDISTURBED["counts"]["passed"] == N - 1 and UNDISTURBED["counts"]["testFailures"] == 1
    assert UNDISTURBED["failures"][0][0] == FAILED_INDEX
    assert {"r/summary.json", "r/junit.xml", "r/run.yaml"} <= set(UNDISTURBED["objects"])
    assert CALLS >= 10  # ensure, status, N summaries, the run-level results


@pytest.mark.parametrize("at", range(CALLS))
def test_operator_killed_before_any_call_finishes_the_run_as_undisturbed(at: int) -> None:
    kube, store = _prepared()
    fault = Fault(at=at, error=OperatorKilled)
    with pytest.raises(OperatorKilled):
        _drive(kube, store, fault)
    _drive(kube, store, None)  # a new operator process: only the API server's and the store's state
    assert _outcome(kube, store) == UNDISTURBED


@pytest.mark.parametrize("status", [429, 500, 503])
@pytest.mark.parametrize("at", range(CALLS))
def test_api_server_errors_before_any_call_are_retried_to_the_same_end(at: int, status: int) -> None:
    kube, store = _prepared()
    fault = Fault(at=at, error=lambda: ApiException(status=status, reason="injected"))
    _drive(kube, store, fault)
    assert fault.fired
    assert _outcome(kube, store) == UNDISTURBED


def test_a_lost_create_response_is_read_and_the_job_is_adopted() -> None:
    """The Job was created but the answer never came (connection reset): the retry's create is answered 409,
    the Job is read and adopted (as in test_operator_desired's race test)."""
    kube, store = _prepared()
    created = kube.create_job

    def create_then_lose_the_answer(namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        created(namespace, body)
        kube.create_job = created  # type: ignore[method-assign]
        raise ApiException(status=500, reason="connection reset")

    kube.create_job = create_then_lose_the_answer  # type: ignore[method-assign]
    _drive(kube, store, None)
    assert _outcome(kube, store) == UNDISTURBED
    assert kube.job_creates == 2  # the retry's create met the Job (409): adopted, nothing else was made
    assert len(kube.jobs) == 1
