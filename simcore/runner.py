"""One run (one index of a SimulationRun): scenario + parameters → simulation → MCAP, metrics, verdict.

Used by the local executor's worker processes and by the `simcore` pod role alike. Results are written to a
scratch directory and uploaded to the object store under `<run>/<index>/`, the summary last: its presence
means the index is complete (DESIGN.md).
"""

from __future__ import annotations

import json
import logging
import platform
import posixpath
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import Any

import yaml

from simcore.errors import BadInput, CarlosError, ExitCode, SimulationError
from simcore.evaluation.criteria import CriterionResult, evaluate
from simcore.evaluation.metrics import MetricsAccumulator
from simcore.evaluation.report import index_summary
from simcore.plan import Plan, RunPoint
from simcore.spec import SimulationRun
from simcore.store import Store
from simcore.transport.bus import Bus, InProcessBus, Message
from simcore.transport.world import WorldPublisher

log = logging.getLogger("carlos.run")

#: called with (index, simulated seconds so far) while a run progresses
Progress = Callable[[int, float], None]


@dataclass(frozen=True)
class RunOutcome:
    index: int
    summary: dict[str, Any]
    exit_code: ExitCode


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for package in ("carlos", "eclipse-sumo", "libsumo", "mcap", "rosbags"):
        try:
            out[package] = version(package)
        except Exception:  # a package missing from the environment is reported, not fatal
            out[package] = "unknown"
    return out


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
        return _fetch_from_s3(source, scratch, store_factory, field)
    if "://" in source:
        raise BadInput(f"unsupported URL scheme in {source!r}: use a path, file:// or s3://", field=field)
    return (base_dir / source).resolve()


def _fetch_from_s3(url: str, scratch: Path, store_factory: Callable[[str], Store], field: str) -> Path:
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
    from simcore.scenario.xosc import read_xml

    root = read_xml(local, what="OpenSCENARIO file")
    logic = root.find("RoadNetwork/LogicFile")
    relative = logic.get("filepath") if logic is not None else None
    if relative and not relative.startswith("$"):
        road_key = posixpath.normpath(posixpath.join(posixpath.dirname(key), relative))
        if road_key.startswith("../") or road_key.startswith("/"):
            raise BadInput(f"road file {relative!r} lies outside the bucket {bucket!r}", field=field)
        target = mirror / road_key
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(store.get_bytes(road_key))
    return local


