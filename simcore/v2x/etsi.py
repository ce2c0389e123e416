"""ETSI ITS messages as ROS 2 messages: CAM (`etsi_its_cam_msgs/msg/CAM`), DENM (`etsi_its_denm_msgs/msg/DENM`),
both laid out as ika's etsi_its_messages packages, and CARLOS' CPM (`carlos_v2x_msgs/msg/CollectivePerceptionMessage`,
the contents of ETSI TS 103 324 in a flat layout).

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

from simcore.transport.messages import TYPESTORE, stamp

CAM_TYPE = "etsi_its_cam_msgs/msg/CAM"
DENM_TYPE = "etsi_its_denm_msgs/msg/DENM"
CPM_TYPE = "carlos_v2x_msgs/msg/CollectivePerceptionMessage"

#: TimestampIts of simulated time 0: 2026-01-01T00:00:00Z, TAI milliseconds since 2004-01-01 (5 leap seconds).
SIM_EPOCH_ITS_MS = (8036 * 86400 + 5) * 1000

PROTOCOL_VERSION_CAM = 2
PROTOCOL_VERSION_DENM = 2
MESSAGE_ID_DENM = 1
MESSAGE_ID_CAM = 2

#: ETSI StationType of an OpenSCENARIO category (unknown categories: 0).
STATION_TYPES = {
    "pedestrian": 1,
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
    return _t(f"{pkg}/msg/ReferencePosition")(
        latitude=_t(f"{pkg}/msg/Latitude")(value=_clip(k.latitude * 1e7, -900000000, 900000000)),
        longitude=_t(f"{pkg}/msg/Longitude")(value=_clip(k.longitude * 1e7, -1800000000, 1800000000)),
        position_confidence_ellipse=_t(f"{pkg}/msg/PosConfidenceEllipse")(
            semi_major_confidence=_t(f"{pkg}/msg/SemiAxisLength")(value=1),  # simulated: exact (1 cm)
            semi_minor_confidence=_t(f"{pkg}/msg/SemiAxisLength")(value=1),
            semi_major_orientation=_t(f"{pkg}/msg/HeadingValue")(value=0),
        ),
        altitude=_t(f"{pkg}/msg/Altitude")(
            altitude_value=_t(f"{pkg}/msg/AltitudeValue")(value=_clip(k.altitude * 100, -100000, 800000)),
            altitude_confidence=_t(f"{pkg}/msg/AltitudeConfidence")(value=0),  # alt-000-01
        ),
    )


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


def clip_ints(values: Any, lo: int, hi: int) -> list[int]:
    """`_clip` of every value (rounded half to even like `round`, non-finite → `hi`), as Python ints."""
    v = np.asarray(values, dtype=np.float64)
    out = np.where(np.isfinite(v), np.clip(np.rint(np.where(np.isfinite(v), v, 0.0)), lo, hi), hi)
    return [int(x) for x in out.astype(np.int64).tolist()]


def clip_rows(values: np.ndarray, limits: np.ndarray) -> list[list[int]]:
    """`clip_ints` of each row of `values` (F, M) to its row of `limits` (F, 2), in one numpy pass."""
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
    """An object a station perceives: map-frame east/north offsets (m) from the station's reference position,
    height above it, velocity (m/s east, north), ETSI heading (deg), dimensions (m), age (s), class."""

    object_id: int
    dx: float
    dy: float
    dz: float
    vx: float
    vy: float
    heading: float
    length: float
    width: float
    height: float
    age: float
    classification: int


def cpm(
    station_id: int, station_type: int, time_s: float, reference: Kinematics, objects: list[PerceivedObject]
) -> Any:
    """A `carlos_v2x_msgs/msg/CollectivePerceptionMessage` with `objects` (measured at `time_s`)."""
    obj_type = _t("carlos_v2x_msgs/msg/PerceivedObject")
    return _t(CPM_TYPE)(
        header=_t("std_msgs/msg/Header")(stamp=stamp(time_s), frame_id="map"),
        station_id=station_id,
        station_type=station_type,
        reference_time=its_time_ms(time_s),
        latitude=_clip(reference.latitude * 1e7, -900000000, 900000000),
        longitude=_clip(reference.longitude * 1e7, -1800000000, 1800000000),
        altitude=_clip(reference.altitude * 100, -100000, 800000),
        perceived_objects=[
            obj_type(
                object_id=o.object_id % 65536,
                measurement_delta_time=0,
                x_distance=_clip(o.dx * 100, -(2**31), 2**31 - 1),
                y_distance=_clip(o.dy * 100, -(2**31), 2**31 - 1),
                z_distance=_clip(o.dz * 100, -(2**31), 2**31 - 1),
                x_speed=_clip(o.vx * 100, -(2**31), 2**31 - 1),
                y_speed=_clip(o.vy * 100, -(2**31), 2**31 - 1),
                yaw_angle=_clip(o.heading * 10, 0, 3600) % 3600,
                x_dimension=_clip(o.length * 10, 0, 65535),
                y_dimension=_clip(o.width * 10, 0, 65535),
                z_dimension=_clip(o.height * 10, 0, 65535),
                object_age=_clip(o.age * 1000, 0, 65535),
                classification=o.classification,
            )
            for o in objects
        ],
    )
