"""ETSI ITS messages as ROS 2 messages: CAM (`etsi_its_cam_msgs/msg/CAM`), DENM (`etsi_its_denm_msgs/msg/DENM`)
and CPM (`etsi_its_cpm_ts_msgs/msg/CollectivePerceptionMessage`, TS 103 324 V2.1.1), laid out as ika's
etsi_its_messages packages.

Units are the standard's: latitude/longitude in 0.1 µdeg, altitude in 0.01 m, heading in 0.1° clockwise from
WGS84 north, speed in 0.01 m/s, acceleration in 0.1 m/s², yaw rate in 0.01 °/s, vehicle length/width in
0.1 m, TimestampIts in ms since 2004-01-01T00:00:00Z (TAI) and GenerationDeltaTime = TimestampIts mod 65536.
Out-of-range values saturate at the standard's largest valid value. Simulated time 0 is `SIM_EPOCH_ITS_MS`.

The builders are pure functions. Containers a message does not use are one shared zero instance per type
(never mutated), so a CAM costs a handful of new objects.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from simcore.transport.messages import TYPESTORE

CAM_TYPE = "etsi_its_cam_msgs/msg/CAM"
DENM_TYPE = "etsi_its_denm_msgs/msg/DENM"
CPM_TYPE = "etsi_its_cpm_ts_msgs/msg/CollectivePerceptionMessage"

#: TimestampIts of simulated time 0: 2026-01-01T00:00:00Z, TAI milliseconds since 2004-01-01 (5 leap seconds).
SIM_EPOCH_ITS_MS = (8036 * 86400 + 5) * 1000

PROTOCOL_VERSION_CAM = 2
PROTOCOL_VERSION_DENM = 2
MESSAGE_ID_DENM = 1
MESSAGE_ID_CAM = 2

#: ETSI StationType of an OpenSCENARIO category (unknown categories: 0).
STATION_TYPES = {
    "pedestrian": 1,
    "animal": 13,
    "bicycle": 2,
    "motorbike": 4,
    "car": 5,
    "van": 5,
    "bus": 6,
    "truck": 8,
    "semitrailer": 8,
    "trailer": 9,
    "tram": 11,
    "train": 11,
}
STATION_TYPE_RSU = 15


def its_time_ms(time_s: float) -> int:
    """TimestampIts (ms) of simulated time `time_s`."""
    return SIM_EPOCH_ITS_MS + round(time_s * 1000.0)


def generation_delta_time(time_s: float) -> int:
    return its_time_ms(time_s) % 65536


def _clip(value: float, lo: int, hi: int) -> int:
    if not math.isfinite(value):
        return hi
    return max(lo, min(hi, round(value)))


def etsi_heading(north_angle: float, map_heading: float) -> float:
    """Degrees clockwise from north in [0, 360) of a map-frame heading (rad, counter-clockwise from +x)."""
    return math.degrees(north_angle - map_heading) % 360.0


def _t(typename: str) -> Any:
    return TYPESTORE.types[typename]


@cache
def zero(typename: str) -> Any:
    """The all-zero instance of a message type (shared: never mutate it)."""
    return _t(typename)(**{name: _zero_field(desc) for name, desc in TYPESTORE.fielddefs[typename][1]})


def _zero_field(desc: Any) -> Any:

    kind = desc[0]
    if kind == 1:  # base type
        base = desc[1][0]
        if base == "string":
            return ""
        if base == "bool":
            return False
        if base in ("float32", "float64"):
            return 0.0
        return 0
    if kind == 2:  # message
        return zero(desc[1])
    # arrays and sequences: empty (fixed-size arrays do not occur in these packages)
    sub = desc[1][0]
    if sub[0] == 1 and sub[1][0] not in ("string", "bool"):
        return np.zeros(0, dtype=np.uint8 if sub[1][0] in ("uint8", "byte", "char") else np.float64)
    return []


@dataclass(frozen=True, slots=True)
class Kinematics:
    """What a station says about itself: WGS84 position (deg, deg, m), ETSI heading (deg), speed (m/s),
    longitudinal acceleration (m/s²), yaw rate (rad/s), length and width (m)."""

    latitude: float
    longitude: float
    altitude: float
    heading: float
    speed: float
    acceleration: float = 0.0
    yaw_rate: float = 0.0
    length: float = 0.0
    width: float = 0.0


def _reference_position(pkg: str, k: Kinematics) -> Any:
    types, ellipse, altitude = _reference_parts(pkg)
    return types[0](
        latitude=types[1](value=_clip(k.latitude * 1e7, -900000000, 900000000)),
        longitude=types[2](value=_clip(k.longitude * 1e7, -1800000000, 1800000000)),
        position_confidence_ellipse=ellipse,
        altitude=altitude(_clip(k.altitude * 100, -100000, 800000)),
    )


@cache
def _reference_parts(pkg: str) -> tuple[tuple[Any, Any, Any], Any, _Memo]:
    """A package's ReferencePosition, Latitude and Longitude types, its (constant) confidence ellipse and its
    altitudes by value (shared parts: never mutate them)."""
    ellipse = _t(f"{pkg}/msg/PosConfidenceEllipse")(
        semi_major_confidence=_t(f"{pkg}/msg/SemiAxisLength")(value=1),  # simulated: exact (1 cm)
        semi_minor_confidence=_t(f"{pkg}/msg/SemiAxisLength")(value=1),
        semi_major_orientation=_t(f"{pkg}/msg/HeadingValue")(value=0),
    )
    confidence = _t(f"{pkg}/msg/AltitudeConfidence")(value=0)  # alt-000-01
    altitude = _Memo(
        lambda v: _t(f"{pkg}/msg/Altitude")(
            altitude_value=_t(f"{pkg}/msg/AltitudeValue")(value=v), altitude_confidence=confidence
        )
    )
    types = (_t(f"{pkg}/msg/ReferencePosition"), _t(f"{pkg}/msg/Latitude"), _t(f"{pkg}/msg/Longitude"))
    return types, ellipse, altitude


def _header(pkg: str, message_id: int, protocol_version: int, station_id: int) -> Any:
    return _t(f"{pkg}/msg/ItsPduHeader")(
        protocol_version=protocol_version,
        message_id=message_id,
        station_id=_t(f"{pkg}/msg/StationID")(value=station_id),
    )


def _heading(pkg: str, degrees: float) -> Any:
    return _t(f"{pkg}/msg/Heading")(
        heading_value=_t(f"{pkg}/msg/HeadingValue")(value=_clip(degrees * 10, 0, 3600) % 3600),
        heading_confidence=_t(f"{pkg}/msg/HeadingConfidence")(value=1),
    )


def _speed(pkg: str, speed: float) -> Any:
    return _t(f"{pkg}/msg/Speed")(
        speed_value=_t(f"{pkg}/msg/SpeedValue")(value=_clip(abs(speed) * 100, 0, 16382)),
        speed_confidence=_t(f"{pkg}/msg/SpeedConfidence")(value=1),
    )


_CAM = "etsi_its_cam_msgs"


def clip_rows(values: np.ndarray, limits: np.ndarray) -> list[list[int]]:
    """`_clip` of every value of `values` (F, M) to its row's `limits` (F, 2) (rounded half to even like
    `round`, non-finite → the row's largest value), as Python ints, in one numpy pass."""
    finite = np.isfinite(values)
    lo, hi = limits[:, 0:1], limits[:, 1:2]
    out = np.where(finite, np.clip(np.rint(np.where(finite, values, 0.0)), lo, hi), hi)
    rows: list[list[int]] = out.astype(np.int64).tolist()
    return rows


