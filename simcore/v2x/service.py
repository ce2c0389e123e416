"""V2X in a run: stations (entities, roadside units) send CAMs, CPMs and DENMs through the channel model;
each receiver gets what the channel delivers on its own topics, and the `v2x.*` metrics accumulate.

The runner creates one `V2XService` after its recorder subscribed to the bus and calls `step(frame)` after
publishing each frame; `metrics()` gives the `v2x.*` metrics.

Topics (recorded): `/carlos/<entity>/v2x/cam|cpm|denm` per receiving entity station,
`/carlos/infrastructure/<rsu>/v2x/cam|cpm|denm` per receiving RSU, `/carlos/v2x/transmissions` (every link
of every message of a step and its outcome, `carlos_v2x_msgs/msg/TransmissionArray`). A message sent at
frame time t and delayed by d is published with time t + d in the step it is sent (latency and jitter are
well below a step; a longer delay is published in the step it arrives). The copies of one message go out as
bus `Message`s sharing one CDR serialisation (made by the first subscriber that asks for bytes).

Stations: `spec.v2x.stations` or every vehicle of the first frame, in frame order (station ids 1, 2, …), then
the RSUs with a `v2x` station (ids 1001, 1002, …). An entity station absent from a frame neither sends nor
receives in it. Antennas sit 0.1 m above the entity's box, RSU antennas at the mast height. RSU and vehicle
CPMs contain the other entities within the station's perception range whose box centre or a box corner (at
mid height) is in line of sight, or for an RSU with `perceptionSensor` the entities with enough points in that
lidar's latest sweep (its `…/objects/info`, received on the bus); a CPM goes out at most every 100 ms, with the
objects the TS 103 324 inclusion rules select, or every second without any.

Per step the work is vectorised over the stations: the CAM triggers and fields of all senders (one numpy pass,
`etsi.cams`), line of sight of all CPM stations' candidate objects in one pass, the CPM values of every
(station, object) pair in one pass, the channel over all (sender, receiver) pairs.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from simcore.errors import BadInput
from simcore.evaluation.criteria import ranges_of
from simcore.spec import NumberOrParameter, SimulationRunSpec
from simcore.transport.bus import Bus, Message, Publisher
from simcore.transport.messages import TYPESTORE, ros_name, stamp
from simcore.v2x import etsi
from simcore.v2x.channel import Channel, ChannelParameters
from simcore.v2x.geo import GeoReference, geo_reference_of
from simcore.v2x.metrics import V2XMetrics
from simcore.v2x.triggers import T_GEN_CPM_MAX, T_GEN_CPM_MIN, CamTriggers, CpmObjectTriggers, HazardTriggers
from simcore.world.infrastructure import resolve_number, unit_pose
from simcore.world.opendrive import OpenDrive
from simcore.world.state import EntityState, WorldFrame

TRANSMISSIONS_TOPIC = "/carlos/v2x/transmissions"
RSU_STATION_BASE = 1000
ANTENNA_ABOVE_ROOF = 0.1
_SLACK = 1e-6


def channel_parameters(spec: SimulationRunSpec, parameters: Mapping[str, Any]) -> ChannelParameters:
    assert spec.v2x is not None
    c = spec.v2x.channel

    def number(name: str, value: NumberOrParameter) -> float:
        return resolve_number(value, parameters, f"spec.v2x.channel.{name}")

    sigma = number("shadowingSigmaDb", c.shadowing_sigma_db)
    if not 0 <= sigma <= 30:
        raise BadInput(f"shadowing of {sigma} dB is outside 0..30", field="spec.v2x.channel.shadowingSigmaDb")
    exponent = number("pathLossExponent", c.path_loss_exponent)
    if not 1 <= exponent <= 8:
        raise BadInput(
            f"path-loss exponent {exponent} is outside 1..8", field="spec.v2x.channel.pathLossExponent"
        )
    return ChannelParameters(
        frequency_hz=c.frequency_hz,
        tx_power_dbm=number("txPowerDbm", c.tx_power_dbm),
        tx_gain_db=c.antenna_gain_db,
        rx_gain_db=c.antenna_gain_db,
        sensitivity_dbm=number("sensitivityDbm", c.sensitivity_dbm),
        path_loss_exponent=exponent,
        reference_distance=c.reference_distance,
        shadowing_sigma_db=sigma,
        fading_m=c.fading_m,
        nlos_loss_db=number("nlosLossDb", c.nlos_loss_db),
        latency=c.latency_seconds,
        jitter=c.jitter_seconds,
        max_messages_per_second=c.max_messages_per_second,
    )


@dataclass
class Station:
    name: str  # entity name, or the RSU's name
    station_id: int
    cam: bool
    denm: bool
    cpm: bool
    perception_range: float
    rsu_pose: tuple[float, float, float, float] | None = None  # x, y, antenna z, yaw (rad)
    topic_prefix: str = ""
    publishers: dict[str, Publisher] = field(default_factory=dict)
    cpm_triggers: CpmObjectTriggers = field(default_factory=CpmObjectTriggers)
    last_cpm: float = -math.inf
    first_seen: dict[str, float] = field(default_factory=dict)
    sequence: int = 0
    #: with a perception lidar: the entities with enough points in its latest sweep (None: line of sight)
    lidar_objects: set[str] | None = None

    @property
    def rsu(self) -> bool:
        return self.rsu_pose is not None


@dataclass(slots=True, eq=False)
class _Outgoing:
    kind: str
    sender: int
    msg: Any
    objects: tuple[str, ...] = ()  # CPM: the entities it describes
    hazard: tuple[str, int, float] | None = None  # DENM: (station, cause, detection time)
    cdr: bytes | None = (
        None  # its CDR bytes, once a receiver's subscriber asked for them (shared by all copies)
    )


def _lidar_perception(station: Station, min_points: int) -> Callable[[Message], None]:
    """A subscriber of a lidar's `…/objects/info`: the station perceives the objects with enough points."""

    def perceive(message: Message) -> None:
        objects = set()
        for status in message.obj().status:
            values = {kv.key: kv.value for kv in status.values}
            if int(values.get("points", "0")) >= min_points:
                objects.add(status.name)
        station.lidar_objects = objects

    return perceive


