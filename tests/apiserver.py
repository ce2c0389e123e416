"""What a real API server checks before it stores an object, for the emulator-backed tests.

- Built-in kinds: the Kubernetes OpenAPI schemas of `KUBERNETES_VERSION` (kubernetes-validate, strict:
  unknown fields are errors, as `kubectl apply` with strict field validation).
- A CustomResourceDefinition: structural, and every `x-kubernetes-validations` rule compiles under
  Kubernetes' rules for which schema nodes are declared to CEL (k8s.io/apiserver/pkg/cel/common
  `SchemaDeclType`): a node is declared when it has a `type` (an object's fields are its declared
  properties; an object with `additionalProperties` is a map; an array is declared when its items are) or
  `x-kubernetes-int-or-string` (dyn). A node with only `x-kubernetes-preserve-unknown-fields` is not
  declared, nor is an object whose property values are not: a rule that selects such a field, or asks
  `has()` of it, fails to compile (`undefined field`), and the API server refuses the CRD.
- A custom resource: the CRD's openAPIV3Schema (OpenAPI 3.0 = JSON schema draft 4 plus the x-kubernetes
  extensions), then every rule evaluated with a real CEL implementation (cel-python): on create the rules
  that do not name `oldSelf`; on update every rule, with `oldSelf` the stored object's node (transition
  rules are evaluated only where the old object has the node too, as Kubernetes does).

The CEL parser and evaluator are cel-python's; the declared-field check is the part of the Kubernetes type
checker that decides what a rule may name (a partial type checker: field selections on `self`, `oldSelf`
and the variables of the list macros are resolved; other expressions are dynamic).
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jsonschema
import kubernetes_validate
import yaml

KUBERNETES_VERSION = "1.30.0"  # the oldest version the chart supports (Chart.yaml kubeVersion)
SHIPPED_CRD = Path(__file__).resolve().parent.parent / "crds" / "simulationrun.yaml"

#: CEL keywords: a property of this name is declared as `__NAME__` (apiserver/pkg/cel/escaping.go)
_RESERVED = {
    "true", "false", "null", "in", "as", "break", "const", "continue", "else", "for", "function", "if",
    "import", "let", "loop", "package", "namespace", "return", "var", "void", "while",
}  # fmt: skip
_LIST_MACROS = {"all", "exists", "exists_one", "map", "filter"}


class Invalid(Exception):
    """The API server would refuse the object (HTTP 422): `problems` are its field errors."""

    def __init__(self, what: str, problems: list[str]) -> None:
        super().__init__(f"{what} is invalid: " + "; ".join(problems))
        self.problems = problems


# --- the declared CEL type of a schema node ------------------------------------------------------------


@dataclass
class Decl:
    kind: str  # object | map | list | scalar | dyn
    fields: dict[str, Decl] = field(default_factory=dict)  # object
    element: Decl | None = None  # map value, list item


_DYN = Decl("dyn")


def escape(name: str) -> str | None:
    """A property name as CEL sees it, or None when it cannot be declared."""
    if name in _RESERVED:
        return f"__{name}__"
    out = name.replace("__", "__underscores__").replace(".", "__dot__").replace("-", "__dash__")
    out = out.replace("/", "__slash__")
    return out if out.replace("_", "a").isalnum() and not out[0].isdigit() else None


def declared(node: dict[str, Any], *, resource_root: bool = False) -> Decl | None:
    """Kubernetes' SchemaDeclType: the CEL type of a schema node, or None when it is not declared."""
    if node.get("x-kubernetes-int-or-string"):
        return _DYN
    if resource_root or node.get("x-kubernetes-embedded-resource"):
        node = copy.deepcopy(node)
        node.setdefault("type", "object")
        props = node.setdefault("properties", {})
        props.setdefault("apiVersion", {"type": "string"})
        props.setdefault("kind", {"type": "string"})
        meta = props.setdefault("metadata", {"type": "object"})
        meta.setdefault("properties", {}).update(name={"type": "string"}, generateName={"type": "string"})
    kind = node.get("type")
    if kind == "array":
        items = node.get("items")
        item = declared(items) if isinstance(items, dict) else None
        return Decl("list", element=item) if item is not None else None
    if kind == "object":
        extra = node.get("additionalProperties")
        if isinstance(extra, dict):
            value = declared(extra)
            return Decl("map", element=value) if value is not None else None
        fields = {}
        for name, child in (node.get("properties") or {}).items():
            child_decl = declared(child)
            escaped = escape(name)
            if child_decl is not None and escaped is not None:
                fields[escaped] = child_decl
        return Decl("object", fields=fields)
    if kind in ("string", "boolean", "number", "integer"):
        return Decl("scalar")
    return None


