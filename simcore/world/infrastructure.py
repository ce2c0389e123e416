"""Roadside units of `spec.infrastructure` placed in the map: where each stands (a map position, or a road
pose resolved on the scenario's OpenDRIVE road), its mast height and orientation, numbers given as
`$parameters` resolved with the run's scenario parameters.

Used by the V2X service (an RSU's station: antenna at the mast top) and the sensor rig (an RSU's sensors,
mounted relative to the unit's foot)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from simcore.errors import BadInput
from simcore.spec import Infrastructure, NumberOrParameter
from simcore.world.opendrive import OpenDrive
from simcore.world.state import BoundingBox, EntityState

#: the box of a roadside unit's stand-in carrier: none (a unit is no obstacle of the scene)
_NO_BOX = BoundingBox(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def resolve_number(value: NumberOrParameter, parameters: Mapping[str, Any], field: str) -> float:
    """A spec number, or the value of the scenario parameter `$name` it names."""
    if isinstance(value, str):
        name = value[1:]
        if name not in parameters:
            raise BadInput(
                f"{value} names no parameter of the scenario (declare it or set it in spec.parameters or the sweep)",
                field=field,
            )
        raw = parameters[name]
        try:
            number = float(raw)
        except (TypeError, ValueError):
            raise BadInput(f"{value} = {raw!r} is not a number", field=field) from None
    else:
        number = float(value)
    if not math.isfinite(number):
        raise BadInput(f"{value} is not a finite number", field=field)
    return number


@dataclass(frozen=True, slots=True)
class UnitPose:
    """Where a roadside unit stands: its foot (map frame, m), mast height (m) and yaw (rad, counter-clockwise
    from east)."""

    name: str
    index: int  # position in spec.infrastructure
    x: float
    y: float
    z: float
    height: float
    yaw: float

    def carrier(self) -> EntityState:
        """A stationary stand-in carrier at the unit's foot (heading = its yaw), for sensors mounted on it."""
        return EntityState(
            self.name,
            "infrastructure",
            "none",
            self.x,
            self.y,
            self.z,
            self.yaw,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            _NO_BOX,
        )


def unit_pose(
    rsu: Infrastructure, index: int, road: OpenDrive | None, parameters: Mapping[str, Any]
) -> UnitPose:
    """The pose of `spec.infrastructure[index]`; bad input (naming the field) for an unknown road, an s
    outside the road, a `$parameter` the scenario lacks or a road pose without a road."""
    where = f"spec.infrastructure[{index}]"

    def number(name: str, value: NumberOrParameter) -> float:
        return resolve_number(value, parameters, f"{where}.{name}")

    if rsu.position is not None:
        x = number("position.x", rsu.position.x)
        y = number("position.y", rsu.position.y)
        z = number("position.z", rsu.position.z)
    else:
        assert rsu.road is not None
        if road is None:
            raise BadInput("a road position needs the scenario's OpenDRIVE road", field=f"{where}.road")
        if rsu.road.road_id not in road.roads:
            raise BadInput(f"the road has no road {rsu.road.road_id!r}", field=f"{where}.road.roadId")
        s = number("road.s", rsu.road.s)
        t = number("road.t", rsu.road.t)
        if not 0 <= s <= road.road_length(rsu.road.road_id):
            raise BadInput(f"s = {s} lies outside road {rsu.road.road_id!r}", field=f"{where}.road.s")
        pose = road.road_to_world(rsu.road.road_id, s, t)
        x, y, z = pose.x, pose.y, pose.z
    height = number("height", rsu.height)
    yaw = math.radians(number("yaw", rsu.yaw))
    return UnitPose(rsu.name, index, x, y, z, height, yaw)
