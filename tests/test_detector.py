"""The example detector (examples/detector): the pipeline on synthetic clouds, the node on a bus, the
program, and the perception example end to end (recall and precision from real matches; a broken
detector fails its criterion with exit code 1)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
import yaml

from examples.detector import Detector, DetectorParams, detect
from examples.detector.detect import cluster, fit_ground
from simcore.errors import BadInput
from simcore.sensors import ros
from simcore.sensors.lidar import Lidar
from simcore.sensors.scene import Boxes, RoadScene
from simcore.spec import LidarSensor
from simcore.transport.bus import InProcessBus, Message
from simcore.world.opendrive import OpenDrive
from simcore.world.state import BoundingBox, EntityState, WorldFrame

ROOT = Path(__file__).resolve().parent.parent
CARLOS = [sys.executable, "-m", "simcore.cli"]
CAR = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)


def car(name: str, x: float, y: float, heading: float = 0.0) -> EntityState:
    return EntityState(name, "vehicle", "car", x, y, 0.0, heading, 0.0, 0.0, 0.0, 0.0, 0.0, CAR)


@pytest.fixture(scope="module")
def highway() -> RoadScene:
    return RoadScene(OpenDrive.from_file(ROOT / "examples" / "maps" / "highway.xodr"))


def scan_of(road: RoadScene, *entities: EntityState) -> np.ndarray:
    frame = WorldFrame(0, 0.0, entities, ego=entities[0].name)
    lidar = Lidar(
        LidarSensor(type="lidar", name="lidar", channels=64, vertical_fov=(-25, 10), mount={"x": 1.4}), seed=0
    )
    return lidar.scan(road, Boxes.of(frame), entities[0], 0).points


def test_ground_plane_and_clusters() -> None:
    rng = np.random.default_rng(0)
    ground = np.column_stack(
        [rng.uniform(-30, 30, 3000), rng.uniform(-30, 30, 3000), rng.normal(-2.0, 0.01, 3000)]
    )
    plane = fit_ground(ground, DetectorParams())
    assert (
        plane is not None
        and plane[:3] == pytest.approx([0, 0, 1], abs=0.01)
        and plane[3] == pytest.approx(2.0, abs=0.02)
    )
    a = rng.uniform(0, 1, (50, 2))
    b = rng.uniform(0, 1, (50, 2)) + np.array([5.0, 0.0])
    labels = cluster(np.vstack([a, b]), 0.8)
    assert len(set(labels[:50])) == 1 and len(set(labels[50:])) == 1 and labels[0] != labels[50]


def test_detects_the_cars_around_the_sensor(highway: RoadScene) -> None:
    ego = car("Ego", 100, -5.25)
    others = [car("Ahead", 125, -5.25), car("Left", 110, -1.75), car("Behind", 80, -8.75)]
    points = scan_of(highway, ego, *others)
    xyz = np.stack([points["x"], points["y"], points["z"]], axis=1)
    boxes = detect(xyz)
    assert len(boxes) == 3
    assert {b.label for b in boxes} == {"car"}
    # the truth in the sensor frame (sensor at x = 1.4 on the rear axle, 2 m up): box centre x + 1.4 - 1.4
    truth = [(125 - 100, 0.0), (110 - 100, 3.5), (80 - 100, -3.5)]
    for tx, ty in truth:
        best = min(boxes, key=lambda b: math.hypot(b.x - tx, b.y - ty))
        assert math.hypot(best.x - tx, best.y - ty) < 0.5
        assert best.length == pytest.approx(4.5, abs=0.3) and best.width == pytest.approx(1.85, abs=0.2)
        assert abs(math.sin(best.yaw)) < 0.1
        assert best.height == pytest.approx(1.5, abs=0.1)


def test_nothing_on_an_empty_road(highway: RoadScene) -> None:
    points = scan_of(highway, car("Ego", 100, -5.25))
    assert detect(np.stack([points["x"], points["y"], points["z"]], axis=1)) == []
    assert detect(np.zeros((0, 3))) == []


def test_node_answers_every_cloud_on_the_bus(highway: RoadScene) -> None:
    bus = InProcessBus()
    out: list[Message] = []
    bus.subscribe("/out", out.append)
    node = Detector(bus, input_topic="/in", output_topic="/out", min_points=3)
    points = scan_of(highway, car("Ego", 100, -5.25), car("Ahead", 120, -5.25))
    bus.advertise("/in", ros.POINTCLOUD2).publish(ros.pointcloud2(points, 2.5, "Ego/lidar"), 2.5)
    assert node.clouds == 1 and len(out) == 1
    msg = out[0].msg
    assert out[0].typename == "vision_msgs/msg/Detection3DArray"
    assert msg.header.frame_id == "Ego/lidar" and msg.header.stamp.sec == 2
    assert len(msg.detections) == 1 and msg.detections[0].results[0].hypothesis.class_id == "car"
    with pytest.raises(TypeError):
        Detector(bus, no_such_parameter=1)


def _manifest(tmp_path: Path, name: str, **changes: object) -> Path:
    data = yaml.safe_load((ROOT / "examples" / "runs" / "perception.yaml").read_text())
    data["metadata"]["name"] = name
    data["spec"]["scenarios"][0]["openscenario"] = str(ROOT / "examples" / "scenarios" / "cut-in.xosc")
    data["spec"]["systemUnderTest"]["pythonPath"] = [str(ROOT)]
    data["spec"]["output"]["url"] = f"file://{tmp_path}/results"
    for path, value in changes.items():
        node = data["spec"]
        *parents, leaf = path.split(".")
        for key in parents:
            node = node[key]
        node[leaf] = value
    target = tmp_path / f"{name}.yaml"
    target.write_text(yaml.safe_dump(data))
    return target


def test_perception_example_scores_real_matches(tmp_path: Path) -> None:
    manifest = _manifest(tmp_path, "perception")
    done = subprocess.run(
        [*CARLOS, "run", str(manifest)], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads((tmp_path / "results" / "perception" / "0" / "summary.json").read_text())
    m = summary["metrics"]
    tp, fp, fn = m["detection.truePositives"], m["detection.falsePositives"], m["detection.falseNegatives"]
    assert m["detection.frames"] > 100 and tp > 100
    assert m["detection.recall"] == pytest.approx(tp / (tp + fn)) and m["detection.recall"] >= 0.9
    assert m["detection.precision"] == pytest.approx(tp / (tp + fp)) and m["detection.precision"] >= 0.9
    assert 0.5 < m["detection.meanIou"] <= 1.0 and m["detection.meanCenterError"] < 1.0
    assert (
        m["detection.truePositives.0-30m"]
        + m["detection.truePositives.30-60m"]
        + m["detection.truePositives.60-80m"]
        == tp
    )
    assert all(c["passed"] for c in summary["criteria"])
    # the recording holds the clouds, the truth and the detections next to each other
    from rosbags.highlevel import AnyReader

    from simcore.transport.messages import TYPESTORE

    with AnyReader(
        [tmp_path / "results" / "perception" / "0" / "recording.mcap"], default_typestore=TYPESTORE
    ) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
        wanted = [c for c in r.connections if c.topic == "/carlos/evaluation/detection"]
        scored = [
            {kv.key: kv.value for kv in r.deserialize(raw, c.msgtype).values}
            for c, _, raw in r.messages(connections=wanted)
        ]
    # every sweep's score is recorded, and they add up to the run's metrics
    assert len(scored) == m["detection.frames"]
    assert sum(int(v["truePositives"]) for v in scored) == tp
    assert sum(int(v["falsePositives"]) for v in scored) == fp
    assert counts["/carlos/Ego/lidar/points"] == counts["/carlos/sut/detections"] == m["detection.frames"]
    assert counts["/carlos/Ego/lidar/objects"] == m["detection.frames"] and counts["/tf_static"] == 1

    # the program replays the recording's clouds through the detector
    replay = subprocess.run(
        [
            sys.executable,
            "-m",
            "examples.detector",
            "--replay",
            str(tmp_path / "results/perception/0/recording.mcap"),
            "--record",
            str(tmp_path / "d.mcap"),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert replay.returncode == 0, replay.stderr
    assert (
        f"{int(m['detection.frames'])} clouds" in replay.stdout and (tmp_path / "d.mcap").stat().st_size > 0
    )


def test_broken_detector_fails_its_criterion(tmp_path: Path) -> None:
    # a detector that needs 100000 points per object never reports anything
    manifest = _manifest(
        tmp_path, "broken", **{"systemUnderTest.parameters.min_points": 100_000, "simulation.maxSeconds": 3}
    )
    done = subprocess.run(
        [*CARLOS, "run", str(manifest)], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 1, done.stdout + done.stderr
    summary = json.loads((tmp_path / "results" / "broken" / "0" / "summary.json").read_text())
    assert summary["status"] == "failed"
    failed = {c["metric"]: c for c in summary["criteria"] if not c["passed"]}
    assert (
        summary["metrics"]["detection.falseNegatives"] > 0
        and summary["metrics"]["detection.truePositives"] == 0
    )
    assert summary["metrics"]["detection.recall"] == 0.0
    assert "detection.recall" in failed and "detection.recall.0-50m" in failed


def test_unimportable_system_under_test_is_bad_input(tmp_path: Path) -> None:
    manifest = _manifest(
        tmp_path, "missing", **{"systemUnderTest.module": "no_such_package.detector:Detector"}
    )
    done = subprocess.run(
        [*CARLOS, "run", str(manifest)], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 2, done.stdout + done.stderr  # bad input, found before any run
    assert "Traceback" not in done.stderr
    assert "spec.systemUnderTest.module: cannot import 'no_such_package.detector'" in done.stderr
    assert not (tmp_path / "results" / "missing" / "0").exists()


class Exploding:
    """A node under test that fails on its third point cloud."""

    def __init__(self, bus: object, input_topic: str = "/carlos/Ego/lidar/points") -> None:
        self.clouds = 0
        self.publisher = bus.advertise("/carlos/sut/detections", "vision_msgs/msg/Detection3DArray")  # type: ignore[attr-defined]
        bus.subscribe(input_topic, self.on_points)  # type: ignore[attr-defined]

    def on_points(self, message: Message) -> None:
        self.clouds += 1
        if self.clouds == 3:
            raise RuntimeError("segmentation fault in the clustering")
        from examples.detector.node import detections_message

        self.publisher.publish(detections_message([], message.obj().header), message.time_s)


def test_a_crash_of_the_system_under_test_is_a_test_result(tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader

    from simcore.manifest import load_manifest
    from simcore.pipeline import simulate
    from simcore.plan import Plan
    from simcore.transport.messages import TYPESTORE

    manifest = _manifest(
        tmp_path,
        "exploding",
        **{
            "systemUnderTest.module": "tests.test_detector:Exploding",
            "systemUnderTest.parameters": {},
            "simulation.maxSeconds": 1,
        },
    )
    run = load_manifest(manifest)
    out = tmp_path / "out"
    ran = simulate(run, Plan(run.spec)[0], ROOT / "examples/scenarios/cut-in.xosc", out, base_dir=tmp_path)
    sim, metrics, log = ran.sim_seconds, ran.metrics, ran.log
    assert sim == pytest.approx(1.0)
    assert metrics["systemUnderTest.failed"] == 1.0
    assert metrics["detection.frames"] == 11 and metrics["detection.truePositives"] == 0
    assert any("system under test failed: RuntimeError: segmentation fault" in line for line in log)
    with AnyReader([out / "recording.mcap"], default_typestore=TYPESTORE) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
        status = [
            r.deserialize(raw, c.msgtype)
            for c, _, raw in r.messages()
            if c.topic == "/carlos/detector/status"
        ]
    assert counts["/carlos/sut/detections"] == 2, "the node got nothing after its failure"
    assert counts["/carlos/Ego/lidar/points"] == 11
    assert len(status) == 1 and status[0].level == 2 and "segmentation fault" in status[0].message


class EnvReader:
    """A node under test that notes the environment it was constructed in."""

    seen: ClassVar[dict[str, str | None]] = {}

    def __init__(self, bus: object) -> None:
        EnvReader.seen = {name: os.environ.get(name) for name in ("MODEL", "LICENSE_KEY")}


def test_system_under_test_env_is_set_for_the_in_process_node(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Locally `env` values are set in the run's process while the node lives; a `secretKeyRef` comes from
    the variable of the same name in the environment of `carlos run` (bad input naming the field and what to
    export when it is not there); the process environment is restored after the run."""
    from simcore.manifest import load_manifest
    from simcore.pipeline import simulate
    from simcore.plan import Plan

    env = [
        {"name": "MODEL", "value": "/models/tiny.onnx"},
        {"name": "LICENSE_KEY", "secretKeyRef": {"name": "detector-license", "key": "key"}},
    ]
    manifest = _manifest(
        tmp_path,
        "envs",
        **{
            "systemUnderTest.module": "tests.test_detector:EnvReader",
            "systemUnderTest.parameters": {},
            "systemUnderTest.env": env,
            "simulation.maxSeconds": 0.2,
        },
    )
    run = load_manifest(manifest)
    scenario = ROOT / "examples/scenarios/cut-in.xosc"
    monkeypatch.delenv("MODEL", raising=False)
    monkeypatch.delenv("LICENSE_KEY", raising=False)
    with pytest.raises(BadInput) as info:
        simulate(run, Plan(run.spec)[0], scenario, tmp_path / "a", base_dir=tmp_path)
    assert info.value.field == "spec.systemUnderTest.env[1].secretKeyRef"
    assert "export LICENSE_KEY=" in str(info.value) and "MODEL" not in os.environ
    monkeypatch.setenv("LICENSE_KEY", "s3cret")
    simulate(run, Plan(run.spec)[0], scenario, tmp_path / "b", base_dir=tmp_path)
    assert EnvReader.seen == {"MODEL": "/models/tiny.onnx", "LICENSE_KEY": "s3cret"}
    assert "MODEL" not in os.environ and os.environ["LICENSE_KEY"] == "s3cret"
