"""Checks of a manifest and its scenarios before any simulation (`carlos validate` and `carlos run`): every
value the manifest gives a parameter (spec.parameters, a scenario's parameters, every value of every
sweep.matrix key, so also the permutations after the first) converts to the parameter's declared type, and
the road network file is a road network that parses safely."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

from simcore.errors import BadInput, CarlosError, SimulationError
from simcore.scenario.parameters import Declaration, ParameterError, ParamValue, convert
from simcore.spec import SimulationRun, SimulationRunSpec


def _manifest_values(spec: SimulationRunSpec, position: int) -> Iterator[tuple[str, str, ParamValue]]:
    """(field path, parameter name, value) of every parameter value the manifest gives scenario `position`."""
    for name, value in spec.parameters.items():
        yield f"spec.parameters.{name}", name, value
    for name, value in spec.scenarios[position].parameters.items():
        yield f"spec.scenarios[{position}].parameters.{name}", name, value
    for name, values in spec.sweep.matrix.items():
        for i, value in enumerate(values):
            yield f"spec.sweep.matrix.{name}[{i}]", name, value


def check_parameter_types(
    spec: SimulationRunSpec, position: int, declarations: Mapping[str, Declaration], *, source: str
) -> None:
    """Raise BadInput naming the manifest field whose value does not fit the declared type."""
    for where, name, value in _manifest_values(spec, position):
        declaration = declarations.get(name)
        if declaration is None:
            continue  # undeclared names are reported by the caller, with the declared ones listed
        try:
            convert(value, declaration.type, name=name)
        except ParameterError as exc:
            raise BadInput(str(exc), file=source, field=where) from None


ROAD_SUFFIXES = (".xodr", ".net.xml")


def check_road_file(road_file: Path, *, scenario_file: str) -> None:
    """The scenario's road network exists, is a road network by its name, and parses safely (OpenDRIVE: the
    full parse with its limits; SUMO: a streamed safe parse): problems are bad input before any run."""
    from simcore.world.opendrive import OpenDrive, OpenDriveError

    field = "RoadNetwork/LogicFile"
    if not road_file.name.endswith(ROAD_SUFFIXES):
        raise BadInput(
            f"road network {str(road_file)!r} is neither OpenDRIVE (.xodr) nor SUMO (.net.xml)",
            file=scenario_file,
            field=field,
        )
    if not road_file.is_file():
        raise BadInput(f"road network {str(road_file)!r} not found", file=scenario_file, field=field)
    if road_file.suffix == ".xodr":
        try:
            OpenDrive.shared(road_file)
        except OpenDriveError as exc:
            raise BadInput(str(exc)) from None  # the message starts with the road file's name
    else:
        from simcore.world.sumo import check_network_xml

        check_network_xml(road_file)


#: sweep points of a scenario whose initial state `carlos validate` builds (each one costs a scenario load)
INITIAL_STATES_CHECKED = 32


def check_initial_states(run: SimulationRun, position: int, scenario_file: Path, *, source: str) -> None:
    """Build the initial state of scenario `position` as a run does before its first step
    (simcore.pipeline.start_engine: the road, SUMO when it drives an entity, every entity placed, the ego,
    the closed loop), for its first INITIAL_STATES_CHECKED sweep points (only the first when SUMO drives
    one: SUMO starts per point): the bad input a run would only meet there (a LanePosition on a lane the road
    does not have, `spec.simulation.ego` naming no entity) is rejected the same way, with the manifest
    named when the message names no file. Anything else going wrong is an infrastructure error (exit 3),
    as it would be in the run."""
    from simcore.pipeline import start_engine
    from simcore.plan import Plan
    from simcore.scenario.xosc import load_scenario
    from simcore.transport.bus import InProcessBus

    plan = Plan(run.spec)
    name = run.spec.scenarios[position].name
    for index in plan.indexes_of(name)[:INITIAL_STATES_CHECKED]:
        point = plan.sweep_point(index)
        scenario = load_scenario(scenario_file, point.parameters)
        bus = InProcessBus()
        try:
            _engine, _road, sumo, _loop = start_engine(run.spec, point, scenario, bus)
        except BadInput as exc:
            if exc.file is None:
                raise BadInput(exc.detail, file=source, field=exc.field) from None
            raise
        except CarlosError:
            raise
        except Exception as exc:  # as in a run: a fault of the simulator, not of the input
            raise SimulationError(
                f"{scenario_file}: building the initial state failed: {type(exc).__name__}: {exc}"
            ) from None
        finally:
            bus.close()
        if sumo is not None:
            sumo.close()
            break