#: the CAM's integer fields in `cams` order: latitude, longitude, altitude, heading, speed, length, width,
#: longitudinal acceleration, curvature, yaw rate (ranges of ETSI TS 102 894-2, largest valid values)
_CAM_LIMITS = np.array(
    [
        [-900000000, 900000000],
        [-1800000000, 1800000000],
        [-100000, 800000],
        [0, 3600],
        [0, 16382],
        [1, 1022],
        [1, 61],
        [-160, 160],
        [-1022, 1022],
        [-32766, 32766],
    ],
    dtype=np.float64,
)


class _Memo:
    """Immutable message parts by their integer content (shared between messages: never mutate them). A
    part's content has a small domain (a heading in 0.1°, a speed in 0.01 m/s, a station id of the run), so
    most messages of a run reuse them; the memo is emptied when it exceeds `limit` entries."""

    __slots__ = ("build", "cache", "limit")

    def __init__(self, build: Callable[[int], Any], limit: int = 200_000) -> None:
        self.build = build
        self.cache: dict[int, Any] = {}
        self.limit = limit

    def __call__(self, value: int) -> Any:
        part = self.cache.get(value)
        if part is None:
            if len(self.cache) >= self.limit:
                self.cache.clear()
            part = self.cache[value] = self.build(value)
        return part


@dataclass(frozen=True, slots=True)
class KinematicsArrays:
    """`Kinematics` of M stations as arrays (M,) of the same units."""

    latitude: np.ndarray
    longitude: np.ndarray
    altitude: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    acceleration: np.ndarray
    yaw_rate: np.ndarray
    length: np.ndarray
    width: np.ndarray

    @classmethod
    def of(cls, ks: Sequence[Kinematics]) -> KinematicsArrays:
        return cls(*(np.array([getattr(k, f) for k in ks], dtype=np.float64) for f in _KINEMATICS_FIELDS))


_KINEMATICS_FIELDS = (
    "latitude",
    "longitude",
    "altitude",
    "heading",
    "speed",
    "acceleration",
    "yaw_rate",
    "length",
    "width",
)


