"""One run (one index of a SimulationRun): scenario + parameters → simulation → MCAP, metrics, verdict.

Used by the local executor's worker processes and by the `simcore` pod role alike. Results are written to a
scratch directory and uploaded to the object store under `<run>/<index>/`, the summary last: its presence
means the index is complete (DESIGN.md).
"""

from __future__ import annotations

import contextlib
import json
import logging
import posixpath
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from simcore.errors import BadInput, CarlosError, ExitCode
from simcore.evaluation.criteria import CriterionResult, evaluate
from simcore.evaluation.report import index_summary, summary_json
from simcore.pipeline import Progress, versions
from simcore.plan import Plan, RunPoint
from simcore.scenario.parameters import ParamValue
from simcore.spec import SimulationRun
from simcore.store import Store
from simcore.transport.bus import Bus

__all__ = ["Judged", "Progress", "RunOutcome", "error_outcome", "judge", "resolve_scenario_file", "run_index",
           "summary_bytes", "versions"]  # fmt: skip

log = logging.getLogger("carlos.run")


@dataclass(frozen=True)
class RunOutcome:
    index: int
    summary: dict[str, Any]
    exit_code: ExitCode


def resolve_scenario_file(
    point: RunPoint, base_dir: Path, scratch: Path, store_factory: Callable[[str], Store]
) -> Path:
    """The local path of the scenario's OpenSCENARIO file (downloading it, and its road, from S3)."""
    ref = point.scenario
    field = f"spec.scenarios[{ref.name}].openscenario"
    if ref.config_map_ref is not None:
        raise BadInput(
            "configMapRef scenarios exist on a cluster only (the operator mounts them); "
            "locally use a path or URL in 'openscenario'",
            field=f"spec.scenarios[{ref.name}].configMapRef",
        )
    source = ref.openscenario or ""
    if source.startswith("file://"):
        return Path(source.removeprefix("file://")).expanduser()
    if source.startswith("s3://"):
        return _fetch_from_s3(source, scratch, store_factory, field, point.parameters)
    if "://" in source:
        raise BadInput(f"unsupported URL scheme in {source!r}: use a path, file:// or s3://", field=field)
    return (base_dir / source).resolve()


def _road_parameter(scenario: Path, text: str, parameters: Mapping[str, ParamValue]) -> str:
    """A `$name` / `${…}` road path resolved with the scenario's declared defaults and the run's values."""
    from simcore.scenario.parameters import ParameterError, declare, resolve
    from simcore.scenario.xosc import parameter_declarations

    try:
        values = declare(list(parameter_declarations(scenario).values()), {}, parameters)
        return resolve(text, values)
    except ParameterError as exc:
        raise BadInput(str(exc), file=str(scenario), field="RoadNetwork/LogicFile") from None


def _fetch_from_s3(
    url: str,
    scratch: Path,
    store_factory: Callable[[str], Store],
    field: str,
    parameters: Mapping[str, ParamValue] | None = None,
) -> Path:
    """Download an s3:// scenario and the road file it names (relative to it, within the same bucket) into
    a mirror of the bucket under `scratch`, so the relative path resolves locally as it does in the bucket."""
    bucket, _, key = url.removeprefix("s3://").partition("/")
    if not bucket or not key or key.endswith("/"):
        raise BadInput(f"{url!r} is not s3://bucket/key of a file", field=field)
    store = store_factory(f"s3://{bucket}")
    mirror = scratch / "s3" / bucket
    local = mirror / key
    local.parent.mkdir(parents=True, exist_ok=True)
    local.write_bytes(store.get_bytes(key))
    from simcore.scenario.xosc_xml import read_xml

    root = read_xml(local, what="OpenSCENARIO file")
    logic = root.find("RoadNetwork/LogicFile")
    relative = logic.get("filepath") if logic is not None else None
    if relative and relative.startswith("$"):  # a parameter: the same bucket check on its value
        relative = _road_parameter(local, relative, parameters or {})
    if relative:
        road_key = posixpath.normpath(posixpath.join(posixpath.dirname(key), relative))
        if road_key.startswith("../") or road_key.startswith("/"):
            raise BadInput(f"road file {relative!r} lies outside the bucket {bucket!r}", field=field)
        target = mirror / road_key
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(store.get_bytes(road_key))
    return local


def error_outcome(run: SimulationRun, index: int, attempt: int, message: str) -> RunOutcome:
    """The outcome of an index that could not run at all (object store down, worker process died)."""
    point = Plan(run.spec)[index]
    summary = index_summary(
        index=index,
        scenario=point.scenario.name,
        parameters=point.parameters,
        seed=point.seed,
        optional=point.scenario.optional,
        sim_seconds=0.0,
        wall_seconds=0.0,
        metrics={},
        results=[],
        error=message,
        end_reason="error",
        attempts=attempt,
    )
    return RunOutcome(index=index, summary=summary, exit_code=ExitCode.INFRASTRUCTURE)


def summary_bytes(summary: dict[str, Any]) -> bytes:
    return summary_json(summary)


def _writes_files(run: SimulationRun, point: RunPoint) -> bool:
    """Whether a run writes files of its own before they are uploaded: its recording, a scenario (and road)
    fetched from S3."""
    return run.spec.recording.enabled or (point.scenario.openscenario or "").startswith("s3://")


