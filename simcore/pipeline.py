"""One run, assembled in one place: scenario engine, road, SUMO, closed loop, bus, world publisher, recorder,
sensors and metrics from a SimulationRun and one of its run points, then stepped to the end.

`carlos run` workers and the `simcore` pod role (through `simcore.runner.judge`) and `carlos conformance`
(`simcore.conformance.run_scenario`: a run compared with a reference) all go through `assemble`, `drive`
and `Assembly.close`.
Each part starts only when something uses it: SUMO (libsumo, netconvert) when an entity is SUMO-driven; the
recorder when recording is on; sensors and the system under test when the spec names them; the closed loop
when an entity is externally driven; a world frame per step only when metrics, a publisher with a consumer,
sensors or the closed loop read it; ROS messages per topic only when someone consumes that topic.
"""

from __future__ import annotations

import functools
import json
import platform
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, Any

from simcore import DISTRIBUTION
from simcore.errors import BadInput
from simcore.file_version import BoundedCache
from simcore.plan import RunPoint
from simcore.spec import SimulationRun, SimulationRunSpec
from simcore.stepping import FrameReaders, step_to_end
from simcore.transport.bus import Bus, InProcessBus, Message
from simcore.transport.world import WorldPublisher

if TYPE_CHECKING:
    from simcore.closedloop import ClosedLoop
    from simcore.evaluation.metrics import MetricsAccumulator
    from simcore.osi import OsiFrames
    from simcore.recorder import McapRecorder
    from simcore.scenario.engine import ScenarioEngine
    from simcore.scenario.model import Scenario
    from simcore.sensors.loop import PerceptionLoop
    from simcore.v2x.service import V2XService
    from simcore.world.opendrive import OpenDrive
    from simcore.world.state import WorldFrame
    from simcore.world.sumo import SumoWorld

#: called with (index, simulated seconds so far) while a run progresses
Progress = Callable[[int, float], None]
#: called with the engine after the initial state and after every step (e.g. a conformance trace)
Observer = Callable[["ScenarioEngine"], None]


@dataclass(frozen=True)
class Outcome:
    metrics: dict[str, float]
    end_reason: str  # stopTrigger | maxSeconds
    sim_seconds: float
    log: list[str]
    #: scenario time = run time + this (negative when a FollowGhost's ghost got a head start: the run, its
    #: recording and `sim_seconds` start at the ghost's start, ROS time cannot be negative)
    scenario_time_offset: float = 0.0
    warnings: tuple[str, ...] = ()


@dataclass
class Assembly:
    """The parts of one run; `drive` steps it, `close` releases it (idempotent)."""

    run: SimulationRun
    point: RunPoint
    scenario: Scenario
    engine: ScenarioEngine
    bus: Bus
    world: WorldPublisher
    metrics: MetricsAccumulator | None
    road: OpenDrive | None = None
    sumo: SumoWorld | None = None
    closed_loop: ClosedLoop | None = None
    recorder: McapRecorder | None = None
    perception: PerceptionLoop | None = None
    v2x: V2XService | None = None
    osi: OsiFrames | None = None  # spec.recording.osi: GroundTruth of every frame into the recording
    _closed: bool = field(default=False, repr=False)

    @property
    def needs_frames(self) -> bool:
        """Whether anything reads a world frame per step (otherwise the engine only advances)."""
        return (
            self.metrics is not None
            or self.perception is not None
            or self.v2x is not None
            or self.closed_loop is not None
            or self.osi is not None
            or self.world.has_consumers()
        )

    def close(self, *, ok: bool = False) -> None:
        """Release every part; the recording is finalised only when `ok` (else aborted)."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.perception is not None:
                self.perception.close()
            self.bus.close()
            if self.recorder is not None:
                if ok:
                    self.recorder.close()
                else:
                    self.recorder.abort()
        finally:
            if self.sumo is not None:
                self.sumo.close()


def sumo_driven(scenario: Scenario) -> list[str]:
    """The entities SUMO drives (`carlos.driver=sumo`): SUMO starts only for these."""
    return [e.name for e in scenario.entities if e.driver == "sumo"]


def load_road(scenario: Scenario) -> OpenDrive | None:
    """The scenario's OpenDRIVE road (None without one, or for a SUMO .net.xml)."""
    if scenario.road_file is None or scenario.road_file.suffix != ".xodr":
        if scenario.road_file is not None and not scenario.road_file.is_file():
            raise BadInput("road network file not found", file=str(scenario.road_file))
        return None
    from simcore.world.opendrive import OpenDrive, OpenDriveError

    try:
        return OpenDrive.shared(scenario.road_file)
    except OpenDriveError as exc:
        raise BadInput(str(exc), file=str(scenario.road_file)) from None
    except FileNotFoundError:
        raise BadInput("road network file not found", file=str(scenario.road_file)) from None