def _antenna(entity: EntityState) -> tuple[float, float, float]:
    top = entity.z + entity.bbox.center_z + entity.bbox.height / 2
    return entity.x, entity.y, top + ANTENNA_ABOVE_ROOF


class V2XService:
    def __init__(
        self,
        spec: SimulationRunSpec,
        bus: Bus,
        *,
        road: OpenDrive | None,
        road_file: Path | None,
        parameters: Mapping[str, Any],
        seed: int,
    ) -> None:
        if spec.v2x is None:
            raise ValueError("V2XService needs spec.v2x")
        self.spec = spec
        self.config = spec.v2x
        self.bus = bus
        self.step_seconds = spec.simulation.step_seconds
        self.channel = Channel(channel_parameters(spec, parameters), seed)
        self.geo = self._geo_reference(road_file)
        self.geo.to_wgs84(0.0, 0.0)  # set up PROJ's transformation now, not in the first step
        self.road = road
        self.road_file = road_file
        self._scene: Any = None
        self.parameters = parameters
        criteria = [*spec.evaluation.criteria, *(c for s in spec.scenarios for c in s.criteria)]
        self.metrics_acc = V2XMetrics(ranges_of((c.metric for c in criteria), "v2x.packetDeliveryRatio"))
        self.stations: list[Station] = []
        self._rsus = self._rsu_stations()
        self._cam: CamTriggers | None = None
        self._hazards: HazardTriggers | None = None
        self._pending: list[
            tuple[float, int, int, _Outgoing, float]
        ] = []  # arrival, seq, receiver, message, sent
        #: CPU seconds of this process spent so far in each phase of `step` (bench/v2x.py)
        self.seconds = {"generate": 0.0, "channel": 0.0, "deliver": 0.0, "metrics": 0.0}
        self._seq = itertools.count()
        self._batch: tuple[list[_Outgoing], np.ndarray, np.ndarray, np.ndarray, float] | None = None
        self._ego_name: str | None = None
        self._ego_cpm: dict[str, float] = {}  # object → arrival of the newest CPM about it at the ego
        self._transmissions = bus.advertise(TRANSMISSIONS_TOPIC, "carlos_v2x_msgs/msg/TransmissionArray")
        #: how a received copy goes out as a `Message` (so that its CDR bytes are made once per message)
        self._send: Callable[[Message], None] | None = getattr(bus, "publish_message", None) or getattr(
            bus, "dispatch", None
        )

    # --- set-up -----------------------------------------------------------------------------------------
    def _geo_reference(self, road_file: Path | None) -> GeoReference:
        origin = self.config.origin
        if origin is not None:
            return GeoReference.at_origin(origin.latitude, origin.longitude, origin.altitude)
        if road_file is not None and road_file.suffix == ".xodr":
            reference = geo_reference_of(road_file)
            if reference is not None:
                return reference
        return GeoReference.at_origin(0.0, 0.0)

    def _rsu_stations(self) -> list[Station]:
        out: list[Station] = []
        for index, rsu in enumerate(self.spec.infrastructure):
            pose = unit_pose(rsu, index, self.road, self.parameters)
            if rsu.v2x is None:
                continue
            station = Station(
                name=rsu.name,
                station_id=RSU_STATION_BASE + 1 + len(out),
                cam=rsu.v2x.cam,
                denm=False,
                cpm=rsu.v2x.cpm,
                perception_range=rsu.v2x.perception_range,
                rsu_pose=(pose.x, pose.y, pose.z + pose.height, pose.yaw),
                topic_prefix=f"/carlos/infrastructure/{ros_name(rsu.name)}/v2x",
            )
            if rsu.v2x.perception_sensor is not None:
                station.lidar_objects = set()
                topic = (
                    f"/carlos/infrastructure/{ros_name(rsu.name)}/{rsu.v2x.perception_sensor}/objects/info"
                )
                self.bus.subscribe(topic, _lidar_perception(station, rsu.v2x.perception_min_points))
            out.append(station)
        return out

    def _setup(self, frame: WorldFrame) -> None:
        names = {e.name for e in frame.entities}
        if self.config.stations is None:
            entity_stations = [
                Station(e.name, 0, True, True, False, 50.0)
                for e in frame.entities
                if e.object_type == "vehicle"
            ]
        else:
            entity_stations = []
            for index, cfg in enumerate(self.config.stations):
                if cfg.entity not in names:
                    raise BadInput(
                        f"no entity {cfg.entity!r} in the scenario (entities: {', '.join(sorted(names))})",
                        field=f"spec.v2x.stations[{index}].entity",
                    )
                entity_stations.append(
                    Station(cfg.entity, 0, cfg.cam, cfg.denm, cfg.cpm, cfg.perception_range)
                )
        for number, station in enumerate(entity_stations, start=1):
            station.station_id = number
            station.topic_prefix = f"/carlos/{ros_name(station.name)}/v2x"
        self.stations = [*entity_stations, *self._rsus]
        for station in self.stations:
            for kind, typename in (("cam", etsi.CAM_TYPE), ("cpm", etsi.CPM_TYPE), ("denm", etsi.DENM_TYPE)):
                station.publishers[kind] = self.bus.advertise(f"{station.topic_prefix}/{kind}", typename)
        self.metrics_acc.stations([s.name for s in self.stations])
        self._rsu_mask = np.array([s.rsu for s in self.stations], dtype=bool)
        self._cam_mask = np.array([s.cam for s in self.stations], dtype=bool)
        self._cpm_mask = np.array([s.cpm for s in self.stations], dtype=bool)
        self._station_ids = np.array([s.station_id for s in self.stations], dtype=np.int64)
        poses = np.array([s.rsu_pose for s in self.stations if s.rsu_pose is not None]).reshape(-1, 4)
        self._rsu_xyz, self._rsu_yaw = poses[:, 0:3], poses[:, 3]
        self._names = [s.name for s in self.stations]
        #: per station, the other stations' names (its message's receivers when every station is present)
        self._others = [self._names[:i] + self._names[i + 1 :] for i in range(len(self.stations))]
        self._cam = CamTriggers(len(self.stations))
        self._hazards = HazardTriggers(len(self.stations), hard_braking=self.config.hard_braking)

    def _scene_for_sight(self) -> Any:
        if self._scene is None and self.road is not None:
            from simcore.sensors.rig import road_scene

            self._scene = road_scene(self.road, self.road_file)
        return self._scene

    # --- one step ---------------------------------------------------------------------------------------
    def step(self, frame: WorldFrame) -> None:
        started = time.process_time()
        if self._cam is None:
            self._setup(frame)
        assert self._cam is not None and self._hazards is not None
        t = frame.time
        self._ego_name = frame.ego
        own = self._entity_index(frame)  # per station its entity's index in the frame, −1: RSU or absent
        rsu = self._rsu_mask
        present = rsu | (own >= 0)
        n = len(self.stations)
        ents = frame.entities
        # per entity: antenna x, y, z, heading, speed, acceleration, yaw rate, length, width
        table = np.array(
            [
                (
                    e.x,
                    e.y,
                    e.z + e.bbox.center_z + e.bbox.height / 2 + ANTENNA_ABOVE_ROOF,
                    e.heading,
                    e.speed,
                    e.acceleration,
                    e.yaw_rate,
                    e.bbox.length,
                    e.bbox.width,
                )
                for e in ents
            ],
            dtype=np.float64,
        ).reshape(-1, 9)
        rows = np.zeros((n, 9))
        has = own >= 0
        rows[has] = table[own[has]]
        rows[rsu, 0:3] = self._rsu_xyz
        rows[rsu, 3] = self._rsu_yaw
        pos = rows[:, 0:3]
        heading, speed, accel = rows[:, 3], rows[:, 4], rows[:, 5]
        sight = self._sight(frame)
        lat, lon, alt, north = self.geo.wgs84_and_north(pos[:, 0], pos[:, 1], pos[:, 2])
        etsi_heading = np.degrees(north - heading) % 360.0
        station_type = np.full(n, etsi.STATION_TYPE_RSU, dtype=np.int64)
        station_type[~rsu] = [
            etsi.STATION_TYPES.get(ents[j].category, 0) if j >= 0 else 0 for j in own[~rsu].tolist()
        ]
        outgoing: list[_Outgoing] = []
        cam_due = self._cam.step(t, pos[:, :2], heading, speed)

        def kinematics(i: int) -> etsi.Kinematics:
            return etsi.Kinematics(
                latitude=float(lat[i]),
                longitude=float(lon[i]),
                altitude=float(alt[i]),
                heading=float(etsi_heading[i]),
                speed=float(speed[i]),
                acceleration=float(accel[i]),
                yaw_rate=float(rows[i, 6]),
                length=float(rows[i, 7]),
                width=float(rows[i, 8]),
            )

        senders = np.flatnonzero(cam_due.send & present & self._cam_mask)
        if len(senders):
            k = etsi.KinematicsArrays(
                lat[senders],
                lon[senders],
                alt[senders],
                etsi_heading[senders],
                speed[senders],
                accel[senders],
                rows[senders, 6],
                rows[senders, 7],
                rows[senders, 8],
            )
            msgs = etsi.cams(
                self._station_ids[senders].tolist(),
                station_type[senders].tolist(),
                t,
                k,
                cam_due.low_frequency[senders].tolist(),
                rsu[senders].tolist(),
            )
            outgoing.extend(_Outgoing("cam", i, msg) for i, msg in zip(senders.tolist(), msgs, strict=True))
        for hazard in self._hazards.step(t, np.where(present, speed, 0.0), np.where(present, accel, 0.0)):
            station = self.stations[hazard.station]
            if station.rsu or not station.denm or not present[hazard.station]:
                continue
            if hazard.new:
                station.sequence += 1
            key = (station.name, hazard.cause, hazard.detection_time)
            if frame.ego is not None and station.name != frame.ego:
                self.metrics_acc.hazard(key)
            msg = etsi.denm(
                station.station_id,
                int(station_type[hazard.station]),
                station.sequence,
                t,
                hazard.detection_time,
                kinematics(hazard.station),
                hazard.cause,
                hazard.sub_cause,
            )
            outgoing.append(_Outgoing("denm", hazard.station, msg, hazard=key))
        due = [
            i
            for i in np.flatnonzero(self._cpm_mask & present).tolist()
            if t - self.stations[i].last_cpm >= T_GEN_CPM_MIN - _SLACK
        ]
        if due:
            by_sight = [i for i in due if self.stations[i].lidar_objects is None]
            reach = np.array([self.stations[i].perception_range for i in by_sight])
            seen = dict(
                zip(by_sight, self._visible_many(sight, pos[by_sight], own[by_sight], reach), strict=True)
            )
            visible = [
                seen[i] if i in seen else self._lidar_seen(self.stations[i], sight, pos[i]) for i in due
            ]
            # every (station, object) pair of this step in one pass: the CPM's values of each object
            objects = np.concatenate(visible).astype(np.int64)
            owner = np.repeat(np.asarray(due), [len(v) for v in visible])
            values = self._object_values(sight.boxes, objects, pos[owner], north[owner])
            categories = self._object_classes(frame)
            start = 0
            for i, v in zip(due, visible, strict=True):
                part = slice(start, start + len(v))
                start += len(v)
                cpm = self._cpm(
                    self.stations[i],
                    i,
                    frame,
                    kinematics(i),
                    int(station_type[i]),
                    objects[part],
                    table[objects[part]],
                    values[:, part],
                    categories[objects[part]],
                )
                if cpm is not None:
                    outgoing.append(cpm)
        clock = time.process_time()
        self.seconds["generate"] += clock - started
        if outgoing:
            self._transmit(frame, outgoing, pos, present, sight, own)
        self.seconds["channel"] += time.process_time() - clock
        clock = time.process_time()
        self._deliver(t + self.step_seconds - _SLACK)
        self.seconds["deliver"] += time.process_time() - clock
        clock = time.process_time()
        self.metrics_acc.sample_age(t)
        self._ego_view(frame, sight)
        self.seconds["metrics"] += time.process_time() - clock

    def _sight(self, frame: WorldFrame) -> Any:
        from simcore.sensors.scene import Boxes
        from simcore.v2x.sight import Sight

        return Sight(Boxes.of(frame), self._scene_for_sight())

    def _visible(self, sight: Any, origin: np.ndarray, own: int, reach: float) -> list[int]:
        """Indexes of the frame's entities (other than `own`) whose box centre lies within `reach` of `origin`
        (horizontally) and whose centre or a ground-plane box corner (at mid height, 10 % inside) is in line of
        sight."""
        seen = self._visible_many(sight, np.asarray(origin)[None, :], np.array([own]), np.array([reach]))
        return [int(j) for j in seen[0]]

    def _visible_many(
        self, sight: Any, origins: np.ndarray, owns: np.ndarray, reaches: np.ndarray
    ) -> list[np.ndarray]:
        """`_visible` for M observers at once (one line-of-sight pass): per observer the ascending indexes."""
        boxes = sight.boxes
        n, m = len(boxes.names), len(origins)
        empty = np.zeros(0, dtype=np.int64)
        if n == 0:
            return [empty] * m
        near = (
            np.hypot(boxes.centers[None, :, 0] - origins[:, 0:1], boxes.centers[None, :, 1] - origins[:, 1:2])
            <= reaches[:, None]
        )
        mine = owns >= 0
        near[np.flatnonzero(mine), owns[mine]] = False
        rows, cols = np.nonzero(near)
        if len(rows) == 0:
            return [empty] * m
        samples = self._sample_points(sight)
        # the box centres first; the four corners only of the boxes whose centre is hidden
        visible = sight.clear(origins[rows], samples[cols, 0], owns[rows], cols)
        hidden = np.flatnonzero(~visible)
        if len(hidden):
            r, c = rows[hidden], cols[hidden]
            corners = sight.clear(
                np.repeat(origins[r], 4, axis=0),
                samples[c, 1:].reshape(-1, 3),
                np.repeat(owns[r], 4),
                np.repeat(c, 4),
            )
            visible[hidden] = corners.reshape(-1, 4).any(axis=1)
        rows, cols = rows[visible], cols[visible]
        bounds = np.searchsorted(rows, np.arange(m + 1))
        return [cols[bounds[i] : bounds[i + 1]] for i in range(m)]

    @staticmethod
    def _lidar_seen(station: Station, sight: Any, origin: np.ndarray) -> np.ndarray:
        """Indexes of the frame's entities the station's perception lidar saw in its latest sweep, within its
        perception range (box centre, horizontally)."""
        boxes = sight.boxes
        names = station.lidar_objects or set()
        index = np.array([j for j, name in enumerate(boxes.names) if name in names], dtype=np.int64)
        if not len(index):
            return index
        gap = np.hypot(boxes.centers[index, 0] - origin[0], boxes.centers[index, 1] - origin[1])
        return index[gap <= station.perception_range]

    @staticmethod
    def _sample_points(sight: Any) -> np.ndarray:
        """(N, 5, 3): per box its centre and its four side corners at mid height, 10 % towards the centre."""
        cached = getattr(sight, "sample_points", None)
        if cached is None:
            boxes = sight.boxes
            signs = np.array(
                [[0.0, 0.0, 0.0], [0.9, 0.9, 0.0], [-0.9, 0.9, 0.0], [-0.9, -0.9, 0.0], [0.9, -0.9, 0.0]]
            )
            offsets = np.einsum("kj,nj,nij->nki", signs, boxes.half, boxes.rotations)
            cached = sight.sample_points = boxes.centers[:, None, :] + offsets
        return np.asarray(cached)

    @staticmethod
    def _object_values(boxes: Any, objects: np.ndarray, origins: np.ndarray, north: np.ndarray) -> np.ndarray:
        """(10, P): per (station, object) pair the object in the CPM's frame (x east, y north: the map's axes
        turned by the north angle at the station) as `etsi.PerceivedObjects.values`, the age left at 0."""
        ex, ey = np.sin(north), -np.cos(north)
        nx, ny = np.cos(north), np.sin(north)
        d = boxes.centers[objects] - origins
        v = boxes.velocities[objects]
        return np.stack(
            [
                d[:, 0] * ex + d[:, 1] * ey,
                d[:, 0] * nx + d[:, 1] * ny,
                d[:, 2],
                v[:, 0] * ex + v[:, 1] * ey,
                v[:, 0] * nx + v[:, 1] * ny,
                np.degrees(boxes.yaws[objects] - (north - math.pi / 2)),  # counter-clockwise from east
                boxes.half[objects, 0] * 2,
                boxes.half[objects, 1] * 2,
                boxes.half[objects, 2] * 2,
                np.zeros(len(objects)),
            ]
        ).reshape(10, -1)

    @staticmethod
    def _object_classes(frame: WorldFrame) -> np.ndarray:
        """Per entity of the frame its class in a CPM: the ETSI station type (−1: not a road user)."""
        return np.array(
            [
                etsi.STATION_TYPES.get(e.category, 0 if e.object_type == "vehicle" else -1)
                for e in frame.entities
            ],
            dtype=np.int64,
        )

    def _cpm(
        self,
        station: Station,
        index: int,
        frame: WorldFrame,
        ref: etsi.Kinematics,
        station_type: int,
        seen: np.ndarray,
        rows: np.ndarray,
        values: np.ndarray,
        classes: np.ndarray,
    ) -> _Outgoing | None:
        """The station's CPM of the objects `seen` (entity indexes; `rows`: their `step` table rows, `values`
        and `classes` as `_object_values` and `_object_classes`), or None when no object is due and the last
        CPM is less than T_GenCpmMax old."""
        t = frame.time
        ids = [frame.entities[j].name for j in seen.tolist()]
        first_seen = station.first_seen
        for name in ids:
            first_seen.setdefault(name, t)
        chosen = station.cpm_triggers.select(t, ids, rows[:, 0:2], rows[:, 4], rows[:, 3])
        if not chosen.any() and t - station.last_cpm < T_GEN_CPM_MAX - _SLACK:
            return None
        station.last_cpm = t
        names = [name for name, take in zip(ids, chosen.tolist(), strict=True) if take]
        values = values[:, chosen]
        values[9] = t - np.array([first_seen[name] for name in names], dtype=np.float64)  # age
        # object ids: the entity's position in the frame + 1, as in the sensors' labels
        perceived = etsi.PerceivedObjects(seen[chosen] + 1, values, classes[chosen])
        msg = etsi.cpm(station.station_id, station_type, t, ref, perceived, rsu=station.rsu)
        return _Outgoing("cpm", index, msg, objects=tuple(names))

    def _transmit(
        self,
        frame: WorldFrame,
        outgoing: list[_Outgoing],
        pos: np.ndarray,
        present: np.ndarray,
        sight: Any,
        own: np.ndarray,
    ) -> None:
        senders = np.array([o.sender for o in outgoing])
        n = len(self.stations)
        same = senders[:, None] == np.arange(n)[None, :]
        same |= ~present[None, :]  # an absent station receives nothing
        if sight is not None and self.config.channel.line_of_sight:

            def los(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
                a, b = senders[rows], cols
                return np.asarray(sight.clear(pos[a], pos[b], own[a], own[b]))

            self.channel.los = los
        else:
            self.channel.los = None
        delivery = self.channel.transmit(frame.step, self.step_seconds, pos[senders], pos, same)
        link = ~same
        delivered = delivery.delivered & link
        self.metrics_acc.links(delivery.distance[link], delivered[link])
        transmission = TYPESTORE.types["carlos_v2x_msgs/msg/Transmission"]
        # every sender is present, so each row links the same number of receivers: the other present stations
        width = int(present.sum()) - 1
        outcomes = delivery.lost[link].astype(np.uint8).reshape(-1, width)
        distances = delivery.distance[link].astype(np.float32).reshape(-1, width)
        power = delivery.rx_power_dbm[link].astype(np.float32).reshape(-1, width)
        delays = delivery.delay[link].astype(np.float32).reshape(-1, width)
        everyone = width == n - 1
        sent = stamp(frame.time)
        records = []
        for m, out in enumerate(outgoing):
            self.metrics_acc.message_sent(out.kind)
            sender = self.stations[out.sender]
            if everyone:
                receivers = self._others[out.sender]
            else:
                receivers = [self._names[r] for r in np.flatnonzero(link[m]).tolist()]
            records.append(
                transmission(
                    sent=sent,
                    sender=sender.name,
                    station_id=sender.station_id,
                    message_type=out.kind,
                    receivers=receivers,
                    outcomes=outcomes[m],
                    distances=distances[m],
                    rx_power_dbm=power[m],
                    delays=delays[m],
                )
            )
        rows, cols = np.nonzero(delivered)
        self._batch = (outgoing, rows, cols, frame.time + delivery.delay[rows, cols], frame.time)
        header = TYPESTORE.types["std_msgs/msg/Header"](stamp=sent, frame_id="map")
        self._transmissions.publish(
            TYPESTORE.types["carlos_v2x_msgs/msg/TransmissionArray"](header=header, transmissions=records),
            frame.time,
        )

    def _entity_index(self, frame: WorldFrame) -> np.ndarray:
        """Per station, the index of its entity's box in the frame (−1: an RSU or absent)."""
        index = {e.name: j for j, e in enumerate(frame.entities)}
        return np.array([-1 if s.rsu else index.get(s.name, -1) for s in self.stations], dtype=np.int64)

    def _deliver(self, until: float) -> None:
        """Publish every copy arriving before `until` on its receiver's topic, in order of arrival: this step's
        (`_batch`) and earlier ones still under way (`_pending`); later ones wait in `_pending`."""
        due: list[tuple[float, int, int, _Outgoing, float]] = []
        while self._pending and self._pending[0][0] <= until:
            item = heapq.heappop(self._pending)
            self.metrics_acc.received(item[2], item[3].sender, item[4])
            due.append(item)
        late = bool(due)
        if self._batch is not None:
            outgoing, rows, cols, arrivals, generated = self._batch
            self._batch = None
            now = arrivals <= until
            senders = np.array([outgoing[m].sender for m in rows], dtype=np.int64)
            self.metrics_acc.received_many(cols[now], senders[now], generated)
            for k in np.argsort(arrivals, kind="stable"):
                item = (float(arrivals[k]), next(self._seq), int(cols[k]), outgoing[rows[k]], generated)
                if now[k]:
                    due.append(item)
                else:
                    heapq.heappush(self._pending, item)
        if late:
            due.sort(key=lambda item: (item[0], item[1]))
        send = self._send
        for arrival, _, r, out, _ in due:
            receiver = self.stations[r]
            publisher = receiver.publishers[out.kind]
            if send is None:
                publisher.publish(out.msg, arrival)
            else:  # every copy carries the CDR bytes the first copy's subscribers made
                message = Message(publisher.topic, publisher.typename, arrival, msg=out.msg, data=out.cdr)
                send(message)
                out.cdr = message.data
            if receiver.name == self._ego_name:
                if out.kind == "cpm":
                    for name in out.objects:
                        self._ego_cpm[name] = arrival
                elif out.kind == "denm" and out.hazard is not None:
                    self.metrics_acc.ego_denm(out.hazard, arrival)

    def _ego_view(self, frame: WorldFrame, sight: Any) -> None:
        if frame.ego is None:
            return
        try:
            ego = frame.entity(frame.ego)
        except KeyError:
            return
        own = next(j for j, e in enumerate(frame.entities) if e.name == frame.ego)
        reach = self.config.ego_sensor_range
        origin = np.array(_antenna(ego))
        seen = {frame.entities[j].name for j in self._visible(sight, origin, own, reach)}
        nearby = {
            e.name
            for e in frame.entities
            if e.name != frame.ego and math.hypot(e.x - ego.x, e.y - ego.y) <= 2 * reach
        }
        unseen = nearby - seen
        known = {name for name, arrival in self._ego_cpm.items() if frame.time - arrival <= 1.0 + _SLACK}
        self.metrics_acc.ego_view(unseen, known)

    def metrics(self) -> dict[str, float]:
        return self.metrics_acc.result()
