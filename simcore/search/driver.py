"""A search in rounds: the steps every runner of a search shares, and the local runner (`run_search`).

Round r asks the study for `batchSize` points (`ask_round`), runs them as indexes r·batchSize… of the run,
tells the study their losses (`tell_round`) and stores, in one atomic write, the study and every evaluated
point (`<run>/search/state.json`, `save_state`). An interrupted search resumes from the last stored round
(`load_state`); the round in flight asks the same points again (see `optimizer`). When the budget is spent,
`finish` writes `search.json` and the failing points.

Two runners share these steps, so both store the same state and ask the same points: `run_search` here
(locally: each round runs a derived sweep over every point so far through the executor and its warm
workers; earlier indexes are complete and kept), and the operator (one Indexed Job per round).
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
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


@dataclass
class Round:
    """One round of a search: its points, asked from the study stored after the rounds before it."""

    number: int
    start: int  # the global index of its first point
    asked: list[dict[str, ParameterValue]]
    study: Study
    log: list[dict[str, Any]]  # the journal with this round's trials (stored when the round completes)
    explore: bool  # its points are uniform over the space (they estimate the failure share)
    optimizer_seconds: float = 0.0

    @property
    def indexes(self) -> range:
        return range(self.start, self.start + len(self.asked))


def search_space(run: SimulationRun, scenario_file: Path) -> list[Dimension]:
    """The search's dimensions, checked against the scenario (bad input names the field)."""
    search = search_of(run)
    check_strategy(search.strategy)
    metric = search.objective.metric
    if metric != MARGIN and metric not in KNOWN_METRICS and not metric.startswith("detection."):
        raise BadInput(
            f"unknown metric {metric!r}: use margin or one of {', '.join(sorted(KNOWN_METRICS))}",
            field="spec.search.objective.metric",
        )
    return dimensions(search, read_declarations(scenario_file), source=scenario_file.name)


def search_of(run: SimulationRun) -> Search:
    if run.spec.search is None:
        raise ValueError("the run has no spec.search")
    return run.spec.search


def search_seed(run: SimulationRun) -> int:
    search = search_of(run)
    return search.seed if search.seed is not None else run.spec.simulation.seed


