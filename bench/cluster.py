"""Compute per run: the local path against the pod path (issue 26), and the operator's memory at 52,500 runs.

For each sweep (200 runs of examples/scenarios/cut-in.xosc; 20 runs of it with a 64-channel lidar on Ego),
recording off, results in a file:// folder:

- local: `carlos run --parallel 2 --quiet` as a fresh process.
- pod path: the Indexed Job the operator builds for the same SimulationRun (carlos_operator.builders:
  the default slices of `simcore.shards`, the default DDS transport), its pods executed as local processes
  by the project's kubelet harness (tests/kubelet.py: native sidecars bridge and recorder, then simcore),
  two pods at a time.

The figure is CPU seconds (user + system) of every process of each side, from the kernel's accounting of
waited-for children (getrusage RUSAGE_CHILDREN deltas: `carlos run` and its workers; the pods' containers).
Not wall time: the machine is shared with other jobs, so wall time says little; CPU seconds do not depend
on the load. The kubelet harness itself (this process' threads) is not counted: it stands for the cluster.

Then the operator's memory: a subprocess runs the controller (in-memory API and store of
tests/test_operator_controller.py) through a 52,500-run sweep with the default slices, the Job reporting
finished pods in 10 steps, to its final status and finalisation (run summary, JUnit); its peak resident set
is reported (the store makes each summary when it is read, as S3 would serve it: none is held beforehand).

Prints a table; the last line is one JSON object (`podPathCpuPerRunOverLocal`: short runs; `lidar...`).
`BENCH_RUNS` / `BENCH_LIDAR_RUNS` scale the sweeps down. Usage: .venv/bin/python bench/cluster.py
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CARLOS = str(Path(sys.executable).with_name("carlos"))
SCENARIO = ROOT / "examples/scenarios/cut-in.xosc"
LIDAR = {
    "type": "lidar",
    "name": "lidar",
    "entity": "Ego",
    "mount": {"x": 1.4, "z": 2.0},
    "channels": 64,
    "verticalFov": [-25, 10],
    "horizontalResolution": 1024,
    "rotationRate": 10,
    "rangeMax": 120,
}


def body(name: str, runs: int, output: str, sensors: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    spec: dict[str, Any] = {
        "scenarios": [{"name": "cut-in", "openscenario": SCENARIO.as_uri()}],
        "sweep": {"repetitions": runs},
        "recording": {"enabled": False},
        "output": {"url": output},
        "execution": {"parallelism": 2},
    }
    if sensors:
        spec["sensors"] = sensors
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default", "uid": f"uid-{name}"},
        "spec": spec,
    }


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def local(manifest: dict[str, Any], workdir: Path) -> tuple[float, float, int]:
    import yaml

    path = workdir / f"{manifest['metadata']['name']}-local.yaml"
    path.write_text(yaml.safe_dump(manifest))
    out = (workdir / "local").as_uri()
    before, started = children_cpu(), time.monotonic()
    proc = subprocess.run(
        [CARLOS, "run", str(path), "--parallel", "2", "--quiet", "--output", out],
        capture_output=True,
        text=True,
    )
    cpu, wall = children_cpu() - before, time.monotonic() - started
    if proc.returncode not in (0, 1):
        raise SystemExit(f"carlos run failed ({proc.returncode}): {proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return cpu, wall, 1


def pod_path(manifest: dict[str, Any], workdir: Path) -> tuple[float, float, int]:
    from carlos_operator.builders import OperatorSettings, Output, build_configmap, build_job

    from simcore.manifest import parse_manifest
    from tests.kubelet import Kubelet

    out = (workdir / "pods").as_uri()
    manifest = json.loads(json.dumps(manifest))
    manifest["spec"]["output"] = {"url": "s3://unused/bench"}  # a cluster spec; the pods get `out` below
    run = parse_manifest(json.loads(json.dumps(manifest)), source="bench")
    settings = OperatorSettings.from_env({})
    cm = build_configmap(run, manifest, settings)
    job = build_job(run, manifest, settings, Output(url=out, endpoint=None, region=None, secret=None))
    pod = job["spec"]["template"]["spec"]
    pods = int(job["spec"]["completions"])
    kubelet = Kubelet(configmaps={cm["metadata"]["name"]: cm["data"]}, secrets={}, workdir=workdir)
    codes: list[int] = []

    def one(index: int) -> None:
        result = kubelet.run_pod(pod, index=index)
        codes.append(result.exit_codes["simcore"])
        if result.exit_codes["simcore"] not in (0, 1):
            print(result.logs, file=sys.stderr)

    before, started = children_cpu(), time.monotonic()
    with ThreadPoolExecutor(max_workers=2) as pool:
        list(pool.map(one, range(pods)))
    cpu, wall = children_cpu() - before, time.monotonic() - started
    if any(code not in (0, 1) for code in codes):
        raise SystemExit(f"pods failed: exit codes {codes}")
    return cpu, wall, pods


def operator_memory(runs: int = 52_500) -> dict[str, float]:
    """Peak RSS (MB) of a subprocess that runs the controller through a `runs`-run sweep to finalisation."""
    code = f"""
