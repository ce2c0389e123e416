"""An example system under test: a lidar object detector written as a ROS 2-style node.

Topic in: `sensor_msgs/PointCloud2` (x, y, z fields; anything else is ignored); topic out:
`vision_msgs/Detection3DArray` in the cloud's frame, with the cloud's stamp. Pipeline (`detect`): range
crop, RANSAC ground plane removal, Euclidean clustering (BEV, k-d tree + connected components), oriented
box fit (L-shape fitting by the closeness criterion, completed to the class's prior size away
from the sensor when only part of the object is visible), classification by size.

It is the user's own software, kept apart from the simulator: it imports no `simcore` module except the
message type store (as a ROS 2 package depends on its message packages), and talks through topics only.

- In process (the embedded executor): `systemUnderTest.module: examples.detector:Detector`.
- As a program: `python -m examples.detector --help` (replays a recording's point clouds into the node
  and records its detections, or runs on a bus given as `module:factory`).
"""

from examples.detector.detect import Box, DetectorParams, detect
from examples.detector.node import Detector

__all__ = ["Box", "Detector", "DetectorParams", "detect"]
