"""No import cycles in simcore.

What counts as an import (the graph is read from the source, nothing is imported):

- every import at module level is an edge, including those under `if TYPE_CHECKING:` (a type-only import is a
  design dependency too: module A needing B's types while B needs A's is the same circle);
- imports inside functions (lazy imports, for heavy or optional dependencies such as libsumo or the ROS
  message store) are not edges of simcore's graph; but inside simcore/scenario they may not hide a circle
  either: the scenario package's graph stays acyclic with them added.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "simcore"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _targets(node: ast.Import | ast.ImportFrom, current: str, known: set[str]) -> list[str]:
    """The simcore modules an import statement loads (`from pkg import mod` names the submodule)."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        base = node.module or ""
        if node.level:
            package = (
                current.split(".")[: -node.level] if not current.endswith("__init__") else current.split(".")
            )
            base = ".".join([*package, base] if base else package)
        names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
    out = []
    for name in names:
        while name and name not in known:  # `import simcore.x.y` of a name inside a module: its module
            name = name.rpartition(".")[0]
        if name.startswith("simcore") and name != current:
            out.append(name)
    return out


def import_graph(*, lazy_within: str | None = None) -> dict[str, set[str]]:
    """Module → the simcore modules it imports at module level (with `lazy_within`, also the function-level
    imports of the modules under that package of modules under it)."""
    found = modules()
    known = set(found)
    graph: dict[str, set[str]] = {}
    for name, path in found.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        graph[name] = _module_level_imports(tree, name, known)
        if lazy_within and name.startswith(lazy_within):
            lazy = _function_imports(tree, name, known)
            graph[name] |= {t for t in lazy if t.startswith(lazy_within)}
    return graph


def _module_level_imports(tree: ast.Module, name: str, known: set[str]) -> set[str]:
    out: set[str] = set()

    def visit(statements: list[ast.stmt]) -> None:
        for stmt in statements:
            if isinstance(stmt, ast.Import | ast.ImportFrom):
                out.update(_targets(stmt, name, known))
            elif isinstance(stmt, ast.If | ast.Try):  # `if TYPE_CHECKING:`, optional imports
                visit(stmt.body)
                visit(stmt.orelse)
                for handler in getattr(stmt, "handlers", []):
                    visit(handler.body)

    visit(tree.body)
    return out


def _function_imports(tree: ast.Module, name: str, known: set[str]) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            for inner in ast.walk(node):
                if isinstance(inner, ast.Import | ast.ImportFrom):
                    out.update(_targets(inner, name, known))
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each as a sorted list."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0

    def connect(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return out


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_type_checking_imports_and_submodules() -> None:
    graph = import_graph()
    assert "simcore.scenario.world" in graph["simcore.scenario.conditions"]  # under `if TYPE_CHECKING:`
    assert (
        "simcore.scenario.positions" in graph["simcore.scenario.engine"]
    )  # `from simcore.scenario import positions`
    assert "simcore.scenario.xosc_xml" not in graph["simcore.scenario.distribution"]  # lazy: not an edge


def test_simcore_has_no_import_cycle() -> None:
    found = cycles(import_graph())
    assert found == [], f"import cycles among simcore's module-level imports: {found}"


def test_no_lazy_import_hides_a_cycle_in_the_scenario_package() -> None:
    found = cycles(import_graph(lazy_within="simcore.scenario"))
    assert found == [], f"import cycles in simcore.scenario once its function-level imports count: {found}"


OPERATOR = ROOT / "operator" / "carlos_operator"


def operator_graph() -> dict[str, set[str]]:
    """carlos_operator's modules → the carlos_operator modules they import (module level, `if TYPE_CHECKING:`
    included) and, separately, every module any of their imports names (functions' too) under `*`."""
    graph: dict[str, set[str]] = {}
    for path in sorted(OPERATOR.glob("*.py")):
        name = f"carlos_operator.{path.stem}"
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        edges: set[str] = set()

        def visit(statements: list[ast.stmt], edges: set[str] = edges) -> None:
            for stmt in statements:
                if isinstance(stmt, ast.ImportFrom) and (stmt.module or "").startswith("carlos_operator"):
                    module = stmt.module or ""
                    edges.update(
                        f"{module}.{a.name}" if module == "carlos_operator" else module for a in stmt.names
                    )
                elif isinstance(stmt, ast.If | ast.Try):
                    visit(stmt.body)
                    visit(stmt.orelse)

        visit(tree.body)
        graph[name] = edges - {name}
        graph[f"{name}*"] = {
            alias.name if isinstance(node, ast.Import) else (node.module or "")
            for node in ast.walk(tree)
            if isinstance(node, ast.Import | ast.ImportFrom)
            for alias in node.names
        }
    return graph


def test_the_operator_has_no_import_cycle() -> None:
    graph = {k: v for k, v in operator_graph().items() if not k.endswith("*")}
    assert "carlos_operator.desired" in graph["carlos_operator.controller"]
    found = cycles(graph)
    assert found == [], f"import cycles among carlos_operator's modules: {found}"


def test_the_operators_decision_does_no_io() -> None:
    """desired.py (what a run should have) imports nothing that talks to Kubernetes or the object store, and
    none of the operator's modules that do (reading, apply, kube, the controller)."""
    imported = operator_graph()["carlos_operator.desired*"]
    io = {"kubernetes", "kopf", "boto3", "botocore", "threading", "simcore.store"}
    io |= {f"carlos_operator.{m}" for m in ("kube", "reading", "apply", "controller", "hosting", "inputs")}
    assert not {m for m in imported if m in io or m.split(".")[0] in io}, imported
