"""A search in rounds through the sweep pipeline (the local executor and its warm workers).

Round r asks the study for `batchSize` points, runs them as indexes r·batchSize… of a derived run (a sweep
over a ParameterValueDistribution of every point so far: earlier indexes are complete and kept), tells the
study their losses and stores, in one atomic write, the study and every evaluated point
(`<run>/search/state.json`). An interrupted search resumes from the last stored round; the round in flight
asks the same points again (see `optimizer`), and its finished indexes are kept by the executor.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simcore.errors import BadInput
from simcore.evaluation.metrics import KNOWN_METRICS
from simcore.executor import Events, RunReport, _dump_spec, execute
from simcore.scenario.parameters import format_value
from simcore.search.export import distribution_xml
from simcore.search.objective import MARGIN, loss, raw_value
from simcore.search.optimizer import Study, check_strategy
from simcore.search.report import search_document
from simcore.search.space import Dimension, dimensions, read_declarations
from simcore.spec import ParameterValue, Search, SimulationRun, Sweep
from simcore.store import Store, open_store

STATE_VERSION = 1


@dataclass
class SearchReport:
    run: RunReport
    document: dict[str, Any]
    #: per round run by this call: (seconds in the optimiser: load, ask, tell; seconds of the whole round)
    timings: list[tuple[float, float]] = field(default_factory=list)


def search_space(run: SimulationRun, scenario_file: Path) -> list[Dimension]:
    """The search's dimensions, checked against the scenario (bad input names the field)."""
    search = _search_of(run)
    check_strategy(search.strategy)
    metric = search.objective.metric
    if metric != MARGIN and metric not in KNOWN_METRICS and not metric.startswith("detection."):
        raise BadInput(
            f"unknown metric {metric!r}: use margin or one of {', '.join(sorted(KNOWN_METRICS))}",
            field="spec.search.objective.metric",
        )
    return dimensions(search, read_declarations(scenario_file), source=scenario_file.name)


def _search_of(run: SimulationRun) -> Search:
    if run.spec.search is None:
        raise ValueError("the run has no spec.search")
    return run.spec.search


def derived_run(run: SimulationRun, points_file: Path) -> SimulationRun:
    """The sweep that runs the points listed in `points_file`, one index each, in order."""
    spec = run.spec.model_copy(update={"search": None, "sweep": Sweep(distribution=str(points_file))})
    return run.model_copy(update={"spec": spec})


def _state_bytes(run: SimulationRun, log: list[dict[str, Any]], points: list[dict[str, Any]]) -> bytes:
    state = {"version": STATE_VERSION, "spec": _dump_spec(run).decode(), "study": log, "points": points}
    return (json.dumps(state, indent=1) + "\n").encode()


