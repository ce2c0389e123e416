"""Invalid manifests are refused by the real API server (the CRD's schema and CEL rules) with the meaning
`carlos validate` gives them."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.e2e.conftest import ROOT, RUNS_NS, Cluster

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(600)]

BASE: dict[str, Any] = {
    "apiVersion": "carlos.dev/v1alpha1",
    "kind": "SimulationRun",
    "metadata": {"name": "bad-input"},
    "spec": {
        "scenarios": [
            {"name": "cut-in", "openscenario": "file:///opt/carlos/examples/scenarios/cut-in.xosc"}
        ],
        "output": {"url": "s3://carlos-test/results"},
    },
}


def _with(path: str, value: Any) -> dict[str, Any]:
    body = copy.deepcopy(BASE)
    node = body
    keys = path.split(".")
    for key in keys[:-1]:
        node = node[int(key)] if key.isdigit() else node.setdefault(key, {})  # type: ignore[index]
    node[keys[-1]] = value
    return body


#: (case, manifest, the field both name)
CASES = [
    ("unknown field", _with("spec.sweeep", {"matrix": {}}), "sweeep"),
    ("negative step", _with("spec.simulation.stepSeconds", -0.1), "stepSeconds"),
    ("no scenarios", _with("spec.scenarios", []), "scenarios"),
    ("wrong type", _with("spec.execution.parallelism", "many"), "parallelism"),
    ("unknown scenario field", _with("spec.scenarios.0.criterio", ["x > 1"]), "criterio"),
]


@pytest.mark.parametrize(("case", "body", "field"), CASES, ids=[c[0] for c in CASES])
def test_api_server_refuses_what_validate_refuses(
    cluster: Cluster, tmp_path: Path, case: str, body: dict[str, Any], field: str
) -> None:
    manifest = tmp_path / "run.yaml"
    manifest.write_text(yaml.safe_dump(body))
    validate = subprocess.run(
        [str(Path(sys.executable).with_name("carlos")), "validate", str(manifest)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert validate.returncode == 2, validate.stdout + validate.stderr
    assert field in validate.stderr + validate.stdout
    applied = cluster.kubectl("-n", RUNS_NS, "apply", "-f", str(manifest), check=False)
    assert applied.returncode != 0, f"{case}: the API server accepted it"
    assert field in applied.stderr, applied.stderr


def test_spec_is_immutable(cluster: Cluster, tmp_path: Path) -> None:
    body = _with("spec.suspend", True)
    body["metadata"]["name"] = "immutable"
    cluster.apply(yaml.safe_dump(body))
    changed = copy.deepcopy(body)
    changed["spec"]["simulation"] = {"stepSeconds": 0.05}
    refused = cluster.kubectl("-n", RUNS_NS, "apply", "-f", "-", stdin=yaml.safe_dump(changed), check=False)
    assert refused.returncode != 0
    assert "immutable" in refused.stderr.lower() or "spec" in refused.stderr
    cluster.delete_run("immutable")