class _CamParts:
    """The CAM's message types and memoised parts, built once per process."""

    def __init__(self) -> None:
        c = f"{_CAM}/msg/"
        t = {name: _t(c + name) for name in _CAM_TYPE_NAMES}
        self.t = t
        self.cam = _t(CAM_TYPE)
        one = t["SemiAxisLength"](value=1)  # simulated: exact (1 cm)
        self.confidence_ellipse = t["PosConfidenceEllipse"](
            semi_major_confidence=one,
            semi_minor_confidence=one,
            semi_major_orientation=t["HeadingValue"](value=0),
        )
        self.altitude = _Memo(
            lambda v: t["Altitude"](
                altitude_value=t["AltitudeValue"](value=v),
                altitude_confidence=t["AltitudeConfidence"](value=0),  # alt-000-01
            )
        )
        self.header = _Memo(
            lambda v: t["ItsPduHeader"](
                protocol_version=PROTOCOL_VERSION_CAM,
                message_id=MESSAGE_ID_CAM,
                station_id=t["StationID"](value=v),
            )
        )
        self.station_type = _Memo(lambda v: t["StationType"](value=v))
        self.generation_delta_time = _Memo(lambda v: t["GenerationDeltaTime"](value=v), limit=1024)
        heading_confidence = t["HeadingConfidence"](value=1)
        self.heading = _Memo(
            lambda v: t["Heading"](
                heading_value=t["HeadingValue"](value=v), heading_confidence=heading_confidence
            )
        )
        speed_confidence = t["SpeedConfidence"](value=1)
        self.speed = _Memo(
            lambda v: t["Speed"](speed_value=t["SpeedValue"](value=v), speed_confidence=speed_confidence)
        )
        self.drive_direction = (t["DriveDirection"](value=0), t["DriveDirection"](value=1))
        length_confidence = t["VehicleLengthConfidenceIndication"](value=0)
        self.vehicle_length = _Memo(
            lambda v: t["VehicleLength"](
                vehicle_length_value=t["VehicleLengthValue"](value=v),
                vehicle_length_confidence_indication=length_confidence,
            )
        )
        self.vehicle_width = _Memo(lambda v: t["VehicleWidth"](value=v))
        acceleration_confidence = t["AccelerationConfidence"](value=1)
        self.acceleration = _Memo(
            lambda v: t["LongitudinalAcceleration"](
                longitudinal_acceleration_value=t["LongitudinalAccelerationValue"](value=v),
                longitudinal_acceleration_confidence=acceleration_confidence,
            )
        )
        curvature_confidence = t["CurvatureConfidence"](value=0)
        self.curvature = _Memo(
            lambda v: t["Curvature"](
                curvature_value=t["CurvatureValue"](value=v), curvature_confidence=curvature_confidence
            )
        )
        self.curvature_mode = t["CurvatureCalculationMode"](value=0)
        yaw_rate_confidence = t["YawRateConfidence"](value=0)
        self.yaw_rate = _Memo(
            lambda v: t["YawRate"](
                yaw_rate_value=t["YawRateValue"](value=v), yaw_rate_confidence=yaw_rate_confidence
            )
        )
        self.bvc_zero = zero(f"{c}BasicVehicleContainerHighFrequency")
        self.rsu_zero = zero(f"{c}RSUContainerHighFrequency")
        self.lf_zero = zero(f"{c}LowFrequencyContainer")
        self.special_zero = zero(f"{c}SpecialVehicleContainer")
        hf = t["HighFrequencyContainer"]
        self.rsu_hf = hf(
            choice=hf.CHOICE_RSU_CONTAINER_HIGH_FREQUENCY,
            basic_vehicle_container_high_frequency=self.bvc_zero,
            rsu_container_high_frequency=self.rsu_zero,
        )


_CAM_TYPE_NAMES = (
    "AccelerationConfidence",
    "Altitude",
    "AltitudeConfidence",
    "AltitudeValue",
    "BasicContainer",
    "BasicVehicleContainerHighFrequency",
    "CamParameters",
    "CoopAwareness",
    "Curvature",
    "CurvatureCalculationMode",
    "CurvatureConfidence",
    "CurvatureValue",
    "DriveDirection",
    "GenerationDeltaTime",
    "Heading",
    "HeadingConfidence",
    "HeadingValue",
    "HighFrequencyContainer",
    "ItsPduHeader",
    "Latitude",
    "Longitude",
    "LongitudinalAcceleration",
    "LongitudinalAccelerationValue",
    "PosConfidenceEllipse",
    "ReferencePosition",
    "SemiAxisLength",
    "Speed",
    "SpeedConfidence",
    "SpeedValue",
    "StationID",
    "StationType",
    "VehicleLength",
    "VehicleLengthConfidenceIndication",
    "VehicleLengthValue",
    "VehicleWidth",
    "YawRate",
    "YawRateConfidence",
    "YawRateValue",
)


@cache
def _cam_parts() -> _CamParts:
    return _CamParts()


def cam(
    station_id: int,
    station_type: int,
    time_s: float,
    k: Kinematics,
    *,
    low_frequency: bool,
    rsu: bool = False,
) -> Any:
    """An `etsi_its_cam_msgs/msg/CAM`: basic container, the vehicle high-frequency container (an RSU: the RSU
    container) and, when `low_frequency`, the low-frequency container (role default, no lights, empty path)."""
    return cams([station_id], [station_type], time_s, KinematicsArrays.of([k]), [low_frequency], [rsu])[0]


