"""A tenant of one namespace cannot read another namespace's SimulationRuns, results credentials or
Secrets. The tenant is a ServiceAccount bound to the aggregated `edit` ClusterRole in its own namespace (the
chart adds SimulationRuns to `edit` and `view`), acting through impersonation."""

from __future__ import annotations

import time

import pytest
import yaml

from tests.e2e.conftest import RUNS_NS, SECRET, Cluster

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(600)]

TENANT_NS = "tenant-b"
TENANT = f"system:serviceaccount:{TENANT_NS}:builder"


@pytest.fixture(scope="module")
def tenant(cluster: Cluster) -> str:
    cluster.kubectl("create", "namespace", TENANT_NS)
    cluster.kubectl("-n", TENANT_NS, "create", "serviceaccount", "builder")
    cluster.kubectl(
        "-n",
        TENANT_NS,
        "create",
        "rolebinding",
        "builder-edit",
        "--clusterrole=edit",
        f"--serviceaccount={TENANT_NS}:builder",
    )
    return TENANT


def test_tenant_works_in_its_own_namespace(cluster: Cluster, tenant: str) -> None:
    assert (
        cluster.kubectl(
            "auth",
            "can-i",
            "create",
            "simulationruns.carlos.dev",
            "-n",
            TENANT_NS,
            as_user=tenant,
            check=False,
        ).stdout.strip()
        == "yes"
    )
    listed = cluster.kubectl("-n", TENANT_NS, "get", "simulationruns", as_user=tenant, check=False)
    assert listed.returncode == 0, listed.stderr


@pytest.mark.parametrize(
    "args",
    [
        ("get", "simulationruns"),
        ("get", "secret", SECRET),
        ("get", "secrets"),
        ("get", "configmaps"),
        ("get", "jobs"),
    ],
)
def test_tenant_cannot_read_another_namespace(cluster: Cluster, tenant: str, args: tuple[str, ...]) -> None:
    refused = cluster.kubectl("-n", RUNS_NS, *args, as_user=tenant, check=False)
    assert refused.returncode != 0
    assert "forbidden" in refused.stderr.lower(), refused.stderr


def test_tenant_runs_may_not_name_secrets(cluster: Cluster, tenant: str) -> None:
    """Runs of a namespace outside secretReferences.namespaces that name a Secret are refused by the
    operator (Accepted=False): the operator would otherwise read that namespace's Secret for them."""

    body = {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": "steal", "namespace": TENANT_NS},
        "spec": {
            "scenarios": [
                {"name": "cut-in", "openscenario": "file:///opt/carlos/examples/scenarios/cut-in.xosc"}
            ],
            "output": {"url": "s3://carlos-test/results", "credentialsSecretRef": {"name": SECRET}},
        },
    }
    created = cluster.kubectl(
        "-n", TENANT_NS, "apply", "-f", "-", stdin=yaml.safe_dump(body), as_user=tenant, check=False
    )
    assert created.returncode == 0, created.stderr

    deadline = time.monotonic() + 60
    accepted: dict[str, str] = {}
    while time.monotonic() < deadline:
        conditions = (cluster.run_object("steal", TENANT_NS).get("status") or {}).get("conditions", [])
        accepted = next((c for c in conditions if c["type"] == "Accepted"), {})
        if accepted:
            break
        time.sleep(1)
    assert accepted.get("status") == "False", accepted
    assert cluster.kubectl("-n", TENANT_NS, "get", "jobs", "-o", "name").stdout.strip() == ""