@contextlib.contextmanager
def _scratch(index: int, root: Path | None, needed: bool) -> Iterator[Path]:
    """The scratch directory of one run, removed afterwards; made only when `needed` (most runs of a sweep
    write no file there: they get its name, and nothing is there)."""
    if needed:
        with tempfile.TemporaryDirectory(prefix=f"carlos-{index}-", dir=root) as name:
            yield Path(name)
    else:
        yield Path(root if root is not None else tempfile.gettempdir()) / f"carlos-{index}-none"


@dataclass
class Judged:
    """An index after its simulation and the evaluation of its criteria."""

    summary: dict[str, Any]
    exit_code: ExitCode
    error: str | None  # what went wrong (CARLOS' error or the crash), None when the simulation ran
    sim_seconds: float  # on the recording's clock (summary.json's simSeconds)


def judge(
    index: int,
    point: RunPoint,
    criteria: list[Any],
    simulate: Callable[[], Any],
    *,
    attempt: int,
    started: float,
    log_lines: list[str],
) -> Judged:
    """Run `simulate()` (a `pipeline.simulate` call: an Outcome) and judge the index: evaluate the criteria,
    build its summary and classify what went wrong (CARLOS' own errors by their exit code, a crash as an
    infrastructure error); appends to `log_lines`. Shared by `carlos run` workers and the simcore pod."""
    metrics: dict[str, float] = {}
    results: list[CriterionResult] = []
    error: str | None = None
    end_reason = "error"
    sim_seconds = 0.0
    offset = 0.0
    exit_code = ExitCode.PASSED
    try:
        result = simulate()
        metrics, end_reason, sim_seconds = result.metrics, result.end_reason, result.sim_seconds
        offset = result.scenario_time_offset
        for warning in result.warnings:  # what the engine read leniently (file, element, what it did)
            log.warning("%s", warning)
            log_lines.append(f"warning: {warning}")
        log_lines.extend(result.log)
        results = evaluate(criteria, metrics)
    except CarlosError as exc:
        error = str(exc)
        exit_code = exc.exit_code
        log_lines.append(f"error: {error}")
    except Exception as exc:  # a crash of the simulator is an infrastructure error of this index
        error = f"{type(exc).__name__}: {exc}"
        exit_code = ExitCode.INFRASTRUCTURE
        log_lines.append("error: " + error)
        log_lines.append(traceback.format_exc())
    summary = index_summary(
        index=index,
        scenario=point.scenario.name,
        parameters=point.parameters,
        seed=point.seed,
        optional=point.scenario.optional,
        sim_seconds=sim_seconds,
        wall_seconds=time.monotonic() - started,
        metrics=metrics,
        results=results,
        error=error,
        end_reason=end_reason if error is None else "error",  # type: ignore[arg-type]
        attempts=attempt,
        scenario_time_offset=offset,
    )
    if error is None and summary["status"] == "failed":
        exit_code = ExitCode.FAILED
    if exit_code == ExitCode.BAD_INPUT:
        summary["badInput"] = True  # the run-level exit code keeps it apart from infrastructure
    return Judged(summary, exit_code, error, sim_seconds)


def run_index(
    run: SimulationRun,
    index: int,
    *,
    base_dir: Path,
    store: Store,
    store_factory: Callable[[str], Store],
    attempt: int = 1,
    final_attempt: bool = True,
    progress: Progress | None = None,
    scratch_root: Path | None = None,
    bus: Bus | None = None,
) -> RunOutcome:
    """Run one index and upload its results; never raises for problems of the run itself (object-store
    failures do raise `StoreError`). An infrastructure error on an attempt that will be retried uploads
    its log but no summary, so the index does not look complete."""
    plan = Plan(run.spec)
    point = plan[index]
    criteria = [*run.spec.evaluation.criteria, *point.scenario.criteria]
    started = time.monotonic()
    deadline = started + run.spec.execution.timeout_seconds
    log_lines: list[str] = [
        f"carlos run {run.name} index {index}: scenario {point.scenario.name}, seed {point.seed}"
    ]
    log_lines.append(f"parameters: {json.dumps(point.parameters, sort_keys=True)}")
    prefix = f"{run.name}/{index}"
    with _scratch(index, scratch_root, _writes_files(run, point)) as scratch:

        def simulate() -> Any:
            from simcore import pipeline

            scenario_file = resolve_scenario_file(point, base_dir, scratch, store_factory)
            return pipeline.simulate(
                run,
                point,
                scenario_file,
                scratch,
                progress=progress,
                deadline=deadline,
                bus=bus,
                base_dir=base_dir,
            )

        judged = judge(
            index, point, criteria, simulate, attempt=attempt, started=started, log_lines=log_lines
        )
        summary, exit_code = judged.summary, judged.exit_code
        log_lines.append(f"status: {summary['status']}")
        recording = scratch / "recording.mcap"
        if recording.is_file():
            store.put_file(f"{prefix}/recording.mcap", recording)
        store.put_bytes(f"{prefix}/log.txt", ("\n".join(log_lines) + "\n").encode())
        if exit_code == ExitCode.INFRASTRUCTURE and not final_attempt:
            return RunOutcome(index=index, summary=summary, exit_code=exit_code)
        store.put_bytes(f"{prefix}/summary.json", summary_bytes(summary))
    return RunOutcome(index=index, summary=summary, exit_code=exit_code)
