"""examples/gitops: the Argo CD health check (Lua, run with lupa), the Kustomization (built by kubectl's
kustomize with the real helm), the Argo CD Application, the SimulationRuns kept in Git, and the CI script
(against a stand-in kubectl that plays the API server's part)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import lupa
import pytest
import yaml

from simcore.spec import SimulationRun
from tests.apiserver import admit
from tests.test_helm import render
from tests.tooling import helm_binary

ROOT = Path(__file__).resolve().parents[1]
GITOPS = ROOT / "examples" / "gitops"
LUA = GITOPS / "argocd" / "health-simulationrun.lua"
ARGO_HEALTH = {"Healthy", "Progressing", "Degraded", "Suspended", "Missing", "Unknown"}
IMAGE_ROOT = "file:///opt/carlos/"  # images/simcore/Dockerfile copies examples/ to /opt/carlos/examples


def health(status: dict[str, Any] | None) -> dict[str, str]:
    """Run the health check as Argo CD does: the object as the global `obj`, the script's return value."""
    lua = lupa.LuaRuntime(register_eval=False, register_builtins=False)
    g = lua.globals()
    for unsafe in ("os", "io", "require", "dofile", "loadfile", "load", "debug", "package"):
        g[unsafe] = None  # Argo CD's sandbox has none of these: the script must not need them
    run: dict[str, Any] = {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": "r"},
    }
    if status is not None:
        run["status"] = status
    g.obj = lua.table_from(run, recursive=True)
    result = lua.execute(LUA.read_text())
    out = {"status": result["status"], "message": result["message"]}
    assert out["status"] in ARGO_HEALTH
    assert isinstance(out["message"], str)
    return out


def condition(kind: str, true: bool, message: str = "") -> dict[str, str]:
    return {"type": kind, "status": "True" if true else "False", "reason": "R", "message": message}


def test_health_without_status_is_progressing() -> None:
    assert health(None)["status"] == "Progressing"
    assert health({})["status"] == "Progressing"


@pytest.mark.parametrize(
    ("status", "expected", "in_message"),
    [
        (
            {"phase": "Pending", "progress": "0/6", "conditions": [condition("Accepted", True)]},
            "Progressing",
            "0/6",
        ),
        (
            {"phase": "Running", "progress": "2/6", "active": 4, "passed": 2, "testFailures": 0, "errors": 0},
            "Progressing",
            "4 pods active",
        ),
        (
            {
                "phase": "Succeeded",
                "progress": "6/6",
                "passed": 6,
                "testFailures": 0,
                "errors": 0,
                "conditions": [condition("Complete", True, "6 passed"), condition("Failed", False)],
            },
            "Healthy",
            "6 passed, 0 failed, 0 errors",
        ),
        (
            {
                "phase": "Failed",
                "progress": "6/6",
                "passed": 5,
                "testFailures": 1,
                "errors": 0,
                "resultsURL": "s3://b/p/r/",
                "conditions": [
                    condition("Complete", True),
                    condition("Failed", True, "1 run failed its criteria, 0 errors"),
                ],
            },
            "Degraded",
            "1 run failed its criteria",
        ),
        (
            {"phase": "Failed", "progress": "6/6", "passed": 4, "testFailures": 0, "errors": 2},
            "Degraded",
            "2 errors",
        ),
        ({"phase": "Suspended", "progress": "0/6"}, "Suspended", "spec.suspend"),
        (
            {
                "phase": "Unknown",
                "conditions": [
                    {
                        "type": "Complete",
                        "status": "Unknown",
                        "message": "the Job carlos-r is gone with 3 of 6",
                    }
                ],
            },
            "Degraded",
            "is gone",
        ),
    ],
)
def test_health_from_status(status: dict[str, Any], expected: str, in_message: str) -> None:
    result = health(status)
    assert result["status"] == expected
    assert in_message in result["message"]


