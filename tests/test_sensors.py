"""Sensors: road mesh, lidar geometry, noise, dropout, intensity, labels, occlusion, motion distortion,
camera, ground truth, ROS 2 messages, scheduling and the spec models."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from simcore.errors import BadInput
from simcore.sensors import kernels, ros
from simcore.sensors.camera import Camera
from simcore.sensors.classes import CLASS_IDS
from simcore.sensors.lidar import POINT_DTYPE, Lidar, LidarScan, mount_pose
from simcore.sensors.rig import SensorRig, ground_truth
from simcore.sensors.scene import (
    Boxes,
    RoadScene,
    StaticObject,
    intersect_box,
    road_mesh,
    rotation,
)
from simcore.spec import CameraSensor, LidarSensor, SimulationRunSpec
from simcore.transport.bus import InProcessBus, Message
from simcore.transport.messages import deserialize, serialize
from simcore.world.opendrive import OpenDrive
from simcore.world.state import BoundingBox, EntityState, WorldFrame
from tests.tooling import corpus_dir

ROOT = Path(__file__).resolve().parent.parent
HIGHWAY = ROOT / "examples" / "maps" / "highway.xodr"
CAR = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)

# A straight road along x: 2 lanes of 3.5 m right of the reference line (y from -7 to 0), 200 m long.
STRAIGHT = """<?xml version="1.0"?>
<OpenDRIVE><header revMajor="1" revMinor="6" name="straight"/>
<road id="1" length="200" junction="-1"><link/>
<planView><geometry s="0" x="0" y="0" hdg="0" length="200"><line/></geometry></planView>
<lanes><laneSection s="0"><center><lane id="0" type="none"/></center>
<right>
<lane id="-1" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
<lane id="-2" type="shoulder"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
</right></laneSection></lanes></road></OpenDRIVE>
"""


@pytest.fixture(scope="module")
def straight() -> RoadScene:
    return RoadScene(OpenDrive.from_string(STRAIGHT))


def car(
    name: str, x: float, y: float, heading: float = 0.0, speed: float = 0.0, yaw_rate: float = 0.0
) -> EntityState:
    return EntityState(name, "vehicle", "car", x, y, 0.0, heading, 0.0, 0.0, speed, 0.0, yaw_rate, CAR)


def lidar(**kw: object) -> Lidar:
    cfg = {"type": "lidar", "name": "lidar", "range_noise": 0.0, **kw}
    return Lidar(LidarSensor.model_validate(cfg), seed=1)


def frame(*entities: EntityState, time: float = 0.0) -> WorldFrame:
    return WorldFrame(0, time, tuple(entities), ego=entities[0].name)


def intersect_box_rows(
    origin: np.ndarray, dirs: Sequence[np.ndarray], center: np.ndarray, rot: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The numpy slab test `kernels.box_returns` replaced (the reference of its tests): `intersect_box` for
    rays from one `origin` (3,) with directions given as three rows (x, y, z
    components, (M,) each): the slab test one axis at a time on contiguous rows, several times faster than
    on (M, 3) arrays in numpy.

    Returns (t (M,) with inf where the ray misses or starts inside the box, |cos| of the angle between the
    ray and the normal of the face hit (M,) float32: the ray's box-frame component along that face's axis)."""
    o = (origin - center) @ rot  # into the box frame
    m = len(dirs[0])
    tmin = np.full(m, -np.inf)
    tmax = np.full(m, np.inf)
    axis_d = np.zeros(m)  # the box-frame direction component along the axis of the entry face
    for k in range(3):
        d = dirs[0] * rot[0, k] + dirs[1] * rot[1, k] + dirs[2] * rot[2, k]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t1 = (-half[k] - o[k]) * inv
            t2 = (half[k] - o[k]) * inv
        near = np.minimum(t1, t2)
        far = np.maximum(t1, t2, out=t2)
        if not np.isfinite(inv).all():  # 0 * inf: parallel to a face and in its plane (NaN: no constraint)
            np.copyto(near, -np.inf, where=np.isnan(near))
            np.copyto(far, np.inf, where=np.isnan(far))
        later = near > tmin  # the first axis of the largest entry wins, as argmax
        np.copyto(tmin, near, where=later)
        np.copyto(axis_d, d, where=later)
        np.minimum(tmax, far, out=tmax)
    hit = (tmax >= tmin) & (tmin > 0.0)
    return np.where(hit, tmin, np.inf), np.abs(axis_d).astype(np.float32)


# --- scene -------------------------------------------------------------------------------------------


def test_road_mesh_covers_the_lanes_and_nothing_else(straight: RoadScene) -> None:
    xs = np.linspace(1, 199, 50)
    ys = np.array([-6.9, -5.0, -1.0, -0.1, 0.5, 3.0, -7.5])
    gx, gy = np.meshgrid(xs, ys)
    rays = np.zeros((gx.size, 6), np.float32)
    rays[:, 0], rays[:, 1], rays[:, 2] = gx.ravel(), gy.ravel(), 10.0
    rays[:, 5] = -1.0
    t, _, classes = straight.cast(rays)
    on_road = (gy.ravel() > -7.0) & (gy.ravel() < 0.0)
    assert np.all(np.isfinite(t[on_road])) and np.allclose(t[on_road], 10.0, atol=1e-4)
    assert np.all(np.isinf(t[~on_road])), "beyond the outer lanes there is no ground (not an infinite plane)"
    driving = on_road & (gy.ravel() > -3.5)
    assert set(classes[driving]) == {CLASS_IDS["road"]}
    assert set(classes[on_road & ~driving]) == {CLASS_IDS["roadside"]}


def test_highway_mesh_follows_the_curve() -> None:
    road = OpenDrive.from_file(HIGHWAY)
    _vertices, triangles, classes = road_mesh(road)
    assert len(triangles) > 1000 and len(classes) == len(triangles)
    scene = RoadScene(road)
    # the lane centre of lane -2 in the curve is on the surface; 30 m off it is not
    for s in (700.0, 1500.0):
        p = road.lane_to_world("1", -2, s)
        ray = np.array([[p.x, p.y, p.z + 5, 0, 0, -1]], np.float32)
        t, _, cls = scene.cast(ray)
        assert t[0] == pytest.approx(5.0, abs=1e-3) and cls[0] == CLASS_IDS["road"]
        ray[0, 0] += 30 * -math.sin(p.heading)
        ray[0, 1] += 30 * math.cos(p.heading)
        assert np.isinf(scene.cast(ray)[0][0])


def test_ray_box_intersection_is_exact() -> None:
    rot = rotation(0.3)
    center = np.array([10.0, 2.0, 1.0])
    half = np.array([2.0, 1.0, 0.5])
    # rays from the origin to points on the box surface hit them
    rng = np.random.default_rng(0)
    local = rng.uniform(-1, 1, (200, 3)) * half
    face = rng.integers(0, 3, 200)
    local[np.arange(200), face] = -half[face]  # faces facing away from +x... any face
    world = center + local @ rot.T
    origin = np.array([0.0, 0.0, 1.0])
    dirs = (world - origin) / np.linalg.norm(world - origin, axis=1, keepdims=True)
    t, normals = intersect_box(origin, dirs, center, rot, half)
    hit = np.isfinite(t)
    p = origin + dirs[hit] * t[hit, None]
    inside = np.abs((p - center) @ rot) <= half + 1e-9
    assert hit.sum() > 100 and np.all(inside)
    assert np.all(t[hit] <= np.linalg.norm(world - origin, axis=1)[hit] + 1e-9), "first hit, not a later one"
    assert np.allclose(np.linalg.norm(normals[hit], axis=1), 1.0)
    # from inside the box nothing is hit
    t_in, _ = intersect_box(center, dirs, center, rot, half)
    assert np.all(np.isinf(t_in))


def test_row_wise_box_intersection_matches_the_slab_test() -> None:
    """`intersect_box_rows` (one origin, directions as x/y/z rows) gives `intersect_box`'s distances and
    |cos| of the incidence angle, also for rays parallel to a face and starting in its plane."""
    rng = np.random.default_rng(1)
    rot = rotation(0.3, 0.05, -0.02)
    center, half = np.array([10.0, 2.0, 1.0]), np.array([2.0, 1.0, 0.5])
    dirs = rng.normal(size=(5000, 3))
    dirs[:100, 2] = 0.0  # level rays
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for origin, r in ((np.array([0.0, 0.0, 1.0]), rot), (np.array([16.0, 2.0, 1.5]), np.eye(3))):
        # the second origin lies in the plane of the top face: level rays are parallel to it, in it
        t, normals = intersect_box(origin, dirs, center, r, half)
        t_rows, cos = intersect_box_rows(origin, list(dirs.astype(np.float32).T), center, r, half)
        t32, _ = intersect_box(origin, dirs.astype(np.float32), center, r, half)
        assert np.array_equal(np.isfinite(t_rows), np.isfinite(t32)) and np.isfinite(t).sum() > 10
        hit = np.isfinite(t_rows)
        assert np.allclose(t_rows[hit], t32[hit], rtol=1e-12, atol=1e-12)
        assert np.allclose(cos[hit], np.abs(np.einsum("ij,ij->i", dirs[hit], normals[hit])), atol=1e-6)


