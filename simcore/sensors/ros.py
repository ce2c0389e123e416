"""ROS 2 messages of the sensors (types of `simcore.transport.messages.TYPESTORE`).

Topics (DESIGN.md), `<e>` = the carrier's ROS name, `<s>` = the sensor name:

| topic | type | frame |
|---|---|---|
| `/carlos/<e>/<s>/points` | sensor_msgs/PointCloud2 (x, y, z, intensity, time: float32; object_id: uint32; ring: uint16; label: uint8) | `<e>/<s>` |
| `/carlos/<e>/<s>/objects` | vision_msgs/Detection3DArray: ground truth (box, class, id = entity name) | `<e>/<s>` |
| `/carlos/<e>/<s>/objects/info` | diagnostic_msgs/DiagnosticArray: per object velocity (vx, vy, vz in the sensor frame), points, occlusion, distance | `<e>/<s>` |
| `/carlos/<e>/<s>/label_info` | vision_msgs/LabelInfo: class id → name (published once) | `<e>/<s>` |
| `/carlos/<e>/<s>/image` | sensor_msgs/Image 32FC1 depth in m (NaN: no return) | `<e>/<s>_optical` |
| `/carlos/<e>/<s>/labels` | sensor_msgs/Image mono8 class ids | `<e>/<s>_optical` |
| `/carlos/<e>/<s>/camera_info` | sensor_msgs/CameraInfo (pinhole, no distortion) | `<e>/<s>_optical` |
| `/tf_static` | tf2_msgs/TFMessage: `<e>/base_link` → `<e>/<s>` (→ `<e>/<s>_optical`), once | |
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from simcore.sensors.classes import CLASS_NAMES
from simcore.transport.messages import TYPESTORE, ros_name, stamp

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
DETECTIONS = "vision_msgs/msg/Detection3DArray"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
LABEL_INFO = "vision_msgs/msg/LabelInfo"
TF = "tf2_msgs/msg/TFMessage"
TF_STATIC_TOPIC = "/tf_static"

_T = TYPESTORE.types
_DATATYPES = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


def sensor_frame(entity: str, sensor: str) -> str:
    return f"{ros_name(entity)}/{sensor}"


def optical_frame(entity: str, sensor: str) -> str:
    return f"{ros_name(entity)}/{sensor}_optical"


def sensor_topic(entity: str, sensor: str, leaf: str) -> str:
    return f"/carlos/{ros_name(entity)}/{sensor}/{leaf}"


def header(time_s: float, frame_id: str) -> Any:
    return _T["std_msgs/msg/Header"](stamp=stamp(time_s), frame_id=frame_id)


def pointcloud2(points: np.ndarray, time_s: float, frame_id: str) -> Any:
    """An unorganised (height 1) PointCloud2 of a structured array; fields in the dtype's order."""
    dtype = points.dtype
    fields = []
    for name in dtype.names or ():
        sub, offset = dtype.fields[name][:2]  # type: ignore[index]
        fields.append(
            _T["sensor_msgs/msg/PointField"](
                name=name, offset=offset, datatype=_DATATYPES[sub.str.lstrip("<>|=")], count=1
            )
        )
    data = np.ascontiguousarray(points).view(np.uint8).reshape(-1)
    return _T[POINTCLOUD2](
        header=header(time_s, frame_id),
        height=1,
        width=len(points),
        fields=fields,
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * len(points),
        data=data,
        is_dense=True,
    )


def packed_points(points: np.ndarray, fields: Sequence[str] | None) -> np.ndarray:
    """`points` with only `fields` (None: all, as they are), in the dtype's order, packed without padding;
    read-only, so the recorder references it instead of copying (pure)."""
    if fields is None or len(fields) == len(points.dtype.names or ()):
        return points
    wanted = set(fields)
    names = [name for name in points.dtype.names or () if name in wanted]
    dtype = np.dtype([(name, points.dtype.fields[name][0]) for name in names])  # type: ignore[index]
    out = np.empty(len(points), dtype)
    for name in names:
        out[name] = points[name]
    out.flags.writeable = False
    return out


