"""The detector as a node: subscribes to a point cloud topic, publishes a Detection3DArray per cloud."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from examples.detector.detect import Box, DetectorParams, detect

_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def xyz_of(cloud: Any) -> np.ndarray:
    """The x, y, z fields of a sensor_msgs/PointCloud2 as an (N, 3) array."""
    fields = {f.name: f for f in cloud.fields}
    missing = {"x", "y", "z"} - set(fields)
    if missing:
        raise ValueError(f"point cloud without fields {sorted(missing)}")
    order = ">" if cloud.is_bigendian else "<"
    dtype = np.dtype(
        {
            "names": ["x", "y", "z"],
            "formats": [order + _DATATYPES[fields[n].datatype] for n in "xyz"],
            "offsets": [fields[n].offset for n in "xyz"],
            "itemsize": cloud.point_step,
        }
    )
    data = np.asarray(cloud.data, dtype=np.uint8)
    points = np.frombuffer(data.tobytes(), dtype=dtype, count=cloud.width * cloud.height)
    return np.stack([points["x"], points["y"], points["z"]], axis=1).astype(np.float64)


def detections_message(boxes: list[Box], header: Any) -> Any:
    """vision_msgs/Detection3DArray of the boxes (one hypothesis each: class and score)."""
    from simcore.transport.messages import TYPESTORE  # the message definitions (like a msgs package)

    t = TYPESTORE.types
    out = []
    for i, b in enumerate(boxes):
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=b.x, y=b.y, z=b.z),
            orientation=t["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(b.yaw / 2), w=math.cos(b.yaw / 2)
            ),
        )
        out.append(
            t["vision_msgs/msg/Detection3D"](
                header=header,
                results=[
                    t["vision_msgs/msg/ObjectHypothesisWithPose"](
                        hypothesis=t["vision_msgs/msg/ObjectHypothesis"](class_id=b.label, score=b.score),
                        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                    )
                ],
                bbox=t["vision_msgs/msg/BoundingBox3D"](
                    center=pose, size=t["geometry_msgs/msg/Vector3"](x=b.length, y=b.width, z=b.height)
                ),
                id=str(i),
            )
        )
    return t["vision_msgs/msg/Detection3DArray"](header=header, detections=out)


class Detector:
    """`Detector(bus, input_topic=…, output_topic=…, **DetectorParams fields)`."""

    OUTPUT_TYPE = "vision_msgs/msg/Detection3DArray"

    def __init__(
        self,
        bus: Any,
        input_topic: str = "/carlos/Ego/lidar/points",
        output_topic: str = "/carlos/sut/detections",
        **params: Any,
    ) -> None:
        self.params = DetectorParams(**params)  # TypeError for an unknown parameter
        self.publisher = bus.advertise(output_topic, self.OUTPUT_TYPE)
        self.clouds = 0
        bus.subscribe(input_topic, self.on_points)

    def on_points(self, message: Any) -> None:
        cloud = message.obj()
        boxes = detect(xyz_of(cloud), self.params)
        self.clouds += 1
        self.publisher.publish(detections_message(boxes, cloud.header), message.time_s)

    def close(self) -> None:
        pass