def test_box_kernel_matches_the_row_wise_slab_test() -> None:
    """`kernels.box_returns` is `intersect_box_rows` ray by ray (the same float64 arithmetic): the same
    ranges (as float32) and |cos|, also for rays parallel to a face and starting in its plane; it only
    takes the rays where the box is closer, and counts the hits within range."""

    rng = np.random.default_rng(2)
    dirs = rng.normal(size=(20000, 3))
    dirs[:500, 2] = 0.0  # level rays
    dirs[500:700, 1] = 0.0
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs_t = np.ascontiguousarray(dirs.astype(np.float32).T)
    center, half = np.array([10.0, 2.0, 1.0]), np.array([2.0, 1.0, 0.5])
    cases = [
        (np.array([0.0, 0.0, 1.0]), rotation(0.3, 0.05, -0.02), np.eye(3)),
        (np.array([16.0, 2.0, 1.5]), np.eye(3), np.eye(3)),  # in the plane of the top face
        (np.array([1.0, -1.0, 1.2]), rotation(-0.4), rotation(0.7, 0.0, 0.01)),  # a rotated sensor
    ]
    for origin, rot, sensor in cases:
        r32 = sensor.astype(np.float32)
        world = [dirs_t[0] * r32[k, 0] + dirs_t[1] * r32[k, 1] + dirs_t[2] * r32[k, 2] for k in range(3)]
        want_t, want_cos = intersect_box_rows(origin, world, center, rot, half)
        # a third of the rays have a return closer than the box, a third one farther
        t = np.select([np.arange(len(dirs)) % 3 == k for k in (0, 1)], [want_t * 0.9, want_t * 1.1], np.inf)
        t = t.astype(np.float32)
        before = t.copy()
        cos = np.zeros(len(dirs), np.float32)
        classes = np.zeros(len(dirs), np.uint8)
        ids = np.zeros(len(dirs), np.uint32)
        hits = kernels.box_returns(
            t, cos, classes, ids, np.arange(len(dirs)), np.zeros(1, np.int64), 1, dirs_t, r32,
            (origin - center) @ rot, rot, half, 0.5, 12.0, np.uint8(3), np.uint32(7),
        )  # fmt: skip
        closer = want_t < before
        assert closer.sum() > 10 and (~closer & np.isfinite(want_t)).sum() > 10
        assert np.array_equal(t, np.where(closer, want_t, before).astype(np.float32))
        assert np.array_equal(cos[closer], want_cos[closer]) and not cos[~closer].any()
        assert np.array_equal(classes != 0, closer) and np.array_equal(ids != 0, closer)
        assert hits == np.count_nonzero((want_t >= 0.5) & (want_t <= 12.0))


# --- lidar -------------------------------------------------------------------------------------------


def test_lidar_points_lie_on_the_box_and_the_road(straight: RoadScene) -> None:
    ego, other = car("Ego", 50, -1.75), car("Other", 70, -5.25, heading=0.2)
    f = frame(ego, other)
    boxes = Boxes.of(f)
    sensor = lidar(channels=32, horizontal_resolution=720)
    scan = sensor.scan(straight, boxes, ego, 0)
    p = scan.points
    assert scan.rays == 32 * 720
    rot, pos = rotation(0.0), np.array([50, -1.75, 2.0])
    world = pos + np.stack([p["x"], p["y"], p["z"]], axis=1).astype(float) @ rot.T
    on_box = p["object_id"] == 2
    assert on_box.sum() > 50 and scan.object_points[1] == on_box.sum()
    assert np.all(p["label"][on_box] == CLASS_IDS["car"])
    local = (world[on_box] - boxes.centers[1]) @ boxes.rotations[1]
    assert np.all(np.abs(local) <= boxes.half[1] + 1e-3)
    ground = p["label"] == CLASS_IDS["road"]
    assert np.allclose(world[ground, 2], 0.0, atol=1e-3)
    assert np.all(p["object_id"][~on_box] == 0), "the carrier does not see itself"
    ranges = np.linalg.norm(np.stack([p["x"], p["y"], p["z"]], axis=1), axis=1)
    assert ranges.min() >= 0.5 - 1e-6 and ranges.max() <= 120 + 1e-6
    # every ring is at its elevation
    elev = np.degrees(np.arcsin(p["z"] / ranges))
    assert np.allclose(elev, np.linspace(-25, 15, 32)[p["ring"]], atol=1e-3)


def test_vertical_angles_fov_and_range_limits(straight: RoadScene) -> None:
    ego = car("Ego", 50, -1.75)
    sensor = lidar(
        channels=3,
        vertical_angles=[-10.0, -5.0, -2.0],
        horizontal_resolution=360,
        horizontal_fov=90,
        range_max=30,
    )
    scan = sensor.scan(straight, Boxes.of(frame(ego)), ego, 0)
    p = scan.points
    azimuth = np.degrees(np.arctan2(p["y"], p["x"]))
    assert np.all(np.abs(azimuth) <= 45.0 + 1e-3)
    # the -2° ring reaches the ground at 2 m / tan(2°) = 57 m: beyond rangeMax, so it returns nothing
    assert set(np.unique(p["ring"])) == {0, 1}
    assert np.linalg.norm(np.stack([p["x"], p["y"], p["z"]], axis=1), axis=1).max() <= 30 + 1e-6


def test_range_noise_is_seeded_and_has_the_configured_spread(straight: RoadScene) -> None:
    ego = car("Ego", 50, -1.75)
    boxes = Boxes.of(frame(ego))
    cfg = LidarSensor(type="lidar", name="l", channels=16, vertical_fov=(-25, -10), range_noise=0.05)
    exact = Lidar(cfg.model_copy(update={"range_noise": 0.0}), seed=3).scan(straight, boxes, ego, 0).points
    a = Lidar(cfg, seed=3).scan(straight, boxes, ego, 0).points
    b = Lidar(cfg, seed=3).scan(straight, boxes, ego, 0).points
    c = Lidar(cfg, seed=4).scan(straight, boxes, ego, 0).points
    assert np.array_equal(a, b)
    assert not np.array_equal(a["x"], c["x"])

    def ranges(p: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.stack([p["x"], p["y"], p["z"]], axis=1).astype(float), axis=1)

    error = ranges(a) - ranges(exact)
    assert abs(error.mean()) < 0.005 and error.std() == pytest.approx(0.05, rel=0.1)


def test_dropout_loses_the_configured_share(straight: RoadScene) -> None:
    ego = car("Ego", 50, -1.75)
    boxes = Boxes.of(frame(ego))
    full = lidar(channels=16, vertical_fov=(-25, -10)).scan(straight, boxes, ego, 0)
    dropped = lidar(channels=16, vertical_fov=(-25, -10), dropout=0.3).scan(straight, boxes, ego, 0)
    assert len(dropped.points) / len(full.points) == pytest.approx(0.7, abs=0.02)


def test_intensity_falls_with_the_incidence_angle(straight: RoadScene) -> None:
    ego = car("Ego", 50, -1.75)
    p = lidar(channels=32).scan(straight, Boxes.of(frame(ego)), ego, 0).points
    road = p[p["label"] == CLASS_IDS["road"]]
    ranges = np.hypot(road["x"], road["y"])
    near, far = road[ranges < 6], road[ranges > 20]
    # the road is hit steeply nearby and at grazing angles far away; intensity = reflectivity × cos
    assert near["intensity"].mean() > 2 * far["intensity"].mean()
    cos = 2.0 / np.linalg.norm(np.stack([road["x"], road["y"], road["z"]], axis=1), axis=1)
    assert np.allclose(road["intensity"], 0.12 * cos, atol=1e-4)


