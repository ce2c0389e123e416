"""Faults on the real cluster: exit codes through the Job's podFailurePolicy, a pod deleted mid-run, the
operator's pod killed mid-run, kube-apiserver restarted mid-run, and a SimulationRun deleted (the garbage
collector removes what the operator made). Nothing is lost and nothing is duplicated."""

from __future__ import annotations

import json
import time
from typing import Any

import pytest
import yaml

from tests.e2e.conftest import RUNS_NS, SYSTEM_NS, Cluster, localcluster

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(1200)]

CUT_IN = "file:///opt/carlos/examples/scenarios/cut-in.xosc"


def sweep(name: str, runs: int = 8, runs_per_pod: int = 2, scenario: str = CUT_IN, **execution: Any) -> str:
    """A cut-in sweep the simcore image can run by itself (its scenario ships in the image)."""
    return yaml.safe_dump(
        {
            "apiVersion": "carlos.dev/v1alpha1",
            "kind": "SimulationRun",
            "metadata": {"name": name},
            "spec": {
                "scenarios": [{"name": "cut-in", "openscenario": scenario}],
                "sweep": {"matrix": {"EgoSpeed": [20.0 + i for i in range(runs)]}},
                "evaluation": {"criteria": ["collision == 0"]},
                "execution": {"parallelism": 2, "runsPerPod": runs_per_pod, "retries": 2, **execution},
            },
        }
    )


def _pods(cluster: Cluster, name: str) -> list[dict[str, Any]]:
    return list(cluster.kubectl_json("-n", RUNS_NS, "get", "pods", "-l", f"carlos.dev/run={name}")["items"])


def _wait_for(what: str, check: Any, timeout: float = 300) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.5)
    raise AssertionError(f"timed out waiting for {what}")


def _running_pod(cluster: Cluster, name: str) -> dict[str, Any] | None:
    return next((p for p in _pods(cluster, name) if p["status"].get("phase") == "Running"), None)


def _complete_and_whole(cluster: Cluster, name: str, runs: int) -> dict[str, Any]:
    status = cluster.wait_phase(name, timeout=900)
    assert status["phase"] == "Succeeded", status
    assert status["total"] == runs and status["passed"] == runs, status
    store = cluster.store(f"results/{RUNS_NS}/{name}")
    for index in range(runs):
        summary = json.loads(store.get_bytes(f"{index}/summary.json"))
        assert summary["index"] == index and summary["status"] == "passed"
    run_summary = json.loads(store.get_bytes("summary.json"))
    assert run_summary["counts"]["total"] == runs and run_summary["counts"]["passed"] == runs
    jobs = cluster.kubectl_json("-n", RUNS_NS, "get", "jobs", "-l", f"carlos.dev/run={name}")["items"]
    assert len(jobs) == 1, [j["metadata"]["name"] for j in jobs]  # never a second Job
    return status


def test_failing_exit_codes_go_through_the_pod_failure_policy(cluster: Cluster) -> None:
    # exit 2 (bad input: the scenario is not in the image) fails the whole Job at once, without retries
    cluster.apply(
        sweep("fault-bad-input", runs=4, scenario="file:///opt/carlos/examples/scenarios/missing.xosc")
    )
    status = cluster.wait_phase("fault-bad-input", timeout=600)
    assert status["phase"] == "Failed", status
    job = cluster.kubectl_json("-n", RUNS_NS, "get", "jobs", "-l", "carlos.dev/run=fault-bad-input")["items"][
        0
    ]
    failed = {c["type"]: c for c in job["status"]["conditions"] if c["status"] == "True"}
    assert failed["Failed"]["reason"] == "PodFailurePolicy", failed
    assert "exit code 2" in failed["Failed"]["message"] or "2" in failed["Failed"]["message"]
    assert len(_pods(cluster, "fault-bad-input")) <= 2  # never retried
    failed_condition = next(c for c in status["conditions"] if c["type"] == "Failed")
    assert failed_condition["status"] == "True" and failed_condition["reason"] == "PodFailurePolicy", status
    assert "exit code 2" in failed_condition["message"], status


def test_a_pod_deleted_mid_run_is_retried(cluster: Cluster) -> None:
    name, runs = "fault-pod-deleted", 8
    cluster.apply(sweep(name, runs=runs))
    pod = _wait_for("a running pod", lambda: _running_pod(cluster, name))
    time.sleep(3)
    cluster.kubectl("-n", RUNS_NS, "delete", "pod", pod["metadata"]["name"], "--wait=false")
    _complete_and_whole(cluster, name, runs)
    # the deleted pod's slice ran again: every index is there, once (checked above)


def test_the_operator_killed_mid_run_loses_and_duplicates_nothing(cluster: Cluster) -> None:
    name, runs = "fault-operator-killed", 8
    cluster.apply(sweep(name, runs=runs))
    _wait_for("a running pod", lambda: _running_pod(cluster, name))
    before = cluster.kubectl_json("-n", SYSTEM_NS, "get", "pods", "-l", "app.kubernetes.io/name=carlos")[
        "items"
    ]
    cluster.kubectl(
        "-n", SYSTEM_NS, "delete", "pod", before[0]["metadata"]["name"], "--grace-period=0", "--force"
    )
    _wait_for(
        "a new operator pod",
        lambda: [
            p
            for p in cluster.kubectl_json(
                "-n", SYSTEM_NS, "get", "pods", "-l", "app.kubernetes.io/name=carlos"
            )["items"]
            if p["metadata"]["uid"] != before[0]["metadata"]["uid"] and p["status"].get("phase") == "Running"
        ],
    )
    _complete_and_whole(cluster, name, runs)


def test_kube_apiserver_restarted_mid_run(cluster: Cluster) -> None:
    name, runs = "fault-apiserver-restart", 6
    cluster.apply(sweep(name, runs=runs))
    _wait_for("a running pod", lambda: _running_pod(cluster, name))
    localcluster.restart(cluster.layout, "kube-apiserver", down_seconds=5)
    _complete_and_whole(cluster, name, runs)


def test_deleting_a_run_collects_its_jobs_pods_and_configmaps(cluster: Cluster) -> None:
    name = "fault-deleted"
    cluster.apply(sweep(name, runs=6))
    _wait_for("a running pod", lambda: _running_pod(cluster, name))
    selector = f"carlos.dev/run={name}"
    assert cluster.kubectl(
        "-n", RUNS_NS, "get", "jobs,configmaps", "-l", selector, "-o", "name"
    ).stdout.strip()
    cluster.kubectl("-n", RUNS_NS, "delete", "simulationrun", name)

    def gone() -> bool:
        left = cluster.kubectl(
            "-n", RUNS_NS, "get", "jobs,pods,configmaps", "-l", selector, "-o", "name"
        ).stdout
        return not left.strip()

    _wait_for("the garbage collector", gone, timeout=180)
