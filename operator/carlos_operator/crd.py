"""The SimulationRun CustomResourceDefinition, generated from the spec models (simcore/spec.py).

Kubernetes accepts only *structural* OpenAPI v3 schemas, a subset of JSON schema: no `$ref`, no `const`, no
types inside `anyOf`/`oneOf`, `exclusiveMinimum` as a boolean beside `minimum`, no `additionalProperties`
beside `properties`, and every node typed unless it is `x-kubernetes-int-or-string` or
`x-kubernetes-preserve-unknown-fields`. `openapi_schema` translates pydantic's JSON schema accordingly:

- `$ref` is inlined; a property's own description wins over the model's docstring.
- `anyOf: [X, null]` (an optional field) becomes X: Kubernetes prunes nulls of non-nullable fields, and an
  absent field means the model's default.
- a union of int and string becomes `x-kubernetes-int-or-string`; any other union of different types (an
  OpenSCENARIO parameter value: bool | int | float | string; a criterion: string or object) becomes
  `x-kubernetes-preserve-unknown-fields` with the union described. The operator validates every spec with
  the pydantic models before it creates anything, so such values are still checked.
- `const` becomes a one-value `enum`; `additionalProperties: false` (unknown fields rejected) is dropped:
  the API server prunes unknown fields, and `kubectl apply` (strict field validation) rejects them.

Nothing here imports kopf or the Kubernetes client.
"""

from __future__ import annotations

import copy
from typing import Any

from simcore import kubeyaml
from simcore.spec import API_GROUP, API_VERSION, KIND, SimulationRun

PLURAL = "simulationruns"
SINGULAR = "simulationrun"
SHORT_NAMES = ["simrun", "simruns"]
CRD_NAME = f"{PLURAL}.{API_GROUP}"

#: JSON-schema keywords Kubernetes' structural schemas keep as they are
_KEEP = {
    "type",
    "description",
    "default",
    "enum",
    "format",
    "pattern",
    "minimum",
    "maximum",
    "minLength",
    "maxLength",
    "minItems",
    "maxItems",
    "minProperties",
    "maxProperties",
    "uniqueItems",
    "multipleOf",
    "nullable",
}
#: models that also accept a string form (a BeforeValidator parses it; pydantic's schema shows only the object)
_STRING_FORMS = {"CriterionModel": "a string 'METRIC OP VALUE' (e.g. 'minDistance >= 2.0') or an object"}
_SCALAR_TYPES = {"string", "integer", "number", "boolean"}

SPEC_IMMUTABLE_MESSAGE = (
    "spec is immutable (only spec.suspend may change): a changed spec is a new run; "
    "create it under a new name (GitOps: metadata.generateName)"
)


class SchemaError(ValueError):
    """The pydantic schema uses a construct this translator does not know (a bug to fix here)."""


def _resolve(node: dict[str, Any], defs: dict[str, Any]) -> tuple[dict[str, Any], str | None]:
    """`node` with a `$ref` inlined (sibling keys win), and the name of the referenced model."""
    ref = node.get("$ref")
    if ref is None:
        return node, None
    name = ref.rsplit("/", 1)[-1]
    if name not in defs:
        raise SchemaError(f"unresolved $ref {ref}")
    merged = {**copy.deepcopy(defs[name]), **{k: v for k, v in node.items() if k != "$ref"}}
    return merged, name


def _type_names(options: list[dict[str, Any]], defs: dict[str, Any]) -> list[str]:
    names = []
    for option in options:
        resolved, _ = _resolve(option, defs)
        kind = resolved.get("type")
        if kind is None:
            raise SchemaError(f"untyped union member {option}")
        names.append(kind)
    return names


