"""The controller with an in-memory Kubernetes API and object store: adoption, conflicts, catching up on
summaries after a restart without publishing lower counts, the run-level summary."""

from __future__ import annotations

import json
from typing import Any

from carlos_operator.builders import OperatorSettings, job_name
from carlos_operator.controller import Controller
from carlos_operator.kube import Conflict, NotFound

from simcore.store import NotFoundError


class FakeStore:
    def __init__(self) -> None:
        self.objects: dict[str, bytes] = {}
        self.gets = 0

    def exists(self, key: str) -> bool:
        return key in self.objects

    def get_bytes(self, key: str) -> bytes:
        self.gets += 1
        if key not in self.objects:
            raise NotFoundError(key)
        return self.objects[key]

    def put_bytes(self, key: str, data: bytes) -> None:
        self.objects[key] = data

    def url_for(self, key: str) -> str:
        return f"s3://bucket/out/{key}"


class FakeKube:
    def __init__(self) -> None:
        self.configmaps: dict[str, dict[str, Any]] = {}
        self.jobs: dict[str, dict[str, Any]] = {}
        self.status_patches: list[dict[str, Any]] = []
        self.events: list[tuple[str, str]] = []
        self.job_creates = 0

    def read_secret_data(self, namespace: str, name: str) -> dict[str, str]:
        return {"AWS_ACCESS_KEY_ID": "a", "AWS_SECRET_ACCESS_KEY": "b"}

    def create_configmap(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        if body["metadata"]["name"] in self.configmaps:
            raise Conflict("exists")
        self.configmaps[body["metadata"]["name"]] = body
        return body

    def read_configmap(self, namespace: str, name: str) -> dict[str, Any]:
        return self.configmaps[name]

    def create_job(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        self.job_creates += 1
        if body["metadata"]["name"] in self.jobs:
            raise Conflict("exists")
        self.jobs[body["metadata"]["name"]] = body
        return body

    def read_job(self, namespace: str, name: str) -> dict[str, Any]:
        if name not in self.jobs:
            raise NotFound(name)
        return self.jobs[name]

    def patch_job(self, namespace: str, name: str, patch: dict[str, Any]) -> dict[str, Any]:
        self.jobs[name]["spec"].update(patch["spec"])
        return self.jobs[name]

    def patch_run_status(self, namespace: str, name: str, status: dict[str, Any]) -> None:
        self.status_patches.append(status)

    def event(self, run: dict[str, Any], kind: str, reason: str, message: str) -> None:
        self.events.append((kind, reason))


def run_body(name: str, uid: str, n: int, status: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default", "uid": uid},
        "spec": {
            "scenarios": [{"name": "s", "openscenario": "s3://bucket/s.xosc"}],
            "sweep": {"repetitions": n},
            "output": {"url": "s3://bucket/out", "credentialsSecretRef": {"name": "s3"}},
        },
        "status": status or {},
    }


def controller(kube: FakeKube, store: FakeStore, batch: int = 500) -> Controller:
    settings = OperatorSettings.from_env({})
    return Controller(kube, settings, batch=batch, store_factory=lambda k, ns, out: store)  # type: ignore[arg-type]


def drain(c: Controller) -> None:
    for _ in range(100):
        if not c._queue:
            return
        key = c._queue.pop(0)
        c._queued.discard(key)
        c.reconcile(key)
    raise AssertionError("the queue does not drain")


def summary(i: int, status: str = "passed") -> bytes:
    return json.dumps(
        {"index": i, "scenario": "s", "status": status, "optional": False, "criteria": []}
    ).encode()


def test_create_adopt_and_conflict() -> None:
    kube, store = FakeKube(), FakeStore()
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    assert list(kube.jobs) == [job_name("r")] and kube.job_creates == 1
    assert store.exists("r/run.yaml") and ("Normal", "JobCreated") in kube.events
    assert kube.status_patches[-1]["phase"] == "Pending"
    # a restarted operator (new controller) adopts the Job: no second one
    c2 = controller(kube, store)
    c2.observe_run("ADDED", run_body("r", "uid-1", 3, kube.status_patches[-1]))
    drain(c2)
    assert len(kube.jobs) == 1 and c2.runs[("default", "r")].ensured
    # another run of the same name (another uid) does not take over the Job
    kube2_store = FakeStore()
    kube2_store.objects = dict(store.objects)
    c3 = controller(kube, kube2_store)
    c3.observe_run("ADDED", run_body("r", "uid-2", 3))
    drain(c3)
    rejected = kube.status_patches[-1]
    assert rejected["conditions"][0]["status"] == "False"
    assert rejected["conditions"][0]["reason"] == "NameConflict"


def test_different_spec_under_an_existing_name_is_rejected() -> None:
    kube, store = FakeKube(), FakeStore()
    store.put_bytes("r/run.yaml", b"something else\n")
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    assert kube.jobs == {}
    assert kube.status_patches[-1]["conditions"][0]["reason"] == "ResultsExist"


def test_restart_catches_up_without_lowering_counts_and_finalizes() -> None:
    n = 1200
    kube, store = FakeKube(), FakeStore()
    for i in range(n):
        store.put_bytes(f"r/{i}/summary.json", summary(i, "failed" if i == 7 else "passed"))
    c = controller(kube, store, batch=500)
    c.observe_run("ADDED", run_body("r", "uid-1", n))
    drain(c)
    job = kube.jobs[job_name("r")]
    job["status"] = {
        "completedIndexes": f"0-6,8-{n - 1}",
        "failedIndexes": "7",
        "startTime": "2026-01-01T00:00:00Z",
        "conditions": [{"type": "Failed", "status": "True", "reason": "FailedIndexes"}],
    }
    before = {"phase": "Running", "passed": 1000, "testFailures": 1, "errors": 0, "conditions": []}
    c2 = controller(kube, store, batch=500)
    kube.status_patches.clear()
    c2.observe_run("ADDED", run_body("r", "uid-1", n, before))
    c2.observe_job("MODIFIED", job)
    drain(c2)
    assert all(int(p.get("passed") or 0) >= 1000 for p in kube.status_patches if "passed" in p)
    final = kube.status_patches[-1]
    assert final["phase"] == "Failed" and final["passed"] == n - 1 and final["testFailures"] == 1
    assert [f["index"] for f in final["failures"]] == [7]
    run_summary = json.loads(store.objects["r/summary.json"])
    assert run_summary["counts"]["passed"] == n - 1 and run_summary["counts"]["failed"] == 1
    assert store.objects["r/junit.xml"].count(b"<testcase") == n
    # a terminal run is not read again
    gets = store.gets
    c2.enqueue(("default", "r"))
    drain(c2)
    assert store.gets == gets


def test_missing_summary_of_a_failed_index_is_an_error() -> None:
    kube, store = FakeKube(), FakeStore()
    store.put_bytes("r/0/summary.json", summary(0))
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", 2))
    drain(c)
    job = kube.jobs[job_name("r")]
    job["status"] = {
        "completedIndexes": "0",
        "failedIndexes": "1",
        "conditions": [{"type": "Failed", "status": "True", "reason": "FailedIndexes"}],
    }
    c.observe_job("MODIFIED", job)
    drain(c)
    final = kube.status_patches[-1]
    assert final["phase"] == "Failed" and final["errors"] == 1
    assert "without writing its summary" in final["failures"][0]["reason"]
