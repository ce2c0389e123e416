"""The emulator refuses what a real API server refuses (tests/apiserver.py): a changed spec of a stored
SimulationRun, a built-in object with a field its kind does not have; it stores what a real one stores."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from carlos_operator.kube import Kube
from kubernetes.client.rest import ApiException

from tests.kube_emulator import Cluster, cluster, write_kubeconfig

ROOT = Path(__file__).resolve().parent.parent
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"


@pytest.fixture
def kube(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Cluster, Kube]]:
    with cluster(tmp_path) as c:
        monkeypatch.setenv("KUBECONFIG", str(write_kubeconfig(tmp_path / "kubeconfig", c.url)))
        yield c, Kube()


def _run() -> dict[str, Any]:
    body = yaml.safe_load((ROOT / "examples/runs/automated-testing.yaml").read_text())
    body["metadata"] = {"name": "immutable", "namespace": "default"}
    return dict(body)


def _patch(kube: Kube, patch: dict[str, Any], status: bool = False) -> dict[str, Any]:
    call = (
        kube.custom.patch_namespaced_custom_object_status
        if status
        else kube.custom.patch_namespaced_custom_object
    )
    raw = call(GROUP, VERSION, "default", PLURAL, "immutable", patch, _preload_content=False)
    return dict(json.loads(raw.data))


def test_spec_is_immutable_but_suspend_through_the_emulator(kube: tuple[Cluster, Kube]) -> None:
    c, k = kube
    k.custom.create_namespaced_custom_object(
        GROUP, VERSION, "default", PLURAL, _run(), _preload_content=False
    )
    suspended = _patch(k, {"spec": {"suspend": True}})
    assert suspended["spec"]["suspend"] is True and suspended["metadata"]["generation"] == 2
    assert _patch(k, {"status": {"phase": "Suspended"}}, status=True)["status"]["phase"] == "Suspended"
    with pytest.raises(ApiException) as refused:
        _patch(k, {"spec": {"simulation": {"stepSeconds": 0.5}}})
    assert refused.value.status == 422 and "spec is immutable" in str(refused.value.body)
    assert c.emulator is not None and len(c.emulator.refused) == 1
    stored = c.objects(PLURAL)[0]
    assert stored["spec"]["simulation"] == _run()["spec"]["simulation"]


def test_a_field_the_kind_does_not_have_is_refused(kube: tuple[Cluster, Kube]) -> None:
    c, k = kube
    job = {
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": {"name": "typo", "namespace": "default"},
        "spec": {
            "completionMode": "Indexed",
            "backoffLimitPerIndx": 1,  # misspelt: strict field validation refuses it
            "template": {"spec": {"restartPolicy": "Never", "containers": [{"name": "c", "image": "i"}]}},
        },
    }
    request = urllib.request.Request(
        f"{c.url}/apis/batch/v1/namespaces/default/jobs",
        data=json.dumps(job).encode(),
        headers={"Content-Type": "application/json"},
        method="POST",
    )  # raw: the kubernetes client would refuse the unknown field itself
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(request, timeout=10)
    assert refused.value.code == 422 and "backoffLimitPerIndx" in refused.value.read().decode()
    run = _run()
    run["spec"]["execution"] = {"retries": 99}
    with pytest.raises(ApiException) as invalid:
        k.custom.create_namespaced_custom_object(
            GROUP, VERSION, "default", PLURAL, run, _preload_content=False
        )
    assert invalid.value.status == 422 and "retries" in str(invalid.value.body)


def test_the_job_watch_has_the_server_select_the_operators_jobs(kube: tuple[Cluster, Kube]) -> None:
    import time

    from carlos_operator.jobwatch import JobWatch

    from tests.kube_emulator import wait_for

    c, k = kube
    events: list[tuple[str, str]] = []
    watch = JobWatch(k, [], lambda kind, job: events.append((kind, job["metadata"]["name"])))
    watch.start()
    try:
        template = {"spec": {"restartPolicy": "Never", "containers": [{"name": "c", "image": "i"}]}}
        for name, labels in (("ours", {"carlos.dev/run": "r"}), ("foreign", {"app": "web"})):
            job = {
                "apiVersion": "batch/v1",
                "kind": "Job",
                "metadata": {"name": name, "namespace": "default", "labels": labels},
                "spec": {"template": template},
            }
            k.create_job("default", job)
        k.batch.patch_namespaced_job_status(
            "ours", "default", {"status": {"active": 1}}, _preload_content=False
        )
        wait_for(lambda: ("MODIFIED", "ours") in events, 10, "the watch event of our Job")
        time.sleep(0.5)
        assert {name for _, name in events} == {"ours"}  # the foreign Job never reached the operator
        assert c.emulator is not None
        jobs = [selector for plural, selector in c.emulator.selectors if plural == "jobs"]
        assert jobs and all(selector == "carlos.dev/run" for selector in jobs)
    finally:
        watch.stop()
