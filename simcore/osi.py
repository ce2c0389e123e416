"""ASAM OSI ground truth (osi3.GroundTruth, OSI 3.8.0) of CARLOS world states, through betterosi.

Shared by `carlos export --format omega-prime` (simcore/export_omega.py) and `spec.recording.osi` (the run's
MCAP gets a channel `/carlos/osi/ground_truth` of protobuf `osi3.GroundTruth`, one message per step).

Mapping (every scenario entity is an OSI MovingObject; ids 0, 1, … in the order the entities first appear):
`type` and `vehicle_classification` from the OpenSCENARIO category (`osi_type`), `base.dimension` = the
bounding box (length, width, height), `base.position` = the box centre in the map frame (OSI's definition;
/tf carries the entity's reference point), `base.orientation` = roll, pitch, yaw (rad, in [-pi, pi]),
`base.velocity` = the speed along the entity's x axis in the map frame, `base.acceleration` along it too;
`source_reference` names the entity; `host_vehicle_id` = the ego.

betterosi is the optional extra `carlos-sim[omega]`: without it, asking for OSI is bad input naming the extra.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from simcore.errors import BadInput

__all__ = [
    "GROUND_TRUTH_SCHEMA",
    "OSI_TOPIC",
    "OSI_VERSION",
    "ObjectRow",
    "OsiFrames",
    "betterosi",
    "forward",
    "ground_truth",
    "osi_type",
    "rpy",
]

OSI_VERSION = "3.8.0"
#: the run MCAP's OSI channel (spec.recording.osi)
OSI_TOPIC = "/carlos/osi/ground_truth"
GROUND_TRUTH_SCHEMA = "osi3.GroundTruth"

#: OSI MovingObject.Type values (osi_object.proto)
TYPE_OTHER, TYPE_VEHICLE, TYPE_PEDESTRIAN, TYPE_ANIMAL = 1, 2, 3, 4
#: OSI MovingObject.VehicleClassification.Type values of the OpenSCENARIO vehicle categories
_VEHICLE_TYPES = {
    "car": 4,  # TYPE_MEDIUM_CAR
    "van": 7,  # TYPE_DELIVERY_VAN
    "truck": 8,  # TYPE_HEAVY_TRUCK
    "semitrailer": 9,  # TYPE_SEMITRACTOR
    "trailer": 10,  # TYPE_TRAILER
    "motorbike": 11,  # TYPE_MOTORBIKE
    "bicycle": 12,  # TYPE_BICYCLE
    "bus": 13,  # TYPE_BUS
    "tram": 14,  # TYPE_TRAM
    "train": 15,  # TYPE_TRAIN
}
_ROLE_CIVIL = 1  # OSI MovingObject.VehicleClassification.Role.ROLE_CIVIL
_PEDESTRIANS = {"pedestrian", "wheelchair"}


def betterosi(what: str) -> Any:
    """The betterosi module, or bad input (exit 2) saying which extra to install for `what`."""
    try:
        import betterosi as bo
    except ImportError:
        raise BadInput(f"{what} needs betterosi: pip install 'carlos-sim[omega]'", field=what) from None
    return bo


def osi_type(category: str) -> tuple[int, int, int]:
    """(OSI MovingObject type, vehicle classification type, role) of an OpenSCENARIO category (pure); -1 for
    the classification of anything but a vehicle, as omega-prime's tables have it."""
    key = category.strip().lower()
    if key in _VEHICLE_TYPES:
        return TYPE_VEHICLE, _VEHICLE_TYPES[key], _ROLE_CIVIL
    if key in _PEDESTRIANS:
        return TYPE_PEDESTRIAN, -1, -1
    if key == "animal":
        return TYPE_ANIMAL, -1, -1
    return TYPE_OTHER, -1, -1


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def rpy(q: tuple[float, float, float, float]) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad, each in [-pi, pi]) of a unit quaternion (x, y, z, w), ZYX order (pure)."""
    x, y, z, w = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return _wrap(roll), _wrap(pitch), _wrap(yaw)


def forward(q: tuple[float, float, float, float]) -> tuple[float, float, float]:
    """The entity's x axis in the map frame: the first column of the quaternion's rotation (pure)."""
    x, y, z, w = q
    return 1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)


@dataclass(frozen=True, slots=True)
class ObjectRow:
    """One entity at one step as OSI has it (map frame, box centre, SI units, angles in rad)."""

    nanos: int
    idx: int
    name: str
    position: tuple[float, float, float]
    orientation: tuple[float, float, float]  # roll, pitch, yaw in [-pi, pi]
    velocity: tuple[float, float, float]
    acceleration: tuple[float, float, float]
    dimension: tuple[float, float, float]  # length, width, height
    types: tuple[int, int, int]  # type, vehicle classification type, role


def _vector(bo: Any, v: tuple[float, float, float]) -> Any:
    return bo.Vector3d(x=v[0], y=v[1], z=v[2])


def _moving_object(bo: Any, row: ObjectRow) -> Any:
    kind, vehicle, role = row.types
    classification = (
        bo.MovingObject.VehicleClassification(type=vehicle, role=role) if kind == TYPE_VEHICLE else None
    )
    length, width, height = row.dimension
    roll, pitch, yaw = row.orientation
    return bo.MovingObject(
        id=bo.Identifier(value=row.idx),
        type=kind,
        base=bo.BaseMoving(
            dimension=bo.Dimension3d(length=length, width=width, height=height),
            position=_vector(bo, row.position),
            orientation=bo.Orientation3d(roll=roll, pitch=pitch, yaw=yaw),
            velocity=_vector(bo, row.velocity),
            acceleration=_vector(bo, row.acceleration),
        ),
        vehicle_classification=classification,
        source_reference=[bo.ExternalReference(identifier=[row.name])],
    )


def ground_truth(bo: Any, nanos: int, rows: Sequence[ObjectRow], host: int | None) -> Any:
    """One osi3.GroundTruth (betterosi) of the moving objects `rows` at `nanos`."""
    major, minor, patch = (int(p) for p in OSI_VERSION.split("."))
    return bo.GroundTruth(
        version=bo.InterfaceVersion(version_major=major, version_minor=minor, version_patch=patch),
        timestamp=bo.Timestamp(seconds=nanos // 1_000_000_000, nanos=nanos % 1_000_000_000),
        host_vehicle_id=None if host is None else bo.Identifier(value=host),
        moving_object=[_moving_object(bo, row) for row in rows],
    )


class OsiFrames:
    """GroundTruth protobuf bytes of the engine's world frames (spec.recording.osi): ids by first
    appearance, acceleration = the engine's longitudinal acceleration along the entity's x axis."""

    def __init__(self) -> None:
        self.bo = betterosi("spec.recording.osi")
        self.ids: dict[str, int] = {}

    def channel(self) -> tuple[str, str, bytes, dict[str, str]]:
        """(schema name, schema encoding, schema data: the FileDescriptorSet, channel metadata)."""
        bo = self.bo
        metadata = bo.prepare_channel_metadata(
            None, description="ASAM OSI GroundTruth of every step (CARLOS)", version=OSI_VERSION
        )
        return GROUND_TRUTH_SCHEMA, "protobuf", bo.load_descriptor_set(OSI_VERSION), dict(metadata)

    def encode(self, frame: Any) -> bytes:
        """The protobuf bytes of one WorldFrame's GroundTruth."""
        from simcore.transport.messages import quaternion

        rows = []
        nanos = round(frame.time * 1e9)
        for entity in frame.entities:
            idx = self.ids.setdefault(entity.name, len(self.ids))
            q = quaternion(entity.heading, entity.pitch, entity.roll)
            quat = (float(q.x), float(q.y), float(q.z), float(q.w))
            fx, fy, fz = forward(quat)
            rows.append(
                ObjectRow(
                    nanos=nanos,
                    idx=idx,
                    name=entity.name,
                    position=tuple(float(v) for v in entity.box_center()),  # type: ignore[arg-type]
                    orientation=rpy(quat),
                    velocity=(entity.speed * fx, entity.speed * fy, entity.speed * fz),
                    acceleration=(
                        entity.acceleration * fx,
                        entity.acceleration * fy,
                        entity.acceleration * fz,
                    ),
                    dimension=(entity.bbox.length, entity.bbox.width, entity.bbox.height),
                    types=osi_type(entity.category),
                )
            )
        host = self.ids.get(frame.ego) if frame.ego is not None else None
        return bytes(ground_truth(self.bo, nanos, rows, host).to_binary())