def cams(
    station_ids: Sequence[int],
    station_types: Sequence[int],
    time_s: float,
    k: KinematicsArrays,
    low_frequency: Sequence[bool],
    rsu: Sequence[bool],
) -> list[Any]:
    """The CAMs of M stations at `time_s` (`cam` of each): every field's value computed for all of them in one
    numpy pass; parts with the same content are shared between the messages (never mutate them)."""
    p = _cam_parts()
    t = p.t
    moving = np.abs(k.speed) > 0.1
    curvature = np.where(moving, k.yaw_rate / np.where(moving, k.speed, 1.0), 0.0)  # 1/m
    values = np.stack(
        [
            k.latitude * 1e7,
            k.longitude * 1e7,
            k.altitude * 100,
            k.heading * 10,
            np.abs(k.speed) * 100,
            k.length * 10,
            k.width * 10,
            k.acceleration * 10,
            curvature * 10000,
            -np.degrees(k.yaw_rate) * 100,  # ETSI: clockwise positive
        ]
    )
    lat, lon, alt, heading, speed, length, width, acceleration, curvature_, yaw_rate = clip_rows(
        values, _CAM_LIMITS
    )
    heading = [v % 3600 for v in heading]
    backwards = (k.speed < 0).tolist()
    gdt = p.generation_delta_time(generation_delta_time(time_s))
    bvc_type, hf_type = t["BasicVehicleContainerHighFrequency"], t["HighFrequencyContainer"]
    ref_type, lat_type, lon_type = t["ReferencePosition"], t["Latitude"], t["Longitude"]
    basic_type, params_type, coop_type = t["BasicContainer"], t["CamParameters"], t["CoopAwareness"]
    z = p.bvc_zero
    out = []
    for m, station_id in enumerate(station_ids):
        if rsu[m]:
            hf = p.rsu_hf
        else:
            hf = hf_type(
                choice=hf_type.CHOICE_BASIC_VEHICLE_CONTAINER_HIGH_FREQUENCY,
                basic_vehicle_container_high_frequency=bvc_type(
                    heading=p.heading(heading[m]),
                    speed=p.speed(speed[m]),
                    drive_direction=p.drive_direction[backwards[m]],
                    vehicle_length=p.vehicle_length(length[m]),
                    vehicle_width=p.vehicle_width(width[m]),
                    longitudinal_acceleration=p.acceleration(acceleration[m]),
                    curvature=p.curvature(curvature_[m]),
                    curvature_calculation_mode=p.curvature_mode,
                    yaw_rate=p.yaw_rate(yaw_rate[m]),
                    acceleration_control=z.acceleration_control,
                    acceleration_control_is_present=False,
                    lane_position=z.lane_position,
                    lane_position_is_present=False,
                    steering_wheel_angle=z.steering_wheel_angle,
                    steering_wheel_angle_is_present=False,
                    lateral_acceleration=z.lateral_acceleration,
                    lateral_acceleration_is_present=False,
                    vertical_acceleration=z.vertical_acceleration,
                    vertical_acceleration_is_present=False,
                    performance_class=z.performance_class,
                    performance_class_is_present=False,
                    cen_dsrc_tolling_zone=z.cen_dsrc_tolling_zone,
                    cen_dsrc_tolling_zone_is_present=False,
                ),
                rsu_container_high_frequency=p.rsu_zero,
            )
        with_lf = bool(low_frequency[m] and not rsu[m])
        out.append(
            p.cam(
                header=p.header(int(station_id)),
                cam=coop_type(
                    generation_delta_time=gdt,
                    cam_parameters=params_type(
                        basic_container=basic_type(
                            station_type=p.station_type(int(station_types[m])),
                            reference_position=ref_type(
                                latitude=lat_type(value=lat[m]),
                                longitude=lon_type(value=lon[m]),
                                position_confidence_ellipse=p.confidence_ellipse,
                                altitude=p.altitude(alt[m]),
                            ),
                        ),
                        high_frequency_container=hf,
                        low_frequency_container=_low_frequency_container() if with_lf else p.lf_zero,
                        low_frequency_container_is_present=with_lf,
                        special_vehicle_container=p.special_zero,
                        special_vehicle_container_is_present=False,
                    ),
                ),
            )
        )
    return out


@cache
def _low_frequency_container() -> Any:
    return _t(f"{_CAM}/msg/LowFrequencyContainer")(
        choice=0,
        basic_vehicle_container_low_frequency=_t(f"{_CAM}/msg/BasicVehicleContainerLowFrequency")(
            vehicle_role=_t(f"{_CAM}/msg/VehicleRole")(value=0),
            exterior_lights=_t(f"{_CAM}/msg/ExteriorLights")(value=np.zeros(1, np.uint8), bits_unused=0),
            path_history=_t(f"{_CAM}/msg/PathHistory")(array=[]),
        ),
    )


_DENM = "etsi_its_denm_msgs"