# --- compiling a rule ----------------------------------------------------------------------------------


def _children(tree: Any) -> list[Any]:
    return [c for c in getattr(tree, "children", []) if hasattr(c, "data")]


def _token(tree: Any, index: int) -> str:
    tokens = [c for c in tree.children if not hasattr(c, "data")]
    return str(tokens[index])


class _Checker:
    """Resolves the declared type of member chains; records selections of undeclared fields."""

    def __init__(self, scope: dict[str, Decl]) -> None:
        self.scope = [scope]
        self.errors: list[str] = []

    def lookup(self, name: str) -> Decl | None:
        for frame in reversed(self.scope):
            if name in frame:
                return frame[name]
        return None

    def check(self, tree: Any) -> Decl | None:
        """The declared type of `tree` (None: dynamic), checking every sub-expression."""
        rule = tree.data
        if rule == "member_dot":
            (inner,) = _children(tree)
            return self._select(self.check(inner), _token(tree, 0))
        if rule == "member_dot_arg":
            inner, *rest = _children(tree)
            target = self.check(inner)
            method = _token(tree, 0)
            args = _children(rest[0]) if rest else []
            if method in _LIST_MACROS and len(args) >= 2 and _is_ident(args[0]):
                variable = _ident_name(args[0])
                element = target.element if target is not None and target.kind in ("list", "map") else None
                if target is not None and target.kind == "map":
                    element = Decl("scalar")  # a map's macros range over its keys
                self.scope.append({variable: element or _DYN})
                for arg in args[1:]:
                    self.check(arg)
                self.scope.pop()
                return None
            for arg in args:
                self.check(arg)
            return None
        if rule == "member_index":
            inner, index = _children(tree)
            target = self.check(inner)
            self.check(index)
            return target.element if target is not None and target.kind in ("list", "map") else None
        if rule == "ident":
            return self.lookup(_token(tree, 0))
        if rule == "ident_arg":
            for child in _children(tree):
                self.check(child)
            return None
        result = None
        for child in _children(tree):
            result = self.check(child)
        # only pass-through nodes (expr → … → member → primary) keep a type: operators make new values
        return result if len(_children(tree)) == 1 and rule in _PASS_THROUGH else None

    def _select(self, target: Decl | None, name: str) -> Decl | None:
        if target is None or target.kind == "dyn":
            return None
        if target.kind == "map":
            return target.element
        if target.kind == "object":
            if name not in target.fields:
                self.errors.append(f"undefined field '{name}'")
                return None
            return target.fields[name]
        self.errors.append(f"type '{target.kind}' does not support field selection ('{name}')")
        return None


_PASS_THROUGH = {
    "expr", "conditionalor", "conditionaland", "relation", "addition", "multiplication", "unary", "member",
    "primary", "paren_expr", "exprlist",
}  # fmt: skip


def _is_ident(tree: Any) -> bool:
    while hasattr(tree, "data") and tree.data != "ident":
        children = _children(tree)
        if len(children) != 1 or tree.data not in _PASS_THROUGH:
            return False
        tree = children[0]
    return hasattr(tree, "data") and tree.data == "ident"


def _ident_name(tree: Any) -> str:
    while tree.data != "ident":
        tree = _children(tree)[0]
    return _token(tree, 0)


@dataclass
class CompiledRule:
    path: str  # where the rule sits, e.g. ".spec"
    rule: str
    message: str
    program: Any
    transition: bool  # names oldSelf


