"""Checks of a manifest and its scenarios before any simulation (`carlos validate` and `carlos run`): every
value the manifest gives a parameter (spec.parameters, a scenario's parameters, every value of every
sweep.matrix key, so also the permutations after the first) converts to the parameter's declared type, and
the road network file is a road network that parses safely."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

from simcore.errors import BadInput
from simcore.scenario.parameters import Declaration, ParameterError, ParamValue, convert
from simcore.spec import SimulationRunSpec


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
