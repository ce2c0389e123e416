"""Trajectories and the road outline of one recorded index, for the bird's-eye plots.

The trajectories come from the recording's ground truth (`/carlos/objects`: every entity's box each frame);
the minimum-distance moment and the collisions are measured on those boxes with the same geometry as the
metrics (`simcore.evaluation.metrics.box_distance`). The road outline is the OpenDRIVE file the recorded
scenario names, when it is readable on this machine.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from simcore.evaluation.metrics import Box, box_distance

if TYPE_CHECKING:  # the outline's arrays come from OpenDrive.sample_lane_boundaries, which imports numpy
    import numpy as np


@dataclass
class Trajectory:
    name: str
    t: list[float] = field(default_factory=list)
    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)


@dataclass
class Moment:
    """A point in time between the ego and another entity: where both were, and how far apart."""

    time: float
    other: str
    distance: float
    ego_xy: tuple[float, float]
    other_xy: tuple[float, float]


@dataclass
class Recording:
    ego: str | None
    trajectories: dict[str, Trajectory]
    closest: Moment | None
    collisions: list[Moment]
    scenario_file: str | None


def _box(x: float, y: float, yaw: float, length: float, width: float) -> Box:
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = length / 2, width / 2
    corners = tuple(
        (x + c * dx - s * dy, y + s * dx + c * dy) for dx, dy in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))
    )
    return Box.of_points(corners, ((c, s), (-s, c)))


def _yaw(q: object) -> float:
    w, x, y, z = (float(getattr(q, k)) for k in ("w", "x", "y", "z"))
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def read_recording(data: bytes, ego: str | None = None, *, max_collisions: int = 20) -> Recording:
    """Trajectories, the closest approach to the ego and the collision moments (first frame of each
    contact) from an MCAP recording's bytes. The ego is `ego`, else the first entity of each frame."""
    from mcap.reader import make_reader

    from simcore.transport.messages import OBJECTS_TOPIC, deserialize  # rosbags: only with a recording

    reader = make_reader(io.BytesIO(data))
    scenario_file = None
    for record in reader.iter_metadata():
        if record.name == "carlos.run":
            scenario_file = record.metadata.get("scenarioFile")
    trajectories: dict[str, Trajectory] = {}
    closest: Moment | None = None
    collisions: list[Moment] = []
    touching: set[str] = set()
    chosen = ego
    for schema, _channel, message in reader.iter_messages(topics=[OBJECTS_TOPIC]):
        if schema is None:
            continue
        msg = deserialize(message.data, schema.name)
        t = float(msg.header.stamp.sec) + float(msg.header.stamp.nanosec) * 1e-9
        boxes: dict[str, tuple[Box, tuple[float, float]]] = {}
        for det in msg.detections:
            pose = det.bbox.center
            x, y = float(pose.position.x), float(pose.position.y)
            track = trajectories.setdefault(det.id, Trajectory(det.id))
            track.t.append(t)
            track.x.append(x)
            track.y.append(y)
            size = det.bbox.size
            boxes[det.id] = (_box(x, y, _yaw(pose.orientation), float(size.x), float(size.y)), (x, y))
        if chosen is None and msg.detections:
            chosen = msg.detections[0].id
        if chosen not in boxes:
            continue
        ego_box, ego_xy = boxes[chosen]
        now_touching = set()
        for other, (box, xy) in boxes.items():
            if other == chosen:
                continue
            distance = box_distance(ego_box, box)
            if closest is None or distance < closest.distance:
                closest = Moment(t, other, distance, ego_xy, xy)
            if distance <= 0.0:
                now_touching.add(other)
                if other not in touching and len(collisions) < max_collisions:
                    collisions.append(Moment(t, other, 0.0, ego_xy, xy))
        touching = now_touching
    return Recording(chosen, trajectories, closest, collisions, scenario_file)


@dataclass
class RoadOutline:
    """Polylines (x, y arrays) of the road's lane borders: `edges` the outer borders, `lanes` the others."""

    edges: list[tuple[np.ndarray, np.ndarray]]
    lanes: list[tuple[np.ndarray, np.ndarray]]


def road_outline(scenario_file: str | Path | None, *, step: float = 2.0) -> RoadOutline | None:
    """The outline of the road network the scenario names (None when the scenario or its .xodr cannot be
    read here, e.g. a recording made in a pod)."""
    from simcore.errors import CarlosError
    from simcore.scenario.xosc import load_scenario
    from simcore.world.opendrive import OpenDrive, OpenDriveError

    if scenario_file is None or not Path(scenario_file).is_file():
        return None
    try:
        road_file = load_scenario(scenario_file).road_file
        if road_file is None or road_file.suffix != ".xodr" or not road_file.is_file():
            return None
        network = OpenDrive.shared(road_file)
    except (CarlosError, OpenDriveError, OSError, ValueError):
        return None
    edges: list[tuple[np.ndarray, np.ndarray]] = []
    lanes: list[tuple[np.ndarray, np.ndarray]] = []
    for road_id in network.roads:
        boundaries = network.sample_lane_boundaries(road_id, step=step)
        outermost: dict[tuple[int, int], int] = {}
        for b in boundaries:
            side = 1 if b.lane_id > 0 else -1
            key = (b.section_index, side)
            outermost[key] = max(outermost.get(key, 0), abs(b.lane_id))
        for b in boundaries:
            line = (b.outer[:, 0], b.outer[:, 1])
            side = 1 if b.lane_id > 0 else -1
            (edges if abs(b.lane_id) == outermost[(b.section_index, side)] else lanes).append(line)
            if b.lane_id == -1:  # the reference line between the two directions
                lanes.append((b.inner[:, 0], b.inner[:, 1]))
    return RoadOutline(edges, lanes)