def test_health_of_the_operators_own_statuses() -> None:
    """Statuses as the operator's aggregator writes them, through the whole life of a run."""
    try:
        from carlos_operator.status import Tally, aggregate
    except ModuleNotFoundError:
        pytest.skip("operator/carlos_operator/status.py is not there yet (issue 5)")
    now = "2026-11-22T00:00:00Z"
    tally = Tally(total=3)
    pending = aggregate(total=3, job=None, tally=tally, results_url="s3://b/r/", now=now)
    assert health(pending)["status"] == "Progressing"
    running_job = {"spec": {}, "status": {"active": 2, "completedIndexes": "0", "startTime": now}}
    tally.record({"index": 0, "scenario": "cut-in", "status": "passed"})
    running = aggregate(
        total=3, job=running_job, tally=tally, results_url="s3://b/r/", now=now, previous=pending
    )
    assert running["phase"] == "Running"
    assert health(running)["status"] == "Progressing"
    done_job = {
        "spec": {},
        "status": {"completedIndexes": "0-2", "conditions": [{"type": "Complete", "status": "True"}]},
    }
    for i in (1, 2):
        tally.record({"index": i, "scenario": "cut-in", "status": "passed"})
    passed = aggregate(total=3, job=done_job, tally=tally, results_url="s3://b/r/", now=now, previous=running)
    assert passed["phase"] == "Succeeded"
    assert health(passed)["status"] == "Healthy"

    failing = Tally(total=3)
    failing.record({"index": 0, "scenario": "cut-in", "status": "passed"})
    failing.record(
        {
            "index": 1,
            "scenario": "cut-in",
            "status": "failed",
            "criteria": [{"name": "collision == 0", "passed": False}],
        }
    )
    failing.record({"index": 2, "scenario": "cut-in", "status": "passed"})
    failed_job = {
        "spec": {},
        "status": {
            "completedIndexes": "0,2",
            "failedIndexes": "1",
            "conditions": [{"type": "Complete", "status": "True"}],
        },
    }
    failed = aggregate(total=3, job=failed_job, tally=failing, results_url="s3://b/r/", now=now)
    assert failed["phase"] == "Failed"
    result = health(failed)
    assert result["status"] == "Degraded"
    assert "failed" in result["message"]
    SimulationRun.model_validate(
        {
            "apiVersion": "carlos.dev/v1alpha1",
            "kind": "SimulationRun",
            "metadata": {"name": "r"},
            "spec": {"scenarios": [{"name": "a", "openscenario": "a.xosc"}]},
            "status": failed,
        }
    )


def test_argocd_cm_carries_the_same_lua() -> None:
    cm = yaml.safe_load((GITOPS / "argocd" / "argocd-cm.yaml").read_text())
    assert cm["kind"] == "ConfigMap" and cm["metadata"] == {
        **cm["metadata"],
        "name": "argocd-cm",
        "namespace": "argocd",
    }
    embedded = cm["data"]["resource.customizations.health.carlos.dev_SimulationRun"]
    assert embedded == LUA.read_text(), "argocd-cm.yaml drifted from health-simulationrun.lua"
    admit(cm)


def check_simulation_run(obj: dict[str, Any], where: str) -> SimulationRun:
    """Valid for the spec models and accepted by the strict stand-in (the shipped CRD's schema and CEL
    rules, tests/apiserver.py); every scenario is a file the image ships."""
    run = SimulationRun.model_validate(obj)
    named = json.loads(json.dumps(obj))
    if not named["metadata"].get("name"):
        named["metadata"]["name"] = named["metadata"]["generateName"] + "x1y2z"  # as the API server names it
    admit(named)
    from simcore.scenario.xosc import declared_parameters

    for scenario in run.spec.scenarios:
        assert scenario.openscenario and scenario.openscenario.startswith(IMAGE_ROOT), where
        local = ROOT / scenario.openscenario.removeprefix(IMAGE_ROOT)
        assert local.is_file(), f"{where}: {scenario.openscenario} is not in the image (no {local})"
        declared = set(declared_parameters(local))
        assert set(run.spec.sweep.matrix) | set(run.spec.parameters) <= declared, where
    return run


def test_runs_in_git_are_valid_named_runs() -> None:
    files = sorted((GITOPS / "runs").glob("*.yaml"))
    listed = yaml.safe_load((GITOPS / "runs" / "kustomization.yaml").read_text())["resources"]
    assert sorted(listed) == sorted(f.name for f in files if f.name != "kustomization.yaml")
    runs = 0
    for path in files:
        for obj in yaml.safe_load_all(path.read_text()):
            if obj.get("kind") != "SimulationRun":
                continue
            runs += 1
            run = check_simulation_run(obj, str(path))
            assert run.metadata.name and not run.metadata.generate_name, f"{path}: GitOps needs a fixed name"
            annotations = obj["metadata"]["annotations"]
            assert "SkipDryRunOnMissingResource=true" in annotations["argocd.argoproj.io/sync-options"]
            assert int(annotations["argocd.argoproj.io/sync-wave"]) > 0
    assert runs


def test_ci_run_uses_generate_name() -> None:
    obj = yaml.safe_load((GITOPS / "ci" / "simulationrun.yaml").read_text())
    run = check_simulation_run(obj, "ci/simulationrun.yaml")
    assert run.metadata.generate_name and not run.metadata.name


