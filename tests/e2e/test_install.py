"""The node, the chart and the operator pod on the real cluster."""

from __future__ import annotations

import pytest

from tests.e2e.conftest import RUNS_NS, SYSTEM_NS, Cluster, localcluster

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]

OPERATOR_SA = f"system:serviceaccount:{SYSTEM_NS}:carlos"


def test_node_is_ready_and_runs_containerd(cluster: Cluster) -> None:
    node = cluster.kubectl_json("get", "node", localcluster.NODE_NAME)
    ready = {c["type"]: c["status"] for c in node["status"]["conditions"]}
    assert ready["Ready"] == "True"
    info = node["status"]["nodeInfo"]
    assert info["containerRuntimeVersion"].startswith("containerd://")
    assert info["kubeletVersion"].startswith("v1.34.")
    addresses = {a["type"]: a["address"] for a in node["status"]["addresses"]}
    assert addresses["InternalIP"] == localcluster.NODE_IP


def test_operator_is_a_pod_under_the_charts_service_account(cluster: Cluster) -> None:
    pods = cluster.kubectl_json("-n", SYSTEM_NS, "get", "pods", "-l", "app.kubernetes.io/name=carlos")[
        "items"
    ]
    assert len(pods) == 1
    pod = pods[0]
    assert pod["status"]["phase"] == "Running"
    assert pod["spec"]["serviceAccountName"] == "carlos"
    container = pod["spec"]["containers"][0]
    security = container["securityContext"]
    assert security["readOnlyRootFilesystem"] is True
    assert security["allowPrivilegeEscalation"] is False
    assert security["capabilities"]["drop"] == ["ALL"]
    assert pod["spec"]["securityContext"]["runAsNonRoot"] is True
    status = pod["status"]["containerStatuses"][0]
    assert status["ready"] is True
    assert status["imageID"]  # a real image, run by containerd


@pytest.mark.parametrize(
    ("verb", "resource", "namespace", "allowed"),
    [
        ("create", "jobs.batch", RUNS_NS, True),
        ("patch", "simulationruns.carlos.dev/status", RUNS_NS, True),
        ("create", "configmaps", RUNS_NS, True),
        ("get", "secrets", RUNS_NS, True),  # secretReferences.namespaces names it
        ("get", "secrets", "default", False),
        ("delete", "nodes", "", False),
        ("create", "pods", RUNS_NS, False),  # pods are the Job controller's
        ("create", "clusterrolebindings", "", False),
    ],
)
def test_operator_rbac_is_least_privilege(
    cluster: Cluster, verb: str, resource: str, namespace: str, allowed: bool
) -> None:
    args = ["auth", "can-i", verb, resource, f"--as={OPERATOR_SA}"]
    args += ["-n", namespace] if namespace else []
    answer = cluster.kubectl(*args, check=False).stdout.strip()
    assert answer == ("yes" if allowed else "no"), (
        f"can-i {verb} {resource} in {namespace or 'cluster'}: {answer}"
    )