def _load_state(run: SimulationRun, store: Store) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(the study's journal log, the evaluated points) stored after the last complete round."""
    key = f"{run.name}/search/state.json"
    if not store.exists(key):
        return [], []
    state = json.loads(store.get_bytes(key))
    spec = _dump_spec(run).decode()
    if state.get("version") != STATE_VERSION or state.get("spec") != spec:
        raise BadInput(
            f"a search named {run.name!r} with a different spec is already stored at {store.url_for(run.name)}: "
            "change metadata.name",
            field="metadata.name",
        )
    return list(state["study"]), list(state["points"])


def _check_resumed(summary: dict[str, Any], parameters: dict[str, ParameterValue], name: str) -> None:
    """An index kept from an interrupted round must be the point the study asks again."""
    stored = summary.get("parameters", {})
    if any(str(stored.get(key)) != format_value(value) for key, value in parameters.items()):
        raise BadInput(
            f"index {summary['index']} of search {name!r} was run with other parameters than the resumed "
            "study asks (a different optuna version?): change metadata.name to start the search anew",
            field="metadata.name",
        )


def _losses(run: SimulationRun, points: list[dict[str, Any]], start: int) -> list[float | None]:
    """The sampler's loss of points[start:]: a run without the metric counts as the worst loss so far."""
    search = _search_of(run)
    boundary = search.strategy == "boundary"
    finite = [
        loss(p["objective"], search.objective, boundary=boundary)
        for p in points[:start]
        if p["objective"] is not None
    ]
    out: list[float | None] = []
    for point in points[start:]:
        if point["status"] == "error":
            out.append(None)
            continue
        if point["objective"] is None:
            out.append(max(finite) if finite else 0.0)
            continue
        value = loss(point["objective"], search.objective, boundary=boundary)
        finite.append(value)
        out.append(value)
    return out


def run_search(
    run: SimulationRun,
    *,
    base_dir: Path,
    scenario_file: Path,
    output_url: str | None = None,
    parallel: int | None = None,
    events: Events | None = None,
    on_round: Callable[[dict[str, Any]], None] = lambda document: None,
) -> SearchReport:
    """Run (or resume) the search of `run` to its budget; writes search.json and the failing points."""
    search = _search_of(run)
    spec = run.spec
    space = search_space(run, scenario_file)
    seed = search.seed if search.seed is not None else spec.simulation.seed
    url = output_url or spec.output.url
    store = open_store(url, endpoint=spec.output.endpoint, region=spec.output.region)
    criteria = [*spec.evaluation.criteria, *spec.scenarios[0].criteria]
    prefix = f"{run.name}/search"
    with tempfile.TemporaryDirectory(prefix="carlos-search-") as scratch:
        work = Path(scratch)
        points_file = work / "points.xosc"
        log, points = _load_state(run, store)
        report: RunReport | None = None
        timings: list[tuple[float, float]] = []
        while len(points) < search.budget or report is None:
            start = len(points)
            round_number = start // search.batch_size
            count = min(search.batch_size, search.budget - start)
            started = time.perf_counter()
            round_log = list(log)  # the stored log stays as it was until the round completes
            study = Study(round_log, search.strategy, seed, round_number, startup=search.batch_size)
            asked = study.ask(space, count) if count else []
            optimizer_seconds = time.perf_counter() - started
            every: list[dict[str, ParameterValue]] = [p["parameters"] for p in points] + asked
            points_file.write_bytes(
                distribution_xml(scenario_file, every, f"search {run.name}: evaluated points")
            )
            report = execute(
                derived_run(run, points_file),
                base_dir=base_dir,
                output_url=url,
                parallel=parallel,
                events=events,
                record=run,
            )
            if not count:
                break
            explore = search.strategy in ("random", "lhs") or round_number == 0
            for position, parameters in enumerate(asked):
                summary = report.outcomes[start + position]
                _check_resumed(summary, parameters, run.name)
                points.append(
                    {
                        "index": start + position,
                        "round": round_number,
                        "parameters": parameters,
                        "status": summary["status"],
                        "objective": raw_value(search.objective, criteria, summary),
                        "explore": explore,
                    }
                )
            told = time.perf_counter()
            for position, value in enumerate(_losses(run, points, start)):
                study.tell(position, value)
            optimizer_seconds += time.perf_counter() - told
            timings.append((optimizer_seconds, time.perf_counter() - started))
            log = round_log
            store.put_bytes(f"{prefix}/state.json", _state_bytes(run, log, points))
            store.sync()
            on_round(search_document(run.name, search, seed, space, points))
        document = search_document(run.name, search, seed, space, points)
        document["outputUrl"] = store.url_for(run.name)
        failing = [p["parameters"] for p in points if p["status"] == "failed"]
        if failing:
            document["failingScenarios"] = store.url_for(f"{prefix}/failing.xosc")
            store.put_bytes(
                f"{prefix}/failing.xosc",
                distribution_xml(
                    scenario_file, failing, f"search {run.name}: the {len(failing)} failing points"
                ),
            )
        store.put_bytes(f"{run.name}/search.json", (json.dumps(document, indent=2) + "\n").encode())
    return SearchReport(run=report, document=document, timings=timings)