def test_occlusion_and_ground_truth_in_the_sensor_frame(straight: RoadScene) -> None:
    ego, front, hidden = car("Ego", 50, -1.75), car("Front", 60, -1.75), car("Hidden", 75, -1.75)
    beside = car("Beside", 70, -5.25)
    f = frame(ego, front, hidden, beside)
    boxes = Boxes.of(f)
    sensor = lidar(channels=64, mount={"x": 1.4, "z": 1.8, "yaw": 90.0})
    scan = sensor.scan(straight, boxes, ego, 0)
    objects = {o["name"]: o for o in ground_truth(sensor, boxes, f, 0, scan)}
    assert set(objects) == {"Front", "Hidden", "Beside"}
    assert objects["Front"]["occlusion"] == pytest.approx(0.0, abs=1e-9)
    assert objects["Hidden"]["occlusion"] > 0.5
    assert objects["Front"]["points"] > objects["Hidden"]["points"]
    # the sensor looks to the left (yaw 90°): the car ahead is on its right (-y), 10 m away
    c = objects["Front"]["center"]
    assert c == pytest.approx([0.0, -10.0, -1.05], abs=1e-9)
    yaw = math.atan2(objects["Front"]["rotation"][1, 0], objects["Front"]["rotation"][0, 0])
    assert yaw == pytest.approx(-math.pi / 2)


def test_ground_truth_velocity_is_in_the_sensor_frame(straight: RoadScene) -> None:
    ego, other = car("Ego", 50, -1.75, speed=10), car("Other", 70, -1.75, heading=0.1, speed=20)
    f = frame(ego, other)
    boxes = Boxes.of(f)
    sensor = lidar(mount={"yaw": 90.0})
    obj = ground_truth(sensor, boxes, f, 0, sensor.scan(straight, boxes, ego, 0))[0]
    assert obj["velocity"] == pytest.approx([20 * math.sin(0.1), -20 * math.cos(0.1), 0.0])


def test_motion_distortion_fires_columns_from_earlier_poses(straight: RoadScene) -> None:
    ego, ahead = car("Ego", 50, -1.75, speed=30.0), car("Ahead", 70, -1.75)
    f = frame(ego, ahead)
    boxes = Boxes.of(f)
    plain = lidar(channels=32).scan(straight, boxes, ego, 0).points
    moving = lidar(channels=32, motion_distortion=True).scan(straight, boxes, ego, 0).points
    assert np.all(plain["time"] == 0.0)
    assert moving["time"].min() >= -0.1 - 1e-9 and moving["time"].max() <= 0.0

    # the sweep starts and ends behind (azimuth ±180°, clockwise): behind-left is fired first (≈ -0.1 s, when
    # the carrier was 3 m further back), behind-right last (≈ 0 s)
    def ring0_behind(p: np.ndarray, left: bool) -> np.ndarray:
        side = (p["y"] > 0) & (p["y"] < 0.5) if left else (p["y"] < 0) & (p["y"] > -0.5)
        return p[(p["ring"] == 0) & (p["x"] < 0) & side & (p["label"] == CLASS_IDS["road"])]

    first, last = ring0_behind(moving, True), ring0_behind(moving, False)
    assert first["time"].mean() < -0.09 and last["time"].mean() > -0.01
    # the ground hit by the same ray lies 3 m further back when fired 0.1 s earlier at 30 m/s
    assert first["x"].mean() == pytest.approx(ring0_behind(plain, True)["x"].mean() - 3.0, abs=0.1)
    assert last["x"].mean() == pytest.approx(ring0_behind(plain, False)["x"].mean(), abs=0.1)
    # the geometry stays right: points on the static car ahead lie on its surface in the end frame
    world = np.array([50.0, -1.75, 2.0]) + np.stack([moving["x"], moving["y"], moving["z"]], axis=1).astype(
        float
    )
    on = moving["object_id"] == 2
    local = (world[on] - boxes.centers[1]) @ boxes.rotations[1]
    assert on.sum() > 20 and np.all(np.abs(local) <= boxes.half[1] + 1e-3)


# --- camera ------------------------------------------------------------------------------------------


def test_camera_depth_and_labels(straight: RoadScene) -> None:
    ego, ahead = car("Ego", 50, -1.75), car("Ahead", 60, -1.75)
    boxes = Boxes.of(frame(ego, ahead))
    cam = Camera(
        CameraSensor(
            type="camera", name="cam", width=64, height=48, horizontal_fov=90, mount={"x": 2.0, "z": 1.0}
        )
    )
    image = cam.capture(straight, boxes, ego, 0)
    assert image.depth.shape == (48, 64) and image.labels.dtype == np.uint8
    # the rear face of the car ahead is at x = 60 + 1.4 - 2.25 = 59.15, the camera at 52.0: depth 7.15
    assert image.depth[24, 32] == pytest.approx(7.15, abs=1e-3)
    assert image.labels[24, 32] == CLASS_IDS["car"] and image.object_ids[24, 32] == 2
    # depth is along the optical axis: the whole rear face has the same depth
    face = image.object_ids == 2
    assert np.allclose(image.depth[face & (np.abs(image.depth - 7.15) < 0.01)], 7.15, atol=1e-3)
    # the bottom rows see the road, the top rows the sky
    assert (
        image.labels[-1, 32] == CLASS_IDS["road"] and np.isnan(image.depth[0, 0]) and image.labels[0, 0] == 0
    )
    assert cam.fx == pytest.approx(32.0)


# --- messages and the rig ----------------------------------------------------------------------------


def test_pointcloud2_round_trip(straight: RoadScene) -> None:
    ego, other = car("Ego", 50, -1.75), car("Other", 65, -1.75)
    points = lidar(channels=16).scan(straight, Boxes.of(frame(ego, other)), ego, 0).points
    msg = ros.pointcloud2(points, 1.5, "Ego/lidar")
    back = deserialize(serialize(msg), ros.POINTCLOUD2)
    assert [f.name for f in back.fields] == ["x", "y", "z", "intensity", "time", "object_id", "ring", "label"]
    assert (
        back.header.frame_id == "Ego/lidar"
        and back.header.stamp.sec == 1
        and back.header.stamp.nanosec == 500_000_000
    )
    assert back.point_step == 28 and back.width == len(points)
    assert np.array_equal(ros.read_pointcloud2(back), points)


def _rig(sensors: list[dict[str, object]], road: OpenDrive | None) -> tuple[SensorRig, list[Message]]:
    spec = SimulationRunSpec.model_validate(
        {"scenarios": [{"name": "s", "openscenario": "x.xosc"}], "sensors": sensors}
    )
    bus = InProcessBus()
    seen: list[Message] = []
    bus.subscribe("*", seen.append)
    return SensorRig(spec.sensors, road, bus, seed=0), seen


def test_rig_publishes_at_the_sensor_rates() -> None:
    rig, seen = _rig(
        [
            {"type": "lidar", "name": "top", "channels": 8, "rotationRate": 10},
            {"type": "camera", "name": "front", "width": 16, "height": 8, "rate": 5, "mount": {"x": 3}},
        ],
        OpenDrive.from_string(STRAIGHT),
    )
    for step in range(21):  # 1 s at 0.05 s
        rig.step(
            WorldFrame(step, step * 0.05, (car("Ego", 50 + step, -1.75), car("B", 80, -1.75)), ego="Ego")
        )
    topics = [m.topic for m in seen]
    assert topics.count("/tf_static") == 1
    assert topics.count("/carlos/Ego/top/points") == 11  # t = 0, 0.1, …, 1.0
    assert topics.count("/carlos/Ego/top/objects") == 11
    assert topics.count("/carlos/Ego/front/image") == 6  # t = 0, 0.2, …, 1.0
    assert topics.count("/carlos/Ego/front/camera_info") == 6
    assert topics.count("/carlos/Ego/top/label_info") == 1
    stamps = [m.time_s for m in seen if m.topic == "/carlos/Ego/top/points"]
    assert stamps == pytest.approx([0.1 * k for k in range(11)])
    tf = next(m.msg for m in seen if m.topic == "/tf_static")
    frames = {(t.header.frame_id, t.child_frame_id) for t in tf.transforms}
    assert frames == {
        ("Ego/base_link", "Ego/top"),
        ("Ego/base_link", "Ego/front"),
        ("Ego/front", "Ego/front_optical"),
    }
    for m in seen:  # every message serialises
        assert deserialize(serialize(m.msg), m.typename) is not None


def test_rig_refuses_an_unknown_carrier() -> None:
    rig, _ = _rig([{"type": "lidar", "name": "top", "entity": "Nobody"}], None)
    with pytest.raises(BadInput, match=r"Nobody.*not an entity") as info:
        rig.step(WorldFrame(0, 0.0, (car("Ego", 0, 0),), ego="Ego"))
    assert "spec.sensors[0].entity" in str(info.value)