def compile_rule(rule: str, node: dict[str, Any], path: str, *, resource_root: bool = False) -> CompiledRule:
    """Compile `rule` on schema `node` as the API server does on CRD create (raises Invalid)."""
    import celpy

    decl = declared(node, resource_root=resource_root)
    if decl is None:
        raise Invalid(
            path, [f"x-kubernetes-validations: rules are not allowed on a node without a type ({path})"]
        )
    env = celpy.Environment()
    try:
        tree = env.compile(rule)
    except celpy.CELParseError as exc:
        raise Invalid(path, [f"compilation failed: {exc}"]) from None
    checker = _Checker({"self": decl, "oldSelf": decl})
    checker.check(tree)
    if checker.errors:
        raise Invalid(path, [f"{path}: compilation failed: {e}" for e in dict.fromkeys(checker.errors)])
    return CompiledRule(path, rule, "", env.program(tree), "oldSelf" in _identifiers(tree))


def _identifiers(tree: Any) -> set[str]:
    found = set()
    for sub in tree.iter_subtrees():
        if sub.data == "ident":
            found.add(_token(sub, 0))
    return found


# --- custom resources ----------------------------------------------------------------------------------


def _walk_rules(
    node: dict[str, Any], path: str, out: list[tuple[str, dict[str, Any], dict[str, Any]]]
) -> None:
    for rule in node.get("x-kubernetes-validations") or []:
        out.append((path, node, rule))
    for name, child in (node.get("properties") or {}).items():
        _walk_rules(child, f"{path}.{name}", out)
    if isinstance(node.get("additionalProperties"), dict):
        _walk_rules(node["additionalProperties"], f"{path}[*]", out)
    if isinstance(node.get("items"), dict):
        _walk_rules(node["items"], f"{path}[]", out)


def _values_at(obj: Any, path: str) -> list[Any]:
    """Every value of `obj` at a rule path (`.a.b[].c[*]`), absent nodes skipped."""
    values = [obj]
    for part in path.replace("[]", ".[]").replace("[*]", ".[*]").split(".")[1:]:
        nxt: list[Any] = []
        for value in values:
            if part == "[]" and isinstance(value, list):
                nxt.extend(value)
            elif part == "[*]" and isinstance(value, dict):
                nxt.extend(value.values())
            elif isinstance(value, dict) and part in value:
                nxt.append(value[part])
        values = nxt
    return values


def _pairs_at(new: Any, old: Any, path: str) -> list[tuple[Any, Any]]:
    """(new, old) value pairs at a rule path; list items pair by position, map values by key."""
    pairs = [(new, old)]
    for part in path.replace("[]", ".[]").replace("[*]", ".[*]").split(".")[1:]:
        nxt: list[tuple[Any, Any]] = []
        for value, before in pairs:
            if part == "[]" and isinstance(value, list):
                olds = before if isinstance(before, list) else []
                nxt.extend((v, olds[i] if i < len(olds) else None) for i, v in enumerate(value))
            elif part == "[*]" and isinstance(value, dict):
                olds = before if isinstance(before, dict) else {}
                nxt.extend((v, olds.get(k)) for k, v in value.items())
            elif isinstance(value, dict) and part in value:
                nxt.append((value[part], before.get(part) if isinstance(before, dict) else None))
        pairs = nxt
    return pairs


def _draft4(node: Any) -> Any:
    """OpenAPI 3.0 → JSON schema draft 4: `nullable` allows null; x-kubernetes-int-or-string is int|string."""
    if isinstance(node, list):
        return [_draft4(n) for n in node]
    if not isinstance(node, dict):
        return node
    out = {k: _draft4(v) for k, v in node.items() if not k.startswith("x-kubernetes-")}
    if node.get("x-kubernetes-int-or-string"):
        out["anyOf"] = [{"type": "integer"}, {"type": "string"}]
    if node.get("nullable") and "type" in out:
        out["type"] = [out["type"], "null"]
    return out


