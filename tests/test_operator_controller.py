"""The controller with an in-memory Kubernetes API and object store: adoption, conflicts, catching up on
summaries after a restart without publishing lower counts, the run-level summary, and the lifecycle on a
real cluster: finished runs never read again, a Job that disappears, prerequisites that appear late, pods
that cannot start, Kueue holds, observedGeneration."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from carlos_operator.builders import OperatorSettings, job_name, round_job_name
from carlos_operator.controller import Controller, _store_for
from carlos_operator.kube import Conflict, NotFound
from carlos_operator.runstate import slim_job
from carlos_operator.status import format_intervals

from simcore.store import NotFoundError


class FakeStore:
    def __init__(self) -> None:
        self.objects: dict[str, bytes] = {}
        self.gets = 0
        self.opened = 0

    def exists(self, key: str) -> bool:
        return key in self.objects

    def get_bytes(self, key: str) -> bytes:
        self.gets += 1
        if key not in self.objects:
            raise NotFoundError(key)
        return self.objects[key]

    def put_bytes(self, key: str, data: bytes) -> None:
        self.objects[key] = data

    def put_file(self, key: str, path: Path) -> None:
        self.put_bytes(key, Path(path).read_bytes())

    def url_for(self, key: str) -> str:
        return f"s3://bucket/out/{key}"

    def sync(self) -> None:
        """Nothing to do: an object S3 acknowledged is durable."""


class FakeKube:
    def __init__(self) -> None:
        self.configmaps: dict[str, dict[str, Any]] = {}
        self.jobs: dict[str, dict[str, Any]] = {}
        self.status_patches: list[dict[str, Any]] = []
        self.events: list[tuple[str, str]] = []
        self.job_creates = 0
        self.secrets: dict[str, dict[str, str]] = {
            "s3": {"AWS_ACCESS_KEY_ID": "a", "AWS_SECRET_ACCESS_KEY": "b"}
        }
        self.secret_reads = 0
        self.deleted: list[tuple[str, str, str]] = []
        self.pods: list[dict[str, Any]] = []
        self.pod_lists: list[tuple[str, int]] = []
        self.configmap_reads: list[str] = []

    def read_secret_data(self, namespace: str, name: str) -> dict[str, str]:
        self.secret_reads += 1
        if name not in self.secrets:
            raise NotFound(name)
        return self.secrets[name]

    def delete(self, kind: str, namespace: str, name: str, uid: str) -> None:
        self.deleted.append((kind, name, uid))
        table = self.jobs if kind == "Job" else self.configmaps
        if name in table and table[name]["metadata"].get("uid", uid) == uid:
            del table[name]

    def list_pods(self, namespace: str, selector: str, limit: int) -> list[dict[str, Any]]:
        self.pod_lists.append((selector, limit))
        return self.pods[:limit]

    def create_configmap(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        if body["metadata"]["name"] in self.configmaps:
            raise Conflict("exists")
        self.configmaps[body["metadata"]["name"]] = body
        return body

    def read_configmap(self, namespace: str, name: str) -> dict[str, Any]:
        self.configmap_reads.append(name)
        if name not in self.configmaps:
            raise NotFound(name)
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

    def close(self) -> None:
        """Nothing queued: events are recorded at once."""


def run_body(name: str, uid: str, n: int, status: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default", "uid": uid},
        "spec": {
            "scenarios": [{"name": "s", "openscenario": "s3://bucket/s.xosc"}],
            "sweep": {"repetitions": n},
            "output": {"url": "s3://bucket/out", "credentialsSecretRef": {"name": "s3"}},
            "execution": {"runsPerPod": 1},  # a pod per run: the Job statuses below are written per run
        },
        "status": status or {},
    }


#: the controllers a test made: their scratch folders (a run's inputs, a search's files) are removed after it,
#: as the operator removes them when it stops
_made: list[Controller] = []


@pytest.fixture(autouse=True)
def _scratch_removed() -> Iterator[None]:
    yield
    while _made:
        made = _made.pop()
        made.scratch.close()
        made.searches.close()


def controller(
    kube: FakeKube, store: FakeStore, batch: int = 500, secrets: str = "default", **kw: Any
) -> Controller:
    settings = OperatorSettings.from_env({"CARLOS_SECRET_NAMESPACES": secrets})

    def factory(k: Any, namespace: str, output: Any) -> FakeStore:
        _store_for(k, namespace, output)  # the real credential checks (no request is made)
        store.opened += 1
        return store

    made = Controller(kube, settings, batch=batch, store_factory=factory, **kw)  # type: ignore[arg-type]
    _made.append(made)
    return made


def watch_jobs(c: Controller) -> None:
    """The controller's Job cache as its Job watch keeps it: the fake API's Jobs as they are now."""
    kube = c.kube
    assert isinstance(kube, FakeKube)
    with c._lock:
        c.jobs.clear()
        for name, job in kube.jobs.items():
            c.jobs[(job["metadata"].get("namespace") or "default", name)] = slim_job(job)


def drain(c: Controller) -> None:
    for _ in range(100):
        if not c._queue:
            return
        key = c._queue.pop(0)
        c._queued.discard(key)
        watch_jobs(c)
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
    # a Job of that name that belongs to something else is never taken over
    for table in (kube.jobs, kube.configmaps):
        table[job_name("r")]["metadata"]["ownerReferences"] = [{"kind": "Workflow", "name": "x", "uid": "w"}]
    c3 = controller(kube, store)
    c3.observe_run("ADDED", run_body("r", "uid-2", 3))
    drain(c3)
    rejected = kube.status_patches[-1]
    assert rejected["conditions"][0]["status"] == "False"
    assert rejected["conditions"][0]["reason"] == "NameConflict"
    assert kube.deleted == []


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


def test_run_deleted_and_created_again_while_its_old_objects_exist_starts() -> None:
    kube, store = FakeKube(), FakeStore()
    c = controller(kube, store, backoff=0.01)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    for table in (kube.jobs, kube.configmaps):
        table[job_name("r")]["metadata"]["uid"] = "old-object"
    # the run is deleted and created again before the garbage collector removed its ConfigMap and Job
    c.observe_run("DELETED", run_body("r", "uid-1", 3))
    c.observe_run("ADDED", run_body("r", "uid-2", 3))
    drain(c)
    assert ("Job", job_name("r"), "old-object") in kube.deleted  # known from the Job watch: deleted first
    waiting = kube.status_patches[-1]
    assert waiting["phase"] == "Pending"
    assert {"type": "Prerequisites", "status": "False", "reason": "PreviousRunCleanup"}.items() <= {
        k: v for c in waiting["conditions"] if c["type"] == "Prerequisites" for k, v in c.items()
    }.items()
    for _ in range(3):  # the backoff timer re-queues it; the old Job is deleted next, then the new one made
        c.enqueue(("default", "r"))
        drain(c)
    assert ("ConfigMap", job_name("r"), "old-object") in kube.deleted  # its create met it (409): deleted
    owners = kube.jobs[job_name("r")]["metadata"]["ownerReferences"]
    assert [o["uid"] for o in owners] == ["uid-2"]
    assert not any(p["conditions"][0].get("reason") == "NameConflict" for p in kube.status_patches)


def _finish(kube: FakeKube, store: FakeStore, n: int) -> dict[str, Any]:
    job = kube.jobs[job_name("r")]
    job["status"] = {
        "completedIndexes": f"0-{n - 1}",
        "startTime": "2026-01-01T00:00:00Z",
        "conditions": [{"type": "Complete", "status": "True"}],
    }
    return job


def test_a_finished_run_is_never_read_again_after_a_restart() -> None:
    n = 50
    kube, store = FakeKube(), FakeStore()
    for i in range(n):
        store.put_bytes(f"r/{i}/summary.json", summary(i))
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", n))
    drain(c)
    c.observe_job("MODIFIED", _finish(kube, store, n))
    drain(c)
    final = kube.status_patches[-1]
    assert final["phase"] == "Succeeded" and store.objects["r/summary.json"]
    first = store.gets
    assert first == 3 * n  # counted once, then the run-level summary and junit.xml
    # restart: the run and its (not yet expired) Job are seen again
    opened, reads, patches = store.opened, kube.secret_reads, len(kube.status_patches)
    c2 = controller(kube, store)
    c2.observe_run("ADDED", run_body("r", "uid-1", n, final))
    c2.observe_job("ADDED", kube.jobs[job_name("r")])
    drain(c2)
    assert store.gets == first  # not one summary read again
    assert (store.opened, kube.secret_reads, len(kube.status_patches)) == (opened, reads, patches)


def test_a_job_that_disappears_leaves_the_run_unknown_never_pending() -> None:
    kube, store = FakeKube(), FakeStore()
    store.put_bytes("r/0/summary.json", summary(0))
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    job = kube.jobs[job_name("r")]
    job["status"] = {"completedIndexes": "0", "active": 2, "startTime": "2026-01-01T00:00:00Z"}
    c.observe_job("MODIFIED", job)
    drain(c)
    assert kube.status_patches[-1]["phase"] == "Running"
    del kube.jobs[job_name("r")]
    c.observe_job("DELETED", job)
    drain(c)
    gone = kube.status_patches[-1]
    assert gone["phase"] == "Unknown" and gone["passed"] == 1
    complete = next(x for x in gone["conditions"] if x["type"] == "Complete")
    assert complete["status"] == "Unknown" and complete["reason"] == "JobGone"
    assert ("Warning", "JobGone") in kube.events
    # later passes and a restarted operator leave it there: no Pending, no second Job
    c.enqueue(("default", "r"))
    drain(c)
    c2 = controller(kube, store)
    c2.observe_run("ADDED", run_body("r", "uid-1", 3, gone))
    drain(c2)
    assert kube.status_patches[-1]["phase"] == "Unknown"
    assert kube.job_creates == 1 and kube.jobs == {}


def test_a_restart_after_the_job_started_never_creates_a_second_one() -> None:
    kube, store = FakeKube(), FakeStore()
    running = {"phase": "Running", "startTime": "2026-01-01T00:00:00Z", "conditions": []}
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", 3, running))
    drain(c)
    assert kube.job_creates == 0 and kube.status_patches[-1]["phase"] == "Unknown"


def test_a_missing_secret_is_waited_for_with_backoff_and_shown() -> None:
    kube, store = FakeKube(), FakeStore()
    kube.secrets = {}
    # the backoff's own re-queue never fires during the test (it would race with the test's drain: a third
    # pass on a loaded machine); the test re-queues by hand
    c = controller(kube, store, backoff=600)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    waiting = kube.status_patches[-1]
    assert waiting["phase"] == "Pending" and kube.jobs == {}
    prerequisites = next(x for x in waiting["conditions"] if x["type"] == "Prerequisites")
    assert prerequisites["status"] == "False" and prerequisites["reason"] == "SecretNotFound"
    assert "credentialsSecretRef" in prerequisites["message"]
    assert ("Warning", "SecretNotFound") in kube.events
    assert c.runs[("default", "r")].waits == 1
    c.enqueue(("default", "r"))
    drain(c)
    assert c.runs[("default", "r")].waits == 2 and kube.events.count(("Warning", "SecretNotFound")) == 1
    kube.secrets["s3"] = {
        "AWS_ACCESS_KEY_ID": "a",
        "AWS_SECRET_ACCESS_KEY": "b",
    }  # External Secrets caught up
    c.enqueue(("default", "r"))
    drain(c)
    assert list(kube.jobs) == [job_name("r")]
    assert not any(x["type"] == "Prerequisites" for x in kube.status_patches[-1]["conditions"])


def test_a_missing_scenario_configmap_is_waited_for() -> None:
    kube, store = FakeKube(), FakeStore()
    body = run_body("r", "uid-1", 1)
    body["spec"]["scenarios"] = [{"name": "s", "configMapRef": {"name": "scenarios", "key": "s.xosc"}}]
    c = controller(kube, store, backoff=0.01)
    c.observe_run("ADDED", body)
    drain(c)
    reason = next(x for x in kube.status_patches[-1]["conditions"] if x["type"] == "Prerequisites")["reason"]
    assert reason == "ConfigMapNotFound" and kube.jobs == {}
    kube.configmaps["scenarios"] = {"metadata": {"name": "scenarios"}, "data": {"s.xosc": "<x/>"}}
    c.enqueue(("default", "r"))
    drain(c)
    assert job_name("r") in kube.jobs


def test_pods_that_cannot_start_surface_in_conditions_and_events() -> None:
    kube, store = FakeKube(), FakeStore()
    c = controller(kube, store, pod_check=0.0)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    job = kube.jobs[job_name("r")]
    job["status"] = {"active": 3, "startTime": "2026-01-01T00:00:00Z"}
    kube.pods = [
        {
            "metadata": {"name": f"carlos-r-{i}-x"},
            "status": {
                "initContainerStatuses": [{"name": "bridge", "state": {"running": {}}}],
                "containerStatuses": [
                    {
                        "name": "simcore",
                        "state": {
                            "waiting": {"reason": "ImagePullBackOff", "message": "Back-off pulling image"}
                        },
                    }
                ],
            },
        }
        for i in range(3)
    ]
    c.observe_job("MODIFIED", job)
    drain(c)
    status = kube.status_patches[-1]
    stuck = next(x for x in status["conditions"] if x["type"] == "PodsStuck")
    assert stuck["status"] == "True" and stuck["reason"] == "ImagePullBackOff"
    assert "carlos-r-0-x" in stuck["message"] and "simcore" in stuck["message"]
    assert ("Warning", "ImagePullBackOff") in kube.events
    assert kube.pod_lists[-1] == (f"job-name={job_name('r')}", 20)  # by label, bounded
    kube.pods = []
    c.enqueue(("default", "r"))
    drain(c)
    stuck = next(x for x in kube.status_patches[-1]["conditions"] if x["type"] == "PodsStuck")
    assert stuck["status"] == "False"


def test_status_carries_observed_generation() -> None:
    kube, store = FakeKube(), FakeStore()
    c = controller(kube, store)
    body = run_body("r", "uid-1", 3)
    body["metadata"]["generation"] = 4
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.status_patches[-1]["observedGeneration"] == 4


def test_suspended_run_with_a_queue_is_held_until_resumed() -> None:
    kube, store = FakeKube(), FakeStore()
    body = run_body("r", "uid-1", 3)
    body["spec"]["suspend"] = True
    body["spec"]["execution"] = {"queueName": "team-a", "runsPerPod": 1}
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.jobs == {} and kube.status_patches[-1]["phase"] == "Suspended"
    resumed = json.loads(json.dumps(body))
    resumed["spec"]["suspend"] = False
    c.observe_run("MODIFIED", resumed)
    drain(c)
    job = kube.jobs[job_name("r")]
    assert job["spec"]["suspend"] is True  # Kueue admits it
    assert job["metadata"]["labels"]["kueue.x-k8s.io/queue-name"] == "team-a"


def test_a_user_chosen_endpoint_never_gets_the_operators_credentials() -> None:
    kube, store = FakeKube(), FakeStore()
    body = run_body("r", "uid-1", 1)
    body["spec"]["output"] = {"url": "s3://bucket/out", "endpoint": "https://attacker.example"}
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    rejected = kube.status_patches[-1]["conditions"][0]
    assert rejected["reason"] == "CredentialsRequired" and "credentialsSecretRef" in rejected["message"]
    assert kube.jobs == {} and store.opened == 0


def test_secret_references_are_opt_in_per_namespace() -> None:
    kube, store = FakeKube(), FakeStore()
    c = controller(kube, store, secrets="other")
    c.observe_run("ADDED", run_body("r", "uid-1", 1))
    drain(c)
    rejected = kube.status_patches[-1]["conditions"][0]
    assert rejected["reason"] == "SecretReferencesNotAllowed"
    assert (
        "spec.output.credentialsSecretRef" in rejected["message"]
        and "secretReferences" in rejected["message"]
    )
    assert kube.secret_reads == 0 and kube.jobs == {}
    body = run_body("r2", "uid-2", 1)
    body["spec"]["output"] = {"url": "s3://bucket/out"}
    body["spec"]["systemUnderTest"] = {
        "name": "node",
        "image": "reg/node:1",
        "env": [{"name": "TOKEN", "secretKeyRef": {"name": "api", "key": "token"}}],
    }
    c.observe_run("ADDED", body)
    drain(c)
    message = kube.status_patches[-1]["conditions"][0]["message"]
    assert "spec.systemUnderTest.env[0].secretKeyRef" in message
    # a run that names no Secret runs; the operator reads none for it
    plain = run_body("r3", "uid-3", 1)
    plain["spec"]["output"] = {"url": "s3://bucket/out"}
    c.observe_run("ADDED", plain)
    drain(c)
    assert job_name("r3") in kube.jobs and kube.secret_reads == 0


# --- a search: one Job per round --------------------------------------------------------------------------

CUT_IN = Path(__file__).resolve().parent.parent / "examples/scenarios/cut-in.xosc"


def search_body(name: str, uid: str, status: dict[str, Any] | None = None, **scenario: Any) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default", "uid": uid},
        "spec": {
            "scenarios": [
                {"name": "cut-in", **(scenario or {"configMapRef": {"name": "inputs", "key": "cut-in.xosc"}})}
            ],
            "search": {
                "parameters": [
                    {"name": "CutInGap", "min": 5.0, "max": 20.0},
                    {"name": "EgoSpeed", "min": 20.0, "max": 30.0},
                ],
                "objective": {"metric": "minDistance"},
                "budget": 6,
                "batchSize": 3,
                "seed": 4,
            },
            "evaluation": {"criteria": ["minDistance >= 10"]},
            "output": {"url": "s3://bucket/out", "credentialsSecretRef": {"name": "s3"}},
            "execution": {"runsPerPod": 1},
        },
        "status": status or {},
    }


def search_kube() -> FakeKube:
    kube = FakeKube()
    kube.configmaps["inputs"] = {"metadata": {"name": "inputs"}, "data": {"cut-in.xosc": CUT_IN.read_text()}}
    return kube


def play_round(kube: FakeKube, store: FakeStore, name: str, number: int, tmp_path: Path) -> list[float]:
    """The round's pods as the test kubelet runs them: index start+k runs point k of the round's ConfigMap
    (minDistance = its CutInGap: a gap under 10 m fails), then the Job completes."""
    from simcore.evaluation.criteria import evaluate
    from simcore.evaluation.report import index_summary
    from simcore.manifest import parse_manifest
    from simcore.scenario.distribution import load_distribution

    job = kube.jobs[round_job_name(name, number)]
    env = {e["name"]: e.get("value") for e in job["spec"]["template"]["spec"]["containers"][0]["env"]}
    offset = int(env["CARLOS_INDEX_OFFSET"])
    points = tmp_path / f"points-{number}.xosc"
    points.write_text(kube.configmaps[round_job_name(name, number)]["data"]["points.xosc"])
    distribution = load_distribution(points)
    criteria = parse_manifest(search_body(name, "u"), source="t").spec.evaluation.criteria
    gaps = []
    failed = []
    for k in range(job["spec"]["completions"]):
        parameters = distribution[k]
        gap = float(parameters["CutInGap"])
        gaps.append(gap)
        summary = index_summary(
            index=offset + k,
            scenario="cut-in",
            parameters=parameters,
            seed=0,
            optional=False,
            sim_seconds=1.0,
            wall_seconds=1.0,
            metrics={"minDistance": gap},
            results=evaluate(criteria, {"minDistance": gap}),
            error=None,
            end_reason="stopTrigger",
        )
        if summary["status"] == "failed":
            failed.append(k)
        store.put_bytes(f"{name}/{offset + k}/summary.json", json.dumps(summary).encode())
    completions = job["spec"]["completions"]
    job["status"] = {
        "startTime": "2026-11-25T00:00:00Z",
        "completedIndexes": format_intervals([k for k in range(completions) if k not in failed]),
        "failedIndexes": format_intervals(failed),
        "conditions": [{"type": "Failed" if failed else "Complete", "status": "True"}],
    }
    return gaps


def test_a_search_makes_one_job_per_round_and_restarts_never_duplicate_one(tmp_path: Path) -> None:
    kube, store = search_kube(), FakeStore()
    r0, r1 = round_job_name("s", 0), round_job_name("s", 1)
    c = controller(kube, store)
    c.observe_run("ADDED", search_body("s", "uid-1"))
    drain(c)
    assert list(kube.jobs) == [r0] and kube.job_creates == 1
    assert kube.jobs[r0]["spec"]["completions"] == 3 and r0 in kube.configmaps
    st = kube.status_patches[-1]
    assert (st["phase"], st["jobName"], st["search"]["rounds"], st["search"]["round"]) == (
        "Pending",
        r0,
        "0/2",
        0,
    )
    assert not store.exists("s/search/state.json")  # nothing told yet
    # a restart in the middle of round 0: the Job is adopted, nothing created
    c2 = controller(kube, store)
    c2.observe_run("ADDED", search_body("s", "uid-1", st))
    drain(c2)
    assert kube.job_creates == 1 and list(kube.jobs) == [r0]
    # round 0 finishes while the operator is down; the next one tells the study and starts round 1
    gaps0 = play_round(kube, store, "s", 0, tmp_path)
    c3 = controller(kube, store)
    c3.observe_run("ADDED", search_body("s", "uid-1", kube.status_patches[-1]))
    drain(c3)
    assert sorted(kube.jobs) == [r0, r1] and kube.job_creates == 2
    assert kube.jobs[r1]["spec"]["template"]["spec"]["containers"][0]["env"][-1] == {
        "name": "CARLOS_INDEX_OFFSET",
        "value": "3",
    }
    state = json.loads(store.objects["s/search/state.json"])
    assert [p["index"] for p in state["points"]] == [0, 1, 2] and state["study"]
    assert [p["parameters"]["CutInGap"] for p in state["points"]] == gaps0
    st = kube.status_patches[-1]
    assert (st["phase"], st["jobName"], st["search"]["rounds"], st["search"]["evaluated"]) == (
        "Running",
        r1,
        "1/2",
        3,
    )
    assert st["search"]["bestObjective"] == min(gaps0)
    c3.enqueue(("default", "s"))
    drain(c3)
    assert kube.job_creates == 2
    # a restart after round 1 finished: the last round is told, the results written, nothing created
    gaps1 = play_round(kube, store, "s", 1, tmp_path)
    c4 = controller(kube, store)
    c4.observe_run("ADDED", search_body("s", "uid-1", kube.status_patches[-1]))
    drain(c4)
    assert kube.job_creates == 2
    final = kube.status_patches[-1]
    gaps = gaps0 + gaps1
    failing = [i for i, gap in enumerate(gaps) if gap < 10]
    assert final["phase"] == ("Failed" if failing else "Succeeded")
    assert final["search"]["rounds"] == "2/2" and final["search"]["round"] is None
    assert final["search"]["failuresFound"] == len(failing) == final["testFailures"]
    assert final["passed"] == 6 - len(failing) and [f["index"] for f in final["failures"]] == failing
    document = json.loads(store.objects["s/search.json"])
    assert [p["parameters"]["CutInGap"] for p in document["points"]] == gaps
    assert document["failing"] == failing and ("s/search/failing.xosc" in store.objects) == bool(failing)
    assert json.loads(store.objects["s/summary.json"])["counts"]["total"] == 6
    assert store.objects["s/junit.xml"].count(b"<testcase") == 6


def test_a_rounds_job_that_disappears_leaves_the_search_unknown(tmp_path: Path) -> None:
    kube, store = search_kube(), FakeStore()
    c = controller(kube, store)
    c.observe_run("ADDED", search_body("s", "uid-1"))
    drain(c)
    c.observe_job("DELETED", kube.jobs.pop(round_job_name("s", 0)))  # the watch tells
    drain(c)
    assert kube.status_patches[-1]["phase"] == "Unknown" and kube.job_creates == 1
    # a restarted operator sees from the status that round 0's Job existed: no second one either
    c2 = controller(kube, store)
    c2.observe_run("ADDED", search_body("s", "uid-1", {**kube.status_patches[-2], "phase": "Running"}))
    drain(c2)
    assert kube.status_patches[-1]["phase"] == "Unknown" and kube.job_creates == 1


def test_a_search_whose_scenario_the_operator_cannot_read_is_not_accepted() -> None:
    kube, store = search_kube(), FakeStore()
    c = controller(kube, store)
    c.observe_run("ADDED", search_body("s", "uid-1", openscenario="file:///inside/the/image.xosc"))
    c.observe_run("ADDED", search_body("t", "uid-2", configMapRef={"name": "inputs", "key": "other.xosc"}))
    drain(c)
    rejected = [p for p in kube.status_patches if p.get("phase") == "Failed"]
    assert len(rejected) == 2 and kube.jobs == {}
    messages = " ".join(p["conditions"][0]["message"] for p in rejected)
    assert "configMapRef" in messages and "s3://" in messages and "'other.xosc'" in messages
    # from s3:// (the fake store answers every bucket): the space is read, round 0 starts
    store.put_bytes("inputs/cut-in.xosc", CUT_IN.read_bytes())
    c.observe_run("ADDED", search_body("u", "uid-3", openscenario="s3://bucket/inputs/cut-in.xosc"))
    drain(c)
    assert list(kube.jobs) == [round_job_name("u", 0)]


def test_a_stored_search_of_another_spec_is_not_resumed() -> None:
    kube, store = search_kube(), FakeStore()
    store.put_bytes(
        "s/search/state.json", json.dumps({"version": 1, "spec": "other", "study": [], "points": []}).encode()
    )
    c = controller(kube, store)
    c.observe_run("ADDED", search_body("s", "uid-1"))
    drain(c)
    assert kube.jobs == {}
    assert kube.status_patches[-1]["conditions"][0]["reason"] == "SearchStateMismatch"


def test_a_rounds_job_that_fails_before_every_index_finished_ends_the_search() -> None:
    kube, store = search_kube(), FakeStore()
    c = controller(kube, store)
    c.observe_run("ADDED", search_body("s", "uid-1"))
    drain(c)
    job = kube.jobs[round_job_name("s", 0)]
    job["status"] = {
        "startTime": "2026-11-25T00:00:00Z",
        "failedIndexes": "0",
        "conditions": [
            {"type": "Failed", "status": "True", "reason": "PodFailurePolicy", "message": "exit code 2"}
        ],
    }
    c.observe_job("MODIFIED", job)
    drain(c)
    final = kube.status_patches[-1]
    failed = {x["type"]: x for x in final["conditions"]}["Failed"]
    assert final["phase"] == "Failed" and failed["reason"] == "PodFailurePolicy"
    assert kube.job_creates == 1 and not store.exists("s/search/state.json")  # never told, no round 1
    assert final["search"]["rounds"] == "0/2" and final["search"]["round"] is None
    assert json.loads(store.objects["s/search.json"])["runs"] == 0 and "s/summary.json" in store.objects


class ReportlessStore(FakeStore):
    """An object store that refuses report.html (a store hiccup, a plot of unusual data)."""

    def put_bytes(self, key: str, data: bytes) -> None:
        if key.endswith("/report.html"):
            raise OSError("the store refused report.html")
        super().put_bytes(key, data)


def _finish_run(kube: FakeKube, store: FakeStore, n: int, failed: int | None = None) -> dict[str, Any]:
    for i in range(n):
        store.put_bytes(f"r/{i}/summary.json", summary(i, "failed" if i == failed else "passed"))
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", n))
    drain(c)
    job = kube.jobs[job_name("r")]
    done = [i for i in range(n) if i != failed]
    job["status"] = {
        "completedIndexes": format_intervals(done),
        "failedIndexes": format_intervals([] if failed is None else [failed]),
        "conditions": [
            {"type": "Failed" if failed is not None else "Complete", "status": "True", "reason": "Done"}
        ],
    }
    c.observe_job("MODIFIED", job)
    drain(c)
    return kube.status_patches[-1]


def test_a_finished_run_gets_report_html_beside_its_summary() -> None:
    kube, store = FakeKube(), FakeStore()
    final = _finish_run(kube, store, 4, failed=2)
    assert final["phase"] == "Failed"
    page = store.objects["r/report.html"].decode()
    assert "SimulationRun r" in page and "4 runs" in page and "1 failed" in page
    assert "indexes shown" not in page  # every index of a small run is in it


def test_a_report_that_cannot_be_written_never_changes_the_verdict() -> None:
    for failed in (None, 1):
        kube, store = FakeKube(), ReportlessStore()
        final = _finish_run(kube, store, 3, failed=failed)
        assert final["phase"] == ("Succeeded" if failed is None else "Failed")
        assert json.loads(store.objects["r/summary.json"])["counts"]["total"] == 3
        assert "r/report.html" not in store.objects and "r/junit.xml" in store.objects


def test_the_report_of_a_large_run_holds_a_bounded_sample(monkeypatch: Any) -> None:
    import carlos_operator.controller as controller_module

    monkeypatch.setattr(controller_module, "REPORT_INDEXES", 5)
    kube, store = FakeKube(), FakeStore()
    final = _finish_run(kube, store, 12, failed=9)
    assert final["phase"] == "Failed"
    page = store.objects["r/report.html"].decode()
    assert "5 of 12 indexes shown" in page and "12 runs" in page
    runs_table = page.split("<table class=runs>")[1].split("</table>")[0]
    assert runs_table.count("<tr><td>") == 5 and "<td class=num>9</td>" in runs_table


DISTRIBUTION = b"""<OpenSCENARIO><ParameterValueDistribution><ScenarioFile filepath="s.xosc"/><Deterministic>
<DeterministicSingleParameterDistribution parameterName="Speed"><DistributionSet>
<Element value="20"/><Element value="25"/><Element value="30"/></DistributionSet>
</DeterministicSingleParameterDistribution></Deterministic></ParameterValueDistribution></OpenSCENARIO>
"""


def test_a_distribution_from_a_configmap_is_waited_for_expanded_and_handed_to_the_pods() -> None:
    import yaml
    from carlos_operator.builders import DISTRIBUTION_FILE, SPEC_FILE

    kube, store = FakeKube(), FakeStore()
    body = run_body("d", "uid-1", 2)
    body["spec"]["sweep"]["distributionConfigMapRef"] = {"name": "d-inputs", "key": "speeds.xosc"}
    c = controller(kube, store, backoff=3600.0)
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.jobs == {} and kube.status_patches[-1]["conditions"][-1]["reason"] == "ConfigMapNotFound"
    kube.configmaps["d-inputs"] = {"metadata": {"name": "d-inputs"}, "data": {"other": "x"}}
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    rejected = kube.status_patches[-1]["conditions"][0]
    assert (
        rejected["reason"] == "InvalidSpec"
        and "spec.sweep.distributionConfigMapRef.key" in rejected["message"]
    )
    kube.configmaps["d-inputs"]["data"]["speeds.xosc"] = DISTRIBUTION.decode()
    kube.status_patches.clear()
    kube.configmap_reads.clear()
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.configmap_reads == ["d-inputs"]  # read once: checked and used from the same answer
    job = kube.jobs[job_name("d")]
    assert job["spec"]["completions"] == 6  # 3 speeds x 2 repetitions
    data = kube.configmaps[job_name("d")]["data"]
    assert data[DISTRIBUTION_FILE] == DISTRIBUTION.decode()
    sweep = yaml.safe_load(data[SPEC_FILE])["spec"]["sweep"]
    assert sweep["distribution"] == DISTRIBUTION_FILE and "distributionConfigMapRef" not in sweep
    # the results keep the spec as submitted
    stored = yaml.safe_load(store.objects["d/run.yaml"])["spec"]["sweep"]
    assert stored["distributionConfigMapRef"] == {"name": "d-inputs", "key": "speeds.xosc"}


def test_the_operators_input_copies_go_when_the_run_is_deleted_or_the_operator_stops() -> None:
    """A long-lived operator keeps no file of a deleted run, and none at all after it stops."""
    from carlos_operator.builders import DISTRIBUTION_FILE

    kube, store = FakeKube(), FakeStore()
    c = controller(kube, store)
    assert c.scratch.root is None  # nothing made until a run needs it
    for name in ("d", "e"):
        body = run_body(name, f"uid-{name}", 1)
        body["spec"]["sweep"]["distribution"] = "s3://bucket/inputs/speeds.xosc"
        store.put_bytes("inputs/speeds.xosc", DISTRIBUTION)
        c.observe_run("ADDED", body)
    drain(c)
    root = c.scratch.root
    assert root is not None
    assert (root / "default" / "d" / DISTRIBUTION_FILE).is_file()
    assert (root / "default" / "e" / DISTRIBUTION_FILE).is_file()
    c.observe_run("DELETED", run_body("d", "uid-d", 1))
    assert not (root / "default" / "d").exists() and (root / "default" / "e" / DISTRIBUTION_FILE).is_file()
    c.stop()
    assert not root.exists()


def test_a_distribution_in_the_object_store_is_read_with_the_runs_credentials() -> None:
    from carlos_operator.builders import DISTRIBUTION_FILE

    kube, store = FakeKube(), FakeStore()
    body = run_body("d", "uid-1", 1)
    body["spec"]["sweep"]["distribution"] = "s3://bucket/inputs/speeds.xosc"
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.status_patches[-1]["conditions"][0]["reason"] == "InvalidSpec"
    assert (
        "s3://bucket/inputs/speeds.xosc does not exist" in kube.status_patches[-1]["conditions"][0]["message"]
    )
    store.put_bytes("inputs/speeds.xosc", DISTRIBUTION)
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.jobs[job_name("d")]["spec"]["completions"] == 3
    assert kube.configmaps[job_name("d")]["data"][DISTRIBUTION_FILE] == DISTRIBUTION.decode()


def _recording(messages: list[bytes]) -> bytes:
    import io

    from mcap.writer import Writer

    out = io.BytesIO()
    writer = Writer(out)
    writer.start()
    schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
    channel = writer.register_channel("/t", "cdr", schema)
    for k, data in enumerate(messages):
        writer.add_message(channel, log_time=k, data=data, publish_time=k)
    writer.finish()
    return out.getvalue()


def test_repeats_flag_flaky_points_and_check_determinism_as_carlos_run() -> None:
    """execution.repeat on a cluster: the run-level summary.json has `repeats` and junit.xml flags the runs
    of a flaky point, as `carlos run` writes them (simcore.evaluation.flaky)."""
    from simcore.evaluation.flaky import RepeatTally, flag_repeats, recording_digests

    kube, store = FakeKube(), FakeStore()
    body = run_body("r", "uid-1", 2)
    body["spec"]["execution"]["repeat"] = 2  # 2 points × 2 repeats, same seed: indexes 0,1 and 2,3
    statuses = ["passed", "failed", "passed", "passed"]
    recordings = [[b"a"], [b"a"], [b"b"], [b"c"]]  # point 1: same seed, different messages
    for i, status in enumerate(statuses):
        store.put_bytes(f"r/{i}/summary.json", summary(i, status))
        store.put_bytes(f"r/{i}/recording.mcap", _recording(recordings[i]))
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    job = kube.jobs[job_name("r")]
    job["status"] = {
        "completedIndexes": "0,2-3",
        "failedIndexes": "1",
        "startTime": "2026-01-01T00:00:00Z",
        "conditions": [{"type": "Failed", "status": "True", "reason": "FailedIndexes"}],
    }
    c.observe_job("MODIFIED", job)
    drain(c)
    repeats = json.loads(store.objects["r/summary.json"])["repeats"]
    assert (repeats["repeat"], repeats["points"], repeats["flaky"]) == (2, 2, 1)
    assert (repeats["determinismChecked"], repeats["nondeterministic"]) == (2, 1)
    assert [(p["indexes"], p["flaky"], p["deterministic"]) for p in repeats["flakyPoints"]] == [
        ([0, 1], True, True),
        ([2, 3], False, False),
    ]
    junit = store.objects["r/junit.xml"].decode()
    assert junit.count('<property name="flaky" value="true"') == 2
    # the same as `carlos run` computes from the same summaries and recordings
    local = RepeatTally(2)
    ordered = [json.loads(store.objects[f"r/{i}/summary.json"]) for i in range(4)]
    list(flag_repeats(ordered, lambda i: i // 2, local, recording_digests(store, "r")))  # type: ignore[arg-type]
    assert local.report() == repeats


def test_the_default_outputs_client_is_made_at_start_and_used_by_the_first_run(monkeypatch: Any) -> None:
    """The operator makes the default output's object-store client at start (handlers.startup), so a burst of
    new runs does not wait for boto3 all at once; a run of the default output gets that very client, and a
    default output that needs a Secret is not opened ahead (the Secret is the run's namespace's)."""
    from carlos_operator import controller as module
    from carlos_operator.builders import resolve_output
    from carlos_operator.desired import parse

    monkeypatch.setattr(module, "_clients", {})
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "warm-key")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "warm-secret")
    env = {"CARLOS_DEFAULT_OUTPUT_URL": "s3://bucket/out", "CARLOS_DEFAULT_S3_ENDPOINT": "http://127.0.0.1:9"}
    kube = FakeKube()
    module.warm_up(kube, OperatorSettings.from_env({**env, "CARLOS_DEFAULT_S3_SECRET": "s3"}))
    assert module._clients == {} and kube.secret_reads == 0
    settings = OperatorSettings.from_env(env)
    module.warm_up(kube, settings)
    assert len(module._clients) == 1
    (warm,) = module._clients.values()
    body = run_body("r", "uid-1", 1)
    del body["spec"]["output"]
    run, _ = parse(body, settings)
    store = _store_for(kube, "default", resolve_output(run, settings, namespace="default"))
    assert store._client is warm and store.prefix == "out/default"