def _translate(node: dict[str, Any], defs: dict[str, Any], path: str) -> dict[str, Any]:
    node, ref_name = _resolve(node, defs)
    description = node.get("description")
    if "anyOf" in node or "oneOf" in node:
        options = [o for o in node.get("anyOf", node.get("oneOf", [])) if o.get("type") != "null"]
        outer = {k: v for k, v in node.items() if k not in ("anyOf", "oneOf")}
        if len(options) == 1:
            inner = dict(options[0])
            if "description" in outer:
                inner["description"] = outer["description"]
            if outer.get("default") is not None:
                inner["default"] = outer["default"]
            return _translate(inner, defs, path)
        kinds = _type_names(options, defs)
        out: dict[str, Any] = {}
        if sorted(set(kinds)) == ["integer", "string"]:
            out["x-kubernetes-int-or-string"] = True
        else:
            out["x-kubernetes-preserve-unknown-fields"] = True
        union = " | ".join(dict.fromkeys("bool" if k == "boolean" else k for k in kinds))
        out["description"] = f"{description} ({union})" if description else union
        if outer.get("default") is not None:
            out["default"] = outer["default"]
        return out
    if ref_name in _STRING_FORMS:
        text = (
            f"{description} Written as {_STRING_FORMS[ref_name]}." if description else _STRING_FORMS[ref_name]
        )
        fields = ", ".join(node.get("properties", {}))
        return {
            "x-kubernetes-preserve-unknown-fields": True,
            "description": f"{text} Object fields: {fields}.",
        }
    if "const" in node:
        node = {**node, "enum": [node["const"]]}
        node.setdefault("type", "string" if isinstance(node["const"], str) else node.get("type"))
    kind = node.get("type")
    if kind is None:
        if node.get("additionalProperties") is True or node == {} or set(node) <= {"description", "title"}:
            out = {"x-kubernetes-preserve-unknown-fields": True}
            if description:
                out["description"] = description
            return out
        raise SchemaError(f"{path}: no type in {node}")
    out = {k: v for k, v in node.items() if k in _KEEP}
    if out.get("default") is None:
        out.pop("default", None)
    if "exclusiveMinimum" in node:
        out["minimum"], out["exclusiveMinimum"] = node["exclusiveMinimum"], True
    if "exclusiveMaximum" in node:
        out["maximum"], out["exclusiveMaximum"] = node["exclusiveMaximum"], True
    if kind == "object":
        properties = node.get("properties")
        if properties:
            out["properties"] = {
                name: _translate(child, defs, f"{path}.{name}") for name, child in properties.items()
            }
            required = node.get("required")
            if required:
                out["required"] = list(required)
        else:
            extra = node.get("additionalProperties", True)
            if extra is True or extra == {}:
                out["x-kubernetes-preserve-unknown-fields"] = True
            elif isinstance(extra, dict):
                out["additionalProperties"] = _translate(extra, defs, f"{path}.*")
    elif kind == "array":
        out["items"] = _translate(node.get("items", {}), defs, f"{path}[]")
    elif kind not in _SCALAR_TYPES:
        raise SchemaError(f"{path}: unsupported type {kind!r}")
    return out


def openapi_schema(model: type[Any], *, root: str = "") -> dict[str, Any]:
    """The structural OpenAPI v3 schema of a pydantic model (validation mode, camelCase aliases)."""
    schema = model.model_json_schema(by_alias=True, mode="validation")
    defs = schema.pop("$defs", {})
    return _translate(schema, defs, root or model.__name__)


def declared_to_cel(node: dict[str, Any]) -> bool:
    """Whether Kubernetes declares a schema node to CEL (apiserver `SchemaDeclType`): typed, or
    int-or-string; an array only when its items are, a map only when its values are. A node with only
    `x-kubernetes-preserve-unknown-fields` is not, and a rule that names it fails to compile."""
    if node.get("x-kubernetes-int-or-string"):
        return True
    kind = node.get("type")
    if kind == "array":
        return isinstance(node.get("items"), dict) and declared_to_cel(node["items"])
    if kind == "object" and isinstance(node.get("additionalProperties"), dict):
        return declared_to_cel(node["additionalProperties"])
    return kind is not None


