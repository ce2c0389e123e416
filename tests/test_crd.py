"""The SimulationRun CRD: generated from the spec models, structural, checked in without drift, and the
example manifests validate against its schema."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from carlos_operator.crd import SPEC_IMMUTABLE_MESSAGE, crd, crd_yaml

from simcore.spec import SimulationRunSpec
from tests.apiserver import CustomResourceValidator, Invalid, declared

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples" / "runs").glob("*.yaml"))
FORBIDDEN = {"$ref", "$defs", "const", "title", "allOf", "propertyNames", "prefixItems", "examples"}


def _schema() -> dict[str, Any]:
    return crd()["spec"]["versions"][0]["schema"]["openAPIV3Schema"]


@pytest.mark.parametrize("path", ["crds/simulationrun.yaml", "helm/carlos/crds/simulationrun.yaml"])
def test_checked_in_crd_matches_the_models(path: str) -> None:
    checked_in = ROOT / path
    assert checked_in.is_file(), f"{path} is missing: run `make crds`"
    assert checked_in.read_text() == crd_yaml(), f"{path} drifted from simcore/spec.py: run `make crds`"


def _walk(node: dict[str, Any], path: str, problems: list[str]) -> None:
    """Kubernetes' structural-schema rules (apiextensions: 'Specifying a structural schema')."""
    for key in FORBIDDEN & set(node):
        problems.append(f"{path}: {key} is not allowed")
    if "type" not in node and not (
        node.get("x-kubernetes-int-or-string") or node.get("x-kubernetes-preserve-unknown-fields")
    ):
        problems.append(f"{path}: no type")
    for junctor in ("anyOf", "oneOf"):
        for option in node.get(junctor, []):
            if {"type", "description", "default", "additionalProperties", "nullable"} & set(option):
                problems.append(f"{path}: {junctor} member sets {sorted(option)}")
    if "properties" in node and "additionalProperties" in node:
        problems.append(f"{path}: properties and additionalProperties together")
    if isinstance(node.get("exclusiveMinimum"), (int, float)) and not isinstance(
        node["exclusiveMinimum"], bool
    ):
        problems.append(f"{path}: exclusiveMinimum must be a boolean")
    if node.get("type") == "array" and "items" not in node:
        problems.append(f"{path}: array without items")
    if "default" in node and node.get("type") == "object" and node.get("default") is None:
        problems.append(f"{path}: null default")
    if node.get("x-kubernetes-list-type") == "map":
        required = set(node["items"].get("required", []))
        for key in node["x-kubernetes-list-map-keys"]:
            if key not in required:
                problems.append(f"{path}: list-map key {key} is not required")
    for name, child in node.get("properties", {}).items():
        _walk(child, f"{path}.{name}", problems)
    if isinstance(node.get("additionalProperties"), dict):
        _walk(node["additionalProperties"], f"{path}.*", problems)
    if "items" in node:
        _walk(node["items"], f"{path}[]", problems)


def test_schema_is_structural_and_documented() -> None:
    schema = _schema()
    problems: list[str] = []
    _walk(schema, "", problems)
    assert problems == []
    missing: list[str] = []

    def described(node: dict[str, Any], path: str) -> None:
        for name, child in node.get("properties", {}).items():
            if name != "metadata" and not child.get("description"):
                missing.append(f"{path}.{name}")
            described(child, f"{path}.{name}")
        if "items" in node:
            described(node["items"], f"{path}[]")

    described(schema["properties"]["spec"], "spec")
    assert missing == [], "every spec field needs a description for kubectl explain"


def test_crd_resource_shape() -> None:
    resource = crd()
    spec = resource["spec"]
    assert resource["metadata"]["name"] == "simulationruns.carlos.dev"
    assert spec["names"]["shortNames"] == ["simrun", "simruns"]
    version = spec["versions"][0]
    assert version["subresources"] == {"status": {}}
    columns = {c["name"]: c["jsonPath"] for c in version["additionalPrinterColumns"]}
    assert columns == {
        "Phase": ".status.phase",
        "Progress": ".status.progress",
        "Passed": ".status.passed",
        "Failed": ".status.failed",
        "Age": ".metadata.creationTimestamp",
        "Rounds": ".status.search.rounds",  # a search's, with -o wide
        "Best": ".status.search.bestObjective",
        "Found": ".status.search.failuresFound",
    }
    wide = {c["name"] for c in version["additionalPrinterColumns"] if c.get("priority") == 1}
    assert wide == {"Rounds", "Best", "Found"}
    schema = version["schema"]["openAPIV3Schema"]
    execution = schema["properties"]["spec"]["properties"]["execution"]["properties"]
    # no defaults in the CRD: the API server would store them, and an unset field would read as set
    assert "default" not in execution["retries"] and "Default 1" in execution["retries"]["description"]
    assert "default:" not in crd_yaml()
    assert (execution["retries"]["minimum"], execution["retries"]["maximum"]) == (0, 10)
    step = schema["properties"]["spec"]["properties"]["simulation"]["properties"]["stepSeconds"]
    assert step["minimum"] == 0 and step["exclusiveMinimum"] is True
    compression = schema["properties"]["spec"]["properties"]["recording"]["properties"]["compression"]
    assert compression["enum"] == ["zstd", "lz4", "none"]
    phases = schema["properties"]["status"]["properties"]["phase"]["enum"]
    assert set(phases) == {"Pending", "Running", "Succeeded", "Failed", "Suspended", "Unknown"}


