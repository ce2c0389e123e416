"""The end-to-end tests on a real single-node cluster (`make e2e`).

The session starts the local cluster of tools/localcluster.py (etcd, the control plane, containerd, kubelet,
kube-proxy from the pinned binaries; the project's images imported into containerd), a SeaweedFS S3 server on
the cluster's bridge address (auth enforced; the pods and this process reach it there), and installs the Helm
chart with the local images: the operator runs as a real pod under the chart's ServiceAccount, so a missing
permission fails a test. Only the test process itself is cluster admin. Everything is stopped at the end.

Nothing here is skipped: a missing prerequisite (root, the binaries, the images) fails the session with
what to run (`make e2e` builds and imports everything first).
"""

from __future__ import annotations

import base64
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.s3server import S3Server, start_s3_server, stop_s3_server

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import localcluster  # noqa: E402

VENV_BIN = Path(sys.executable).parent
CARLOS = str(VENV_BIN / "carlos")
HELM = str(ROOT / ".tools/bin/helm")
IMAGE_PREFIX = os.environ.get("CARLOS_E2E_IMAGE_PREFIX", "carlos.local")
SYSTEM_NS = "carlos-system"
RUNS_NS = "carlos-e2e"
SECRET = "carlos-s3"
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"
TERMINAL = ("Succeeded", "Failed", "Error", "Unknown")


def project_version() -> str:
    for line in (ROOT / "pyproject.toml").read_text().splitlines():
        if line.startswith("version = "):
            return line.split('"')[1]
    raise RuntimeError("no version in pyproject.toml")


@dataclass
class Cluster:
    """The running cluster, the S3 server and helpers the tests share."""

    kubeconfig: Path
    layout: localcluster.Layout
    s3: S3Server
    tmp: Path

    def env(self, **extra: str) -> dict[str, str]:
        return {
            **{k: v for k, v in os.environ.items() if not k.startswith(("AWS_", "KUBECONFIG"))},
            "KUBECONFIG": str(self.kubeconfig),
            **self.s3.env(),
            "PATH": f"{VENV_BIN}:{os.environ.get('PATH', '')}",
            **extra,
        }

    def kubectl(
        self, *args: str, check: bool = True, stdin: str | None = None, as_user: str | None = None
    ) -> subprocess.CompletedProcess[str]:
        cmd = ["kubectl", *args] + ([f"--as={as_user}"] if as_user else [])
        proc = subprocess.run(cmd, input=stdin, capture_output=True, text=True, env=self.env(), timeout=300)
        if check and proc.returncode != 0:
            raise AssertionError(f"{' '.join(cmd)} exited {proc.returncode}: {proc.stderr.strip()}")
        return proc

    def kubectl_json(self, *args: str) -> Any:
        return json.loads(self.kubectl(*args, "-o", "json").stdout)

    def carlos(
        self, *args: str, cwd: Path | None = None, timeout: float = 900
    ) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [CARLOS, *args], capture_output=True, text=True, env=self.env(), cwd=cwd or ROOT, timeout=timeout
        )

    def run_object(self, name: str, namespace: str = RUNS_NS) -> dict[str, Any]:
        return dict(self.kubectl_json("-n", namespace, "get", "simulationrun", name))

    def wait_phase(
        self, name: str, namespace: str = RUNS_NS, phases: Sequence[str] = TERMINAL, timeout: float = 600
    ) -> dict[str, Any]:
        """The run once its phase is one of `phases` (fails with the last status after `timeout`)."""
        deadline = time.monotonic() + timeout
        status: dict[str, Any] = {}
        while time.monotonic() < deadline:
            status = self.run_object(name, namespace).get("status") or {}
            if status.get("phase") in phases:
                return status
            time.sleep(2)
        pods = self.kubectl("-n", namespace, "get", "pods", "-o", "wide", check=False).stdout
        raise AssertionError(
            f"run {namespace}/{name} not {'/'.join(phases)} after {timeout:.0f} s:\n"
            f"{yaml.safe_dump(status)}\npods:\n{pods}\noperator log:\n{self.operator_log()}"
        )

    def operator_log(self, lines: int = 60) -> str:
        return self.kubectl(
            "-n", SYSTEM_NS, "logs", "deployment/carlos", f"--tail={lines}", check=False
        ).stdout

    def store(self, prefix: str = "") -> Any:
        from simcore.store import open_store

        return open_store(f"s3://{self.s3.bucket}/{prefix}".rstrip("/"), endpoint=self.s3.endpoint)

    def apply(self, objects: str, namespace: str = RUNS_NS) -> None:
        self.kubectl("-n", namespace, "apply", "-f", "-", stdin=objects)

    def submit_yaml(self, manifest: Path, namespace: str = RUNS_NS, name: str | None = None) -> str:
        """`carlos submit --dry-run -o yaml` of a manifest: the objects `kubectl apply -f` takes (its local
        scenarios and roads packed into a ConfigMap), renamed to `name` when given."""
        proc = self.carlos("submit", str(manifest), "-n", namespace, "--dry-run", "-o", "yaml")
        assert proc.returncode == 0, proc.stderr
        if name is None:
            return proc.stdout
        docs = list(yaml.safe_load_all(proc.stdout))
        old = next(d for d in docs if d["kind"] == "SimulationRun")["metadata"]["name"]
        return yaml.safe_dump_all(docs).replace(old, name)

    def delete_run(self, name: str, namespace: str = RUNS_NS) -> None:
        self.kubectl("-n", namespace, "delete", "simulationrun", name, "--ignore-not-found", "--wait=false")