import json, resource, sys
sys.path.insert(0, {str(ROOT)!r})
from carlos_operator.builders import OperatorSettings, job_name
from carlos_operator.controller import Controller
from simcore import shards
from tests.test_operator_controller import FakeKube, FakeStore, run_body, summary
runs = {runs}
class Summaries(FakeStore):
    # the pods summaries, made when read (as an object store serves them): none held in this process
    finished = 0
    def _index(self, key):
        parts = key.split("/")
        if len(parts) == 3 and parts[0] == "r" and parts[2] == "summary.json" and parts[1].isdigit():
            return int(parts[1])
        return None
    def exists(self, key):
        i = self._index(key)
        return i < self.finished if i is not None else super().exists(key)
    def get_bytes(self, key):
        i = self._index(key)
        if i is not None and i < self.finished and key not in self.objects:
            self.gets += 1
            return summary(i)
        return super().get_bytes(key)
kube, store = FakeKube(), Summaries()
settings = OperatorSettings.from_env({{"CARLOS_SECRET_NAMESPACES": "default"}})
c = Controller(kube, settings, batch=500, store_factory=lambda k, ns, out: store)
def drain():
    while c._queue:
        key = c._queue.pop(0); c._queued.discard(key); c.reconcile(key)
body = run_body("r", "uid-1", runs)
del body["spec"]["execution"]
c.observe_run("ADDED", body)
drain()
job = kube.jobs[job_name("r")]
pods = job["spec"]["completions"]
per_pod = int(job["metadata"]["annotations"]["carlos.dev/runs-per-pod"])
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
for step in range(1, 11):
    done = pods * step // 10
    store.finished = min(done * per_pod, runs)
    job["status"] = {{"completedIndexes": f"0-{{done - 1}}", "startTime": "2026-01-01T00:00:00Z"}}
    if step == 10:
        job["status"]["conditions"] = [{{"type": "Complete", "status": "True"}}]
    c.observe_job("MODIFIED", job)
    drain()
final = kube.status_patches[-1]
assert final["phase"] == "Succeeded" and final["passed"] == runs, final
assert "r/summary.json" in store.objects
print(json.dumps({{"pods": pods, "runsPerPod": per_pod, "baseMB": base,
                  "peakMB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}}))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"operator memory bench failed: {proc.stderr[-3000:]}")
    return dict(json.loads(proc.stdout.strip().splitlines()[-1]))


def main() -> None:
    runs = int(os.environ.get("BENCH_RUNS", "200"))
    lidar_runs = int(os.environ.get("BENCH_LIDAR_RUNS", "20"))
    rows: list[tuple[str, str, float, float, int, int]] = []
    ratios: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench-cluster-") as tmp:
        workdir = Path(tmp)
        for label, n, sensors in (("cut-in", runs, None), ("cut-in + lidar", lidar_runs, [LIDAR])):
            name = "short" if sensors is None else "lidar"
            manifest = body(name, n, (workdir / "unused").as_uri(), sensors)
            cpu_local, wall_local, _ = local(manifest, workdir)
            cpu_pods, wall_pods, pods = pod_path(manifest, workdir)
            rows.append((label, "carlos run --parallel 2", cpu_local, wall_local, n, 1))
            rows.append((label, "pod path (2 pods at a time)", cpu_pods, wall_pods, n, pods))
            ratios[name] = (cpu_pods / n) / (cpu_local / n)
    memory = operator_memory()
    print(f"{'sweep':<16} {'path':<28} {'runs':>5} {'pods':>5} {'CPU s':>8} {'CPU s/run':>10} {'wall s':>8}")
    for label, path, cpu, wall, n, pods in rows:
        print(f"{label:<16} {path:<28} {n:>5} {pods:>5} {cpu:>8.2f} {cpu / n:>10.4f} {wall:>8.1f}")
    print(f"pod path CPU per run over local: short runs {ratios['short']:.2f}, lidar {ratios['lidar']:.2f}")
    print(
        f"operator, 52,500-run sweep: {memory['pods']} pods of {memory['runsPerPod']} runs; peak RSS "
        f"{memory['peakMB']:.0f} MB (after accepting the run: {memory['baseMB']:.0f} MB)"
    )
    print("(CPU seconds, not wall: the machine is shared with other jobs; wall time is shown for reference)")
    print(
        json.dumps(
            {
                "podPathCpuPerRunOverLocal": round(ratios["short"], 3),
                "lidarPodPathCpuPerRunOverLocal": round(ratios["lidar"], 3),
                "shortRuns": runs,
                "lidarRuns": lidar_runs,
                "operatorPeakRssMB52500": round(memory["peakMB"], 1),
                "podsFor52500": memory["pods"],
            }
        )
    )


if __name__ == "__main__":
    main()