def start_sumo(scenario: Scenario, step_seconds: float, seed: int) -> SumoWorld | None:
    """libsumo on the scenario's road, when an entity is SUMO-driven (a road netconvert cannot convert fails
    such a run only, saying which entities need SUMO)."""
    driven = sumo_driven(scenario)
    if not driven or scenario.road_file is None:
        return None  # without a road the engine reports the SUMO-driven entity
    from simcore.world.sumo import SumoWorld, prepare_network

    try:
        network = prepare_network(scenario.road_file)
    except BadInput as exc:
        raise BadInput(
            f"{exc.detail}; SUMO drives {', '.join(driven)} (controller property carlos.driver=sumo) and needs "
            "the road converted: fix the road, or let the scenario drive them",
            file=exc.file,
        ) from None
    return SumoWorld(network, step_seconds, seed)


def versions() -> dict[str, str]:
    """The versions of Python and of the packages a recording names (`carlos.versions`)."""
    return dict(_versions())


@functools.cache  # installed packages do not change under a running process (a worker asks once per run)
def _versions() -> tuple[tuple[str, str], ...]:
    out = {"python": platform.python_version()}
    for package in ("carlos", "eclipse-sumo", "libsumo", "mcap", "rosbags"):
        try:
            out[package] = version(DISTRIBUTION if package == "carlos" else package)
        except Exception:  # a package missing from the environment is reported, not fatal
            out[package] = "unknown"
    return tuple(out.items())


#: the manifest YAML of a recording's `carlos.spec` metadata, by the run's JSON (a worker's runs share it)
_MANIFEST_YAML: BoundedCache[str, str] = BoundedCache(8)


def manifest_yaml(run: SimulationRun) -> str:
    """The run's manifest as YAML (`carlos.spec` / `manifest` of every recording), dumped once per content."""
    key = run.model_dump_json(by_alias=True, exclude_none=True)
    text = _MANIFEST_YAML.get(key)
    if text is None:
        import yaml

        text = _MANIFEST_YAML.put(
            key, yaml.safe_dump(run.model_dump(mode="json", by_alias=True, exclude_none=True))
        )
    return text


def _metadata(
    run: SimulationRun, point: RunPoint, scenario: Scenario, scenario_file: Path, offset: float = 0.0
) -> dict[str, Any]:
    return {
        "carlos.spec": {"manifest": manifest_yaml(run)},
        "carlos.run": {
            "run": run.name,
            "index": str(point.index),
            "scenario": point.scenario.name,
            "scenarioFile": str(scenario_file),
            "parameters": json.dumps(point.parameters, sort_keys=True),
            "resolvedParameters": json.dumps(scenario.parameters, sort_keys=True, default=str),
            "seed": str(point.seed),
            "stepSeconds": repr(run.spec.simulation.step_seconds),
            # scenario time = log time + this (docs/design.md): a FollowGhost's ghost starts before the
            # scenario's time 0, the recording's clock at the ghost's start (ROS time is never negative)
            "scenarioTimeOffsetSeconds": repr(offset),
        },
        "carlos.versions": versions(),
    }