def read_pointcloud2(msg: Any) -> np.ndarray:
    """A PointCloud2's points as a structured array (fields by name, offsets as given)."""
    names, formats, offsets = [], [], []
    inverse = {v: k for k, v in _DATATYPES.items()}
    for f in msg.fields:
        names.append(f.name)
        formats.append(("<" if not msg.is_bigendian else ">") + inverse[f.datatype])
        offsets.append(f.offset)
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": msg.point_step})
    data = msg.data  # a numpy array (rosbags) or bytes (mcap_ros2)
    raw = (
        bytes(data)
        if isinstance(data, bytes | bytearray | memoryview)
        else np.asarray(data, np.uint8).tobytes()
    )
    return np.frombuffer(raw, dtype=dtype, count=msg.width * msg.height)


def image(array: np.ndarray, encoding: str, time_s: float, frame_id: str) -> Any:
    h, w = array.shape[:2]
    data = np.ascontiguousarray(array)
    return _T[IMAGE](
        header=header(time_s, frame_id),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=data.strides[0],
        data=data.view(np.uint8).reshape(-1),
    )


def camera_info(
    width: int, height: int, fx: float, fy: float, cx: float, cy: float, time_s: float, frame_id: str
) -> Any:
    return _T[CAMERA_INFO](
        header=header(time_s, frame_id),
        height=height,
        width=width,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=float),
        r=np.eye(3).reshape(-1),
        p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=float),
        binning_x=0,
        binning_y=0,
        roi=_T["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


def quaternion_of(r: np.ndarray) -> Any:
    """geometry_msgs/Quaternion of a rotation matrix."""
    m = r
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return _T["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w))


def detection(
    center: np.ndarray, orientation: Any, size: np.ndarray, class_id: str, score: float, ident: str, hdr: Any
) -> Any:
    """One vision_msgs/Detection3D (one hypothesis whose pose is the box's)."""
    pose = _T["geometry_msgs/msg/Pose"](
        position=_T["geometry_msgs/msg/Point"](x=float(center[0]), y=float(center[1]), z=float(center[2])),
        orientation=orientation,
    )
    return _T["vision_msgs/msg/Detection3D"](
        header=hdr,
        results=[
            _T["vision_msgs/msg/ObjectHypothesisWithPose"](
                hypothesis=_T["vision_msgs/msg/ObjectHypothesis"](class_id=class_id, score=float(score)),
                pose=_T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            )
        ],
        bbox=_T["vision_msgs/msg/BoundingBox3D"](
            center=pose,
            size=_T["geometry_msgs/msg/Vector3"](x=float(size[0]), y=float(size[1]), z=float(size[2])),
        ),
        id=ident,
    )


def detection_array(detections: list[Any], hdr: Any) -> Any:
    return _T[DETECTIONS](header=hdr, detections=detections)


def object_info(rows: list[dict[str, str]], hdr: Any) -> Any:
    """diagnostic_msgs/DiagnosticArray: one status per object (name = entity), values = `rows[i]` minus name."""
    status = _T["diagnostic_msgs/msg/DiagnosticStatus"]
    kv = _T["diagnostic_msgs/msg/KeyValue"]
    return _T[DIAGNOSTICS](
        header=hdr,
        status=[
            status(
                level=0,  # OK
                name=row["name"],
                message="ground truth",
                hardware_id=row.get("object_id", ""),
                values=[kv(key=k, value=v) for k, v in row.items() if k != "name"],
            )
            for row in rows
        ],
    )


def label_info(time_s: float, frame_id: str) -> Any:
    vc = _T["vision_msgs/msg/VisionClass"]
    return _T[LABEL_INFO](
        header=header(time_s, frame_id),
        class_map=[vc(class_id=cid, class_name=name) for cid, name in sorted(CLASS_NAMES.items())],
        threshold=0.0,
    )


def transform(parent: str, child: str, translation: np.ndarray, rot: np.ndarray, time_s: float) -> Any:
    return _T["geometry_msgs/msg/TransformStamped"](
        header=header(time_s, parent),
        child_frame_id=child,
        transform=_T["geometry_msgs/msg/Transform"](
            translation=_T["geometry_msgs/msg/Vector3"](
                x=float(translation[0]), y=float(translation[1]), z=float(translation[2])
            ),
            rotation=quaternion_of(rot),
        ),
    )


def tf_message(transforms: list[Any]) -> Any:
    return _T[TF](transforms=transforms)
