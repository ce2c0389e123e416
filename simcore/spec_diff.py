"""What differs between the specs of two runs (`carlos compare` lists it before the verdicts): a changed
threshold or parameter explains a changed verdict, and must not read as a regression of the software.

Compared: the criteria (every run's and each scenario's), the parameters (`spec.parameters`, each scenario's,
the sweep), the simulation's step, end and seed, and the contents of the scenario files (their SHA-256, kept
by `carlos run` in `scenarios.json` next to run.yaml). Pure functions but `record_scenario_digests`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from simcore.evaluation.criteria import format_number
from simcore.spec import SimulationRun

#: key next to run.yaml: {scenario name: {"file": as the manifest names it, "sha256": of its bytes}}
SCENARIO_DIGESTS_KEY = "scenarios.json"


def scenario_digests(files: Mapping[str, tuple[str, Path]]) -> dict[str, dict[str, str]]:
    """{scenario name: {file, sha256}} of scenario files read on this machine."""
    return {
        name: {"file": named, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
        for name, (named, path) in sorted(files.items())
    }


def _text(value: Any) -> str:
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True, separators=(", ", ": "), ensure_ascii=False)


def _criteria(items: list[Any]) -> list[str]:
    """`minDistance >= 1.5`, `collision == 0 (optional)`: as a manifest writes them."""
    out = []
    for c in items:
        if isinstance(c, str):
            out.append(c)
            continue
        text = f"{c.metric} {c.operator} {format_number(c.value)}"
        if c.name and _says(c.name, c):
            text = c.name  # as the manifest wrote it
        elif c.name:
            text = f"{c.name}: {text}"
        out.append(text + (" (optional)" if c.optional else ""))
    return out


def _says(name: str, criterion: Any) -> bool:
    """Whether a criterion's name is the criterion itself (`minDistance >= 1.5`, as a string criterion)."""
    from pydantic import TypeAdapter

    from simcore.spec import Criterion

    try:
        parsed = TypeAdapter(Criterion).validate_python(name)
    except ValueError:
        return False
    return bool(
        (parsed.metric, parsed.operator, parsed.value)
        == (criterion.metric, criterion.operator, criterion.value)
    )


def _listed(what: str, before: list[str], after: list[str]) -> list[str]:
    removed = [c for c in before if c not in after]
    added = [c for c in after if c not in before]
    out = [f"{what}: removed {c!r}" for c in removed] + [f"{what}: added {c!r}" for c in added]
    if not out and before != after:
        out.append(f"{what}: reordered")
    return out


def _mapping(what: str, before: Mapping[str, Any], after: Mapping[str, Any]) -> list[str]:
    out = []
    for key in sorted(set(before) | set(after)):
        if key not in after:
            out.append(f"{what} {key}: {_text(before[key])} → unset")
        elif key not in before:
            out.append(f"{what} {key}: unset → {_text(after[key])}")
        elif before[key] != after[key]:
            out.append(f"{what} {key}: {_text(before[key])} → {_text(after[key])}")
    return out


def spec_differences(
    baseline: SimulationRun | None,
    candidate: SimulationRun | None,
    baseline_digests: Mapping[str, Any] | None = None,
    candidate_digests: Mapping[str, Any] | None = None,
) -> list[str]:
    """One line per difference, criteria first, then parameters, simulation, scenario files (pure). A side
    whose spec could not be read (another version's run.yaml) compares as nothing known."""
    if baseline is None or candidate is None:
        return []
    a, b = baseline.spec, candidate.spec
    out = _listed("criteria", _criteria(a.evaluation.criteria), _criteria(b.evaluation.criteria))
    scenarios_a = {s.name: s for s in a.scenarios}
    scenarios_b = {s.name: s for s in b.scenarios}
    for name in [n for n in scenarios_a if n in scenarios_b]:
        sa, sb = scenarios_a[name], scenarios_b[name]
        out += _listed(f"{name} criteria", _criteria(sa.criteria), _criteria(sb.criteria))
    out += _mapping("parameter", a.parameters, b.parameters)
    for name in [n for n in scenarios_a if n in scenarios_b]:
        out += _mapping(f"{name} parameter", scenarios_a[name].parameters, scenarios_b[name].parameters)
    sweep_a = a.sweep.model_dump(mode="json", by_alias=True, exclude_none=True)
    sweep_b = b.sweep.model_dump(mode="json", by_alias=True, exclude_none=True)
    out += _mapping("sweep.matrix", sweep_a.pop("matrix", {}), sweep_b.pop("matrix", {}))
    out += _mapping("sweep", sweep_a, sweep_b)
    simulation_a = a.simulation.model_dump(mode="json", by_alias=True, exclude_none=True)
    simulation_b = b.simulation.model_dump(mode="json", by_alias=True, exclude_none=True)
    out += _mapping("simulation", simulation_a, simulation_b)
    out += [f"scenario {n}: only in the baseline" for n in scenarios_a if n not in scenarios_b]
    out += [f"scenario {n}: only in the candidate" for n in scenarios_b if n not in scenarios_a]
    digests_a, digests_b = baseline_digests or {}, candidate_digests or {}
    for name in [n for n in scenarios_a if n in scenarios_b]:
        da, db = digests_a.get(name), digests_b.get(name)
        if da and db and da.get("sha256") != db.get("sha256"):
            out.append(
                f"scenario {name}: file contents differ ({da.get('file')} sha256 {str(da['sha256'])[:12]} → "
                f"{db.get('file')} sha256 {str(db['sha256'])[:12]})"
            )
    return out
