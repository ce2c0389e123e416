"""ROS 2 jazzy messages built from the world state (DESIGN.md, "Topics").

One type store, :data:`TYPESTORE`: rosbags' ROS 2 jazzy store extended with `vision_msgs` (4.x) and
`ackermann_msgs` (2.x), whose official `.msg` definitions ship under `simcore/transport/msg/<pkg>/`, and the
V2X packages: `etsi_its_cam_msgs`, `etsi_its_denm_msgs` and `etsi_its_cpm_ts_msgs` (the layout of ika's
etsi_its_messages, written from the ETSI ASN.1: EN 302 637-2/-3, CDD TS 102 894-2 V1.3.1, CPM TS 103 324
V2.1.1 with CDD V2.1.1) and CARLOS' own `carlos_v2x_msgs` (link outcomes); see `simcore/v2x/etsi.py`.

Every builder is a pure function of a :class:`~simcore.world.state.WorldFrame`; stamps are simulated time
from 0 (`/clock` and every header carry `frame.time`). Frames follow REP-103/105: the world frame is
`map` (ENU), each entity's frame `<entity>/base_link` at its reference point (x forward, y left, z up).

Entity names become ROS name tokens through :func:`ros_name`, injectively: a name that is a valid token
stays as it is; any other is made one (characters other than letters, digits and `_` become `_`, runs of
`_` collapse, a leading digit gets an `e` prefix) and gets the first 6 hex digits of its SHA-256 as a
suffix, so `Ego_0_-1` and `Ego_0_1` (or `car-2` and `car 2`) never share a frame. The original name stays
in the messages that name entities (ground truth ids, metadata).

`/carlos/status` uses `diagnostic_msgs/msg/DiagnosticStatus` (see :func:`status`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import cache, partial
from typing import TYPE_CHECKING, Any

import numpy as np

from simcore.transport import world_cdr
from simcore.transport.conversions import quaternion_xyzw, stamp_parts
from simcore.transport.msgdefs import FIELDDEFS
from simcore.transport.ros_names import MAP_FRAME, base_link, odometry_topic, ros_name
from simcore.transport.typestore import MSG_DIR, LazyTypestore
from simcore.world.state import EntityState, WorldFrame

__all__ = [
    "MAP_FRAME",
    "MSG_DIR",
    "STATUS_TOPIC",
    "TYPESTORE",
    "base_link",
    "clock",
    "deserialize",
    "frame_builders",
    "frame_messages",
    "msgdef",
    "objects",
    "odometry",
    "odometry_topic",
    "quaternion",
    "ros_name",
    "serialize",
    "stamp",
    "status",
    "tf",
]

CLOCK_TOPIC = "/clock"
TF_TOPIC = "/tf"
OBJECTS_TOPIC = "/carlos/objects"
STATUS_TOPIC = "/carlos/status"

_ZERO_COVARIANCE = np.zeros(36, dtype=np.float64)

#: The one type store of CARLOS: ROS 2 jazzy + vision_msgs + ackermann_msgs + the V2X packages; each type's
#: class is generated when it is first used (simcore/transport/typestore.py).
TYPESTORE: LazyTypestore = LazyTypestore(FIELDDEFS)


def _type(typename: str) -> Any:
    return TYPESTORE.types[typename]


if TYPE_CHECKING:
    from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
    from rosbags.typesys.stores.ros2_jazzy import diagnostic_msgs__msg__DiagnosticStatus as DiagnosticStatus
    from rosbags.typesys.stores.ros2_jazzy import diagnostic_msgs__msg__KeyValue as KeyValue
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseWithCovariance as PoseWithCovariance
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Transform as Transform
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TransformStamped as TransformStamped
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
    from rosbags.typesys.stores.ros2_jazzy import (
        geometry_msgs__msg__TwistWithCovariance as TwistWithCovariance,
    )
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3
    from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as Odometry
    from rosbags.typesys.stores.ros2_jazzy import rosgraph_msgs__msg__Clock as Clock
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header
    from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage
else:
    Time = _type("builtin_interfaces/msg/Time")
    DiagnosticStatus = _type("diagnostic_msgs/msg/DiagnosticStatus")
    KeyValue = _type("diagnostic_msgs/msg/KeyValue")
    Point = _type("geometry_msgs/msg/Point")
    Pose = _type("geometry_msgs/msg/Pose")
    PoseWithCovariance = _type("geometry_msgs/msg/PoseWithCovariance")
    Quaternion = _type("geometry_msgs/msg/Quaternion")
    Transform = _type("geometry_msgs/msg/Transform")
    TransformStamped = _type("geometry_msgs/msg/TransformStamped")
    Twist = _type("geometry_msgs/msg/Twist")
    TwistWithCovariance = _type("geometry_msgs/msg/TwistWithCovariance")
    Vector3 = _type("geometry_msgs/msg/Vector3")
    Odometry = _type("nav_msgs/msg/Odometry")
    Clock = _type("rosgraph_msgs/msg/Clock")
    Header = _type("std_msgs/msg/Header")
    TFMessage = _type("tf2_msgs/msg/TFMessage")


# --- names and small conversions ------------------------------------------------------------------------


def _check_unique(frame: WorldFrame) -> None:
    seen: dict[str, str] = {}
    for entity in (*frame.entities, *frame.ghosts):
        token = ros_name(entity.name)
        if token in seen and seen[token] != entity.name:
            raise ValueError(
                f"entities {seen[token]!r} and {entity.name!r} both map to the ROS name {token!r}; "
                "rename one of them in the scenario"
            )
        seen[token] = entity.name


def stamp(time_s: float) -> Time:
    """Simulated time in seconds as builtin_interfaces/Time (rounded to the nanosecond)."""
    sec, nanosec = stamp_parts(time_s)
    return Time(sec=sec, nanosec=nanosec)


def quaternion(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> Quaternion:
    """Quaternion of the intrinsic z-y'-x'' rotation (yaw, pitch, roll), as tf2's `setRPY(roll, pitch, yaw)`."""
    x, y, z, w = quaternion_xyzw(yaw, pitch, roll)
    return Quaternion(x=x, y=y, z=z, w=w)


def _header(frame: WorldFrame, frame_id: str = MAP_FRAME) -> Header:
    return Header(stamp=stamp(frame.time), frame_id=frame_id)


def _orientation(entity: EntityState) -> Quaternion:
    return quaternion(entity.heading, entity.pitch, entity.roll)


# --- message builders ----------------------------------------------------------------------------------


def clock(frame: WorldFrame) -> Clock:
    """rosgraph_msgs/msg/Clock at the frame's simulated time."""
    return Clock(clock=stamp(frame.time))


