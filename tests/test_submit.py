"""`carlos submit`: every example manifest becomes objects the operator accepts, and one submitted example
runs to Succeeded in kmock's emulator with the test kubelet, results in the real S3 server."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml
from carlos_operator.builders import (
    OperatorSettings,
    SearchRound,
    build_configmap,
    build_job,
    check_cluster_spec,
    resolve_output,
)
from carlos_operator.kube import Kube

from simcore.spec import SimulationRun
from simcore.store import open_store
from simcore.workflow.submit import inputs_name
from tests.kube_emulator import Cluster, JobRunner, wait_for
from tests.s3server import S3Server
from tests.test_cli import ROOT, RUNS, carlos
from tests.test_operator import env, terminal  # noqa: F401 - env: the emulator fixture, reused

#: every example (a search runs on the cluster in rounds: one Job per round)
EXAMPLES = sorted(RUNS.glob("*.yaml"))


def _objects(text: str) -> tuple[dict[str, Any] | None, dict[str, Any]]:
    docs = [d for d in yaml.safe_load_all(text) if d]
    configmaps = [d for d in docs if d["kind"] == "ConfigMap"]
    runs = [d for d in docs if d["kind"] == "SimulationRun"]
    assert len(runs) == 1 and len(configmaps) <= 1
    return (configmaps[0] if configmaps else None), runs[0]


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.stem)
def test_dry_run_objects_are_accepted_by_the_operator(example: Path) -> None:
    result = carlos("submit", example, "--dry-run", "-o", "yaml", "--namespace", "sims")
    assert result.returncode == 0, result.stderr
    configmap, body = _objects(result.stdout)
    assert body["metadata"]["namespace"] == "sims"
    run = SimulationRun.model_validate(body)
    check_cluster_spec(run)  # raises BadInput for anything a pod could not reach
    settings = OperatorSettings.from_env({"CARLOS_DEFAULT_OUTPUT_URL": "s3://results/carlos"})
    output = resolve_output(run, settings)
    assert output.url == "s3://results/carlos"  # file://./results of the example means nothing in a pod
    owner = {
        "metadata": {"name": run.name, "uid": "u1", "namespace": "sims"},
        "apiVersion": "carlos.dev/v1alpha1",
    }
    build_configmap(run, owner, settings)
    search = run.spec.search
    # a search's pods are its rounds' (the first one here), a sweep's the run's Job's
    first = SearchRound(0, 0, min(search.batch_size, search.budget)) if search is not None else None
    job = build_job(run, owner, settings, output, search_round=first)
    assert configmap is not None and configmap["metadata"]["name"] == inputs_name(run.name)
    mounted = {v["configMap"]["name"] for v in job["spec"]["template"]["spec"]["volumes"] if "configMap" in v}
    assert configmap["metadata"]["name"] in mounted
    data = configmap["data"]
    for scenario in body["spec"]["scenarios"]:
        ref = scenario["configMapRef"]
        assert "openscenario" not in scenario and ref["name"] == configmap["metadata"]["name"]
        text = data[ref["key"]]
        road = re.search(r'<LogicFile filepath="([^"]+)"', text)
        assert road is not None and road.group(1) in data  # the road is a key beside the scenario


def test_submit_refuses_what_a_cluster_cannot_run(tmp_path: Path) -> None:
    manifest = tmp_path / "local.yaml"
    manifest.write_text(
        (RUNS / "perception.yaml")
        .read_text()
        .replace("    image: ghcr.io/carlos-sim/carlos-detector:0.1.0\n", "")
    )
    result = carlos("submit", manifest, "--dry-run")
    assert result.returncode == 2 and "spec.systemUnderTest.image" in result.stderr
    result = carlos("submit", RUNS / "prototyping.yaml", "--dry-run", "--results", "file:///tmp/x")
    assert result.returncode == 2 and "--results" in result.stderr and "s3://" in result.stderr


def test_kubectl_plugin_name_is_installed() -> None:
    plugin = Path(sys.executable).with_name("kubectl-carlos")
    assert plugin.is_file()
    done = subprocess.run([str(plugin), "submit", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "--dry-run" in done.stdout


@pytest.mark.s3
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_submitted_example_runs_to_succeeded_with_results_in_s3(
    env: tuple[Cluster, Kube],  # noqa: F811 - the fixture imported from tests.test_operator
    s3_server: S3Server,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    c, kube = env
    monkeypatch.setenv("CARLOS_DEFAULT_S3_SECRET", "s3")  # the Helm value: the example names no Secret
    c.start_operator()
    # the test kubelet maps env values that lie inside a mount, and CARLOS_SCENARIO_DIR is the parent of the
    # ConfigMap mounts: stand in for it with the ConfigMap's content as the dry run prints it
    dry = carlos("submit", RUNS / "prototyping.yaml", "--dry-run", "-n", "default")
    planned, _ = _objects(dry.stdout)
    assert planned is not None
    mounted = tmp_path / "scenarios" / planned["metadata"]["name"]
    mounted.mkdir(parents=True)
    for key, text in planned["data"].items():
        (mounted / key).write_text(text)
    jobs = JobRunner(
        kube=kube,
        workdir=tmp_path,
        extra_env={"AWS_REGION": s3_server.region, "CARLOS_SCENARIO_DIR": str(mounted.parent)},
    ).start()
    try:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "simcore.cli",
                "submit",
                str(RUNS / "prototyping.yaml"),
                "-n",
                "default",
                "--results",
                f"s3://{s3_server.bucket}/submitted",
            ],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=ROOT,
            env=dict(os.environ),
        )
        assert done.returncode == 0, done.stderr
        assert "simulationrun.carlos.dev/prototyping created in namespace default" in done.stdout
        st = wait_for(lambda: terminal(kube, "prototyping"), 120, "a terminal phase")
    finally:
        jobs.stop()
    assert jobs.errors == []
    assert st["phase"] == "Succeeded", st
    configmap = next(m for m in c.objects("configmaps") if m["metadata"]["name"] == "prototyping-inputs")
    run_uid = kube.custom.get_namespaced_custom_object(
        "carlos.dev", "v1alpha1", "default", "simulationruns", "prototyping"
    )["metadata"]["uid"]
    assert configmap["metadata"]["ownerReferences"][0]["uid"] == run_uid
    assert configmap["data"] == planned["data"]
    for key, value in s3_server.env().items():
        monkeypatch.setenv(key, value)
    # on a cluster results go under the run's namespace: <output>/<namespace>/<run>/
    assert st["resultsURL"].rstrip("/").endswith("/submitted/default/prototyping"), st
    store = open_store(
        f"s3://{s3_server.bucket}/submitted/default", endpoint=s3_server.endpoint, region=s3_server.region
    )
    summary = json.loads(store.get_bytes("prototyping/summary.json"))
    assert summary["status"] == "passed" and summary["counts"]["total"] == 1
    assert store.exists("prototyping/0/recording.mcap")
    # the same run through its name on the cluster
    assert "prototyping: Succeeded · 1 finished · 1 passed" in carlos("get", "-n", "default").stdout
    assert carlos("watch", "prototyping", "-n", "default").returncode == 0
    log = carlos("logs", "prototyping", "-i", "0", "-n", "default")
    assert log.returncode == 0 and "index 0" in log.stdout, log.stderr


def test_inputs_over_the_configmap_limit_go_to_the_object_store(monkeypatch: pytest.MonkeyPatch) -> None:
    from simcore import errors
    from simcore.manifest import load_manifest
    from simcore.workflow import submit

    monkeypatch.setattr(submit, "CONFIGMAP_LIMIT", 1000)
    manifest = RUNS / "automated-testing.yaml"
    run = load_manifest(manifest)
    with pytest.raises(errors.BadInput, match="over a ConfigMap"):
        submit.pack(run, manifest, "default")
    packed = submit.pack(run, manifest, "default", results_url="s3://bucket/out")
    assert packed.configmap() is None and "automated-testing/inputs/highway.xodr" in packed.uploads
    sources = [s["openscenario"] for s in packed.run["spec"]["scenarios"]]
    assert sources[0] == "s3://bucket/out/automated-testing/inputs/cut-in.xosc"
    scenario = packed.uploads["automated-testing/inputs/cut-in.xosc"].decode()
    assert '<LogicFile filepath="highway.xodr"' in scenario  # resolves beside it, as the pod fetches it


def test_configmap_names_stay_dns_labels() -> None:
    assert inputs_name("demo") == "demo-inputs"
    long = inputs_name("x" * 63)
    assert len(long) <= 63 and long.endswith("-inputs")


DISTRIBUTION = """<?xml version="1.0" encoding="UTF-8"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="2" date="2026-11-25T00:00:00" description="two speeds" author="tests"/>
  <ParameterValueDistribution>
    <ScenarioFile filepath="braking.xosc"/>
    <Deterministic>
      <DeterministicSingleParameterDistribution parameterName="Speed">
        <DistributionSet><Element value="20.0"/><Element value="25.0"/></DistributionSet>
      </DeterministicSingleParameterDistribution>
    </Deterministic>
  </ParameterValueDistribution>