def start_engine(
    spec: SimulationRunSpec, point: RunPoint, scenario: Scenario, bus: Bus
) -> tuple[ScenarioEngine, OpenDrive | None, SumoWorld | None, ClosedLoop | None]:
    """The scenario's engine in its initial state (every entity placed, nothing stepped), with the road, SUMO
    (when it drives an entity) and the closed loop it uses: what a run builds before its first step, and
    what `carlos validate` builds to reject the same bad input (a position on a lane the road does not
    have, an ego that is no entity). SUMO is closed again on an error."""
    from simcore.scenario.engine import ScenarioEngine

    road = load_road(scenario)
    sumo = start_sumo(scenario, spec.simulation.step_seconds, point.seed)
    try:
        closed_loop = None
        control = spec.control
        if control is not None or (any(e.driver == "external" for e in scenario.entities)):
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
            seed=point.seed,
        )
        for name in control.entities if control is not None else ():
            engine.drive_externally(name)
    except BaseException:
        if sumo is not None:
            sumo.close()
        raise
    return engine, road, sumo, closed_loop


def assemble(
    run: SimulationRun,
    point: RunPoint,
    scenario_file: Path,
    out_dir: Path,
    *,
    bus: Bus | None = None,
    base_dir: Path | None = None,
    with_metrics: bool = True,
    on_loaded: Callable[[Scenario], None] | None = None,
) -> Assembly:
    """Build the run of `point` (recording into `out_dir/recording.mcap` when the spec records). Externally
    driven entities stand still (as in the reference player) until a command for them arrives. `on_loaded`
    sees the scenario once parsed. On an error every part started so far is released."""
    from simcore.scenario.xosc import load_scenario

    spec = run.spec
    scenario = load_scenario(scenario_file, point.parameters)
    if on_loaded is not None:
        on_loaded(scenario)
    bus = bus if bus is not None else InProcessBus()
    try:
        engine, road, sumo, closed_loop = start_engine(spec, point, scenario, bus)
    except BaseException:
        bus.close()
        raise
    parts: Assembly | None = None
    try:
        metrics = None
        if with_metrics:
            from simcore.evaluation.metrics import MetricsAccumulator

            metrics = MetricsAccumulator()
        parts = Assembly(
            run=run,
            point=point,
            scenario=scenario,
            engine=engine,
            bus=bus,
            world=WorldPublisher(bus),
            metrics=metrics,
            road=road,
            sumo=sumo,
            closed_loop=closed_loop,
        )
        if spec.recording.enabled:
            from simcore.recorder import McapRecorder

            recorder = parts.recorder = McapRecorder(
                out_dir / "recording.mcap",
                topics=spec.recording.topics,
                compression=spec.recording.compression,
                metadata=_metadata(run, point, scenario, scenario_file, engine.output_time_offset),
            )
            _subscribe(bus, "*", _record_into(recorder), wants=recorder.wants)
            if spec.recording.osi:
                from simcore.osi import OSI_TOPIC, OsiFrames

                parts.osi = OsiFrames()
                name, encoding, schema, channel_metadata = parts.osi.channel()
                recorder.add_channel(OSI_TOPIC, name, encoding, schema, "protobuf", channel_metadata)
        perceiving = spec.sensors or any(rsu.sensors for rsu in spec.infrastructure)
        if perceiving or spec.system_under_test is not None or spec.evaluation.detection is not None:
            from simcore.sensors.loop import PerceptionLoop

            parts.perception = PerceptionLoop(
                spec,
                bus,
                road=road,
                road_file=scenario.road_file,
                seed=point.seed,
                base_dir=base_dir,
                parameters=scenario.parameters,
            )
        if spec.v2x is not None:
            from simcore.v2x.service import V2XService

            parts.v2x = V2XService(
                spec,
                bus,
                road=road,
                road_file=scenario.road_file,
                parameters=scenario.parameters,
                seed=point.seed,
            )
        return parts
    except BaseException:
        if parts is not None:
            parts.close()
        else:
            bus.close()
            if sumo is not None:
                sumo.close()
        raise