# --- spec --------------------------------------------------------------------------------------------


def _spec(**spec: object) -> SimulationRunSpec:
    return SimulationRunSpec.model_validate({"scenarios": [{"name": "s", "openscenario": "x.xosc"}], **spec})


def test_spec_sensor_models() -> None:
    spec = _spec(sensors=[{"type": "lidar", "name": "lidar"}, {"type": "camera", "name": "cam"}])
    assert isinstance(spec.sensors[0], LidarSensor) and isinstance(spec.sensors[1], CameraSensor)
    assert spec.sensors[0].channels == 32 and spec.sensors[0].rotation_rate == 10.0
    bad = [
        ([{"type": "radar", "name": "r"}], "radar"),
        ([{"type": "lidar", "name": "l", "channels": 2, "verticalAngles": [1.0]}], "one angle per channel"),
        ([{"type": "lidar", "name": "l", "rangeMin": 10, "rangeMax": 5}], "rangeMin"),
        ([{"type": "lidar", "name": "l", "verticalFov": [10, -10]}], "lowest angle comes first"),
        ([{"type": "lidar", "name": "l"}, {"type": "camera", "name": "l"}], "defined twice"),
        ([{"type": "lidar", "name": "l", "channel": 3}], "channel"),
        ([{"type": "lidar", "name": "bad name"}], "pattern"),
    ]
    for sensors, message in bad:
        with pytest.raises(ValidationError, match=message):
            _spec(sensors=sensors)


def test_spec_system_under_test_and_detection() -> None:
    spec = _spec(
        sensors=[{"type": "lidar", "name": "lidar"}],
        systemUnderTest={"module": "examples.detector:Detector", "parameters": {"min_points": 3}},
        evaluation={
            "detection": {"sensor": "Ego/lidar", "topic": "/carlos/sut/detections"},
            "criteria": ["detection.recall.0-30m >= 0.9"],
        },
    )
    assert spec.system_under_test is not None and spec.system_under_test.name == "sut"
    assert spec.evaluation.criteria[0].metric == "detection.recall.0-30m"
    assert spec.evaluation.detection is not None and spec.evaluation.detection.bands == [0.0, 30.0, 60.0]
    with pytest.raises(ValidationError, match="set 'module'"):
        _spec(systemUnderTest={"name": "x"})
    with pytest.raises(ValidationError, match="pattern"):
        _spec(systemUnderTest={"module": "no-colon"})
    with pytest.raises(ValidationError, match="strictly increasing"):
        _spec(
            sensors=[{"type": "lidar", "name": "lidar"}],
            evaluation={"detection": {"sensor": "Ego/lidar", "topic": "/d", "bands": [0, 50, 30]}},
        )
    assert _spec(
        systemUnderTest={"image": "registry/detector:1", "command": ["python", "-m", "x"]}
    ).system_under_test