def simulate(
    run: SimulationRun,
    point: RunPoint,
    scenario_file: Path,
    out_dir: Path,
    *,
    progress: Progress | None = None,
    deadline: float | None = None,
    bus: Bus | None = None,
    base_dir: Path | None = None,
) -> tuple[dict[str, float], str, float, list[str]]:
    """Run the simulation of one index, recording into `out_dir/recording.mcap`. The world is published on
    `bus` (default: a new in-process bus); whatever subscribed to it before (a live view, another process'
    transport) receives every message.

    Sensors (`spec.sensors`) run every frame they are due; the system under test (`spec.systemUnderTest`,
    its `pythonPath` relative to `base_dir`) runs on the same bus; `spec.evaluation.detection` adds the
    `detection.*` metrics.

    Returns (metrics, end reason, simulated seconds, storyboard log)."""
    from simcore.recorder import McapRecorder
    from simcore.scenario.engine import ScenarioEngine
    from simcore.scenario.xosc import load_scenario
    from simcore.world.opendrive import OpenDrive, OpenDriveError
    from simcore.world.sumo import SumoWorld, prepare_network

    spec = run.spec
    scenario = load_scenario(scenario_file, point.parameters)
    road = None
    sumo = None
    if scenario.road_file is not None:
        try:
            road = OpenDrive.from_file(scenario.road_file) if scenario.road_file.suffix == ".xodr" else None
        except OpenDriveError as exc:
            raise BadInput(str(exc), file=str(scenario.road_file)) from None
        except FileNotFoundError:
            raise BadInput("road network file not found", file=str(scenario.road_file)) from None
        network = prepare_network(scenario.road_file)
        sumo = SumoWorld(network, spec.simulation.step_seconds, point.seed)
    metadata = {
        "carlos.spec": {
            "manifest": yaml.safe_dump(run.model_dump(mode="json", by_alias=True, exclude_none=True))
        },
        "carlos.run": {
            "run": run.name,
            "index": str(point.index),
            "scenario": point.scenario.name,
            "scenarioFile": str(scenario_file),
            "parameters": json.dumps(point.parameters, sort_keys=True),
            "resolvedParameters": json.dumps(scenario.parameters, sort_keys=True, default=str),
            "seed": str(point.seed),
            "stepSeconds": repr(spec.simulation.step_seconds),
        },
        "carlos.versions": versions(),
    }
    metrics = MetricsAccumulator()
    bus = bus if bus is not None else InProcessBus()
    recorder = None
    perception = None
    v2x = None
    try:
        closed_loop = None
        control = spec.control
        if control is not None or any(e.driver == "external" for e in scenario.entities):
            from simcore.closedloop import ClosedLoop

            closed_loop = ClosedLoop(
                bus,
                mode=control.mode if control is not None else "freeRunning",
                timeout_s=control.timeout_seconds if control is not None else 10.0,
                startup_timeout_s=control.startup_timeout_seconds if control is not None else 60.0,
            )
        engine = ScenarioEngine(
            scenario,
            road=road,
            sumo=sumo,
            step_seconds=spec.simulation.step_seconds,
            ego=spec.simulation.ego,
            external=closed_loop,
        )
        for name in control.entities if control is not None else ():
            engine.drive_externally(name)
        if spec.recording.enabled:
            recorder = McapRecorder(
                out_dir / "recording.mcap",
                topics=spec.recording.topics,
                compression=spec.recording.compression,
                metadata=metadata,
            )
            bus.subscribe("*", _record_into(recorder))
        world = WorldPublisher(bus)
        if spec.sensors or spec.system_under_test is not None or spec.evaluation.detection is not None:
            from simcore.sensors.loop import PerceptionLoop

            perception = PerceptionLoop(
                spec, bus, road=road, road_file=scenario.road_file, seed=point.seed, base_dir=base_dir
            )
        if spec.v2x is not None:
            from simcore.v2x.service import V2XService

            v2x = V2XService(
                spec,
                bus,
                road=road,
                road_file=scenario.road_file,
                parameters=scenario.parameters,
                seed=point.seed,
            )
        if closed_loop is not None:
            closed_loop.wait_for_nodes(b.name for b in engine.bodies.values() if b.external)
        frame = engine.frame()
        metrics.update(frame)
        if closed_loop is not None:
            closed_loop.published(frame.time)
        world.publish(frame)
        if perception is not None:
            perception.step(frame)
        if v2x is not None:
            v2x.step(frame)
        max_steps = round(spec.simulation.max_seconds / spec.simulation.step_seconds)
        reported = 0.0
        while not engine.ended and engine.step_index < max_steps:
            if closed_loop is not None:
                closed_loop.wait((b.name for b in engine.bodies.values() if b.external), frame.time)
            frame = engine.step()
            metrics.update(frame)
            if closed_loop is not None:
                closed_loop.published(frame.time)
            world.publish(frame)
            if perception is not None:
                perception.step(frame)
            if v2x is not None:
                v2x.step(frame)
            if progress is not None and frame.time - reported >= 1.0:
                reported = frame.time
                progress(point.index, frame.time)
            if deadline is not None and engine.step_index % 100 == 0 and time.monotonic() > deadline:
                raise SimulationError(
                    f"run exceeded execution.timeoutSeconds={spec.execution.timeout_seconds} "
                    f"at simulated t={frame.time:.1f} s"
                )
        if perception is not None:
            perception.close()
        world.publish_status(frame, "ended")
        if recorder is not None:
            recorder.close()
            recorder = None
    finally:
        if perception is not None:
            perception.close()
        bus.close()
        if recorder is not None:
            recorder.abort()
        if sumo is not None:
            sumo.close()
    result = metrics.result()
    end_reason = engine.ended_by or "maxSeconds"
    result["stopTriggered"] = 1.0 if end_reason == "stopTrigger" else 0.0
    log_lines = engine.log
    if v2x is not None:
        result.update(v2x.metrics())
    if perception is not None:
        result.update(perception.metrics())
        if perception.failure is not None:
            log_lines = [*log_lines, f"system under test failed: {perception.failure}"]
    return result, end_reason, engine.time, log_lines


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
    return (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode()


def _record_into(recorder: Any) -> Callable[[Message], None]:
    def record(message: Message) -> None:
        recorder.write(message.topic, message.typename, message.obj(), message.time_s)

    return record


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
    metrics: dict[str, float] = {}
    results: list[CriterionResult] = []
    error: str | None = None
    end_reason = "error"
    sim_seconds = 0.0
    exit_code = ExitCode.PASSED
    log_lines: list[str] = [
        f"carlos run {run.name} index {index}: scenario {point.scenario.name}, seed {point.seed}"
    ]
    log_lines.append(f"parameters: {json.dumps(point.parameters, sort_keys=True)}")
    prefix = f"{run.name}/{index}"
    with tempfile.TemporaryDirectory(prefix=f"carlos-{index}-", dir=scratch_root) as scratch_name:
        scratch = Path(scratch_name)
        try:
            scenario_file = resolve_scenario_file(point, base_dir, scratch, store_factory)
            metrics, end_reason, sim_seconds, storyboard_log = simulate(
                run,
                point,
                scenario_file,
                scratch,
                progress=progress,
                deadline=deadline,
                bus=bus,
                base_dir=base_dir,
            )
            log_lines.extend(storyboard_log)
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
        )
        if error is None and summary["status"] == "failed":
            exit_code = ExitCode.FAILED
        log_lines.append(f"status: {summary['status']}")
        recording = scratch / "recording.mcap"
        if recording.is_file():
            store.put_file(f"{prefix}/recording.mcap", recording)
        store.put_bytes(f"{prefix}/log.txt", ("\n".join(log_lines) + "\n").encode())
        if exit_code == ExitCode.INFRASTRUCTURE and not final_attempt:
            return RunOutcome(index=index, summary=summary, exit_code=exit_code)
        store.put_bytes(
            f"{prefix}/summary.json", (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode()
        )
    return RunOutcome(index=index, summary=summary, exit_code=exit_code)
