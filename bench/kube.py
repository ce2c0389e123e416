"""The operator at scale on a real control plane: tools/localcluster.py's etcd, kube-apiserver,
kube-controller-manager and kube-scheduler, with kwok fake nodes beside the real one.

- The operator runs as `carlos operator --all-namespaces`, a separate process under the chart's
  ServiceAccount and RBAC (a token kubeconfig), its output defaulting to a SeaweedFS bucket on loopback.
- kwok (tools/k8s/build) manages `BENCH_KWOK_NODES` fake nodes (annotation `kwok.x-k8s.io/node=fake`) with its
  fast pod stages: a Job's pod is Running, then Succeeded, without a container. The real node is cordoned, so
  every run pod lands on a fake node. Fake pods write no results: their indexes end `missing` and the runs
  end Failed, which is a terminal phase like any other for this bench.
- `BENCH_KUBE_RUNS` (200) SimulationRuns are created at once (8 client threads) plus one sweep of
  `BENCH_KUBE_SWEEP` (52,500) runs. Measured:
  - SimulationRun created → its Job created (p50, p99), both as the API server's audit log stamps them
    (microseconds, one clock). `applyToJobSeenSecondsP99` is the same from this process (created by the
    client → seen by a watch), which adds this process' lag;
  - the operator's CPU seconds and peak RSS (/proc);
  - its own API writes per SimulationRun, from the audit log (create/update/patch/delete by its
    ServiceAccount);
  - the sweep's pods (listed at the end), and whether every run reached a terminal phase.

Goals (issue 36): p99 ≤ 5 s, ≤ 400 MB, ≤ 30 writes per SimulationRun, sweepPods ≤ 1,050, all terminal.
Prints a table; the last line is one JSON object. Needs root, the binaries (`make k8s`) and the dev
virtualenv; no images (nothing runs in a container). The cluster is stopped at the end.
"""

from __future__ import annotations

import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

import localcluster  # noqa: E402

from tests.s3server import start_s3_server, stop_s3_server  # noqa: E402

RUNS = int(os.environ.get("BENCH_KUBE_RUNS", "200"))
SWEEP = int(os.environ.get("BENCH_KUBE_SWEEP", "52500"))
KWOK_NODES = int(os.environ.get("BENCH_KWOK_NODES", "20"))
TIMEOUT_S = float(os.environ.get("BENCH_KUBE_TIMEOUT", "1800"))
NS = "bench"
OPERATOR_NS = "carlos-system"
OPERATOR_USER = f"system:serviceaccount:{OPERATOR_NS}:carlos"
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"
TERMINAL = {"Succeeded", "Failed", "Unknown"}
WRITE_VERBS = {"create", "update", "patch", "delete", "deletecollection"}
KUBECTL = str(Path(sys.executable).with_name("kubectl"))
HELM = str(ROOT / ".tools/bin/helm")


def kubectl(kubeconfig: Path, *args: str, stdin: str | None = None) -> str:
    return subprocess.run(
        [KUBECTL, f"--kubeconfig={kubeconfig}", *args],
        input=stdin,
        capture_output=True,
        text=True,
        check=True,
    ).stdout


def fake_node(i: int) -> dict[str, Any]:
    return {
        "apiVersion": "v1",
        "kind": "Node",
        "metadata": {
            "name": f"kwok-node-{i}",
            "annotations": {"kwok.x-k8s.io/node": "fake", "node.alpha.kubernetes.io/ttl": "0"},
            "labels": {
                "type": "kwok",
                "kubernetes.io/hostname": f"kwok-node-{i}",
                "kubernetes.io/os": "linux",
            },
        },
        "status": {
            "allocatable": {"cpu": "64", "memory": "256Gi", "pods": "1000", "ephemeral-storage": "1Ti"},
            "capacity": {"cpu": "64", "memory": "256Gi", "pods": "1000", "ephemeral-storage": "1Ti"},
        },
    }