class CustomResourceValidator:
    """A CRD as the API server takes it (structural, rules compiled) and validates its objects."""

    def __init__(self, crd: dict[str, Any]) -> None:
        validate_builtin(crd)
        version = crd["spec"]["versions"][0]
        self.schema = version["schema"]["openAPIV3Schema"]
        self.kind = crd["spec"]["names"]["kind"]
        self._validator = jsonschema.Draft4Validator(_draft4(self.schema))
        self.rules: list[CompiledRule] = []
        problems: list[str] = []
        found: list[tuple[str, dict[str, Any], dict[str, Any]]] = []
        _walk_rules(self.schema, "", found)
        for path, node, rule in found:
            try:
                compiled = compile_rule(rule["rule"], node, path or ".", resource_root=path == "")
            except Invalid as exc:
                problems.extend(exc.problems)
                continue
            compiled.message = rule.get("message") or f"failed rule: {rule['rule']}"
            self.rules.append(compiled)
        if problems:
            raise Invalid(f"CustomResourceDefinition {crd['metadata']['name']}", problems)

    def validate(self, obj: dict[str, Any], old: dict[str, Any] | None = None) -> None:
        """Raise Invalid as the API server would answer a create (`old` None) or an update of `obj`."""
        from celpy import celtypes, json_to_cel

        what = f"{self.kind} {obj.get('metadata', {}).get('name')!r}"
        problems = [
            f".{'.'.join(str(p) for p in e.absolute_path)}: {e.message}"
            for e in self._validator.iter_errors(obj)
        ]
        if problems:
            raise Invalid(what, problems)
        for rule in self.rules:
            path = "" if rule.path == "." else rule.path
            if old is None:
                if rule.transition:
                    continue
                pairs = [(value, None) for value in _values_at(obj, path)]
            else:
                pairs = _pairs_at(obj, old, path)
            for value, before in pairs:
                if rule.transition and before is None:
                    continue
                activation = {"self": json_to_cel(value)}
                if rule.transition:
                    activation["oldSelf"] = json_to_cel(before)
                try:
                    result = rule.program.evaluate(activation)
                except Exception as exc:  # a runtime error is a failed rule too
                    problems.append(f"{rule.path}: {rule.message} (evaluation error: {exc})")
                    continue
                if isinstance(result, Exception) or not (isinstance(result, celtypes.BoolType) and result):
                    problems.append(f"{rule.path}: Invalid value: {rule.message}")
        if problems:
            raise Invalid(what, problems)


def validate_builtin(obj: dict[str, Any]) -> None:
    """Raise Invalid unless `obj` passes the Kubernetes OpenAPI schema of its kind (strict)."""
    try:
        kubernetes_validate.validate(obj, KUBERNETES_VERSION, strict=True)
    except kubernetes_validate.ValidationError as exc:
        name = obj.get("metadata", {}).get("name")
        raise Invalid(f"{obj.get('kind')} {name!r}", [str(exc)]) from None


def merge_patch(target: Any, patch: Any) -> Any:
    """RFC 7386 JSON merge patch (what `kubectl patch --type merge` and the operator's patches send)."""
    if not isinstance(patch, dict):
        return copy.deepcopy(patch)
    out = dict(target) if isinstance(target, dict) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = merge_patch(out.get(key), value)
    return out


@functools.cache
def shipped_crd() -> CustomResourceValidator:
    """The checked-in crds/simulationrun.yaml as the API server takes it (tests/test_crd.py: no drift)."""
    return CustomResourceValidator(yaml.safe_load(SHIPPED_CRD.read_text()))


def admit(obj: dict[str, Any]) -> None:
    """Raise Invalid unless the API server would store `obj` as created (`kubectl apply`, `helm install`):
    a CRD is structural and its rules compile; a SimulationRun passes the shipped CRD; any other built-in
    kind its OpenAPI schema."""
    if obj.get("kind") == "CustomResourceDefinition":
        CustomResourceValidator(obj)
    elif obj.get("kind") == "SimulationRun":
        shipped_crd().validate(obj)
    else:
        validate_builtin(obj)
