"""The operator end to end against kmock's Kubernetes emulator: SimulationRun → ConfigMap + Indexed Job →
pods run by the test kubelet as local processes → results in the real S3 server → status."""

from __future__ import annotations

import base64
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from carlos_operator.builders import job_name
from carlos_operator.kube import Kube

from tests.kube_emulator import Cluster, JobRunner, cluster, operator_env, wait_for, write_kubeconfig
from tests.s3server import S3Server

pytestmark = [pytest.mark.s3, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = (ROOT / "examples/scenarios/braking.xosc").as_uri()
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"


def manifest(name: str, bucket: str, criteria: list[str], speeds: list[float], **spec: Any) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default"},
        "spec": {
            "scenarios": [{"name": "braking", "openscenario": SCENARIO}],
            "sweep": {"matrix": {"Speed": speeds}},
            "simulation": {"stepSeconds": 0.1, "maxSeconds": 3},
            "evaluation": {"criteria": criteria},
            "output": {"url": f"s3://{bucket}/operator", "credentialsSecretRef": {"name": "s3"}},
            "execution": {"parallelism": 2, "retries": 1, "runsPerPod": 1},
            **spec,
        },
    }


@pytest.fixture
def env(
    s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Iterator[tuple[Cluster, Kube]]:
    with cluster(tmp_path) as c:
        monkeypatch.setenv("KUBECONFIG", str(write_kubeconfig(tmp_path / "kubeconfig", c.url)))
        for key, value in operator_env(s3_server.endpoint).items():
            monkeypatch.setenv(key, value)
        for key in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_ENDPOINT_URL"):
            monkeypatch.delenv(key, raising=False)  # the operator must use the run's Secret
        kube = Kube()
        secret = {
            "apiVersion": "v1",
            "kind": "Secret",
            "metadata": {"name": "s3", "namespace": "default"},
            "data": {
                "AWS_ACCESS_KEY_ID": base64.b64encode(s3_server.access_key.encode()).decode(),
                "AWS_SECRET_ACCESS_KEY": base64.b64encode(s3_server.secret_key.encode()).decode(),
            },
        }
        kube.core.create_namespaced_secret("default", secret, _preload_content=False)
        try:
            yield c, kube
        finally:
            c.stop_operator()


def create(kube: Kube, body: dict[str, Any]) -> None:
    kube.custom.create_namespaced_custom_object(
        GROUP, VERSION, "default", PLURAL, body, _preload_content=False
    )


def status(kube: Kube, name: str) -> dict[str, Any]:
    raw = kube.custom.get_namespaced_custom_object(
        GROUP, VERSION, "default", PLURAL, name, _preload_content=False
    )
    return dict(json.loads(raw.data).get("status") or {})


def terminal(kube: Kube, name: str) -> dict[str, Any] | None:
    st = status(kube, name)
    return st if st.get("phase") in ("Succeeded", "Failed") else None


def results(s3: S3Server, monkeypatch: pytest.MonkeyPatch) -> Any:
    from simcore.store import open_store

    for key, value in s3.env().items():
        monkeypatch.setenv(key, value)
    return open_store(f"s3://{s3.bucket}/operator/default", endpoint=s3.endpoint, region=s3.region)


def runner(kube: Kube, s3: S3Server, tmp_path: Path, **kw: Any) -> JobRunner:
    # the pods run the code under test (a PYTHONPATH that points at a work tree reaches them too)
    python_path = {"PYTHONPATH": os.environ["PYTHONPATH"]} if os.environ.get("PYTHONPATH") else {}
    return JobRunner(
        kube=kube, workdir=tmp_path, extra_env={"AWS_REGION": s3.region, **python_path}, **kw
    ).start()


def test_run_succeeds_end_to_end(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    c, kube = env
    c.start_operator()
    jobs = runner(kube, s3_server, tmp_path)
    try:
        create(kube, manifest("e2e-pass", s3_server.bucket, ["simSeconds <= 100"], [10.0, 15.0, 20.0]))
        st = wait_for(lambda: terminal(kube, "e2e-pass"), 180, "a terminal phase")
    finally:
        jobs.stop()
    assert jobs.errors == []
    assert st["phase"] == "Succeeded", st
    assert (st["total"], st["succeeded"], st["failed"], st["passed"], st["testFailures"], st["errors"]) == (
        3,
        3,
        0,
        3,
        0,
        0,
    )
    assert st["progress"] == "3/3" and st["resultsURL"].endswith(
        "/operator/default/e2e-pass"
    )  # <url>/<namespace>/<run>
    conditions = {x["type"]: x for x in st["conditions"]}
    assert conditions["Accepted"]["status"] == "True" and conditions["Complete"]["status"] == "True"
    assert st.get("completionTime") and st.get("startTime")
    # one ConfigMap and one Indexed Job, owned by the run
    jobs_seen = [j for j in c.objects("jobs") if j["metadata"]["name"] == job_name("e2e-pass")]
    assert len(jobs_seen) == 1
    job = jobs_seen[0]
    assert job["spec"]["completionMode"] == "Indexed" and job["spec"]["completions"] == 3
    run_uid = kube.custom.get_namespaced_custom_object(GROUP, VERSION, "default", PLURAL, "e2e-pass")[
        "metadata"
    ]["uid"]
    assert job["metadata"]["ownerReferences"][0]["uid"] == run_uid
    assert [m["metadata"]["name"] for m in c.objects("configmaps")] == [job_name("e2e-pass")]
    store = results(s3_server, monkeypatch)
    keys = set(store.list("e2e-pass/"))
    for index in range(3):
        assert {f"e2e-pass/{index}/recording.mcap", f"e2e-pass/{index}/summary.json"} <= keys
    assert {"e2e-pass/run.yaml", "e2e-pass/summary.json", "e2e-pass/junit.xml"} <= keys
    summary = json.loads(store.get_bytes("e2e-pass/summary.json"))
    assert summary["counts"]["passed"] == 3 and summary["status"] == "passed"
    assert "<testcase" in store.get_bytes("e2e-pass/junit.xml").decode()
    # the report beside the summary, its links relative to it (the recordings of the run)
    page = store.get_bytes("e2e-pass/report.html").decode()
    assert "SimulationRun e2e-pass" in page and 'href="0/recording.mcap"' in page
    reasons = {e.get("reason") for e in c.objects("events")}
    assert {"JobCreated", "Succeeded"} <= reasons


def test_failing_index_and_crashing_container(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    c, kube = env
    c.start_operator()
    # Ego drives at the swept Speed: 'maxSpeed <= 16' fails index 2 (30 m/s) only, a test failure (exit 1).
    # Index 0's first simcore container is killed: an infrastructure failure, retried.
    jobs = runner(kube, s3_server, tmp_path, crash_first_attempt={0})
    try:
        create(kube, manifest("e2e-mixed", s3_server.bucket, ["maxSpeed <= 16"], [10.0, 15.0, 30.0]))
        st = wait_for(lambda: terminal(kube, "e2e-mixed"), 180, "a terminal phase")
    finally:
        jobs.stop()
    assert jobs.errors == []
    assert st["phase"] == "Failed", st
    assert (st["succeeded"], st["failed"], st["passed"], st["testFailures"], st["errors"]) == (2, 1, 2, 1, 0)
    assert [f["index"] for f in st["failures"]] == [2]
    assert "maxSpeed" in st["failures"][0]["reason"]
    assert {x["type"]: x for x in st["conditions"]}["Failed"]["reason"] == "TestFailures"
    uid = c.objects("jobs")[0]["metadata"]["uid"]
    assert jobs.attempts[(uid, 0)] == 2  # crashed once, retried
    assert jobs.attempts[(uid, 2)] == 1  # a test failure is never retried
    store = results(s3_server, monkeypatch)
    assert json.loads(store.get_bytes("e2e-mixed/0/summary.json"))["attempts"] == 2
    junit = store.get_bytes("e2e-mixed/junit.xml").decode()
    assert "<failure" in junit


def test_operator_restart_adopts_the_job(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    c, kube = env
    c.start_operator()
    create(kube, manifest("e2e-restart", s3_server.bucket, [], [10.0, 15.0]))
    wait_for(lambda: c.objects("jobs"), 30, "the Job")
    c.stop_operator()
    jobs = runner(kube, s3_server, tmp_path)
    try:
        wait_for(
            lambda: c.objects("jobs")[0].get("status", {}).get("completedIndexes"), 120, "a finished index"
        )
        assert status(kube, "e2e-restart").get("phase") != "Succeeded"  # the operator was down
        c.start_operator()
        st = wait_for(lambda: terminal(kube, "e2e-restart"), 180, "a terminal phase")
    finally:
        jobs.stop()
    assert st["phase"] == "Succeeded" and st["passed"] == 2, st
    assert len(c.objects("jobs")) == 1
    assert len(c.objects("configmaps")) == 1


def test_invalid_spec_is_not_accepted(env: tuple[Cluster, Kube], s3_server: S3Server) -> None:
    c, kube = env
    for namespace in ("default", "elsewhere"):
        kube.core.create_namespace({"metadata": {"name": namespace}}, _preload_content=False)
    c.start_operator(namespaces=["default"])  # namespace-scoped, as `carlos operator --namespace default`
    ignored = manifest("e2e-elsewhere", s3_server.bucket, [], [10.0])
    ignored["metadata"]["namespace"] = "elsewhere"
    kube.custom.create_namespaced_custom_object(
        GROUP, VERSION, "elsewhere", PLURAL, ignored, _preload_content=False
    )
    bad = manifest("e2e-bad", s3_server.bucket, [], [10.0])
    bad["spec"]["scenarios"][0]["openscenario"] = "relative/path.xosc"
    create(kube, bad)
    typo = manifest("e2e-typo", s3_server.bucket, [], [10.0])
    typo["spec"]["simulation"]["stepSecond"] = 0.1
    create(kube, typo)
    for name, words in (("e2e-bad", "spec.scenarios[0].openscenario"), ("e2e-typo", "stepSecond")):
        st = wait_for(lambda n=name: status(kube, n).get("conditions"), 30, f"{name}'s conditions")
        accepted = {x["type"]: x for x in st}["Accepted"]
        assert accepted["status"] == "False" and accepted["reason"] == "InvalidSpec"
        assert words in accepted["message"]
    assert c.objects("jobs") == [] and c.objects("configmaps") == []
    # the Warning event is posted after the status (kopf's event poster runs on its own): wait for it
    wait_for(
        lambda: any(
            e.get("reason") == "InvalidSpec" and e.get("type") == "Warning" for e in c.objects("events")
        ),
        30,
        "the InvalidSpec Warning event",
    )
    # the run in a namespace the operator does not serve is left alone
    raw = kube.custom.get_namespaced_custom_object(GROUP, VERSION, "elsewhere", PLURAL, "e2e-elsewhere")
    assert not raw.get("status")


def test_suspended_run_starts_when_resumed(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path
) -> None:
    c, kube = env
    c.start_operator()
    jobs = runner(kube, s3_server, tmp_path)
    try:
        create(kube, manifest("e2e-suspend", s3_server.bucket, [], [10.0], suspend=True))
        wait_for(lambda: status(kube, "e2e-suspend").get("phase") == "Suspended", 30, "phase Suspended")
        job = c.objects("jobs")[0]
        assert job["spec"]["suspend"] is True and not job.get("status", {}).get("completedIndexes")
        kube.custom.patch_namespaced_custom_object(
            GROUP, VERSION, "default", PLURAL, "e2e-suspend", {"spec": {"suspend": False}}
        )
        st = wait_for(lambda: terminal(kube, "e2e-suspend"), 120, "a terminal phase")
    finally:
        jobs.stop()
    assert st["phase"] == "Succeeded" and st["passed"] == 1
    assert c.objects("jobs")[0]["spec"]["suspend"] is False


def test_carlos_operator_command_serves_liveness_and_metrics(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path
) -> None:
    import subprocess
    import urllib.request

    from tests.kubelet import CARLOS, free_port

    _, kube = env
    liveness, metrics = free_port(), free_port()
    log = (tmp_path / "operator.log").open("wb")
    proc = subprocess.Popen(
        [
            CARLOS,
            "operator",
            "--all-namespaces",
            "--liveness-port",
            str(liveness),
            "--metrics-port",
            str(metrics),
        ],
        env=dict(os.environ),
        stdout=log,
        stderr=subprocess.STDOUT,
    )

    def get(port: int, path: str) -> str | None:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=2) as response:
                return response.read().decode()
        except OSError:
            return None

    try:
        wait_for(lambda: get(liveness, "/healthz"), 60, "the liveness endpoint")
        bad = manifest("cli-bad", s3_server.bucket, [], [10.0])
        bad["spec"]["output"]["url"] = "file:///results"
        create(kube, bad)
        st = wait_for(lambda: status(kube, "cli-bad").get("conditions"), 30, "conditions")
        assert st[0]["reason"] == "InvalidSpec" and "s3://" in st[0]["message"]
        text = wait_for(
            lambda: (
                (m := get(metrics, "/metrics")) and 'carlos_simulationruns{phase="Failed"} 1.0' in m and m
            ),
            30,
            "the run in the metrics",
        )
        assert "carlos_reconcile_seconds_count" in text
    finally:
        proc.terminate()
        proc.wait(30)
        log.close()


def test_api_server_errors_are_retried_to_the_same_end(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The API server throttles (429), fails (500/503) and expires watches (410) once on each kind of call the
    operator makes; the run still ends Succeeded with one ConfigMap and one Job."""
    c, kube = env
    assert c.emulator is not None
    ours = "carlos.dev/run"  # the operator's Job list and watch (the test kubelet lists every Job)
    faults = [
        ("WATCH", "simulationruns", "", 410, ""),
        ("LIST", "jobs", "", 429, ours),
        ("WATCH", "jobs", "", 410, ours),
        ("CREATE", "configmaps", "", 503, ""),
        ("CREATE", "jobs", "", 429, ""),
        ("UPDATE", "simulationruns", "status", 500, ""),
    ]
    c.emulator.faults.extend(faults)
    c.start_operator()
    jobs = runner(kube, s3_server, tmp_path)
    try:
        create(kube, manifest("e2e-faults", s3_server.bucket, [], [10.0, 15.0]))
        st = wait_for(lambda: terminal(kube, "e2e-faults"), 180, "a terminal phase")
    finally:
        jobs.stop()
    assert sorted(c.emulator.injected) == sorted(faults)  # every fault was met
    assert jobs.errors == []
    assert st["phase"] == "Succeeded" and st["passed"] == 2, st
    assert [j["metadata"]["name"] for j in c.objects("jobs")] == [job_name("e2e-faults")]
    assert len(c.objects("configmaps")) == 1
    store = results(s3_server, monkeypatch)
    assert json.loads(store.get_bytes("e2e-faults/summary.json"))["counts"]["passed"] == 2


def test_a_killed_shard_is_retried_without_rerunning_its_finished_runs(
    env: tuple[Cluster, Kube],
    s3_server: S3Server,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two pods of three runs each. Pod 0's simcore is killed mid-slice, once runs 0 and 1 wrote their
    summaries: the retried pod skips them and runs 2 only. The results equal those of the same run left
    alone (in another namespace): summaries but for the wall time and run 2's attempts, and the recordings
    byte for byte."""
    c, kube = env
    monkeypatch.setenv("CARLOS_SECRET_NAMESPACES", "default,calm")
    # over the loopback hub the recorder receives one publisher's messages in publish order; over DDS the
    # order among topics at the same instant varies from run to run (two undisturbed runs differ in it too)
    monkeypatch.setenv("CARLOS_POD_TRANSPORT", "loopback")
    secret = kube.core.read_namespaced_secret("s3", "default")
    kube.core.create_namespaced_secret(
        "calm",
        {
            "apiVersion": "v1",
            "kind": "Secret",
            "metadata": {"name": "s3", "namespace": "calm"},
            "data": secret.data,
        },
        _preload_content=False,
    )
    c.start_operator()
    store = results(s3_server, monkeypatch)
    from simcore.store import open_store

    calm = open_store(
        f"s3://{s3_server.bucket}/operator/calm", endpoint=s3_server.endpoint, region=s3_server.region
    )
    body = manifest("shard", s3_server.bucket, ["simSeconds <= 100"], [10.0, 12.0, 14.0, 16.0, 18.0, 20.0])
    body["spec"]["execution"]["runsPerPod"] = 3
    # runs of 300 steps (~0.1 s): run 2 is still under way when the kill below sees run 1's summary (a warm
    # pod's 30-step run could end within one look of it)
    body["spec"]["simulation"]["stepSeconds"] = 0.01
    killed: list[bool] = []

    def mid_slice() -> bool:  # once (the undisturbed run's pod 0 is left alone)
        if not killed and store.exists("shard/1/summary.json"):
            killed.append(True)
            return True
        return False

    jobs = runner(kube, s3_server, tmp_path, crash_first_attempt_when={0: mid_slice})
    try:
        create(kube, body)
        st = wait_for(lambda: terminal(kube, "shard"), 240, "a terminal phase")
        quiet = json.loads(json.dumps(body))
        quiet["metadata"]["namespace"] = "calm"
        kube.custom.create_namespaced_custom_object(
            GROUP, VERSION, "calm", PLURAL, quiet, _preload_content=False
        )

        def calm_terminal() -> dict[str, Any] | None:
            raw = kube.custom.get_namespaced_custom_object(
                GROUP, VERSION, "calm", PLURAL, "shard", _preload_content=False
            )
            got = dict(json.loads(raw.data).get("status") or {})
            return got if got.get("phase") in ("Succeeded", "Failed") else None

        calm_st = wait_for(calm_terminal, 240, "the undisturbed run's terminal phase")
    finally:
        jobs.stop()
    assert jobs.errors == []
    assert st["phase"] == calm_st["phase"] == "Succeeded", (st, calm_st)
    assert (st["total"], st["passed"], st["progress"]) == (6, 6, "6/6")
    job = next(j for j in c.objects("jobs") if j["metadata"]["namespace"] == "default")
    assert job["spec"]["completions"] == 2
    uid = job["metadata"]["uid"]
    assert jobs.attempts[(uid, 0)] == 2 and jobs.attempts[(uid, 1)] == 1  # pod 0 killed once, retried
    for index in range(6):
        disturbed = json.loads(store.get_bytes(f"shard/{index}/summary.json"))
        undisturbed = json.loads(calm.get_bytes(f"shard/{index}/summary.json"))
        # run 2 was the one in progress when pod 0 was killed: its second attempt
        assert (disturbed.pop("attempts"), undisturbed.pop("attempts")) == (2 if index == 2 else 1, 1)
        for summary in (disturbed, undisturbed):
            summary.pop("wallSeconds")
        assert disturbed == undisturbed
        assert store.get_bytes(f"shard/{index}/recording.mcap") == calm.get_bytes(
            f"shard/{index}/recording.mcap"
        )
    # runs 0 and 1 ran once (the first pod), run 2 again in the retried pod: its log says so
    assert "pod attempt 1" in store.get_bytes("shard/0/log.txt").decode()
    assert "pod attempt 1" in store.get_bytes("shard/1/log.txt").decode()
    assert "pod attempt 2" in store.get_bytes("shard/2/log.txt").decode()


def test_login_in_a_pod_uses_the_service_address_not_cluster_dns(monkeypatch: pytest.MonkeyPatch) -> None:
    """A real cluster without DNS: kopf's service-account login names https://kubernetes.default.svc, which
    does not resolve; the operator takes KUBERNETES_SERVICE_HOST/PORT as client-go does."""
    import kopf
    from carlos_operator import handlers

    monkeypatch.setattr(
        kopf,
        "login_with_service_account",
        lambda **_: kopf.ConnectionInfo(
            server="https://kubernetes.default.svc", token="t", default_namespace="ns"
        ),
    )
    monkeypatch.setenv("KUBERNETES_SERVICE_HOST", "10.96.0.1")
    monkeypatch.setenv("KUBERNETES_SERVICE_PORT", "443")
    info = handlers.login()
    assert info is not None and info.server == "https://10.96.0.1:443" and info.token == "t"
    monkeypatch.setenv("KUBERNETES_SERVICE_HOST", "fd00::1")
    assert handlers.login().server == "https://[fd00::1]:443"  # type: ignore[union-attr]
