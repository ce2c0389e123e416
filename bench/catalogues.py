"""The differential on real catalogues, on the user's path: every scenario the esmini player ends on its own
(INDEX.tsv of the public corpus: Euro NCAP, UN R157 ALKS, ASAM examples) run through `carlos run` — a fresh
process per file, a manifest per file, recording on — its trajectories read back from the MCAP it wrote, and
compared with what esmini makes of the same file.

Comparison (`simcore.conformance.compare`, as `carlos conformance`): per entity the position RMSE over the
common time span and the distance at the last common time. A file agrees by the catalogue rule when it ran
to its own end, its end time is within 0.15 s of esmini's and every compared entity's final position within
1 m; by the RMSE rule when the end is within 0.1 s and every RMSE within 0.5 m (`carlos conformance`'s).
Entities a controller CARLOS does not model drives are reported, not compared.

Prints a table per catalogue and per feature (the OpenSCENARIO action, condition, position and controller
types a file uses, read from its XML), the disagreeing files with the worst entity and its error, and as
its last line one JSON object (per-catalogue agreement counts).

Usage: .venv/bin/python bench/catalogues.py CORPUS [--esmini PATH] [-j J] [-k GLOB…] [--carlos CMD]
           [--keep DIR]
CORPUS is the public corpus folder (with INDEX.tsv); esmini comes from --esmini, $ESMINI or PATH (exit 3
without it). --carlos replaces the `carlos` command (e.g. another checkout's, to measure before a change).
"""

from __future__ import annotations

import argparse
import csv
import json
import shlex
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore import conformance as conf  # noqa: E402
from simcore.reference_player import find_esmini, run_esmini  # noqa: E402

CATALOGUES = {
    "OSC-NCAP-scenarios": "Euro NCAP",
    "sl-3-1-osc-alks-scenarios": "UN R157 ALKS",
    "openscenario.api.test": "ASAM examples",
}
#: elements that only group the actions, conditions and positions of a file (not features of their own)
CONTAINERS = {
    "PrivateAction",
    "GlobalAction",
    "UserDefinedAction",
    "LongitudinalAction",
    "LateralAction",
    "ControllerAction",
    "RoutingAction",
    "AppearanceAction",
    "EntityAction",
    "InfrastructureAction",
    "TrafficAction",
    "ParameterAction",
    "VariableAction",
    "Condition",
    "ByEntityCondition",
    "ByValueCondition",
    "EntityCondition",
    "ValueCondition",
    "Position",
    "Action",
}
RUN_TIMEOUT_S = 600.0
_LOAD = threading.Lock()  # the scenario reader's per-process caches are not meant for threads


@dataclass
class FileRun:
    """One file: what `carlos run` did (exit code, result compared with esmini) and the features it uses."""

    path: str  # relative to the corpus
    catalogue: str
    result: conf.ScenarioResult
    exit_code: int | None = None
    features: list[str] = field(default_factory=list)


def esmini_ended(corpus: Path, include: list[str] | None = None) -> list[str]:
    """The INDEX.tsv paths of the scenarios esmini ends on its own (`ok`), optionally filtered by globs."""
    with (corpus / "INDEX.tsv").open(newline="") as handle:
        rows = [r for r in csv.DictReader(handle, delimiter="\t")]
    paths = [r["path"] for r in rows if r.get("kind") == "scenario" and r.get("esmini_status") == "ok"]
    if include:
        paths = [p for p in paths if any(Path(p).match(g) for g in include)]
    return paths


def features(path: Path) -> list[str]:
    """The OpenSCENARIO action, condition and position types a file's XML uses (sorted `kind:Type`); its
    catalogues' contents are not read."""
    from simcore.scenario.xosc_xml import read_xml

    found: set[str] = set()
    for element in read_xml(path, what="OpenSCENARIO file").iter():
        tag = element.tag if isinstance(element.tag, str) else ""
        if tag in CONTAINERS:
            continue
        for suffix, kind in (("Action", "action"), ("Condition", "condition"), ("Position", "position")):
            if tag.endswith(suffix):
                found.add(f"{kind}:{tag}")
    return sorted(found)