</OpenSCENARIO>
"""


def distribution_manifest(
    folder: Path, name: str = "dist", max_seconds: float = 40, criterion: str = "simSeconds <= 100"
) -> Path:
    """A sweep over a local distribution file of 2 points on the braking example (beside the manifest)."""
    (folder / "speeds.xosc").write_text(DISTRIBUTION)
    manifest = folder / f"{name}.yaml"
    manifest.write_text(
        f"""apiVersion: carlos.dev/v1alpha1
kind: SimulationRun
metadata: {{name: {name}}}
spec:
  scenarios:
    - name: braking
      openscenario: {ROOT / "examples" / "scenarios" / "braking.xosc"}
  sweep: {{distribution: speeds.xosc}}
  simulation: {{stepSeconds: 0.1, maxSeconds: {max_seconds}}}
  evaluation: {{criteria: ["{criterion}"]}}
"""
    )
    return manifest


def test_a_local_distribution_is_packed_and_reaches_the_pods_beside_the_spec(tmp_path: Path) -> None:
    from carlos_operator.builders import DISTRIBUTION_FILE, SPEC_FILE

    from simcore.manifest import load_manifest
    from simcore.plan import Plan
    from tests.apiserver import admit

    result = carlos("submit", distribution_manifest(tmp_path), "--dry-run", "-o", "yaml", "-n", "sims")
    assert result.returncode == 0, result.stderr
    configmap, body = _objects(result.stdout)
    assert configmap is not None
    admit(configmap)
    admit(body)  # the strict stand-in: the shipped CRD knows distributionConfigMapRef
    sweep = body["spec"]["sweep"]
    assert "distribution" not in sweep
    assert sweep["distributionConfigMapRef"] == {"name": "dist-inputs", "key": "speeds.xosc"}
    assert configmap["data"]["speeds.xosc"] == DISTRIBUTION
    # the operator hands the file it read to the pods beside the spec they load
    run = SimulationRun.model_validate(body)
    owner = {
        "metadata": {"name": "dist", "uid": "u1", "namespace": "sims"},
        "apiVersion": "carlos.dev/v1alpha1",
    }
    cm = build_configmap(run, owner, OperatorSettings.from_env({}), DISTRIBUTION)
    admit(cm)
    pod_dir = tmp_path / "pod"
    pod_dir.mkdir()
    for key, text in cm["data"].items():
        (pod_dir / key).write_text(text)
    assert set(cm["data"]) == {SPEC_FILE, DISTRIBUTION_FILE}
    plan = Plan(load_manifest(pod_dir / SPEC_FILE).spec)
    assert [p.parameters["Speed"] for p in plan] == ["20.0", "25.0"]


def test_a_distribution_over_the_configmap_limit_goes_to_the_object_store(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from simcore.manifest import load_manifest
    from simcore.workflow import submit

    monkeypatch.setattr(submit, "CONFIGMAP_LIMIT", 1000)
    manifest = distribution_manifest(tmp_path)
    packed = submit.pack(load_manifest(manifest), manifest, "default", results_url="s3://bucket/out")
    assert packed.configmap() is None
    sweep = packed.run["spec"]["sweep"]
    assert sweep["distribution"] == "s3://bucket/out/dist/inputs/speeds.xosc"
    assert "distributionConfigMapRef" not in sweep
    assert packed.uploads["dist/inputs/speeds.xosc"].decode() == DISTRIBUTION


def test_a_rerun_of_a_cluster_run_is_a_new_run_over_its_failed_indexes() -> None:
    from simcore.workflow.rerun import cluster_rerun, rerun_name

    obj = {
        "metadata": {"name": "dist", "namespace": "sims"},
        "spec": {
            "scenarios": [{"name": "b", "configMapRef": {"name": "dist-inputs", "key": "braking.xosc"}}],
            "sweep": {"distributionConfigMapRef": {"name": "dist-inputs", "key": "speeds.xosc"}},
            "suspend": True,
        },
    }
    packed = cluster_rerun(obj, [1, 3], "dist-rerun", {"braking.xosc": "a", "speeds.xosc": "b"})
    spec = packed.run["spec"]
    assert spec["sweep"]["indexes"] == [1, 3] and "suspend" not in spec
    assert spec["scenarios"][0]["configMapRef"]["name"] == "dist-rerun-inputs"
    assert spec["sweep"]["distributionConfigMapRef"]["name"] == "dist-rerun-inputs"
    assert packed.configmap() is not None and packed.files == {"braking.xosc": "a", "speeds.xosc": "b"}
    # a rerun of a rerun: its indexes are the whole sweep's
    again = cluster_rerun(packed.run, [1], "dist-rerun-2", None)
    assert again.run["spec"]["sweep"]["indexes"] == [3]
    assert rerun_name("dist", {"dist-rerun"}.__contains__) == "dist-rerun-2"
    assert len(rerun_name("x" * 63, lambda _: False)) <= 63


@pytest.mark.s3
@pytest.mark.timeout(400)
def test_a_submitted_distribution_runs_on_the_cluster_and_its_failures_rerun_there(
    env: tuple[Cluster, Kube],  # noqa: F811 - the fixture imported from tests.test_operator
    s3_server: S3Server,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """2 points of a local distribution (Speed 20 passes maxSpeed <= 22, Speed 25 fails it), then
    `carlos rerun dist --failed`: a new SimulationRun over index 1 only, same parameters and seed."""
    c, kube = env
    monkeypatch.setenv("CARLOS_DEFAULT_S3_SECRET", "s3")  # the Helm value: the manifest names no Secret
    c.start_operator()
    manifest = distribution_manifest(tmp_path, max_seconds=2, criterion="maxSpeed <= 22")
    dry = carlos("submit", manifest, "--dry-run", "-n", "default")
    planned, _ = _objects(dry.stdout)
    assert planned is not None
    for name in ("dist-inputs", "dist-rerun-inputs"):  # the kubelet stand-in's scenario mounts
        mounted = tmp_path / "scenarios" / name
        mounted.mkdir(parents=True)
        for key, text in planned["data"].items():
            (mounted / key).write_text(text)
    python_path = {"PYTHONPATH": os.environ["PYTHONPATH"]} if os.environ.get("PYTHONPATH") else {}
    jobs = JobRunner(
        kube=kube,
        workdir=tmp_path,
        extra_env={
            "AWS_REGION": s3_server.region,
            "CARLOS_SCENARIO_DIR": str(tmp_path / "scenarios"),
            **python_path,
        },
    ).start()
    s3_env = s3_server.env()
    try:
        result = carlos("submit", manifest, "-n", "default", "--results", f"s3://{s3_server.bucket}/d")
        assert result.returncode == 0, result.stderr
        st = wait_for(lambda: terminal(kube, "dist"), 150, "a terminal phase")
        assert st["phase"] == "Failed" and (st["total"], st["passed"], st["testFailures"]) == (2, 1, 1), st
        for key, value in s3_env.items():
            monkeypatch.setenv(key, value)  # the client reads the results (as a user with S3 access)
        rerun = carlos("rerun", "dist", "--failed", "-n", "default")
        assert rerun.returncode == 0, rerun.stderr
        assert "dist-rerun: rerunning indexes 1 of dist" in rerun.stdout
        again = wait_for(lambda: terminal(kube, "dist-rerun"), 150, "a terminal phase of the rerun")
    finally:
        jobs.stop()
    assert jobs.errors == []
    assert again["phase"] == "Failed" and (again["total"], again["testFailures"]) == (1, 1), again
    body = kube.custom.get_namespaced_custom_object(
        "carlos.dev", "v1alpha1", "default", "simulationruns", "dist-rerun"
    )
    assert body["spec"]["sweep"]["indexes"] == [1]
    inputs = next(m for m in c.objects("configmaps") if m["metadata"]["name"] == "dist-rerun-inputs")
    assert inputs["metadata"]["ownerReferences"][0]["uid"] == body["metadata"]["uid"]
    assert inputs["data"] == planned["data"]
    store = open_store(
        f"s3://{s3_server.bucket}/d/default", endpoint=s3_server.endpoint, region=s3_server.region
    )
    old = json.loads(store.get_bytes("dist/1/summary.json"))
    new = json.loads(store.get_bytes("dist-rerun/0/summary.json"))
    assert old["parameters"]["Speed"] == new["parameters"]["Speed"] == "25.0"
    assert old["seed"] == new["seed"] and new["status"] == "failed"
    for run in ("dist", "dist-rerun"):
        assert "<h1>SimulationRun" in store.get_bytes(f"{run}/report.html").decode()