def denm(
    station_id: int,
    station_type: int,
    sequence_number: int,
    time_s: float,
    detection_time_s: float,
    event: Kinematics,
    cause: int,
    sub_cause: int,
    *,
    validity_s: int = 10,
    transmission_interval_ms: int = 100,
) -> Any:
    """An `etsi_its_denm_msgs/msg/DENM` of one event: management container (action id, detection and reference
    time, event position, relevance < 500 m all directions, validity, transmission interval), situation
    container (information quality 1, the cause code), location container (event speed and heading)."""
    management = _t(f"{_DENM}/msg/ManagementContainer")
    zm = zero(management.__msgtype__)
    situation = _t(f"{_DENM}/msg/SituationContainer")
    zs = zero(situation.__msgtype__)
    location = _t(f"{_DENM}/msg/LocationContainer")
    zl = zero(location.__msgtype__)
    cause_code = _t(f"{_DENM}/msg/CauseCode")(
        cause_code=_t(f"{_DENM}/msg/CauseCodeType")(value=cause),
        sub_cause_code=_t(f"{_DENM}/msg/SubCauseCodeType")(value=sub_cause),
    )
    return _t(DENM_TYPE)(
        header=_header(_DENM, MESSAGE_ID_DENM, PROTOCOL_VERSION_DENM, station_id),
        denm=_t(f"{_DENM}/msg/DecentralizedEnvironmentalNotificationMessage")(
            management=management(
                action_id=_t(f"{_DENM}/msg/ActionID")(
                    originating_station_id=_t(f"{_DENM}/msg/StationID")(value=station_id),
                    sequence_number=_t(f"{_DENM}/msg/SequenceNumber")(value=sequence_number % 65536),
                ),
                detection_time=_t(f"{_DENM}/msg/TimestampIts")(value=its_time_ms(detection_time_s)),
                reference_time=_t(f"{_DENM}/msg/TimestampIts")(value=its_time_ms(time_s)),
                termination=zm.termination,
                termination_is_present=False,
                event_position=_reference_position(_DENM, event),
                relevance_distance=_t(f"{_DENM}/msg/RelevanceDistance")(value=3),  # lessThan500m
                relevance_distance_is_present=True,
                relevance_traffic_direction=_t(f"{_DENM}/msg/RelevanceTrafficDirection")(value=0),
                relevance_traffic_direction_is_present=True,
                validity_duration=_t(f"{_DENM}/msg/ValidityDuration")(value=validity_s),
                transmission_interval=_t(f"{_DENM}/msg/TransmissionInterval")(value=transmission_interval_ms),
                transmission_interval_is_present=True,
                station_type=_t(f"{_DENM}/msg/StationType")(value=station_type),
            ),
            situation=situation(
                information_quality=_t(f"{_DENM}/msg/InformationQuality")(value=1),
                event_type=cause_code,
                linked_cause=zs.linked_cause,
                linked_cause_is_present=False,
                event_history=zs.event_history,
                event_history_is_present=False,
            ),
            situation_is_present=True,
            location=location(
                event_speed=_speed(_DENM, event.speed),
                event_speed_is_present=True,
                event_position_heading=_heading(_DENM, event.heading),
                event_position_heading_is_present=True,
                traces=zl.traces,
                road_type=zl.road_type,
                road_type_is_present=False,
            ),
            location_is_present=True,
            alacarte=zero(f"{_DENM}/msg/AlacarteContainer"),
            alacarte_is_present=False,
        ),
    )


@dataclass(frozen=True, slots=True)
class PerceivedObject:
    """An object a station perceives, in the CPM's frame (TS 103 324: x east, y north, z up, from the
    station's reference position): offsets (m), velocity (m/s east, north), yaw (deg, counter-clockwise from
    east), dimensions (m), age (s), the ETSI StationType / TrafficParticipantType of its class (−1: not a
    road user, e.g. an obstacle)."""

    object_id: int
    x: float
    y: float
    z: float
    vx: float
    vy: float
    yaw: float
    length: float
    width: float
    height: float
    age: float
    classification: int


@dataclass(frozen=True, slots=True)
class PerceivedObjects:
    """`PerceivedObject`s of one CPM as arrays: `ids` (M,), `values` (10, M) = x, y, z, vx, vy, yaw, length,
    width, height, age in `PerceivedObject`'s units, `classification` (M,)."""

    ids: np.ndarray
    values: np.ndarray
    classification: np.ndarray

    @classmethod
    def of(cls, objects: Sequence[PerceivedObject]) -> PerceivedObjects:
        values = np.array(
            [(o.x, o.y, o.z, o.vx, o.vy, o.yaw, o.length, o.width, o.height, o.age) for o in objects],
            dtype=np.float64,
        ).reshape(-1, 10)
        return cls(
            np.array([o.object_id for o in objects], dtype=np.int64),
            values.T,
            np.array([o.classification for o in objects], dtype=np.int64),
        )

    def __len__(self) -> int:
        return len(self.ids)