def tf(frame: WorldFrame) -> TFMessage:
    """tf2_msgs/msg/TFMessage: one transform `map` → `<entity>/base_link` per entity and per FollowGhost ghost
    (full orientation)."""
    _check_unique(frame)
    header = _header(frame)
    return TFMessage(
        transforms=[
            TransformStamped(
                header=header,
                child_frame_id=base_link(entity.name),
                transform=Transform(
                    translation=Vector3(x=entity.x, y=entity.y, z=entity.z),
                    rotation=_orientation(entity),
                ),
            )
            for entity in (*frame.entities, *frame.ghosts)
        ]
    )


def odometry(frame: WorldFrame, entity: str | EntityState) -> Odometry:
    """nav_msgs/msg/Odometry of one entity: pose in `map`, twist in `<entity>/base_link`
    (linear.x = speed, angular.z = yaw_rate). Ground truth, so the covariances are zero."""
    state = frame.entity(entity) if isinstance(entity, str) else entity
    return Odometry(
        header=_header(frame),
        child_frame_id=base_link(state.name),
        pose=PoseWithCovariance(
            pose=Pose(position=Point(x=state.x, y=state.y, z=state.z), orientation=_orientation(state)),
            covariance=_ZERO_COVARIANCE.copy(),
        ),
        twist=TwistWithCovariance(
            twist=Twist(
                linear=Vector3(x=state.speed, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=state.yaw_rate)
            ),
            covariance=_ZERO_COVARIANCE.copy(),
        ),
    )