def rounds_total(search: Search) -> int:
    return -(-search.budget // search.batch_size)


def derived_run(run: SimulationRun, points_file: str | Path) -> SimulationRun:
    """The sweep that runs the points listed in `points_file`, one index each, in order."""
    spec = run.spec.model_copy(update={"search": None, "sweep": Sweep(distribution=str(points_file))})
    return run.model_copy(update={"spec": spec})


def state_key(run: SimulationRun) -> str:
    return f"{run.name}/search/state.json"


def state_bytes(run: SimulationRun, log: list[dict[str, Any]], points: list[dict[str, Any]]) -> bytes:
    state = {"version": STATE_VERSION, "spec": _dump_spec(run).decode(), "study": log, "points": points}
    return (json.dumps(state, indent=1) + "\n").encode()


def save_state(
    run: SimulationRun, store: Store, log: list[dict[str, Any]], points: list[dict[str, Any]]
) -> None:
    """The study and every evaluated point, in one write (the truth a resumed search starts from)."""
    store.put_bytes(state_key(run), state_bytes(run, log, points))
    store.sync()  # the round's results and the state that counts them are durable before the next round


def load_state(run: SimulationRun, store: Store) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(the study's journal log, the evaluated points) stored after the last complete round."""
    key = state_key(run)
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


def _check_resumed(summary: Mapping[str, Any], parameters: dict[str, ParameterValue], name: str) -> None:
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
    search = search_of(run)
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


def ask_round(
    run: SimulationRun, space: Sequence[Dimension], log: list[dict[str, Any]], points: list[dict[str, Any]]
) -> Round | None:
    """The next round after `points` (None: the budget is spent). The same stored state always asks the
    same points: a round interrupted and asked again runs the same parameters."""
    search = search_of(run)
    start = len(points)
    count = min(search.batch_size, search.budget - start)
    if count <= 0:
        return None
    started = time.perf_counter()
    number = start // search.batch_size
    round_log = list(log)  # the stored log stays as it was until the round completes
    study = Study(round_log, search.strategy, search_seed(run), number, startup=search.batch_size)
    asked = study.ask(space, count)
    return Round(
        number=number,
        start=start,
        asked=asked,
        study=study,
        log=round_log,
        explore=search.strategy in ("random", "lhs") or number == 0,
        optimizer_seconds=time.perf_counter() - started,
    )


def tell_round(
    run: SimulationRun, round_: Round, summaries: Sequence[Mapping[str, Any]], points: list[dict[str, Any]]
) -> None:
    """Record the round's index summaries (in index order) as points and tell the study their losses.
    `points` gets the round's points; `round_.log` is then the journal to store with them."""
    search = search_of(run)
    criteria = [*run.spec.evaluation.criteria, *run.spec.scenarios[0].criteria]
    if len(points) != round_.start or len(summaries) != len(round_.asked):
        raise ValueError(f"round {round_.number}: {len(summaries)} summaries for {len(round_.asked)} points")
    for position, parameters in enumerate(round_.asked):
        summary = summaries[position]
        _check_resumed(summary, parameters, run.name)
        points.append(
            {
                "index": round_.start + position,
                "round": round_.number,
                "parameters": parameters,
                "status": summary["status"],
                "objective": raw_value(search.objective, criteria, summary),
                "explore": round_.explore,
            }
        )
    told = time.perf_counter()
    for position, value in enumerate(_losses(run, points, round_.start)):
        round_.study.tell(position, value)
    round_.optimizer_seconds += time.perf_counter() - told


def document_of(
    run: SimulationRun, space: Sequence[Dimension], points: Sequence[dict[str, Any]]
) -> dict[str, Any]:
    return search_document(run.name, search_of(run), search_seed(run), space, points)


def finish(
    run: SimulationRun,
    store: Store,
    space: Sequence[Dimension],
    points: Sequence[dict[str, Any]],
    scenario_file: Path,
) -> dict[str, Any]:
    """Write `search/failing.xosc` (when a point failed) and `search.json`; returns the document."""
    prefix = f"{run.name}/search"
    document = document_of(run, space, points)
    document["outputUrl"] = store.url_for(run.name)
    failing = [p["parameters"] for p in points if p["status"] == "failed"]
    if failing:
        document["failingScenarios"] = store.url_for(f"{prefix}/failing.xosc")
        store.put_bytes(
            f"{prefix}/failing.xosc",
            distribution_xml(scenario_file, failing, f"search {run.name}: the {len(failing)} failing points"),
        )
    store.put_bytes(f"{run.name}/search.json", (json.dumps(document, indent=2) + "\n").encode())
    return document


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
    spec = run.spec
    space = search_space(run, scenario_file)
    url = output_url or spec.output.url
    store = open_store(url, endpoint=spec.output.endpoint, region=spec.output.region)
    with tempfile.TemporaryDirectory(prefix="carlos-search-") as scratch:
        points_file = Path(scratch) / "points.xosc"
        log, points = load_state(run, store)
        report: RunReport | None = None
        resumed: int | None = None  # runs resumed from an earlier invocation (the first round's)
        begun = time.monotonic()
        timings: list[tuple[float, float]] = []
        while True:
            started = time.perf_counter()
            round_ = ask_round(run, space, log, points)
            if round_ is None and report is not None:
                break
            asked = round_.asked if round_ is not None else []
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
            resumed = report.skipped if resumed is None else resumed
            if round_ is None:
                break  # resumed after the last round: the run-level results are written again
            tell_round(run, round_, [report.outcomes[i] for i in round_.indexes], points)
            timings.append((round_.optimizer_seconds, time.perf_counter() - started))
            log = round_.log
            save_state(run, store, log, points)
            on_round(document_of(run, space, points))
        document = finish(run, store, space, points, scenario_file)
    assert report is not None
    # each round resumes the rounds before it: the search resumed only what the first round found written
    report = dataclasses.replace(report, skipped=resumed or 0, wall_seconds=time.monotonic() - begun)
    return SearchReport(run=report, document=document, timings=timings)