_CPM = "etsi_its_cpm_ts_msgs"
PROTOCOL_VERSION_CPM = 2
MESSAGE_ID_CPM = 14
#: CpmContainerId of the containers CARLOS sends (TS 103 324 V2.1.1, CpmContainers)
CONTAINER_ORIGINATING_VEHICLE = 1
CONTAINER_ORIGINATING_RSU = 2
CONTAINER_PERCEIVED_OBJECTS = 5
#: ETSI classes that are vulnerable road users in a CPM's ObjectClass (vruSubClass: profile, sub-profile);
#: vehicleSubClass takes only unknown, passengerCar..tram and agricultural
_VRU_CLASSES = {
    1: (0, 1),
    2: (1, 1),
    3: (2, 1),
    4: (2, 2),
    13: (3, 0),
}  # pedestrian, cyclist, moped, motorcycle, animal
_VEHICLE_CLASSES = frozenset({0, 5, 6, 7, 8, 9, 10, 11, 14})


def _cpm_t(name: str) -> Any:
    return _t(f"{_CPM}/msg/{name}")


def _object_class(station_type: int) -> Any:
    """ObjectClassWithConfidence (ground truth: 100 %) of an ETSI class."""
    cls = _cpm_t("ObjectClass")
    z = zero(cls.__msgtype__)
    if station_type in _VRU_CLASSES:
        profile, sub = _VRU_CLASSES[station_type]
        vru = _cpm_t("VruProfileAndSubprofile")
        zv = zero(vru.__msgtype__)
        parts = {
            0: ("pedestrian", "VruSubProfilePedestrian"),
            1: ("bicyclist_and_light_vru_vehicle", "VruSubProfileBicyclist"),
            2: ("motorcyclist", "VruSubProfileMotorcyclist"),
            3: ("animal", "VruSubProfileAnimal"),
        }
        field, typename = parts[profile]
        fields = {
            "choice": profile,
            "pedestrian": zv.pedestrian,
            "bicyclist_and_light_vru_vehicle": zv.bicyclist_and_light_vru_vehicle,
            "motorcyclist": zv.motorcyclist,
            "animal": zv.animal,
        }
        fields[field] = _cpm_t(typename)(value=sub)
        object_class = cls(
            choice=cls.CHOICE_VRU_SUB_CLASS,
            vehicle_sub_class=z.vehicle_sub_class,
            vru_sub_class=vru(**fields),
            group_sub_class=z.group_sub_class,
            other_sub_class=z.other_sub_class,
        )
    elif station_type in _VEHICLE_CLASSES:
        object_class = cls(
            choice=cls.CHOICE_VEHICLE_SUB_CLASS,
            vehicle_sub_class=_cpm_t("TrafficParticipantType")(value=station_type),
            vru_sub_class=z.vru_sub_class,
            group_sub_class=z.group_sub_class,
            other_sub_class=z.other_sub_class,
        )
    else:  # an obstacle, an animal, …: a single object of another class
        object_class = cls(
            choice=cls.CHOICE_OTHER_SUB_CLASS,
            vehicle_sub_class=z.vehicle_sub_class,
            vru_sub_class=z.vru_sub_class,
            group_sub_class=z.group_sub_class,
            other_sub_class=_cpm_t("OtherSubClass")(value=1),  # singleObject
        )
    return _cpm_t("ObjectClassWithConfidence")(
        object_class=object_class, confidence=_cpm_t("ConfidenceLevel")(value=100)
    )