def operator_kubeconfig(admin: Path, tmp: Path) -> Path:
    """A kubeconfig with a token of the chart's ServiceAccount (RBAC from `helm template`)."""
    rendered = subprocess.run(
        [
            HELM,
            "template",
            "carlos",
            str(ROOT / "helm/carlos"),
            "--namespace",
            OPERATOR_NS,
            "--show-only",
            "templates/serviceaccount.yaml",
            "--show-only",
            "templates/rbac.yaml",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    kubectl(admin, "create", "namespace", OPERATOR_NS)
    kubectl(admin, "-n", OPERATOR_NS, "apply", "-f", "-", stdin=rendered)
    token = kubectl(admin, "-n", OPERATOR_NS, "create", "token", "carlos", "--duration=4h").strip()
    config = json.loads(admin.read_text())
    config["users"] = [{"name": "operator", "user": {"token": token}}]
    config["contexts"][0]["context"]["user"] = "operator"
    path = tmp / "operator.kubeconfig"
    path.write_text(json.dumps(config))
    return path


def run_body(name: str, runs: int) -> dict[str, Any]:
    # a matrix of `runs` permutations: A × B with A·B = runs
    a = next(d for d in range(int(runs**0.5), 0, -1) if runs % d == 0)
    return {
        "apiVersion": f"{GROUP}/{VERSION}",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": NS},
        "spec": {
            "scenarios": [
                {"name": "cut-in", "openscenario": "file:///opt/carlos/examples/scenarios/cut-in.xosc"}
            ],
            "sweep": {
                "matrix": {
                    "EgoSpeed": [20.0 + i * 0.01 for i in range(a)],
                    "CutInGap": [8.0 + i * 0.01 for i in range(runs // a)],
                }
            },
        },
    }


def _run_label(obj: dict[str, Any]) -> str | None:
    """The run an object (as JSON: the watches do not build the client's models, which would take this
    process' CPU from the control plane it measures) belongs to."""
    return ((obj.get("metadata") or {}).get("labels") or {}).get("carlos.dev/run")


class Watch(threading.Thread):
    """Records when each run's Job is first seen (a watch, as the operator's own: a cross-check of the audit
    log's figure, with this process' lag in it)."""

    def __init__(self, kubeconfig: Path) -> None:
        super().__init__(daemon=True)
        self.kubeconfig = kubeconfig
        self.jobs: dict[str, float] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        from kubernetes import client, config, watch

        batch = client.BatchV1Api(config.new_client_from_config(str(self.kubeconfig)))
        while not self.stop.is_set():
            try:
                for event in watch.Watch().stream(
                    batch.list_namespaced_job, NS, timeout_seconds=30, deserialize=False
                ):
                    run = _run_label(event["object"])
                    if run and run not in self.jobs:
                        self.jobs[run] = time.time()
            except Exception:  # a dropped watch (the API server closes them): watch again
                time.sleep(0.2)


def proc_cpu_rss(pid: int) -> tuple[float, float]:
    """CPU seconds (user + system, of the process and its waited-for children) and peak RSS in MB."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    cpu = sum(int(f) for f in fields[11:15]) / ticks
    hwm = next(
        line for line in Path(f"/proc/{pid}/status").read_text().splitlines() if line.startswith("VmHWM")
    )
    return cpu, int(hwm.split()[1]) / 1024


def audit_events(log: Path) -> Iterator[dict[str, Any]]:
    """The API server's audit events of completed requests (the log and its rotated files)."""
    for path in sorted(log.parent.glob(log.name + "*")):
        for line in path.read_text(errors="replace").splitlines():
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if event.get("stage") == "ResponseComplete":
                yield event


def audit_writes(events: list[dict[str, Any]]) -> int:
    return sum(
        1
        for e in events
        if e.get("user", {}).get("username") == OPERATOR_USER and e.get("verb") in WRITE_VERBS
    )


def _stamp(text: str) -> float:
    return datetime.datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def apply_to_job(events: list[dict[str, Any]]) -> dict[str, float]:
    """Seconds from each SimulationRun's create to its Job's create (the operator's), both as the API server
    answered them (the audit log's stageTimestamp, in microseconds: one clock, no watch in between)."""
    runs: dict[str, float] = {}
    jobs: dict[str, float] = {}
    for e in events:
        ref = e.get("objectRef") or {}
        if e.get("verb") != "create" or ref.get("namespace") != NS or int(e["responseStatus"]["code"]) >= 300:
            continue
        if ref.get("resource") == PLURAL:
            runs[ref["name"]] = _stamp(e["stageTimestamp"])
        elif ref.get("resource") == "jobs" and e.get("user", {}).get("username") == OPERATOR_USER:
            jobs[ref["name"]] = _stamp(e["stageTimestamp"])
    return {name: jobs[f"carlos-{name}"] - t for name, t in runs.items() if f"carlos-{name}" in jobs}


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q * (len(ordered) - 1))))]