def manifest(scenario: Path, output: Path, cap_seconds: float) -> str:
    """The SimulationRun of one file as a user writes it: conformance's step, seed and cap, recording on."""
    return (
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: catalogue}\nspec:\n"
        f"  scenarios: [{{name: s, openscenario: {json.dumps(str(scenario))}}}]\n"
        f"  simulation: {{stepSeconds: {conf.STEP_SECONDS}, maxSeconds: {cap_seconds}, seed: 1}}\n"
        "  recording: {enabled: true}\n"
        f"  output: {{url: {json.dumps(output.as_uri())}}}\n"
    )


def carlos_run(
    carlos: list[str],
    scenario: Path,
    workdir: Path,
    names: set[str],
    cap_seconds: float = conf.DEFAULT_CAP_SECONDS,
) -> tuple[conf.ScenarioResult, conf.Trace, int | None]:
    """Run `scenario` through `carlos run` (a fresh process) and read back its summary and recording
    (`simcore.conformance.recorded_run`): (result, trace on the scenario's time axis by entity name — those
    of `names` —, exit code)."""
    workdir.mkdir(parents=True, exist_ok=True)
    out = workdir / "results"
    spec = workdir / "run.yaml"
    spec.write_text(manifest(scenario.resolve(), out, cap_seconds))
    result = conf.ScenarioResult(file=str(scenario), kind="scenario")
    trace = conf.Trace()
    started = time.perf_counter()
    try:
        done = subprocess.run(
            [*carlos, "run", str(spec), "-q", "-j", "1"],
            cwd=workdir,
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired:
        result.status, result.message = "error", f"carlos run did not end within {RUN_TIMEOUT_S:g} s wall"
        return result, trace, None
    index = out / "catalogue" / "0"
    if not (index / "summary.json").is_file():
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or [""]
        result.status = "bad_input" if done.returncode == 2 else "error"
        result.message = f"exit {done.returncode}: {tail[0][:200]}"
        return result, trace, done.returncode
    result, trace = conf.recorded_run(index, str(scenario), frozenset(names))
    result.wall_seconds = time.perf_counter() - started
    result.warnings = [line for line in done.stderr.splitlines() if "warning" in line.lower()]
    return result, trace, done.returncode


def one(corpus: Path, rel: str, scratch: Path, carlos: list[str], esmini: Path, number: int) -> FileRun:
    path = corpus / rel
    run = FileRun(rel, rel.split("/", 1)[0], conf.ScenarioResult(file=rel))
    try:
        run.features = features(path)
    except Exception as exc:  # an unreadable file is still run (and reported by carlos run)
        run.features = [f"unreadable:{type(exc).__name__}"]
    controlled: set[str] = set()
    names: set[str] = set()
    try:
        from simcore.scenario import model as m
        from simcore.scenario.xosc import load_scenario

        with _LOAD:
            scenario = load_scenario(path, {})
        controlled = conf.uncompared_entities(scenario)
        names = {e.name for e in scenario.entities}
        kinds = {k for ks in m.controller_kinds(scenario).values() for k in ks}
        run.features += sorted(f"controller:{k}" for k in kinds)
    except Exception:
        pass
    played = run_esmini(esmini, path, step=conf.STEP_SECONDS)
    result, trace, run.exit_code = carlos_run(
        carlos, path, scratch / f"{number:03d}", names | set(played.tracks)
    )
    result.file = rel
    run.result = result
    if not played.ok:
        result.reference_message = played.message
        return run
    result.reference = "esmini"
    conf.compare(result, trace, played.tracks, played.end, controlled)
    return run


def _rate(agreed: int, total: int) -> str:
    return f"{100 * agreed / total:.0f}%" if total else "—"


def catalogue_table(runs: list[FileRun]) -> tuple[list[str], dict[str, dict[str, int]]]:
    groups: dict[str, list[FileRun]] = defaultdict(list)
    for run in runs:
        groups[CATALOGUES.get(run.catalogue, run.catalogue)].append(run)
    lines = [
        "| catalogue | files | carlos run errors | ended | esmini ran | agreed (final ≤1 m, end ≤0.15 s) | "
        "agreed (RMSE ≤0.5 m, end ≤0.1 s) |",
        "|---|---|---|---|---|---|---|",
    ]
    figures: dict[str, dict[str, int]] = {}
    for name in [*sorted(groups), "all"]:
        rows = runs if name == "all" else groups[name]
        compared = [r for r in rows if r.result.reference is not None]
        final = sum(r.result.agreed_final for r in compared)
        rmse = sum(r.result.agreed for r in compared)
        errors = sum(r.result.status in ("error", "bad_input") for r in rows)
        ended = sum(r.result.ended for r in rows)
        figures[name] = {"files": len(rows), "compared": len(compared), "agreed": final, "agreed_rmse": rmse}
        lines.append(
            f"| {name} | {len(rows)} | {errors} | {ended} | {len(compared)} | {final} ({_rate(final, len(rows))}) "
            f"| {rmse} ({_rate(rmse, len(rows))}) |"
        )
    return lines, figures


def feature_table(runs: list[FileRun]) -> list[str]:
    groups: dict[str, list[FileRun]] = defaultdict(list)
    for run in runs:
        for feature in run.features:
            groups[feature].append(run)
    lines = [
        "| feature | files | agreed (final rule) | agreed (RMSE rule) | disagreeing |",
        "|---|---|---|---|---|",
    ]
    for feature in sorted(groups):
        rows = groups[feature]
        final = sum(r.result.agreed_final for r in rows)
        rmse = sum(r.result.agreed for r in rows)
        lines.append(f"| {feature} | {len(rows)} | {final} | {rmse} | {len(rows) - final} |")
    return lines


def disagreeing(runs: list[FileRun]) -> list[str]:
    lines = []
    for run in runs:
        r = run.result
        if r.agreed_final:
            continue
        compared = [e for e in r.entities if e.scripted and e.rmse is not None]
        worst = max(compared, key=lambda e: (e.final_error or 0.0, e.rmse or 0.0), default=None)
        where = (
            f"worst {worst.name}: final {worst.final_error:.2f} m, RMSE {worst.rmse:.2f} m"
            if worst is not None and worst.final_error is not None and worst.rmse is not None
            else "no entity compared"
        )
        end = (
            f"end {r.sim_seconds:.2f} / esmini {r.reference_end:.2f} s" if r.reference_end is not None else ""
        )
        why = r.message or r.reference_message
        text = f"- {run.path}: {r.status}; {end}; {where}" if r.loaded else f"- {run.path}: {r.status}"
        lines.append(text + (f"; {why[:160]}" if why else ""))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("corpus", type=Path, help="the public corpus folder (with INDEX.tsv)")
    parser.add_argument("--esmini", type=Path, default=None)
    parser.add_argument("--jobs", "-j", type=int, default=2)
    parser.add_argument("-k", dest="include", action="append", help="only paths matching this glob")
    parser.add_argument("--carlos", default=None, help="the carlos command (default: this environment's)")
    parser.add_argument("--keep", type=Path, default=None, help="keep the manifests and results here")
    args = parser.parse_args()
    if not (args.corpus / "INDEX.tsv").is_file():
        print(f"no INDEX.tsv in {args.corpus}: give the public corpus folder", file=sys.stderr)
        sys.exit(2)
    esmini = find_esmini(args.esmini)
    if esmini is None:
        print("no esmini binary: give --esmini PATH or set ESMINI=/path/to/esmini", file=sys.stderr)
        sys.exit(3)
    carlos = shlex.split(args.carlos) if args.carlos else [str(Path(sys.executable).parent / "carlos")]
    corpus = args.corpus.resolve()
    files = esmini_ended(corpus, args.include)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="carlos-catalogues-") as name:
        scratch = args.keep.resolve() if args.keep else Path(name)
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            runs = list(
                pool.map(
                    lambda item: one(corpus, item[1], scratch, carlos, esmini, item[0]), enumerate(files)
                )
            )
    wall = time.perf_counter() - started
    lines, figures = catalogue_table(runs)
    print(f"# carlos run vs esmini on {corpus} ({len(files)} scenarios esmini ends on its own)\n")
    print("\n".join(lines))
    print("\n## per feature\n")
    print("\n".join(feature_table(runs)))
    print("\n## disagreeing (catalogue rule)\n")
    print("\n".join(disagreeing(runs)) or "none")
    print(f"\n{wall:.1f} s wall, -j {args.jobs}")
    print(json.dumps({"catalogues": figures, "wall_s": round(wall, 1)}))


if __name__ == "__main__":
    main()