@pytest.mark.parametrize("fov", [360.0, 200.0, 90.0])
def test_column_culling_changes_nothing(
    straight: RoadScene, fov: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    # boxes ahead, beside, behind across the ±180° seam, turned, and one straddling the fov's edge
    ego = car("Ego", 50, -1.75)
    others = [
        car("Ahead", 70, -1.75, heading=0.4),
        car("Behind", 35, -1.75),
        car("Side", 52, -5.25, heading=-0.3),
        car("Edge", 60, -12.0, heading=1.2),
    ]
    boxes = Boxes.of(frame(ego, *others))
    sensor = lidar(channels=24, horizontal_resolution=round(1024 * fov / 360), horizontal_fov=fov)
    culled = sensor.scan(straight, boxes, ego, 0)
    monkeypatch.setattr(Lidar, "_columns_of", lambda self, corners, pad: None)
    every_ray = sensor.scan(straight, boxes, ego, 0)
    assert np.array_equal(culled.points, every_ray.points)
    assert np.array_equal(culled.unoccluded_rays, every_ray.unoccluded_rays)
    assert culled.object_points.sum() > 0


def test_camera_pixel_culling_changes_nothing(straight: RoadScene, monkeypatch: pytest.MonkeyPatch) -> None:
    ego = car("Ego", 50, -1.75)
    others = [
        car("Ahead", 58, -1.75, heading=0.4),
        car("Near", 53.5, -4.5, heading=-0.8),
        car("Back", 40, -1.75),
    ]
    boxes = Boxes.of(frame(ego, *others))
    cam = Camera(
        CameraSensor(
            type="camera", name="cam", width=80, height=60, horizontal_fov=100, mount={"x": 2.5, "z": 1.2}
        )
    )
    culled = cam.capture(straight, boxes, ego, 0)
    monkeypatch.setattr(Camera, "_pixels_of", lambda self, corners: None)
    every_pixel = cam.capture(straight, boxes, ego, 0)
    assert np.array_equal(culled.labels, every_pixel.labels)
    assert np.array_equal(culled.object_ids, every_pixel.object_ids)
    assert np.allclose(culled.depth, every_pixel.depth, equal_nan=True)
    assert {2, 3} <= set(np.unique(culled.object_ids).tolist())  # both cars in front are seen


def test_spec_detection_names_a_lidar_with_ground_truth() -> None:
    detection = {"sensor": "Ego/lidar", "topic": "/carlos/sut/detections"}
    assert _spec(sensors=[{"type": "lidar", "name": "lidar"}], evaluation={"detection": detection})
    assert _spec(
        sensors=[{"type": "lidar", "name": "lidar", "entity": "Ego"}], evaluation={"detection": detection}
    )
    for sensors, message in [
        ([], "names no lidar"),
        ([{"type": "camera", "name": "lidar"}], "names no lidar"),
        ([{"type": "lidar", "name": "lidar", "entity": "Other"}], "names no lidar"),
        ([{"type": "lidar", "name": "lidar", "groundTruth": False}], "groundTruth: false"),
    ]:
        with pytest.raises(ValidationError, match=message):
            _spec(sensors=sensors, evaluation={"detection": detection})


SCENERY = STRAIGHT.replace(
    "</lanes></road>",
    """</lanes><objects>
<object id="p1" name="lamp" type="pole" s="60" t="2" zOffset="0" radius="0.15" height="6" hdg="0"/>
<object id="b1" name="wall" type="barrier" s="80" t="-8" zOffset="0" length="10" width="0.5" height="1.2" hdg="0"/>
<object id="c1" name="zebra" type="crosswalk" s="70" t="-3" length="4" width="7" height="0"/>
<object id="x1" name="odd" type="pole" s="oops" t="0" radius="0.1" height="3"/>
</objects></road>""",
)


def test_static_scenery_from_the_road_file(tmp_path: Path) -> None:
    from simcore.sensors.rig import road_scene
    from simcore.sensors.scene import static_objects

    road = OpenDrive.from_string(SCENERY)
    objects = static_objects(road, SCENERY.encode())
    assert [o.name for o in objects] == ["lamp", "wall"], "flat and malformed records are left out"
    assert objects[0].center == pytest.approx([60.0, 2.0, 3.0])
    assert objects[1].half == pytest.approx([5.0, 0.25, 0.6])
    file = tmp_path / "scenery.xodr"
    file.write_text(SCENERY)
    scene = road_scene(road, file)
    assert len(scene.scenery) == 2
    ego = car("Ego", 50, -1.75)
    p = lidar(channels=32).scan(scene, Boxes.of(frame(ego)), ego, 0).points
    world = np.array([50.0, -1.75, 2.0]) + np.stack([p["x"], p["y"], p["z"]], axis=1).astype(float)
    pole = world[p["label"] == CLASS_IDS["pole"]]
    wall = world[p["label"] == CLASS_IDS["barrier"]]
    assert len(pole) > 5 and np.all(np.hypot(pole[:, 0] - 60, pole[:, 1] - 2) <= 0.15 * math.sqrt(2) + 1e-3)
    assert len(wall) > 5 and np.all((np.abs(wall[:, 0] - 80) <= 5 + 1e-3) & (wall[:, 2] <= 1.2 + 1e-3))
    assert np.all(p["object_id"][p["label"] == CLASS_IDS["pole"]] == 0), (
        "scenery is not an object of the truth"
    )


# A road that climbs (z = 0.002 s², 180 m at its end): upward rays from the bottom hit it ahead.
HILL = """<?xml version="1.0"?>
<OpenDRIVE><header revMajor="1" revMinor="6" name="hill"/>
<road id="1" length="300" junction="-1"><link/>
<planView><geometry s="0" x="0" y="0" hdg="0" length="300"><line/></geometry></planView>
<elevationProfile><elevation s="0" a="0" b="0" c="0.002" d="0"/></elevationProfile>
<lanes><laneSection s="0"><center><lane id="0" type="none"/></center>
<right><lane id="-1" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
</laneSection></lanes></road></OpenDRIVE>
"""


def count_casts(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The number of rays of every open3d cast from now on (the list fills as the scans cast)."""
    sizes: list[int] = []
    original_cast = RoadScene.cast_ids

    def counting(self: RoadScene, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sizes.append(len(rays))
        return original_cast(self, rays)

    monkeypatch.setattr(RoadScene, "cast_ids", counting)
    return sizes


@pytest.mark.parametrize("where", ["valley", "slope", "flat", "distorted", "pole", "tilted"])
def test_ray_culling_changes_nothing(
    straight: RoadScene, where: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rays that cannot reach the static scene within range are not cast: the scan is the same as when
    every ray is cast, and on a flat road the rays above the horizon are indeed left out."""

    scene = straight if where in ("flat", "pole", "tilted") else RoadScene(OpenDrive.from_string(HILL))
    if where == "pole":  # a 12 m pole beside the road: upward rays must still reach it
        pole = StaticObject(
            "pole", CLASS_IDS["pole"], np.array([70.0, 1.0, 6.0]), np.eye(3), np.array([0.3, 0.3, 6.0])
        )
        scene = RoadScene(OpenDrive.from_string(STRAIGHT), scenery=[pole])
    z = {"valley": 0.0, "slope": 0.002 * 150**2, "distorted": 0.002 * 150**2}.get(where, 0.0)
    x = 20.0 if where == "valley" else 150.0 if where in ("slope", "distorted") else 50.0
    speed, yaw_rate = (25.0, 0.3) if where == "distorted" else (0.0, 0.0)
    ego = EntityState("Ego", "vehicle", "car", x, -1.75, z, 0.1, 0.0, 0.0, speed, 0.0, yaw_rate, CAR)
    ahead = EntityState("Ahead", "vehicle", "car", x + 15, -1.75, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, CAR)
    boxes = Boxes.of(frame(ego, ahead))
    config = {"channels": 32, "horizontal_resolution": 360, "vertical_fov": [-25, 15], "range_noise": 0.02}
    config["motion_distortion"] = where == "distorted"
    if where == "tilted":  # pitched down 5°: directions are no longer level per channel
        config["mount"] = {"z": 1.8, "pitch": 5}
    cast_sizes = count_casts(monkeypatch)
    culled = lidar(**config).scan(scene, boxes, ego, 0)
    with monkeypatch.context() as m:
        m.setattr(Lidar, "_reachable", lambda self, *args: None)
        m.setattr(Lidar, "_level_rays", every_level_ray)
        every_ray = lidar(**config).scan(scene, boxes, ego, 0)
    assert cast_sizes[1] == culled.rays
    for name in culled.points.dtype.names or ():
        assert np.allclose(culled.points[name], every_ray.points[name], rtol=0, atol=1e-6), name
    assert np.array_equal(culled.visible_rays, every_ray.visible_rays)
    assert np.array_equal(culled.unoccluded_rays, every_ray.unoccluded_rays)
    up = culled.points["z"] > 0.0
    if where == "valley":
        assert np.count_nonzero(up & (culled.points["label"] == CLASS_IDS["road"])) > 50  # the climb ahead
    if where == "pole":
        assert np.count_nonzero(up & (culled.points["label"] == CLASS_IDS["pole"])) > 5
    if where in ("flat", "tilted"):
        assert cast_sizes[0] < culled.rays * 0.75  # the 15° above and the level rays are not cast
    if where == "flat":  # per column: the downward rays that meet the ground past the road's edge neither
        downward = culled.rays * np.count_nonzero(np.asarray(lidar(**config).elevations) < 0) // 32
        assert cast_sizes[0] < downward * 0.8


def every_level_ray(self: Lidar, road: RoadScene, pos: np.ndarray, r32: np.ndarray) -> tuple[np.ndarray, ...]:
    """`Lidar._level_rays` casting every ray of the sweep."""
    rays = self._ray_array(self.ray_count, pos)
    rays[:, 3], rays[:, 4] = self._world_dirs(r32, None, range(2))
    rays[:, 5] = self._dirs_t[2]
    return np.arange(self.ray_count), rays


def test_point_padding_is_zero(straight: RoadScene) -> None:
    """The cloud's bytes are a function of the scan alone (the padding byte too): recordings reproduce."""
    junk = np.full(1 << 20, 0xAB, np.uint8)  # leave non-zero memory behind for the allocator
    del junk
    ego = car("Ego", 50, -1.75)
    scans = [lidar(channels=16).scan(straight, Boxes.of(frame(ego)), ego, 0) for _ in range(2)]
    raw = scans[0].points.view(np.uint8).reshape(-1, scans[0].points.dtype.itemsize)
    assert len(raw) > 100 and not raw[:, 27].any()
    assert scans[0].points.tobytes() == scans[1].points.tobytes()


@pytest.mark.parametrize("where", ["level", "tilted", "distorted", "rolled"])
def test_box_channel_culling_is_exact(
    straight: RoadScene, where: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Only the channels whose elevation can reach a box are intersected with it: the same scan as
    intersecting every channel, for boxes beside, above, below and around the sensor (tall ones, one the
    sensor sits inside, one out of range)."""
    speed, yaw_rate = (25.0, 0.3) if where == "distorted" else (0.0, 0.0)
    roll = 0.1 if where == "rolled" else 0.0
    ego = EntityState("Ego", "vehicle", "car", 50, -1.75, 0.0, 0.1, 0.0, roll, speed, 0.0, yaw_rate, CAR)
    tall = BoundingBox(0.0, 0.0, 6.0, 2.0, 2.0, 12.0)
    overhead = BoundingBox(0.0, 0.0, 0.0, 6.0, 12.0, 0.6)
    around = BoundingBox(0.0, 0.0, 1.0, 20.0, 20.0, 2.0)
    others = [
        car("Near", 55, -1.75),
        car("Beside", 50, -5.25),
        car("Behind", 30, -5.25, heading=0.4),
        car("Far", 140, -1.75),
        EntityState("Pole", "miscellaneous", "pole", 62, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, tall),
        EntityState(
            "Bridge", "miscellaneous", "none", 70, -1.75, 6.0, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0, overhead
        ),
        EntityState("Pit", "miscellaneous", "none", 45, -8.0, -3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, CAR),
    ]
    config: dict[str, object] = {"channels": 32, "horizontal_resolution": 360, "vertical_fov": [-30, 20]}
    config["motion_distortion"] = where == "distorted"
    if where == "tilted":
        config["mount"] = {"z": 1.8, "pitch": 5, "yaw": 20}
    for extra in (
        [],
        [EntityState("Hall", "miscellaneous", "none", 50, -1.75, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, around)],
    ):
        boxes = Boxes.of(frame(ego, *others, *extra))
        culled = lidar(**config).scan(straight, boxes, ego, 0)
        with monkeypatch.context() as m:
            m.setattr(Lidar, "_channels_of", lambda self, *args: None)
            m.setattr(kernels, "boxes_returns", every_box_ray)
            every = lidar(**config).scan(straight, boxes, ego, 0)
        assert len(culled.points) == len(every.points) > 100
        assert culled.points.tobytes() == every.points.tobytes()
        assert np.array_equal(culled.visible_rays, every.visible_rays)
        assert np.array_equal(culled.unoccluded_rays, every.unoccluded_rays)
        assert np.count_nonzero(culled.unoccluded_rays) >= 5


def every_box_ray(
    t: np.ndarray,
    cos_inc: np.ndarray,
    classes: np.ndarray,
    object_id: np.ndarray,
    centers: np.ndarray,
    rotations: np.ndarray,
    halves: np.ndarray,
    box_classes: np.ndarray,
    box_ids: np.ndarray,
    skip: int,
    pos: np.ndarray,
    rot: np.ndarray,
    r32: np.ndarray,
    dirs_t: np.ndarray,
    tan_elev: np.ndarray,
    columns: int,
    *_: object,
) -> None:
    """`kernels.boxes_returns` intersecting every box (but the carrier) with every ray of the sweep."""
    range_min, range_max, unoccluded = _[-3:]
    for i in range(len(centers)):
        unoccluded[i] = 0  # type: ignore[index]
        if i == skip:
            continue
        r = [float(centers[i, a] - pos[a]) for a in range(3)]
        o = np.array([-(r[0] * rotations[i, 0, a] + r[1] * rotations[i, 1, a] + r[2] * rotations[i, 2, a])
                      for a in range(3)])  # fmt: skip
        unoccluded[i] = kernels.box_returns(  # type: ignore[index]
            t, cos_inc, classes, object_id, np.arange(columns), np.arange(len(tan_elev)), len(tan_elev),
            dirs_t, r32, o, rotations[i], halves[i], range_min, range_max, box_classes[i], box_ids[i],
        )  # fmt: skip


# --- the compiled kernels against the numpy reference ----------------------------------------------------


def numpy_scan(
    self: Lidar, road: RoadScene, boxes: Boxes, carrier: EntityState, carrier_index: int
) -> LidarScan:
    """The numpy reference of `Lidar.scan` (its implementation before the numba kernels)."""
    cfg = self.config
    rot, pos = mount_pose(carrier, self.mount_rot, self.mount_pos)
    n_rays = len(self.dirs)
    r32 = rot.astype(np.float32)
    distort = cfg.motion_distortion and (carrier.speed != 0.0 or carrier.yaw_rate != 0.0)
    level_sweep = not distort and r32[2, 0] == 0.0 and r32[2, 1] == 0.0 and r32[2, 2] == 1.0
    # the road cast: only the rays that can reach the static scene, (K, 6) float32 for open3d
    if distort:
        # the ray layout with motion distortion was not replaced by a kernel: shared with `Lidar.scan`
        rays, cast, col_pos, origins, dirs_world = self._distorted_rays(road, carrier)
    elif level_sweep:
        # level (no pitch, no roll): a ray's world z component is its channel's, so the rays that can
        # reach the scene are whole channels; their index set, directions and ray buffer are cached
        kept = self._reachable(
            road, float(np.float32(pos[2])), self._dirs_t[2, : self.channels], pos[:2], pos[:2]
        )
        channels = np.arange(self.channels) if kept is None else kept
        cast = (np.arange(self.columns)[:, None] * self.channels + channels[None, :]).ravel()
        d0, d1, d2 = (row[cast] for row in self._dirs_t)
        rays = np.empty((len(cast), 6), np.float32)
        rays[:, 5] = d2  # level: the world z component is the sensor's
        for axis, value in enumerate(pos.astype(np.float32)):
            rays[:, axis] = value  # one scalar fill per column: faster than broadcasting the row
        for row, col in ((0, 3), (1, 4)):
            # r32[row, 2] is 0 for a level sensor (bar a float32 underflow): that term adds nothing
            a = d0 * r32[row, 0]
            a += d1 * r32[row, 1]
            if r32[row, 2] != 0.0:
                a += d2 * r32[row, 2]
            rays[:, col] = a
    else:
        dz = self._world_dirs(r32, None, range(2, 3))[0]
        cast = self._reachable(road, float(np.float32(pos[2])), dz, pos[:2], pos[:2])
        rays = self._ray_array(n_rays if cast is None else len(cast), pos)
        dx, dy = self._world_dirs(r32, cast, range(2))
        rays[:, 3] = dx
        rays[:, 4] = dy
        rays[:, 5] = dz if cast is None else dz[cast]
    t_cast, normals, classes_cast = road.cast(rays)
    # |cos(incidence)| of the road returns: direction . normal (a miss has a zero normal)
    cos_cast = rays[:, 3] * normals[:, 0]
    cos_cast += rays[:, 4] * normals[:, 1]
    cos_cast += rays[:, 5] * normals[:, 2]
    np.abs(cos_cast, out=cos_cast)
    if cast is None:
        t, classes, cos_inc = t_cast, classes_cast, cos_cast
    else:
        t = np.full(n_rays, np.inf, np.float32)
        t[cast] = t_cast
        classes = np.zeros(n_rays, np.uint8)
        classes[cast] = classes_cast
        cos_inc = np.zeros(n_rays, np.float32)
        cos_inc[cast] = cos_cast
    object_id = np.zeros(n_rays, np.uint32)
    nbox = len(boxes.names)
    unoccluded = np.zeros(nbox, np.int64)
    reach = cfg.range_max
    if nbox:
        rel = boxes.centers - pos
        radius = np.linalg.norm(boxes.half, axis=1)
        near = np.linalg.norm(rel, axis=1) - radius <= reach
        widen: float | None = 0.0  # how far the rays' origins are from `pos` horizontally; None: not level
        if distort:
            shift = np.hypot(*carrier.velocity) * self.period
            level = self._mount_level and carrier.pitch == 0.0 and carrier.roll == 0.0
            widen = float(np.max(np.hypot(*(col_pos[:, :2] - pos[:2]).T))) if level else None
        for i in np.flatnonzero(near):
            if i == carrier_index:
                continue  # a sensor does not see its own carrier
            corners = (boxes.corners(int(i)) - pos) @ rot
            pad = 1
            if distort:
                dist = max(float(np.linalg.norm(rel[i])) - float(radius[i]), 0.5)
                pad += math.ceil((shift / dist + abs(carrier.yaw_rate) * self.period) / self.col_width)
            cols = self._columns_of(corners, pad)
            chans = None if widen is None else self._channels_of(corners, widen)
            if cols is None and chans is None:
                idx = np.arange(n_rays)
            else:
                if cols is None:
                    cols = np.arange(self.columns)
                if chans is None:
                    chans = np.arange(self.channels)
                idx = (cols[:, None] * self.channels + chans[None, :]).ravel()
            if not len(idx):
                continue
            if distort:
                dw = dirs_world[idx]
                tb, nb = intersect_box(origins[idx], dw, boxes.centers[i], boxes.rotations[i], boxes.half[i])
                cos_box = np.abs(np.einsum("ij,ij->i", dw, nb.astype(np.float32)))
            else:
                tb, cos_box = intersect_box_rows(
                    pos, self._world_dirs(r32, idx), boxes.centers[i], boxes.rotations[i], boxes.half[i]
                )
            in_range = (tb >= cfg.range_min) & (tb <= cfg.range_max)
            unoccluded[i] = int(np.count_nonzero(in_range))
            closer = tb < t[idx]
            if np.any(closer):
                sel = idx[closer]
                t[sel] = tb[closer]
                cos_inc[sel] = cos_box[closer]
                classes[sel] = boxes.classes[i]
                object_id[sel] = boxes.ids[i]
    idx = np.flatnonzero((t >= cfg.range_min) & (t <= cfg.range_max))
    ids = object_id[idx]
    visible = np.bincount(ids, minlength=nbox + 1)[1 : nbox + 1]
    if cfg.dropout > 0.0:
        kept = self.rng.random(n_rays, dtype=np.float32)[idx] >= cfg.dropout
        idx = idx[kept]
        ids = ids[kept]
    rng_t = t[idx]
    if cfg.range_noise > 0.0:
        noise = self.rng.standard_normal(len(idx), dtype=np.float32)
        noise *= cfg.range_noise
        noise += rng_t
        rng_t = np.maximum(noise, 0.0, out=noise)
    cls = classes[idx]
    points = np.zeros(len(idx), POINT_DTYPE)  # zeros: the padding byte too (reproducible files)
    if distort:
        world = origins[idx] + dirs_world[idx] * rng_t[:, None]
        local = (world - pos) @ rot
        points["time"] = np.repeat(self.column_time, self.channels)[idx]
        points["x"] = local[:, 0]
        points["y"] = local[:, 1]
        points["z"] = local[:, 2]
    else:  # time: 0 (the zeros)
        points["x"] = self._dirs_t[0, idx] * rng_t
        points["y"] = self._dirs_t[1, idx] * rng_t
        points["z"] = self._dirs_t[2, idx] * rng_t
    points["intensity"] = road.reflectivity[cls] * cos_inc[idx]
    points["object_id"] = ids
    points["ring"] = self.ring[idx]
    points["label"] = cls
    counts = np.bincount(ids, minlength=nbox + 1)[1 : nbox + 1]
    points.flags.writeable = False  # immutable: messages and recordings reference it without a copy
    return LidarScan(
        points=points, object_points=counts, visible_rays=visible, unoccluded_rays=unoccluded, rays=n_rays
    )


@pytest.mark.parametrize(
    "where",
    ["level", "tilted", "distorted", "rolled", "hill", "fov", "plain", "noise", "dropout", "empty", "pole"],
)
def test_scan_equals_the_numpy_reference(straight: RoadScene, where: str) -> None:
    """`Lidar.scan` (numba kernels) gives the cloud the numpy passes gave, bit for bit (intensity within one
    float32 ulp), the same per-object counts, and draws the same random numbers, sweep after sweep."""
    scene = {
        "hill": lambda: RoadScene(OpenDrive.from_string(HILL)),
        "empty": lambda: RoadScene(None),
        "pole": lambda: RoadScene(
            OpenDrive.from_string(STRAIGHT),
            scenery=[
                StaticObject(
                    "pole",
                    CLASS_IDS["pole"],
                    np.array([70.0, 1.0, 6.0]),
                    np.eye(3),
                    np.array([0.3, 0.3, 6.0]),
                )
            ],
        ),
    }.get(where, lambda: straight)()
    config: dict[str, object] = {
        "channels": 32,
        "horizontal_resolution": 360,
        "vertical_fov": [-30, 20],
        "range_noise": 0.0 if where in ("plain", "dropout") else 0.05,
        "dropout": 0.0 if where in ("plain", "noise") else 0.1,
        "motion_distortion": where == "distorted",
    }
    if where == "tilted":
        config["mount"] = {"z": 1.8, "pitch": 5, "yaw": 20}
    if where == "fov":
        config["horizontal_fov"] = 120.0
    speed, yaw_rate = (25.0, 0.3) if where == "distorted" else (0.0, 0.0)
    roll = 0.1 if where == "rolled" else 0.0
    z = 0.002 * 150**2 if where == "hill" else 0.0
    compiled, reference = lidar(**config), lidar(**config)
    for sweep in range(3):
        x = (150.0 if where == "hill" else 50.0) + 2.5 * sweep
        ego = EntityState("Ego", "vehicle", "car", x, -1.75, z, 0.1, 0.0, roll, speed, 0.0, yaw_rate, CAR)
        others = [
            EntityState("Near", "vehicle", "car", x + 6, -1.75, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, CAR),
            car("Beside", x, -5.25),
            car("Behind", x - 20, -5.25, heading=0.4),
            car("Far", x + 90, -1.75),
        ]
        boxes = Boxes.of(frame(ego, *others))
        got = compiled.scan(scene, boxes, ego, 0)
        want = numpy_scan(reference, scene, boxes, ego, 0)
        assert len(got.points) == len(want.points) > (0 if where == "empty" else 100)
        for name in got.points.dtype.names or ():
            if name != "intensity":
                assert got.points[name].tobytes() == want.points[name].tobytes(), (sweep, name)
        ulps = got.points["intensity"].view(np.int32).astype(np.int64) - want.points["intensity"].view(
            np.int32
        )
        assert np.abs(ulps).max(initial=0) <= 1
        assert not got.points.view(np.uint8).reshape(-1, POINT_DTYPE.itemsize)[:, 27].any()
        assert np.array_equal(got.object_points, want.object_points)
        assert np.array_equal(got.visible_rays, want.visible_rays)
        assert np.array_equal(got.unoccluded_rays, want.unoccluded_rays)
        assert got.rays == want.rays
        assert compiled.rng.bit_generator.state == reference.rng.bit_generator.state


@pytest.mark.parametrize("fov", [360.0, 100.0])
def test_column_culling_is_exact_on_the_curved_highway(monkeypatch: pytest.MonkeyPatch, fov: float) -> None:
    """A level sweep casts, per column, only the channels that can meet a triangle the column spans: on the
    curved highway (in and out of the curves, across lanes, turned against the road, a limited field of
    view on a yawed mount) the scan is the one casting every ray gives, and far fewer rays are cast."""
    road = OpenDrive.from_file(HIGHWAY)
    scene = RoadScene(road)
    config: dict[str, object] = {
        "channels": 32,
        "horizontal_resolution": round(720 * fov / 360),
        "horizontal_fov": fov,
        "vertical_fov": [-25, 10],
        "range_max": 80.0,
        "mount": {"x": 1.0, "z": 1.9, "yaw": 0.0 if fov == 360 else 35.0},
    }
    cast_sizes = count_casts(monkeypatch)
    for s, lane, turn in ((300.0, -1, 0.0), (700.0, -2, 0.7), (1500.0, -3, -2.0), (1100.0, -4, math.pi)):
        p = road.lane_to_world("1", lane, s)
        ego = car("Ego", p.x, p.y, heading=p.heading + turn)
        ego = ego.replace(z=p.z)
        ahead = car(
            "Ahead", p.x + 12 * math.cos(p.heading), p.y + 12 * math.sin(p.heading), heading=p.heading
        )
        boxes = Boxes.of(frame(ego, ahead))
        culled = lidar(**config).scan(scene, boxes, ego, 0)
        with monkeypatch.context() as m:
            m.setattr(Lidar, "_level_rays", every_level_ray)
            every = lidar(**config).scan(scene, boxes, ego, 0)
        assert cast_sizes[-1] == culled.rays and cast_sizes[-2] < culled.rays * 0.6, (s, cast_sizes[-2:])
        assert len(culled.points) == len(every.points) > 100
        assert culled.points.tobytes() == every.points.tobytes(), (s, lane, turn)
        assert np.array_equal(culled.visible_rays, every.visible_rays)
        assert np.array_equal(culled.unoccluded_rays, every.unoccluded_rays)


def test_triangle_groups_and_grid_cover_every_triangle() -> None:
    """The culling's groups are runs of consecutive triangles within 5 m of their centre, and the xy grid
    lists every group in every cell its bounding box meets."""
    from simcore.sensors.scene import triangle_groups, xy_grid

    scene = RoadScene(OpenDrive.from_file(HIGHWAY))
    start = scene.group_start
    assert start[0] == 0 and start[-1] == scene.triangle_count and np.all(np.diff(start) >= 1)
    assert len(start) - 1 < scene.triangle_count / 4  # neighbours do group
    lo, hi = scene.corners.min(axis=1), scene.corners.max(axis=1)
    for g in range(len(start) - 1):
        a, b = lo[start[g] : start[g + 1]].min(axis=0), hi[start[g] : start[g + 1]].max(axis=0)
        assert np.hypot(*(b - a)[:2]) <= 10.0 + 1e-9
        assert scene.groups[g, 2] >= np.hypot(*(b - a)[:2]) / 2
    grid, cell_start, cell_groups = xy_grid(lo, hi, cell=50.0)
    x0, y0, size, _nx, ny = grid
    for j in (0, 17, scene.triangle_count - 1):
        for x in (lo[j, 0], hi[j, 0]):
            for y in (lo[j, 1], hi[j, 1]):
                cell = int((x - x0) // size) * int(ny) + int((y - y0) // size)
                assert j in cell_groups[cell_start[cell] : cell_start[cell + 1]]
    assert list(triangle_groups(np.zeros((0, 3)), np.zeros((0, 3)))) == [0]
    far = np.array([[0.0, 0.0, 0.0], [99_000.0, 99_000.0, 0.0]])  # a 99 km map: the cells grow
    grid, cell_start, cell_groups = xy_grid(far, far + 1.0)
    assert grid[3] * grid[4] <= 1.01 * 2**20 and len(cell_start) == grid[3] * grid[4] + 1
    assert set(cell_groups) == {0, 1}


@pytest.mark.slow
def test_kernels_load_from_a_seeded_cache(tmp_path: Path) -> None:
    """An image compiles the kernels at build time (generic CPU) into a read-only seed; a pod with an empty
    NUMBA_CACHE_DIR copies it and loads every kernel from it: no compilation."""
    import os
    import subprocess
    import sys

    count = (
        "from simcore.sensors import kernels; kernels.warm(); "
        "print(sum(sum(getattr(kernels, n).stats.cache_misses.values()) for n in dir(kernels) "
        "if hasattr(getattr(kernels, n), 'stats')))"
    )
    env = {**os.environ, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp_path / "seed")}
    env.pop("CARLOS_NUMBA_CACHE_SEED", None)
    built = subprocess.run([sys.executable, "-c", count], env=env, capture_output=True, text=True, check=True)
    assert int(built.stdout.split()[-1]) > 0  # compiled into the seed
    (tmp_path / "seed").chmod(0o555)
    env.update(NUMBA_CACHE_DIR=str(tmp_path / "pod"), CARLOS_NUMBA_CACHE_SEED=str(tmp_path / "seed"))
    pod = subprocess.run([sys.executable, "-c", count], env=env, capture_output=True, text=True, check=True)
    assert int(pod.stdout.split()[-1]) == 0, pod.stderr
    assert any((tmp_path / "pod").rglob("*.nbi"))


@pytest.mark.parametrize("name", ["multi_intersections", "crest-curve"])
def test_column_culling_is_exact_on_corpus_roads(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Junctions full of short curved lanes, a crest on a curve: from random poses on the road (random
    heading, mount yaw, 360° or 90° field of view) a level sweep gives the cloud casting every ray gives."""
    scene = RoadScene(OpenDrive.from_file(corpus_dir() / "resources" / "xodr" / f"{name}.xodr"))
    rng = np.random.default_rng(7)
    cast_sizes = count_casts(monkeypatch)
    seen = 0
    for _ in range(5):
        p = scene.corners[rng.integers(len(scene.corners))].mean(axis=0)
        for fov in (360.0, 90.0):
            config = {
                "channels": 32,
                "horizontal_resolution": round(720 * fov / 360),
                "horizontal_fov": fov,
                "vertical_fov": [-25, 10],
                "range_max": 100.0,
                "mount": {"x": 1.0, "z": 1.9, "yaw": float(rng.uniform(-90, 90))},
            }
            ego = car("Ego", p[0], p[1], heading=float(rng.uniform(-3, 3))).replace(z=float(p[2]))
            boxes = Boxes.of(frame(ego, car("Other", p[0] + 8, p[1] + 3)))
            culled = lidar(**config).scan(scene, boxes, ego, 0)
            with monkeypatch.context() as m:
                m.setattr(Lidar, "_level_rays", every_level_ray)
                every = lidar(**config).scan(scene, boxes, ego, 0)
            assert cast_sizes[-2] < cast_sizes[-1] == culled.rays
            assert culled.points.tobytes() == every.points.tobytes()
            assert np.array_equal(culled.visible_rays, every.visible_rays)
            seen += len(culled.points)
    assert seen > 20_000


# --- roadside units' sensors ---------------------------------------------------------------------------


@pytest.mark.parametrize("mount", ["level", "tilted"])
def test_culling_is_exact_for_a_roadside_lidar(monkeypatch: pytest.MonkeyPatch, mount: str) -> None:
    """A lidar on a roadside unit (a stationary stand-in carrier with no box, 6 m up a mast beside the
    curved highway, level or pitched down 15°) culls rays and boxes exactly: the scan is the one casting every
    ray and intersecting every box with every ray gives; the level sweep still casts far fewer rays."""
    from simcore.world.infrastructure import UnitPose

    road = OpenDrive.from_file(HIGHWAY)
    scene = RoadScene(road)
    side = road.road_to_world("1", 1200.0, -18.0)
    unit = UnitPose("rsu", 0, side.x, side.y, side.z, 6.0, side.heading + 0.3).carrier()
    config: dict[str, object] = {
        "channels": 32,
        "horizontal_resolution": 720,
        "vertical_fov": [-30, 10],
        "range_max": 100.0,
        "mount": {"z": 6.0, "pitch": 15.0 if mount == "tilted" else 0.0},
    }
    cars = []
    for k, (lane, ds) in enumerate(((-1, -30.0), (-2, 5.0), (-3, 25.0), (-4, -10.0), (-1, 60.0))):
        p = road.lane_to_world("1", lane, 1200.0 + ds)
        cars.append(car(f"c{k}", p.x, p.y, heading=p.heading).replace(z=p.z))
    boxes = Boxes.of(frame(*cars))
    cast_sizes = count_casts(monkeypatch)
    culled = lidar(**config).scan(scene, boxes, unit, -1)
    with monkeypatch.context() as m:
        m.setattr(Lidar, "_reachable", lambda self, *args: None)
        m.setattr(Lidar, "_level_rays", every_level_ray)
        m.setattr(Lidar, "_channels_of", lambda self, *args: None)
        m.setattr(kernels, "boxes_returns", every_box_ray)
        every = lidar(**config).scan(scene, boxes, unit, -1)
    assert cast_sizes[-1] == culled.rays
    assert len(culled.points) == len(every.points) > 1000
    for name in culled.points.dtype.names or ():
        assert np.allclose(culled.points[name], every.points[name], rtol=0, atol=1e-6), name
    assert np.array_equal(culled.visible_rays, every.visible_rays)
    assert np.array_equal(culled.unoccluded_rays, every.unoccluded_rays)
    assert np.count_nonzero(culled.object_points) == len(cars)  # it sees every car, none is its own
    if mount == "level":
        assert cast_sizes[-2] < culled.rays * 0.5, cast_sizes[-2:]


def test_rig_runs_a_roadside_units_sensors_from_its_pose() -> None:
    """Sensors of `spec.infrastructure[]`: topics under /carlos/infrastructure/<unit>/, frames
    `<unit>/<sensor>` with a static transform from `map` at the unit's pose and mount, ground truth in that
    frame, and the same cloud as a lidar with that pose on a standing vehicle."""
    from simcore.world.infrastructure import unit_pose

    spec = SimulationRunSpec.model_validate(
        {
            "scenarios": [{"name": "s", "openscenario": "x.xosc"}],
            "infrastructure": [
                {
                    "name": "rsu",
                    "position": {"x": 60.0, "y": 8.0},
                    "yaw": 90.0,
                    "sensors": [
                        {"type": "lidar", "name": "top", "channels": 8, "mount": {"z": 6.0, "pitch": 10}},
                        {"type": "camera", "name": "cam", "width": 16, "height": 8, "mount": {"z": 5.0}},
                    ],
                }
            ],
        }
    )
    rsu = spec.infrastructure[0]
    pose = unit_pose(rsu, 0, None, {})
    road = OpenDrive.from_string(STRAIGHT)
    bus = InProcessBus()
    seen: list[Message] = []
    bus.subscribe("*", seen.append)
    rig = SensorRig([], road, bus, seed=0, units=[(pose, rsu.sensors)])
    cars = (car("Ego", 50, -1.75), car("B", 70, -1.75))
    for step in range(3):
        rig.step(WorldFrame(step, step * 0.1, cars, ego="Ego"))
    topics = [m.topic for m in seen]
    assert topics.count("/carlos/infrastructure/rsu/top/points") == 3
    assert topics.count("/carlos/infrastructure/rsu/top/objects") == 3
    assert topics.count("/carlos/infrastructure/rsu/cam/image") == 3
    assert topics.count("/carlos/infrastructure/rsu/top/label_info") == 1
    tf = next(m.msg for m in seen if m.topic == "/tf_static")
    by_child = {t.child_frame_id: t for t in tf.transforms}
    assert by_child["rsu/top"].header.frame_id == "map"
    assert by_child["rsu/cam_optical"].header.frame_id == "rsu/cam"
    top = by_child["rsu/top"].transform.translation
    assert (top.x, top.y, top.z) == pytest.approx((60.0, 8.0, 6.0))
    points = next(m.msg for m in seen if m.topic == "/carlos/infrastructure/rsu/top/points")
    assert points.header.frame_id == "rsu/top"
    cloud = ros.read_pointcloud2(points)
    assert {1, 2} <= set(cloud["object_id"].tolist())  # both cars, from the mast
    objects = next(m.msg for m in seen if m.topic == "/carlos/infrastructure/rsu/top/objects")
    assert len(objects.detections) == 2
    # ground truth in the sensor frame: the box centre seen from the mast's pose
    rot, pos = mount_pose(pose.carrier(), rig.sensors[0].model.mount_rot, rig.sensors[0].model.mount_pos)  # type: ignore[union-attr]
    want = (Boxes.of(frame(*cars)).centers[1] - pos) @ rot
    got = next(d for d in objects.detections if d.id == "B").bbox.center.position
    assert (got.x, got.y, got.z) == pytest.approx(tuple(want))
    for m in seen:  # every message serialises
        assert deserialize(serialize(m.msg), m.typename) is not None


def test_spec_roadside_sensors_stand_on_the_unit() -> None:
    unit = {"name": "rsu", "position": {"x": 0, "y": 0}}
    spec = _spec(infrastructure=[{**unit, "sensors": [{"type": "lidar", "name": "top"}]}])
    assert isinstance(spec.infrastructure[0].sensors[0], LidarSensor)
    with pytest.raises(ValidationError, match="stands on the unit; leave out entity"):
        _spec(infrastructure=[{**unit, "sensors": [{"type": "lidar", "name": "top", "entity": "Ego"}]}])
    with pytest.raises(ValidationError, match="sensor name 'top' is used twice"):
        _spec(infrastructure=[{**unit, "sensors": [{"type": "lidar", "name": "top"}] * 2}])