def main() -> None:
    layout = localcluster.default_layout()
    tmp = Path(tempfile.mkdtemp(prefix="bench-kube-"))
    admin = localcluster.up(layout, images=False)
    s3_proc = operator = kwok = None
    try:
        bins = localcluster.binaries(build=False)
        version = json.loads(kubectl(admin, "version", "-o", "json"))["serverVersion"]["gitVersion"]
        kubectl(admin, "cordon", localcluster.NODE_NAME)
        kwok = subprocess.Popen(
            [
                str(bins["kwok"]),
                f"--kubeconfig={admin}",
                "--manage-all-nodes=false",
                "--manage-nodes-with-annotation-selector=kwok.x-k8s.io/node=fake",
                "--cidr=10.90.0.1/16",
                "--node-lease-duration-seconds=40",
            ],
            stdout=(tmp / "kwok.log").open("wb"),
            stderr=subprocess.STDOUT,
        )
        nodes = "\n---\n".join(json.dumps(fake_node(i)) for i in range(KWOK_NODES))
        kubectl(admin, "apply", "-f", "-", stdin=nodes)
        crd = subprocess.run(
            [str(Path(sys.executable).with_name("carlos")), "crds"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        kubectl(admin, "apply", "-f", "-", stdin=crd)
        for _ in range(120):  # the CRD is served once Established
            served = json.loads(kubectl(admin, "get", f"crd/{PLURAL}.{GROUP}", "-o", "json"))
            conditions = (served.get("status") or {}).get("conditions") or []  # null until the first update
            if any(c["type"] == "Established" and c["status"] == "True" for c in conditions):
                break
            time.sleep(0.5)
        kubectl(admin, "create", "namespace", NS)
        kubectl(admin, "wait", "--for=condition=Ready", "node", "-l", "type=kwok", "--timeout=120s")
        s3_proc, s3 = start_s3_server(tmp / "s3")
        op_config = operator_kubeconfig(admin, tmp)
        env = {
            **{k: v for k, v in os.environ.items() if not k.startswith(("AWS_", "KUBECONFIG"))},
            **s3.env(),
            "KUBECONFIG": str(op_config),
            "CARLOS_DEFAULT_OUTPUT_URL": f"s3://{s3.bucket}/results",
            "CARLOS_DEFAULT_S3_ENDPOINT": s3.endpoint,
        }
        operator = subprocess.Popen(
            [
                str(Path(sys.executable).with_name("carlos")),
                "operator",
                "--all-namespaces",
                "--liveness-port",
                "0",
                "--metrics-port",
                "0",
            ],
            env=env,
            stdout=(tmp / "operator.log").open("wb"),
            stderr=subprocess.STDOUT,
        )
        time.sleep(5)
        watcher = Watch(admin)
        watcher.start()
        time.sleep(2)
        from kubernetes import client, config

        api = client.CustomObjectsApi(config.new_client_from_config(str(admin)))
        created: dict[str, float] = {}

        def create(name: str, runs: int) -> None:
            started = time.time()
            api.create_namespaced_custom_object(GROUP, VERSION, NS, PLURAL, run_body(name, runs))
            created[name] = started

        names = [f"run-{i:04d}" for i in range(RUNS)]
        with ThreadPoolExecutor(8) as pool:
            list(pool.map(lambda n: create(n, 2), names))
        create("sweep", SWEEP)
        deadline = time.monotonic() + TIMEOUT_S
        phases: dict[str, str] = {}
        peak_rss = 0.0
        while time.monotonic() < deadline:
            peak_rss = max(peak_rss, proc_cpu_rss(operator.pid)[1])
            listed = api.list_namespaced_custom_object(GROUP, VERSION, NS, PLURAL)["items"]
            phases = {o["metadata"]["name"]: (o.get("status") or {}).get("phase", "") for o in listed}
            if len(phases) == RUNS + 1 and all(p in TERMINAL for p in phases.values()):
                break
            if operator.poll() is not None:
                raise RuntimeError(
                    f"the operator exited {operator.returncode}: {(tmp / 'operator.log').read_text()[-3000:]}"
                )
            time.sleep(5)
        cpu, peak = proc_cpu_rss(operator.pid)
        peak_rss = max(peak_rss, peak)
        watcher.stop.set()
        seen = [watcher.jobs[n] - created[n] for n in created if n in watcher.jobs]
        time.sleep(2)  # the audit log's last batch
        # the sweep's pods, listed once at the end (they stay: Succeeded pods are not collected this soon)
        sweep_pods = len(
            kubectl(admin, "-n", NS, "get", "pods", "-l", "carlos.dev/run=sweep", "-o", "name").split()
        )
        events = list(audit_events(layout.audit_log))
        writes = audit_writes(events)
        latencies = list(apply_to_job(events).values())
        result = {
            "serverVersion": version,
            "simulationRuns": RUNS + 1,
            "allTerminal": len(phases) == RUNS + 1 and all(p in TERMINAL for p in phases.values()),
            "phases": {p: list(phases.values()).count(p) for p in sorted(set(phases.values()))},
            "jobsCreated": len(latencies),
            "applyToJobSecondsP50": round(statistics.median(latencies), 3) if latencies else None,
            "applyToJobSecondsP99": round(percentile(latencies, 0.99), 3) if latencies else None,
            "jobsSeen": len(seen),
            "applyToJobSeenSecondsP99": round(percentile(seen, 0.99), 3) if seen else None,
            "operatorCpuSeconds": round(cpu, 1),
            "operatorPeakRssMB": round(peak_rss, 1),
            "apiWritesPerSimulationRun": round(writes / (RUNS + 1), 2),
            "sweepRuns": SWEEP,
            "sweepPods": sweep_pods,
            "kwokNodes": KWOK_NODES,
        }
        goals = [
            (
                "applyToJobSecondsP99",
                "≤ 5 s",
                result["applyToJobSecondsP99"] is not None and result["applyToJobSecondsP99"] <= 5,
            ),
            ("operatorPeakRssMB", "≤ 400 MB", peak_rss <= 400),
            ("apiWritesPerSimulationRun", "≤ 30", result["apiWritesPerSimulationRun"] <= 30),
            ("sweepPods", "≤ 1,050", 0 < result["sweepPods"] <= 1050),
            ("allTerminal", "true", result["allTerminal"]),
        ]
        print(f"{'figure':<28} {'value':>14}  goal")
        for key, value in result.items():
            goal = next((f"{g} {'met' if ok else 'NOT met'}" for k, g, ok in goals if k == key), "")
            print(f"{key:<28} {value!s:>14}  {goal}")
        print(json.dumps(result))
    finally:
        for proc in (operator, kwok):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                proc.wait(30)
        if s3_proc is not None:
            stop_s3_server(s3_proc)
        if not os.environ.get("BENCH_KUBE_KEEP"):  # debugging: leave the cluster running
            localcluster.down(layout, quiet=True)


if __name__ == "__main__":
    main()