def objects(frame: WorldFrame) -> Any:
    """vision_msgs/msg/Detection3DArray in `map`: ground truth, one Detection3D per entity.

    bbox.center = the box centre (`EntityState.box_center()`) with the heading as orientation, bbox.size =
    (length, width, height); one hypothesis with class_id = category, score 1 and the same pose;
    id = the entity's name as in the scenario."""
    _check_unique(frame)
    detection_array = _type("vision_msgs/msg/Detection3DArray")
    detection = _type("vision_msgs/msg/Detection3D")
    bbox3d = _type("vision_msgs/msg/BoundingBox3D")
    hypothesis_with_pose = _type("vision_msgs/msg/ObjectHypothesisWithPose")
    hypothesis = _type("vision_msgs/msg/ObjectHypothesis")
    header = _header(frame)
    detections = []
    for entity in frame.entities:
        cx, cy, cz = entity.box_center()
        center = Pose(position=Point(x=cx, y=cy, z=cz), orientation=quaternion(entity.heading))
        detections.append(
            detection(
                header=header,
                results=[
                    hypothesis_with_pose(
                        hypothesis=hypothesis(class_id=entity.category, score=1.0),
                        pose=PoseWithCovariance(pose=center, covariance=_ZERO_COVARIANCE.copy()),
                    )
                ],
                bbox=bbox3d(
                    center=center,
                    size=Vector3(x=entity.bbox.length, y=entity.bbox.width, z=entity.bbox.height),
                ),
                id=entity.name,
            )
        )
    return detection_array(header=header, detections=detections)


#: `state` values of /carlos/status that are errors (level ERROR); every other state is level OK.
ERROR_STATES = frozenset({"error", "failed"})


def status(frame: WorldFrame, state: str, detail: Mapping[str, str] | None = None) -> DiagnosticStatus:
    """The run state for `/carlos/status` as diagnostic_msgs/msg/DiagnosticStatus.

    name = "carlos", message = `state` (e.g. "running", "ended", "error"), level = ERROR for "error" and
    "failed", else OK; values (KeyValue): `state`, `time` (simulated seconds, repr), `step`, then `detail`
    in its order. The end of the run is the status whose state is "ended" or "error"."""
    values = [
        KeyValue(key="state", value=state),
        KeyValue(key="time", value=repr(float(frame.time))),
        KeyValue(key="step", value=str(frame.step)),
    ]
    values.extend(KeyValue(key=str(k), value=str(v)) for k, v in (detail or {}).items())
    return DiagnosticStatus(
        level=DiagnosticStatus.ERROR if state in ERROR_STATES else DiagnosticStatus.OK,
        name="carlos",
        message=state,
        hardware_id="",
        values=values,
    )


#: (topic, typename, build, encode): `build()` makes the message object, `encode()` its CDR bytes (those of
#: `serialize(build())`, written straight from the frame by `simcore.transport.world_cdr`).
FrameTopic = tuple[str, str, Callable[[], Any], Callable[[], bytes]]


def frame_builders(frame: WorldFrame) -> list[FrameTopic]:
    """(topic, typename, build, encode) for one step: `/clock`, `/tf`, `/carlos/<entity>/odometry` for every
    entity and FollowGhost ghost, `/carlos/objects` (entities only); `build()` makes the message and
    `encode()` its CDR (each called only for topics someone consumes, as they consume it)."""
    _check_unique(frame)
    out: list[FrameTopic] = [
        (CLOCK_TOPIC, Clock.__msgtype__, partial(clock, frame), partial(world_cdr.clock, frame)),
        (TF_TOPIC, TFMessage.__msgtype__, partial(tf, frame), partial(world_cdr.tf, frame)),
    ]
    out.extend(
        (
            odometry_topic(entity.name),
            Odometry.__msgtype__,
            partial(odometry, frame, entity),
            partial(world_cdr.odometry, frame, entity),
        )
        for entity in (*frame.entities, *frame.ghosts)
    )
    out.append(
        (
            OBJECTS_TOPIC,
            "vision_msgs/msg/Detection3DArray",
            partial(objects, frame),
            partial(world_cdr.objects, frame),
        )
    )
    return out


def frame_messages(frame: WorldFrame) -> list[tuple[str, str, Any]]:
    """(topic, typename, message) for one step: every topic of `frame_builders`, built."""
    return [(topic, typename, build()) for topic, typename, build, _ in frame_builders(frame)]


# --- serialisation -------------------------------------------------------------------------------------


def serialize(msg: Any) -> bytes:
    """CDR (little endian, with the 4-byte encapsulation header) as on the wire and in rosbag2."""
    return bytes(TYPESTORE.serialize_cdr(msg, msg.__msgtype__))


def deserialize(data: bytes, typename: str) -> Any:
    return TYPESTORE.deserialize_cdr(data, typename)


@cache
def msgdef(typename: str) -> str:
    """The ros2msg schema text of `typename` as ROS 2 bag writers store it: the type's own fields, then one
    `====…\\nMSG: pkg/Type` section per nested type."""
    if typename not in TYPESTORE.fielddefs:
        raise KeyError(f"unknown message type {typename!r}")
    text, _ = TYPESTORE.generate_msgdef(typename, ros_version=2)
    return text