class _CpmParts:
    """The CPM's message types and memoised parts (shared between messages: never mutate them)."""

    def __init__(self) -> None:
        t = {name: _cpm_t(name) for name in _CPM_TYPE_NAMES}
        self.t = t
        coordinate_confidence = t["CoordinateConfidence"](value=1)  # ground truth: within 1 cm
        self.coordinate = _Memo(
            lambda v: t["CartesianCoordinateWithConfidence"](
                value=t["CartesianCoordinateLarge"](value=v), confidence=coordinate_confidence
            )
        )
        speed_confidence = t["SpeedConfidence"](value=1)
        self.velocity = _Memo(
            lambda v: t["VelocityComponent"](
                value=t["VelocityComponentValue"](value=v), confidence=speed_confidence
            )
        )
        dimension_confidence = t["ObjectDimensionConfidence"](value=1)
        self.dimension = _Memo(
            lambda v: t["ObjectDimension"](
                value=t["ObjectDimensionValue"](value=v), confidence=dimension_confidence
            )
        )
        angle_confidence = t["AngleConfidence"](value=1)
        no_angle = zero(f"{_CPM}/msg/CartesianAngle")
        self.angles = _Memo(
            lambda v: t["EulerAnglesWithConfidence"](
                z_angle=t["CartesianAngle"](
                    value=t["CartesianAngleValue"](value=v), confidence=angle_confidence
                ),
                y_angle=no_angle,
                y_angle_is_present=False,
                x_angle=no_angle,
                x_angle_is_present=False,
            )
        )
        self.delta_time = _Memo(lambda v: t["DeltaTimeMilliSecondSigned"](value=v))
        self.identifier = _Memo(lambda v: t["Identifier2B"](value=v))
        self.classification = _Memo(lambda v: t["ObjectClassDescription"](array=[_object_class(v)]))
        self.quality = t["ObjectPerceptionQuality"](value=15)  # ground truth
        self.cpm = _t(CPM_TYPE)
        self.count = _Memo(lambda v: t["CardinalNumber1B"](value=v))
        self.header = _Memo(
            lambda v: t["ItsPduHeader"](
                protocol_version=t["OrdinalNumber1B"](value=PROTOCOL_VERSION_CPM),
                message_id=t["MessageId"](value=MESSAGE_ID_CPM),
                station_id=t["StationId"](value=v),
            )
        )
        self.management_zero = zero(f"{_CPM}/msg/ManagementContainer")
        self.wrapped = _cpm_t("WrappedCpmContainer")
        empty = zero(self.wrapped.__msgtype__)
        #: a perceived object container's WrappedCpmContainer fields but its data: id 5, the others zero
        self.perceived_fields = {
            name: getattr(empty, name)
            for name in self.wrapped.__dataclass_fields__
            if name != "container_data_perceived_object_container"
        }
        self.perceived_fields["container_id"] = _cpm_t("CpmContainerId")(value=CONTAINER_PERCEIVED_OBJECTS)
        self.rsu_container = _wrapped(
            CONTAINER_ORIGINATING_RSU,
            container_data_originating_rsu_container=zero(f"{_CPM}/msg/OriginatingRsuContainer"),
        )
        heading_confidence = t["Wgs84AngleConfidence"](value=1)
        no_angle = zero(f"{_CPM}/msg/CartesianAngle")
        no_trailer = zero(f"{_CPM}/msg/TrailerDataSet")
        self.vehicle_container = _Memo(
            lambda v: _wrapped(
                CONTAINER_ORIGINATING_VEHICLE,
                container_data_originating_vehicle_container=t["OriginatingVehicleContainer"](
                    orientation_angle=t["Wgs84Angle"](
                        value=t["Wgs84AngleValue"](value=v), confidence=heading_confidence
                    ),
                    pitch_angle=no_angle,
                    pitch_angle_is_present=False,
                    roll_angle=no_angle,
                    roll_angle_is_present=False,
                    trailer_data_set=no_trailer,
                    trailer_data_set_is_present=False,
                ),
            )
        )
        self.no_velocity = zero(f"{_CPM}/msg/VelocityComponent")
        self.no_polar = zero(f"{_CPM}/msg/VelocityPolarWithZ")
        self.object_zero = zero(f"{_CPM}/msg/PerceivedObject")


_CPM_TYPE_NAMES = (
    "AngleConfidence",
    "CardinalNumber1B",
    "ConstraintWrappedCpmContainers",
    "CpmPayload",
    "ItsPduHeader",
    "ManagementContainer",
    "MessageId",
    "OrdinalNumber1B",
    "OriginatingVehicleContainer",
    "PerceivedObjectContainer",
    "PerceivedObjects",
    "StationId",
    "TimestampIts",
    "Wgs84Angle",
    "Wgs84AngleConfidence",
    "Wgs84AngleValue",
    "WrappedCpmContainers",
    "CartesianAngle",
    "CartesianAngleValue",
    "CartesianCoordinateLarge",
    "CartesianCoordinateWithConfidence",
    "CartesianPosition3dWithConfidence",
    "CoordinateConfidence",
    "DeltaTimeMilliSecondSigned",
    "EulerAnglesWithConfidence",
    "Identifier2B",
    "ObjectClassDescription",
    "ObjectDimension",
    "ObjectDimensionConfidence",
    "ObjectDimensionValue",
    "ObjectPerceptionQuality",
    "PerceivedObject",
    "SpeedConfidence",
    "Velocity3dWithConfidence",
    "VelocityCartesian",
    "VelocityComponent",
    "VelocityComponentValue",
)


@cache
def _cpm_parts() -> _CpmParts:
    return _CpmParts()


#: a perceived object's integer fields in `_perceived_objects` order: x, y, z (cm), vx, vy (cm/s), yaw
#: (0.1°), length, width, height (dm, rounded up), age (ms; 1500: more than 1.5 s)
_OBJECT_LIMITS = np.array(
    [
        [-131072, 131071],
        [-131072, 131071],
        [-131072, 131071],
        [-16383, 16382],
        [-16383, 16382],
        [0, 3600],
        [1, 255],
        [1, 255],
        [1, 255],
        [0, 1500],
    ],
    dtype=np.float64,
)