def test_spec_immutability_rule_covers_every_field_declared_to_cel_but_suspend() -> None:
    rules = _schema()["properties"]["spec"]["x-kubernetes-validations"]
    assert len(rules) == 1 and rules[0]["message"] == SPEC_IMMUTABLE_MESSAGE
    rule = rules[0]["rule"]
    spec = _schema()["properties"]["spec"]
    for name in SimulationRunSpec.model_json_schema(by_alias=True)["properties"]:
        if name == "suspend" or declared(spec["properties"][name]) is None:
            assert f"self.{name}" not in rule, name
        else:
            assert f"self.{name} == oldSelf.{name}" in rule


def _old_rule_naming_every_field() -> dict[str, Any]:
    """The CRD as it shipped before: its immutability rule named every spec field but suspend."""
    resource = copy.deepcopy(crd())
    spec = resource["spec"]["versions"][0]["schema"]["openAPIV3Schema"]["properties"]["spec"]
    parts = [
        f"(has(self.{n}) ? has(oldSelf.{n}) && self.{n} == oldSelf.{n} : !has(oldSelf.{n}))"
        for n in spec["properties"]
        if n != "suspend"
    ]
    spec["x-kubernetes-validations"] = [{"rule": " && ".join(parts), "message": SPEC_IMMUTABLE_MESSAGE}]
    return resource


def test_the_strict_stand_in_refuses_a_rule_naming_undeclared_fields() -> None:
    with pytest.raises(Invalid) as refused:
        CustomResourceValidator(_old_rule_naming_every_field())
    problems = " ".join(refused.value.problems)
    assert "undefined field 'parameters'" in problems and "undefined field 'sensors'" in problems


@pytest.mark.parametrize("path", ["crds/simulationrun.yaml", "helm/carlos/crds/simulationrun.yaml"])
def test_the_shipped_crd_is_accepted_by_the_strict_stand_in(path: str) -> None:
    validator = CustomResourceValidator(yaml.safe_load((ROOT / path).read_text()))
    assert [r.transition for r in validator.rules] == [True]


def _named(path: Path) -> dict[str, Any]:
    manifest = yaml.safe_load(path.read_text())
    manifest.setdefault("metadata", {}).setdefault("name", path.stem)
    manifest["metadata"].pop("generateName", None)
    return dict(manifest)


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_spec_changes_are_refused_on_update_but_suspend(path: Path) -> None:
    validator = CustomResourceValidator(yaml.safe_load((ROOT / "crds/simulationrun.yaml").read_text()))
    old = _named(path)
    validator.validate(old)  # create
    resumed = copy.deepcopy(old)
    resumed["spec"]["suspend"] = not old["spec"].get("suspend", False)
    resumed["status"] = {"phase": "Running"}
    validator.validate(resumed, old)
    changed = copy.deepcopy(old)
    changed["spec"].setdefault("execution", {})["retries"] = 1 + int(
        old["spec"].get("execution", {}).get("retries", 1)
    )
    with pytest.raises(Invalid, match="spec is immutable"):
        validator.validate(changed, old)
    dropped = copy.deepcopy(old)
    dropped["spec"].pop("simulation", None) or dropped["spec"].pop("scenarios")
    with pytest.raises(Invalid):
        validator.validate(dropped, old)


def _validator() -> jsonschema.Draft4Validator:
    # OpenAPI v3.0's boolean exclusiveMinimum is JSON-schema draft 4's; x-kubernetes-* keys are ignored
    return jsonschema.Draft4Validator(_schema())


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_examples_validate_against_the_crd(path: Path) -> None:
    manifest = yaml.safe_load(path.read_text())
    errors = [f"{list(e.absolute_path)}: {e.message}" for e in _validator().iter_errors(manifest)]
    assert errors == []


@pytest.mark.parametrize(
    ("change", "where"),
    [
        (lambda s: s["execution"].update(retries=11), "retries"),
        (lambda s: s["simulation"].update(stepSeconds=0), "stepSeconds"),
        (lambda s: s["recording"].update(compression="gzip"), "compression"),
        (lambda s: s["output"].update(url="ftp://x"), "url"),
        (lambda s: s.update(scenarios=[]), "scenarios"),
        (lambda s: s["scenarios"][0].pop("name"), "name"),
    ],
)
def test_the_crd_rejects_invalid_specs(change: Any, where: str) -> None:
    manifest = yaml.safe_load((ROOT / "examples/runs/automated-testing.yaml").read_text())
    manifest["spec"].setdefault("execution", {})
    bad = copy.deepcopy(manifest)
    change(bad["spec"])
    errors = list(_validator().iter_errors(bad))
    assert errors, f"{where}: accepted"
    assert any(where in [str(p) for p in e.absolute_path] or where in e.message for e in errors)


def test_crd_yaml_reads_the_same_with_yaml_1_1_booleans() -> None:
    """kubectl and the API server read YAML with Go's YAML 1.1 rules, where a plain `y`, `n`, `on`, `off`
    is a boolean: a property `y` written unquoted made the real API server refuse the CRD."""
    import re

    import yaml
    from carlos_operator.crd import crd, crd_yaml

    class Yaml11(yaml.SafeLoader):
        pass

    Yaml11.add_implicit_resolver(
        "tag:yaml.org,2002:bool",
        re.compile(r"^(?:y|Y|yes|Yes|YES|n|N|no|No|NO|on|On|ON|off|Off|OFF)$"),
        list("yYnNoO"),
    )
    assert yaml.load(crd_yaml(), Loader=Yaml11) == crd()
    # the operator's ConfigMaps and run.yaml (libyaml's emitter) keep the quotes too
    from simcore import kubeyaml

    data = {"y": ["n", "on", "Off", "yes", "x"], "matrix": {"y": [1.5, 2.0]}, "long": "word " * 40}
    assert yaml.load(kubeyaml.dump_fast(data, sort_keys=False), Loader=Yaml11) == data