def _secret_yaml(namespace: str, s3: S3Server) -> str:
    def b64(text: str) -> str:
        return base64.b64encode(text.encode()).decode()

    return yaml.safe_dump(
        {
            "apiVersion": "v1",
            "kind": "Secret",
            "metadata": {"name": SECRET, "namespace": namespace},
            "data": {"AWS_ACCESS_KEY_ID": b64(s3.access_key), "AWS_SECRET_ACCESS_KEY": b64(s3.secret_key)},
        }
    )


def chart_values(s3: S3Server) -> dict[str, Any]:
    """The chart's values for the local cluster: the local images (never pulled), the S3 server as the
    default output, small requests so that a few run pods fit on two cores."""
    version = project_version()
    images = {
        role: {"repository": f"{IMAGE_PREFIX}/carlos-{role}", "tag": version, "pullPolicy": "Never"}
        for role in ("operator", "simcore", "bridge", "recorder", "detector")
    }
    return {
        "images": images,
        "objectStore": {
            "bucket": s3.bucket,
            "prefix": "results",
            "endpoint": s3.endpoint,
            "credentialsSecret": SECRET,
        },
        "secretReferences": {"namespaces": [RUNS_NS]},
        "jobTTLSeconds": 3600,
        "runPods": {
            "resources": {
                "requests": {"cpu": "200m", "memory": "256Mi", "ephemeral-storage": "100Mi"},
                "limits": {"memory": "3Gi", "ephemeral-storage": "4Gi"},
            },
            "sidecarResources": {
                "requests": {"cpu": "50m", "memory": "64Mi", "ephemeral-storage": "50Mi"},
                "limits": {"memory": "512Mi", "ephemeral-storage": "1Gi"},
            },
        },
    }


def _install_chart(cluster: Cluster) -> None:
    values = cluster.tmp / "values.yaml"
    values.write_text(yaml.safe_dump(chart_values(cluster.s3)))
    for namespace in (RUNS_NS,):
        cluster.kubectl("create", "namespace", namespace)
        cluster.apply(_secret_yaml(namespace, cluster.s3), namespace)
    cmd = [
        HELM,
        "install",
        "carlos",
        str(ROOT / "helm/carlos"),
        "--namespace",
        SYSTEM_NS,
        "--create-namespace",
    ]
    cmd += ["--values", str(values), "--wait", "--timeout", "180s"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=cluster.env(), timeout=300)
    if proc.returncode != 0:
        pods = cluster.kubectl("-n", SYSTEM_NS, "describe", "pods", check=False).stdout
        raise RuntimeError(f"helm install failed: {proc.stderr.strip()}\n{pods[-3000:]}")


@pytest.fixture(scope="session")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    if os.geteuid() != 0:
        pytest.fail("the e2e tests start a local cluster and need root (make e2e as root)", pytrace=False)
    if not Path(HELM).exists():
        pytest.fail("no helm at .tools/bin/helm: make helm", pytrace=False)
    tmp = tmp_path_factory.mktemp("e2e")
    layout = localcluster.default_layout()
    try:
        kubeconfig = localcluster.up(layout)
    except localcluster.ClusterError as e:
        pytest.fail(f"the local cluster did not start: {e}", pytrace=False)
    proc = None
    try:
        proc, s3 = start_s3_server(tmp / "s3", ip=localcluster.NODE_IP)
        env = Cluster(kubeconfig, layout, s3, tmp)
        _install_chart(env)
        yield env
    finally:
        if proc is not None:
            stop_s3_server(proc)
        localcluster.down(layout, quiet=True)