def _perceived_objects(objects: PerceivedObjects) -> list[Any]:
    """The PerceivedObject messages of `objects`: every field's value computed in one numpy pass."""
    if not len(objects):
        return []
    p = _cpm_parts()
    t = p.t
    raw = objects.values
    values = np.stack(
        [
            raw[0] * 100,
            raw[1] * 100,
            raw[2] * 100,
            raw[3] * 100,
            raw[4] * 100,
            np.mod(raw[5], 360.0) * 10,
            np.ceil(raw[6] * 10 - 1e-9),
            np.ceil(raw[7] * 10 - 1e-9),
            np.ceil(raw[8] * 10 - 1e-9),
            raw[9] * 1000,
        ]
    )
    x, y, z, vx, vy, yaw, length, width, height, age = clip_rows(values, _OBJECT_LIMITS)
    zo = p.object_zero
    position, velocity, cartesian = (
        t["CartesianPosition3dWithConfidence"],
        t["Velocity3dWithConfidence"],
        t["VelocityCartesian"],
    )
    out = []
    ids = (objects.ids % 65536).tolist()
    classes = objects.classification.tolist()
    for k in range(len(ids)):
        out.append(
            t["PerceivedObject"](
                object_id=p.identifier(ids[k]),
                object_id_is_present=True,
                measurement_delta_time=p.delta_time(0),  # measured at the reference time
                position=position(
                    x_coordinate=p.coordinate(x[k]),
                    y_coordinate=p.coordinate(y[k]),
                    z_coordinate=p.coordinate(z[k]),
                    z_coordinate_is_present=True,
                ),
                velocity=velocity(
                    choice=velocity.CHOICE_CARTESIAN_VELOCITY,
                    polar_velocity=p.no_polar,
                    cartesian_velocity=cartesian(
                        x_velocity=p.velocity(vx[k]),
                        y_velocity=p.velocity(vy[k]),
                        z_velocity=p.no_velocity,
                        z_velocity_is_present=False,
                    ),
                ),
                velocity_is_present=True,
                acceleration=zo.acceleration,
                acceleration_is_present=False,
                angles=p.angles(yaw[k] % 3600),
                angles_is_present=True,
                z_angular_velocity=zo.z_angular_velocity,
                z_angular_velocity_is_present=False,
                lower_triangular_correlation_matrices=zo.lower_triangular_correlation_matrices,
                lower_triangular_correlation_matrices_is_present=False,
                object_dimension_z=p.dimension(height[k]),
                object_dimension_z_is_present=True,
                object_dimension_y=p.dimension(width[k]),
                object_dimension_y_is_present=True,
                object_dimension_x=p.dimension(length[k]),
                object_dimension_x_is_present=True,
                object_age=p.delta_time(age[k]),
                object_age_is_present=True,
                object_perception_quality=p.quality,
                object_perception_quality_is_present=True,
                sensor_id_list=zo.sensor_id_list,
                sensor_id_list_is_present=False,
                classification=p.classification(classes[k]),
                classification_is_present=True,
                map_position=zo.map_position,
                map_position_is_present=False,
            )
        )
    return out


def _wrapped(container_id: int, **data: Any) -> Any:
    """A WrappedCpmContainer: `container_id` and its container (the other alternatives zero)."""
    wrapped = _cpm_t("WrappedCpmContainer")
    z = zero(wrapped.__msgtype__)
    fields = {name: getattr(z, name) for name in wrapped.__dataclass_fields__ if name != "container_id"}
    fields.update(data)
    return wrapped(container_id=_cpm_t("CpmContainerId")(value=container_id), **fields)


def cpm(
    station_id: int,
    station_type: int,
    time_s: float,
    reference: Kinematics,
    objects: Sequence[PerceivedObject] | PerceivedObjects,
    *,
    rsu: bool = False,
) -> Any:
    """An `etsi_its_cpm_ts_msgs/msg/CollectivePerceptionMessage` (TS 103 324 V2.1.1) with `objects` measured at
    `time_s`: management container (reference time and position), the originating vehicle container (its
    heading) or the originating RSU container, and the perceived object container. `station_type` is not a
    field of the CPM (its originating container tells a vehicle from an RSU)."""
    p = _cpm_parts()
    if not isinstance(objects, PerceivedObjects):
        objects = PerceivedObjects.of(objects)
    if len(objects) > 255:  # the most a CPM carries
        objects = PerceivedObjects(objects.ids[:255], objects.values[:, :255], objects.classification[:255])
    station = p.rsu_container if rsu else p.vehicle_container(_clip(reference.heading * 10, 0, 3600) % 3600)
    perceived = p.wrapped(
        **p.perceived_fields,
        container_data_perceived_object_container=p.t["PerceivedObjectContainer"](
            number_of_perceived_objects=p.count(len(objects)),
            perceived_objects=p.t["PerceivedObjects"](array=_perceived_objects(objects)),
        ),
    )
    z = p.management_zero
    return p.cpm(
        header=p.header(station_id),
        payload=p.t["CpmPayload"](
            management_container=p.t["ManagementContainer"](
                reference_time=p.t["TimestampIts"](value=its_time_ms(time_s)),
                reference_position=_reference_position(_CPM, reference),
                segmentation_info=z.segmentation_info,
                segmentation_info_is_present=False,
                message_rate_range=z.message_rate_range,
                message_rate_range_is_present=False,
            ),
            cpm_containers=p.t["ConstraintWrappedCpmContainers"](
                value=p.t["WrappedCpmContainers"](array=[station, perceived])
            ),
        ),
    )