def _helm_shim(tmp_path: Path) -> Path:
    """kustomize (v5.5 in kubectl) asks `helm version -c` and refuses helm v4; the shim answers as helm v3
    and hands every other call to the real helm v4 binary."""
    shim = tmp_path / "helm"
    shim.write_text(
        f'#!/bin/bash\nif [ "$1" = version ]; then echo v3.16.0; exit 0; fi\nexec {helm_binary()} "$@"\n'
    )
    shim.chmod(0o755)
    return shim


def test_kustomization_builds_and_every_object_validates(tmp_path: Path) -> None:
    kubectl = shutil.which("kubectl")
    if kubectl is None:
        pytest.skip("kubectl (its built-in kustomize) is not on PATH")
    result = subprocess.run(
        [
            kubectl,
            "kustomize",
            "--enable-helm",
            "--load-restrictor",
            "LoadRestrictionsNone",
            "--helm-command",
            str(_helm_shim(tmp_path)),
            str(GITOPS),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    objects = [o for o in yaml.safe_load_all(result.stdout) if o]
    kinds = sorted(o["kind"] for o in objects)
    for kind in ("Deployment", "ServiceAccount", "Role", "RoleBinding", "SimulationRun", "Namespace"):
        assert kind in kinds
    assert "CustomResourceDefinition" in kinds
    values = yaml.safe_load((GITOPS / "kustomization.yaml").read_text())["helmCharts"][0]["valuesInline"]
    for obj in objects:
        if obj["kind"] == "SimulationRun":
            check_simulation_run(obj, "kustomize build")
            assert obj["metadata"]["namespace"] in values["watchNamespaces"]
        else:
            admit(obj)
    namespaces = {o["metadata"]["name"] for o in objects if o["kind"] == "Namespace"}
    assert namespaces == {"carlos-system", *values["watchNamespaces"]}
    roles = [o for o in objects if o["kind"] == "Role"]
    assert sorted(r["metadata"]["namespace"] for r in roles) == sorted(values["watchNamespaces"])
    (deployment,) = [o for o in objects if o["kind"] == "Deployment"]
    assert deployment["metadata"]["namespace"] == "carlos-system"
    args = deployment["spec"]["template"]["spec"]["containers"][0]["args"]
    assert [args[i + 1] for i, a in enumerate(args) if a == "--namespace"] == values["watchNamespaces"]


def test_argocd_application(tmp_path: Path) -> None:
    app = yaml.safe_load((GITOPS / "argocd" / "application.yaml").read_text())
    assert app["apiVersion"] == "argoproj.io/v1alpha1" and app["kind"] == "Application"
    spec = app["spec"]
    paths = [s["path"] for s in spec["sources"]]
    assert paths == ["helm/carlos", "examples/gitops/runs"]
    for path in paths:
        assert (ROOT / path).is_dir()
    assert spec["syncPolicy"]["automated"]["prune"] is False, "finished runs must not be pruned"
    assert {"group": "carlos.dev", "kind": "SimulationRun", "jsonPointers": ["/status"]} in spec[
        "ignoreDifferences"
    ]
    values = spec["sources"][0]["helm"]["valuesObject"]
    # the same settings as the Kustomization, and the chart accepts them (values.schema.json) and renders
    kustomize_values = yaml.safe_load((GITOPS / "kustomization.yaml").read_text())["helmCharts"][0][
        "valuesInline"
    ]
    assert values["watchNamespaces"] == kustomize_values["watchNamespaces"]
    assert values["objectStore"] == kustomize_values["objectStore"]
    objects = render(helm_binary(), values, tmp_path)
    (deployment,) = [o for o in objects if o["kind"] == "Deployment"]
    assert spec["destination"]["namespace"] == "carlos-system"
    env = {e["name"]: e["value"] for e in deployment["spec"]["template"]["spec"]["containers"][0]["env"]}
    assert env["CARLOS_DEFAULT_OUTPUT_URL"] == "s3://carlos-results/gitops"
    runs_namespace = yaml.safe_load((GITOPS / "runs" / "kustomization.yaml").read_text())["namespace"]
    assert values["watchNamespaces"] == [runs_namespace]


# ---- ci/run-simulation.sh against a stand-in kubectl ----

FAKE_KUBECTL = """#!/usr/bin/env python3
import json, os, sys
args = sys.argv[1:]
with open(os.environ["FAKE_LOG"], "a") as log:
    log.write(json.dumps(args) + "\\n")
if "create" in args:
    print("ci-x7k2p", end="")
elif "wait" in args:
    sys.exit(int(os.environ.get("FAKE_WAIT_EXIT", "0")))
elif "get" in args and "json" in args:
    print(json.dumps({"metadata": {"name": "ci-x7k2p"}, "status": json.loads(os.environ["FAKE_STATUS"])}))
elif "get" in args:
    print("apiVersion: carlos.dev/v1alpha1")
"""


def run_ci_script(
    tmp_path: Path, status: dict[str, Any], *, wait_exit: int = 0, manifest: Path | None = None
) -> tuple[subprocess.CompletedProcess[str], list[list[str]], str]:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    kubectl = bin_dir / "kubectl"
    kubectl.write_text(FAKE_KUBECTL)
    kubectl.chmod(0o755)
    log = tmp_path / "kubectl.log"
    log.write_text("")
    output = tmp_path / "github_output"
    output.write_text("")
    env = {
        **os.environ,
        "PATH": f"{bin_dir}:{os.environ['PATH']}",
        "FAKE_LOG": str(log),
        "FAKE_STATUS": json.dumps(status),
        "FAKE_WAIT_EXIT": str(wait_exit),
        "GITHUB_OUTPUT": str(output),
    }
    env.pop("GITHUB_ACTIONS", None)
    result = subprocess.run(
        [
            "bash",
            str(GITOPS / "ci" / "run-simulation.sh"),
            str(manifest or GITOPS / "ci" / "simulationrun.yaml"),
            "carlos-runs",
            "5m",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    calls = [json.loads(line) for line in log.read_text().splitlines()]
    return result, calls, output.read_text()


def test_ci_script_passes_on_a_passed_run(tmp_path: Path) -> None:
    status = {
        "phase": "Succeeded",
        "progress": "3/3",
        "passed": 3,
        "testFailures": 0,
        "errors": 0,
        "resultsURL": "s3://b/ci-x7k2p/",
    }
    result, calls, output = run_ci_script(tmp_path, status)
    assert result.returncode == 0, result.stdout + result.stderr
    assert calls[0][:4] == ["-n", "carlos-runs", "create", "-f"]
    wait = calls[1]
    assert "wait" in wait and "simulationrun/ci-x7k2p" in wait
    assert "--for=condition=Complete" in wait and "--timeout=5m" in wait
    assert "Succeeded" in result.stdout and "s3://b/ci-x7k2p/" in result.stdout
    assert "name=ci-x7k2p" in output and "results=s3://b/ci-x7k2p/" in output


def test_ci_script_fails_the_pipeline_on_test_failures(tmp_path: Path) -> None:
    status = {
        "phase": "Failed",
        "progress": "3/3",
        "passed": 2,
        "testFailures": 1,
        "errors": 0,
        "failures": [
            {
                "index": 1,
                "scenario": "braking",
                "status": "failed",
                "reason": "criteria failed: minDistance >= 1.5",
            }
        ],
    }
    result, _, _ = run_ci_script(tmp_path, status)
    assert result.returncode == 1
    assert "index 1 (braking): failed criteria failed: minDistance >= 1.5" in result.stdout


def test_ci_script_errors_and_timeouts_are_infrastructure_failures(tmp_path: Path) -> None:
    errors = {"phase": "Failed", "progress": "3/3", "passed": 2, "testFailures": 0, "errors": 1}
    assert run_ci_script(tmp_path, errors)[0].returncode == 3
    result, calls, _ = run_ci_script(tmp_path, {}, wait_exit=1)
    assert result.returncode == 3
    assert "did not complete within 5m" in result.stderr
    assert not any("json" in c for c in calls)


def test_ci_script_refuses_a_manifest_without_generate_name(tmp_path: Path) -> None:
    manifest = tmp_path / "named.yaml"
    manifest.write_text((GITOPS / "runs" / "cut-in-sweep-v1.yaml").read_text())
    result, calls, _ = run_ci_script(tmp_path, {}, manifest=manifest)
    assert result.returncode == 2 and "generateName" in result.stderr
    assert calls == []


def test_ci_workflow_example_uses_the_script() -> None:
    workflow = yaml.safe_load((GITOPS / "ci" / "simulation-tests.yml").read_text())
    steps = workflow["jobs"]["simulation"]["steps"]
    runs = " ".join(s.get("run", "") for s in steps)
    assert "examples/gitops/ci/run-simulation.sh examples/gitops/ci/simulationrun.yaml" in runs
    assert any("junit" in json.dumps(s) for s in steps)
