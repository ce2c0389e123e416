"""Opt-in end-to-end test against a real cluster (kind, k3d…): skipped unless CARLOS_E2E_KUBECONFIG is set.

Needs (see docs/kubernetes/walkthrough.md, step 6):
- CARLOS_E2E_KUBECONFIG: kubeconfig of the cluster (the test installs the CRD and uses namespace
  CARLOS_E2E_NAMESPACE, default `carlos-e2e`, creating it when missing);
- the CARLOS images loadable by the cluster: CARLOS_IMAGE_SIMCORE, CARLOS_IMAGE_BRIDGE, CARLOS_IMAGE_RECORDER
  (defaults: ghcr.io/carlos-sim/carlos-<role>:<version>);
- an S3 endpoint reachable from the pods and from this machine: CARLOS_E2E_S3_ENDPOINT (pods),
  CARLOS_E2E_S3_LOCAL_ENDPOINT (this machine; default the same), CARLOS_E2E_S3_BUCKET, AWS_ACCESS_KEY_ID,
  AWS_SECRET_ACCESS_KEY.
The operator runs in this process (as `carlos operator --namespace NS` would); the pods run on the cluster.
"""

from __future__ import annotations

import base64
import json
import os
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import pytest

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(
        not os.environ.get("CARLOS_E2E_KUBECONFIG"), reason="CARLOS_E2E_KUBECONFIG is not set"
    ),
    pytest.mark.timeout(1200),
]

ROOT = Path(__file__).resolve().parent.parent
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"


def test_simulation_run_on_a_real_cluster(monkeypatch: pytest.MonkeyPatch) -> None:
    import carlos_operator.handlers  # noqa: F401
    import kopf
    import yaml
    from carlos_operator.crd import crd
    from carlos_operator.kube import Kube
    from kubernetes.client.rest import ApiException

    from simcore.store import open_store

    monkeypatch.setenv("KUBECONFIG", os.environ["CARLOS_E2E_KUBECONFIG"])
    namespace = os.environ.get("CARLOS_E2E_NAMESPACE", "carlos-e2e")
    bucket = os.environ["CARLOS_E2E_S3_BUCKET"]
    pod_endpoint = os.environ["CARLOS_E2E_S3_ENDPOINT"]
    local_endpoint = os.environ.get("CARLOS_E2E_S3_LOCAL_ENDPOINT", pod_endpoint)
    monkeypatch.setenv("CARLOS_DEFAULT_S3_ENDPOINT", pod_endpoint)
    kube = Kube()
    from kubernetes import client

    ext = client.ApiextensionsV1Api(kube.api_client)
    try:
        ext.create_custom_resource_definition(crd())
    except ApiException as exc:
        if exc.status != 409:
            raise
    time.sleep(3)  # the CRD becomes established
    try:
        kube.core.create_namespace({"metadata": {"name": namespace}})
    except ApiException as exc:
        if exc.status != 409:
            raise
    name = f"e2e-{uuid.uuid4().hex[:8]}"
    key_id, secret = os.environ["AWS_ACCESS_KEY_ID"], os.environ["AWS_SECRET_ACCESS_KEY"]
    kube.core.create_namespaced_secret(
        namespace,
        {
            "metadata": {"name": f"{name}-s3"},
            "data": {
                "AWS_ACCESS_KEY_ID": base64.b64encode(key_id.encode()).decode(),
                "AWS_SECRET_ACCESS_KEY": base64.b64encode(secret.encode()).decode(),
            },
        },
    )
    store = open_store(f"s3://{bucket}", endpoint=local_endpoint)
    store.put_file(f"{name}/inputs/scenarios/braking.xosc", ROOT / "examples/scenarios/braking.xosc")
    store.put_file(f"{name}/inputs/maps/highway.xodr", ROOT / "examples/maps/highway.xodr")
    body: dict[str, Any] = {
        "apiVersion": f"{GROUP}/{VERSION}",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": namespace},
        "spec": {
            "scenarios": [
                {"name": "braking", "openscenario": f"s3://{bucket}/{name}/inputs/scenarios/braking.xosc"}
            ],
            "sweep": {"matrix": {"Speed": [10.0, 20.0]}},
            "simulation": {"stepSeconds": 0.1, "maxSeconds": 5},
            "evaluation": {"criteria": ["simSeconds <= 100"]},
            "output": {"url": f"s3://{bucket}/results", "credentialsSecretRef": {"name": f"{name}-s3"}},
        },
    }
    stop = threading.Event()
    operator = threading.Thread(
        target=lambda: kopf.run(namespaces=[namespace], standalone=True, stop_flag=stop), daemon=True
    )
    operator.start()
    try:
        kube.custom.create_namespaced_custom_object(GROUP, VERSION, namespace, PLURAL, body)
        deadline = time.monotonic() + 900
        status: dict[str, Any] = {}
        while time.monotonic() < deadline:
            raw = kube.custom.get_namespaced_custom_object(
                GROUP, VERSION, namespace, PLURAL, name, _preload_content=False
            )
            status = json.loads(raw.data).get("status") or {}
            if status.get("phase") in ("Succeeded", "Failed"):
                break
            time.sleep(5)
        assert status.get("phase") == "Succeeded", yaml.safe_dump(status)
        assert status["passed"] == 2 and status["total"] == 2
        results = open_store(f"s3://{bucket}/results", endpoint=local_endpoint)
        for index in range(2):
            assert results.exists(f"{name}/{index}/summary.json")
            assert results.exists(f"{name}/{index}/recording.mcap")
        assert results.exists(f"{name}/summary.json") and results.exists(f"{name}/junit.xml")
    finally:
        stop.set()
        operator.join(30)
        kube.custom.delete_namespaced_custom_object(GROUP, VERSION, namespace, PLURAL, name)
