"""The sensors of a run: scheduling, ground truth and publishing on the bus.

`SensorRig(spec.sensors, road, bus, seed, units=…)`; `start(frame)` checks the carriers and publishes
`/tf_static` and every lidar's label table; `step(frame)` runs every sensor that is due (a lidar at its rotation rate,
a camera at its rate, both from t = 0, stamped with the frame's time) and publishes its messages
(`simcore.sensors.ros`). The road scene is built once per road file and worker process.

Sensors of roadside units (`units`: each unit's pose and `spec.infrastructure[].sensors`) work the same
way from a fixed pose: mounted relative to the unit's foot (a stationary stand-in carrier that is no box of
the scene), frame `<unit>/<sensor>` with a static transform from `map`, topics
`/carlos/infrastructure/<unit>/<sensor>/…`.
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from simcore.errors import BadInput
from simcore.sensors import ros
from simcore.sensors.camera import OPTICAL, Camera
from simcore.sensors.lidar import Lidar, LidarScan, mount_pose
from simcore.sensors.scene import Boxes, RoadScene, static_objects
from simcore.spec import CameraSensor, LidarSensor
from simcore.transport.bus import Bus, Publisher
from simcore.transport.messages import MAP_FRAME, base_link, ros_name
from simcore.world.infrastructure import UnitPose
from simcore.world.opendrive import OpenDrive
from simcore.world.state import EntityState, WorldFrame

_ROAD_CACHE: dict[tuple[str, int, int], RoadScene] = {}
_EPS = 1e-9


def road_scene(road: OpenDrive | None, road_file: Path | None = None) -> RoadScene:
    """The road scene of a network with its static scenery, cached per road file (path, size, mtime) in this
    process."""
    if road is None or road_file is None:
        return RoadScene(road)
    stat = road_file.stat()
    key = (str(road_file.resolve()), stat.st_size, stat.st_mtime_ns)
    scene = _ROAD_CACHE.get(key)
    if scene is None:
        if len(_ROAD_CACHE) >= 4:
            _ROAD_CACHE.clear()
        scenery = static_objects(road, road_file.read_bytes()) if road_file.suffix == ".xodr" else []
        scene = _ROAD_CACHE[key] = RoadScene(road, scenery=scenery)
    return scene


@dataclass
class _Mounted:
    config: LidarSensor | CameraSensor
    index: int
    entity: str = ""
    model: Lidar | Camera | None = None
    next_time: float = 0.0
    publishers: dict[str, Publisher] = field(default_factory=dict)
    unit: UnitPose | None = None  # a roadside unit's sensor
    stand_in: EntityState | None = None  # the unit's stationary stand-in carrier

    @property
    def spec_field(self) -> str:
        if self.unit is not None:
            return f"spec.infrastructure[{self.unit.index}].sensors[{self.index}]"
        return f"spec.sensors[{self.index}]"

    def frame_id(self) -> str:
        return ros.sensor_frame(self.entity, self.config.name)

    def optical_frame(self) -> str:
        return ros.optical_frame(self.entity, self.config.name)

    def topic(self, leaf: str) -> str:
        if self.unit is not None:
            return f"/carlos/infrastructure/{ros_name(self.unit.name)}/{self.config.name}/{leaf}"
        return ros.sensor_topic(self.entity, self.config.name, leaf)


@dataclass
class Timings:
    """Wall seconds spent per phase (for benchmarks)."""

    scene: float = 0.0
    cast: float = 0.0
    messages: float = 0.0
    scans: int = 0
    rays: int = 0


class SensorRig:
    def __init__(
        self,
        sensors: Sequence[LidarSensor | CameraSensor],
        road: OpenDrive | None,
        bus: Bus,
        seed: int,
        *,
        road_file: Path | None = None,
        units: Sequence[tuple[UnitPose, Sequence[LidarSensor | CameraSensor]]] = (),
    ) -> None:
        self.bus = bus
        self.seed = seed
        self.road = road_scene(road, road_file)
        self.sensors = [_Mounted(config, i) for i, config in enumerate(sensors)]
        for unit, configs in units:
            carrier = unit.carrier()
            self.sensors.extend(
                _Mounted(config, i, entity=unit.name, unit=unit, stand_in=carrier)
                for i, config in enumerate(configs)
            )
        self.timings = Timings()
        self._started = False

    def start(self, frame: WorldFrame) -> None:
        names = [e.name for e in frame.entities]
        transforms = []
        labels: list[tuple[str, str]] = []
        for s in self.sensors:
            cfg = s.config
            if s.unit is None:
                entity = cfg.entity or frame.ego or (names[0] if names else None)
                if entity is None or entity not in names:
                    raise BadInput(
                        f"sensor {cfg.name!r} is mounted on {entity!r}, which is not an entity of the scenario "
                        f"(entities: {', '.join(names) or 'none'})",
                        field=f"{s.spec_field}.entity",
                    )
                s.entity = entity
            frame_id = s.frame_id()
            if isinstance(cfg, LidarSensor):
                # seed per sensor: the run's seed and the sensor's name and carrier, stable across edits of others
                salt = zlib.crc32(f"{s.entity}/{cfg.name}".encode())
                s.model = Lidar(cfg, seed=np.random.SeedSequence([self.seed, salt]).generate_state(1)[0])
                leaves = ["points"] + (["objects", "objects/info"] if cfg.ground_truth else [])
                types = [ros.POINTCLOUD2, ros.DETECTIONS, ros.DIAGNOSTICS]
                for leaf, typename in zip(leaves, types, strict=False):
                    s.publishers[leaf] = self.bus.advertise(s.topic(leaf), typename)
                labels.append((s.topic("label_info"), frame_id))
            else:
                s.model = Camera(cfg)
                s.publishers["image"] = self.bus.advertise(s.topic("image"), ros.IMAGE)
                s.publishers["labels"] = self.bus.advertise(s.topic("labels"), ros.IMAGE)
                s.publishers["camera_info"] = self.bus.advertise(s.topic("camera_info"), ros.CAMERA_INFO)
                transforms.append(
                    ros.transform(frame_id, s.optical_frame(), np.zeros(3), OPTICAL, frame.time)
                )
            model = s.model
            if s.stand_in is not None:  # a unit's sensor: its pose in the map, fixed
                rot, pos = mount_pose(s.stand_in, model.mount_rot, model.mount_pos)
                transforms.insert(0, ros.transform(MAP_FRAME, frame_id, pos, rot, frame.time))
            else:
                transforms.insert(
                    0,
                    ros.transform(
                        base_link(s.entity), frame_id, model.mount_pos, model.mount_rot, frame.time
                    ),
                )
        if transforms:
            self.bus.advertise(ros.TF_STATIC_TOPIC, ros.TF).publish(ros.tf_message(transforms), frame.time)
        for topic, frame_id in labels:
            self.bus.advertise(topic, ros.LABEL_INFO).publish(
                ros.label_info(frame.time, frame_id), frame.time
            )
        self._started = True

    def step(self, frame: WorldFrame) -> None:
        """Run and publish every sensor due at this frame."""
        if not self._started:
            self.start(frame)
        due = [s for s in self.sensors if frame.time >= s.next_time - _EPS]
        if not due:
            return
        t0 = time.perf_counter()
        boxes = Boxes.of(frame)
        index = {name: i for i, name in enumerate(boxes.names)}
        self.timings.scene += time.perf_counter() - t0
        for s in due:
            period = s.model.period  # type: ignore[union-attr]
            while s.next_time <= frame.time + _EPS:
                s.next_time += period
            if s.stand_in is not None:
                i, carrier = -1, s.stand_in  # a unit's sensor: no box of its own in the scene
            else:
                j = index.get(s.entity)
                if j is None:
                    continue  # the carrier left the simulation
                i, carrier = j, frame.entities[j]
            t1 = time.perf_counter()
            if isinstance(s.model, Lidar):
                scan = s.model.scan(self.road, boxes, carrier, i)
                self.timings.rays += scan.rays
                t2 = time.perf_counter()
                self._publish_lidar(s, scan, boxes, frame, i, carrier)
            else:
                assert isinstance(s.model, Camera)
                img = s.model.capture(self.road, boxes, carrier, i)
                self.timings.rays += img.depth.size
                t2 = time.perf_counter()
                self._publish_camera(s, img, frame)
            self.timings.scans += 1
            self.timings.cast += t2 - t1
            self.timings.messages += time.perf_counter() - t2

    def _publish_lidar(
        self,
        s: _Mounted,
        scan: LidarScan,
        boxes: Boxes,
        frame: WorldFrame,
        carrier: int,
        carrier_state: EntityState,
    ) -> None:
        cfg = s.config
        assert isinstance(cfg, LidarSensor) and isinstance(s.model, Lidar)
        frame_id = s.frame_id()
        points = ros.packed_points(scan.points, cfg.point_fields)
        s.publishers["points"].publish(ros.pointcloud2(points, frame.time, frame_id), frame.time)
        if not cfg.ground_truth:
            return
        objects = ground_truth(s.model, boxes, frame, carrier, scan, mounted_on=carrier_state)
        hdr = ros.header(frame.time, frame_id)
        dets = [
            ros.detection(
                o["center"], ros.quaternion_of(o["rotation"]), o["size"], o["class"], 1.0, o["name"], hdr
            )
            for o in objects
        ]
        s.publishers["objects"].publish(ros.detection_array(dets, hdr), frame.time)
        rows = [
            {
                "name": o["name"],
                "object_id": str(o["object_id"]),
                "class": o["class"],
                "vx": repr(float(o["velocity"][0])),
                "vy": repr(float(o["velocity"][1])),
                "vz": repr(float(o["velocity"][2])),
                "points": str(o["points"]),
                "occlusion": repr(o["occlusion"]),
                "distance": repr(o["distance"]),
            }
            for o in objects
        ]
        s.publishers["objects/info"].publish(ros.object_info(rows, hdr), frame.time)

    def _publish_camera(self, s: _Mounted, img: Any, frame: WorldFrame) -> None:
        cfg = s.config
        assert isinstance(cfg, CameraSensor) and isinstance(s.model, Camera)
        optical = s.optical_frame()
        s.publishers["image"].publish(ros.image(img.depth, "32FC1", frame.time, optical), frame.time)
        s.publishers["labels"].publish(ros.image(img.labels, "mono8", frame.time, optical), frame.time)
        m = s.model
        info = ros.camera_info(cfg.width, cfg.height, m.fx, m.fy, m.cx, m.cy, frame.time, optical)
        s.publishers["camera_info"].publish(info, frame.time)


def ground_truth(
    lidar: Lidar,
    boxes: Boxes,
    frame: WorldFrame,
    carrier: int,
    scan: LidarScan,
    *,
    mounted_on: EntityState | None = None,
) -> list[dict[str, Any]]:
    """The objects within the lidar's maximum range (box centre), in the sensor frame at the stamp: centre,
    rotation, size (length, width, height), class, velocity (the object's, in the sensor frame), points in
    the cloud, occlusion ratio (1 - rays whose first return is the object / rays that would hit it alone;
    1 when no ray reaches it: out of the field of view), BEV distance. `carrier` is the index of the
    carrier's box (−1: none), `mounted_on` the carrier when it is not an entity of the frame (a roadside
    unit's stand-in)."""
    carrier_state = mounted_on if mounted_on is not None else frame.entities[carrier]
    rot, pos = mount_pose(carrier_state, lidar.mount_rot, lidar.mount_pos)
    out = []
    for i, name in enumerate(boxes.names):
        if i == carrier:
            continue
        center = (boxes.centers[i] - pos) @ rot
        distance = math.hypot(center[0], center[1])
        if distance > lidar.config.range_max:
            continue
        potential = int(scan.unoccluded_rays[i])
        occlusion = 1.0 - scan.visible_rays[i] / potential if potential else 1.0
        out.append(
            {
                "name": name,
                "object_id": int(boxes.ids[i]),
                "center": center,
                "rotation": rot.T @ boxes.rotations[i],
                "size": boxes.half[i] * 2,
                "class": boxes.class_names[i],
                "velocity": rot.T @ boxes.velocities[i],
                "points": int(scan.object_points[i]),
                "occlusion": float(max(0.0, min(1.0, occlusion))),
                "distance": distance,
            }
        )
    return out
