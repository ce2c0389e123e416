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
from dataclasses import dataclass
from functools import cache
from typing import Any

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
    import numpy as np

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
    hf_type = _t(f"{_CAM}/msg/HighFrequencyContainer")
    if rsu:
        hf = hf_type(
            choice=hf_type.CHOICE_RSU_CONTAINER_HIGH_FREQUENCY,
            basic_vehicle_container_high_frequency=zero(f"{_CAM}/msg/BasicVehicleContainerHighFrequency"),
            rsu_container_high_frequency=zero(f"{_CAM}/msg/RSUContainerHighFrequency"),
        )
    else:
        curvature = k.yaw_rate / k.speed if abs(k.speed) > 0.1 else 0.0  # 1/m
        bvc = zero(f"{_CAM}/msg/BasicVehicleContainerHighFrequency")
        hf = hf_type(
            choice=hf_type.CHOICE_BASIC_VEHICLE_CONTAINER_HIGH_FREQUENCY,
            basic_vehicle_container_high_frequency=_t(f"{_CAM}/msg/BasicVehicleContainerHighFrequency")(
                heading=_heading(_CAM, k.heading),
                speed=_speed(_CAM, k.speed),
                drive_direction=_t(f"{_CAM}/msg/DriveDirection")(value=0 if k.speed >= 0 else 1),
                vehicle_length=_t(f"{_CAM}/msg/VehicleLength")(
                    vehicle_length_value=_t(f"{_CAM}/msg/VehicleLengthValue")(
                        value=_clip(k.length * 10, 1, 1022)
                    ),
                    vehicle_length_confidence_indication=_t(f"{_CAM}/msg/VehicleLengthConfidenceIndication")(
                        value=0
                    ),
                ),
                vehicle_width=_t(f"{_CAM}/msg/VehicleWidth")(value=_clip(k.width * 10, 1, 61)),
                longitudinal_acceleration=_t(f"{_CAM}/msg/LongitudinalAcceleration")(
                    longitudinal_acceleration_value=_t(f"{_CAM}/msg/LongitudinalAccelerationValue")(
                        value=_clip(k.acceleration * 10, -160, 160)
                    ),
                    longitudinal_acceleration_confidence=_t(f"{_CAM}/msg/AccelerationConfidence")(value=1),
                ),
                curvature=_t(f"{_CAM}/msg/Curvature")(
                    curvature_value=_t(f"{_CAM}/msg/CurvatureValue")(
                        value=_clip(curvature * 10000, -1022, 1022)
                    ),
                    curvature_confidence=_t(f"{_CAM}/msg/CurvatureConfidence")(value=0),
                ),
                curvature_calculation_mode=_t(f"{_CAM}/msg/CurvatureCalculationMode")(value=0),
                yaw_rate=_t(f"{_CAM}/msg/YawRate")(
                    yaw_rate_value=_t(f"{_CAM}/msg/YawRateValue")(
                        value=_clip(
                            -math.degrees(k.yaw_rate) * 100, -32766, 32766
                        )  # ETSI: clockwise positive
                    ),
                    yaw_rate_confidence=_t(f"{_CAM}/msg/YawRateConfidence")(value=0),
                ),
                acceleration_control=bvc.acceleration_control,
                acceleration_control_is_present=False,
                lane_position=bvc.lane_position,
                lane_position_is_present=False,
                steering_wheel_angle=bvc.steering_wheel_angle,
                steering_wheel_angle_is_present=False,
                lateral_acceleration=bvc.lateral_acceleration,
                lateral_acceleration_is_present=False,
                vertical_acceleration=bvc.vertical_acceleration,
                vertical_acceleration_is_present=False,
                performance_class=bvc.performance_class,
                performance_class_is_present=False,
                cen_dsrc_tolling_zone=bvc.cen_dsrc_tolling_zone,
                cen_dsrc_tolling_zone_is_present=False,
            ),
            rsu_container_high_frequency=zero(f"{_CAM}/msg/RSUContainerHighFrequency"),
        )
    lf = zero(f"{_CAM}/msg/LowFrequencyContainer")
    if low_frequency and not rsu:
        lf = _low_frequency_container()
    return _t(CAM_TYPE)(
        header=_header(_CAM, MESSAGE_ID_CAM, PROTOCOL_VERSION_CAM, station_id),
        cam=_t(f"{_CAM}/msg/CoopAwareness")(
            generation_delta_time=_t(f"{_CAM}/msg/GenerationDeltaTime")(value=generation_delta_time(time_s)),
            cam_parameters=_t(f"{_CAM}/msg/CamParameters")(
                basic_container=_t(f"{_CAM}/msg/BasicContainer")(
                    station_type=_t(f"{_CAM}/msg/StationType")(value=station_type),
                    reference_position=_reference_position(_CAM, k),
                ),
                high_frequency_container=hf,
                low_frequency_container=lf,
                low_frequency_container_is_present=bool(low_frequency and not rsu),
                special_vehicle_container=zero(f"{_CAM}/msg/SpecialVehicleContainer"),
                special_vehicle_container_is_present=False,
            ),
        ),
    )


@cache
def _low_frequency_container() -> Any:
    import numpy as np

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