def _subscribe(bus: Bus, pattern: str, callback: Callable[[Message], None], *, wants: Any) -> None:
    if isinstance(bus, InProcessBus):
        bus.subscribe(pattern, callback, wants=wants)
    else:
        bus.subscribe(pattern, callback)


def _record_into(recorder: McapRecorder) -> Callable[[Message], None]:
    return recorder.write_message


def drive(
    parts: Assembly,
    *,
    progress: Progress | None = None,
    deadline: float | None = None,
    observe: Observer | None = None,
) -> None:
    """Step the run until the scenario ends or `simulation.maxSeconds`; publishes and measures every frame
    that anything reads."""
    spec = parts.run.spec
    v2x = parts.v2x
    engine, closed_loop, perception, metrics, world = (
        parts.engine,
        parts.closed_loop,
        parts.perception,
        parts.metrics,
        parts.world,
    )
    if closed_loop is not None:
        closed_loop.wait_for_nodes(b.name for b in engine.bodies.values() if b.external)
    osi, recorder = parts.osi, parts.recorder
    frame = readers = None
    if parts.needs_frames:
        ground_truth = None
        if osi is not None and recorder is not None:
            from simcore.osi import GROUND_TRUTH_SCHEMA, OSI_TOPIC

            def ground_truth(frame: WorldFrame) -> None:
                recorder.write(OSI_TOPIC, GROUND_TRUTH_SCHEMA, osi.encode(frame), frame.time)

        readers = FrameReaders(
            world, metrics, ground_truth=ground_truth, closed_loop=closed_loop, perception=perception, v2x=v2x
        )
        frame = engine.frame()
        readers.take(frame)
    if observe is not None:
        observe(engine)
    frame = step_to_end(
        engine,
        readers,
        round(spec.simulation.max_seconds / spec.simulation.step_seconds),
        frame,
        closed_loop=closed_loop,
        observe=observe,
        progress=progress,
        index=parts.point.index,
        deadline=deadline,
        timeout_seconds=spec.execution.timeout_seconds,
    )
    if perception is not None:
        perception.close()
    world.publish_status(frame if frame is not None else engine.frame(), "ended")


def outcome(parts: Assembly) -> Outcome:
    """Metrics, end reason, simulated seconds and storyboard log of a driven run."""
    engine = parts.engine
    result = parts.metrics.result() if parts.metrics is not None else {}
    end_reason = engine.ended_by or "maxSeconds"
    result["stopTriggered"] = 1.0 if end_reason == "stopTrigger" else 0.0
    log_lines = list(engine.log)
    if parts.v2x is not None:
        result.update(parts.v2x.metrics())
    if parts.perception is not None:
        result.update(parts.perception.metrics())
        if parts.perception.failure is not None:
            log_lines.append(f"system under test failed: {parts.perception.failure}")
    warnings = (*parts.scenario.warnings, *engine.warnings)
    return Outcome(result, end_reason, engine.time, log_lines, engine.output_time_offset, warnings)


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
    observe: Observer | None = None,
    on_loaded: Callable[[Scenario], None] | None = None,
) -> Outcome:
    """Assemble, drive and close one run: what `carlos run` (`simcore.runner`) and `carlos conformance`
    (`simcore.conformance.run_scenario`, which observes the engine every step) both do."""
    parts = assemble(run, point, scenario_file, out_dir, bus=bus, base_dir=base_dir, on_loaded=on_loaded)
    ok = False
    try:
        drive(parts, progress=progress, deadline=deadline, observe=observe)
        ok = True
    finally:
        parts.close(ok=ok)
    return outcome(parts)