def _immutable_rule(spec: dict[str, Any]) -> str:
    """CEL: every field of spec declared to CEL but `suspend` equals the old one (presence included).

    Fields whose values mix types (`parameters`: bool | int | float | string; `sensors`: one of several
    sensor objects) are not declared to CEL, so no rule can name them: the operator runs the spec it
    accepted first (its ConfigMap and run.yaml are written once), whatever a later edit says."""
    parts = []
    for name, child in spec["properties"].items():
        if name == "suspend" or not declared_to_cel(child):
            continue
        parts.append(
            f"(has(self.{name}) ? has(oldSelf.{name}) && self.{name} == oldSelf.{name} : !has(oldSelf.{name}))"
        )
    return " && ".join(parts)


def crd() -> dict[str, Any]:
    """The SimulationRun CustomResourceDefinition (apiextensions.k8s.io/v1) as a dict."""
    full = SimulationRun.model_json_schema(by_alias=True, mode="validation")
    defs = full.get("$defs", {})
    spec = _translate(full["properties"]["spec"], defs, "spec")
    spec["x-kubernetes-validations"] = [{"rule": _immutable_rule(spec), "message": SPEC_IMMUTABLE_MESSAGE}]
    status = _translate(full["properties"]["status"], defs, "status")
    conditions = status["properties"]["conditions"]
    conditions["x-kubernetes-list-type"] = "map"
    conditions["x-kubernetes-list-map-keys"] = ["type"]
    schema = {
        "type": "object",
        "description": SimulationRun.__doc__ or KIND,
        "properties": {
            "apiVersion": {"type": "string", "description": full["properties"]["apiVersion"]["description"]},
            "kind": {"type": "string", "description": full["properties"]["kind"]["description"]},
            "metadata": {"type": "object"},
            "spec": spec,
            "status": status,
        },
        "required": ["spec"],
    }
    columns = [
        {"name": "Phase", "type": "string", "jsonPath": ".status.phase", "description": "Run phase."},
        {
            "name": "Progress",
            "type": "string",
            "jsonPath": ".status.progress",
            "description": "Finished / total.",
        },
        {
            "name": "Passed",
            "type": "integer",
            "jsonPath": ".status.passed",
            "description": "Runs that passed.",
        },
        {
            "name": "Failed",
            "type": "integer",
            "jsonPath": ".status.failed",
            "description": "Runs that failed (test failures and errors).",
        },
        {"name": "Age", "type": "date", "jsonPath": ".metadata.creationTimestamp"},
        # a search's (spec.search), with -o wide
        {
            "name": "Rounds",
            "type": "string",
            "jsonPath": ".status.search.rounds",
            "description": "A search's rounds done / in all.",
            "priority": 1,
        },
        {
            "name": "Best",
            "type": "number",
            "jsonPath": ".status.search.bestObjective",
            "description": "A search's best objective so far.",
            "priority": 1,
        },
        {
            "name": "Found",
            "type": "integer",
            "jsonPath": ".status.search.failuresFound",
            "description": "A search's failing points so far.",
            "priority": 1,
        },
    ]
    return {
        "apiVersion": "apiextensions.k8s.io/v1",
        "kind": "CustomResourceDefinition",
        "metadata": {"name": CRD_NAME, "labels": {"app.kubernetes.io/part-of": "carlos"}},
        "spec": {
            "group": API_GROUP,
            "scope": "Namespaced",
            "names": {
                "kind": KIND,
                "listKind": f"{KIND}List",
                "plural": PLURAL,
                "singular": SINGULAR,
                "shortNames": list(SHORT_NAMES),
                "categories": ["carlos"],
            },
            "versions": [
                {
                    "name": API_VERSION,
                    "served": True,
                    "storage": True,
                    "schema": {"openAPIV3Schema": schema},
                    "subresources": {"status": {}},
                    "additionalPrinterColumns": columns,
                }
            ],
        },
    }


HEADER = "# Generated from simcore/spec.py by `make crds` (carlos crds): do not edit.\n"


def crd_yaml() -> str:
    """The CRD as YAML, with a header saying it is generated."""
    return HEADER + kubeyaml.dump(crd(), sort_keys=False, allow_unicode=True, width=110)
