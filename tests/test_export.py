"""`carlos export`: parquet (one row per index) and KITTI (lidar frames, labels, calibration)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from simcore.export import calib_text, index_rows, kitti_label
from tests.test_cli import ROOT, carlos

CUT_IN = (ROOT / "examples" / "scenarios" / "cut-in.xosc").as_uri()


@pytest.fixture(scope="module")
def lidar_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("kitti")
    manifest = tmp / "sweep.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: lidar-sweep}\nspec:\n"
        f"  scenarios: [{{name: cut-in, openscenario: '{CUT_IN}'}}]\n"
        "  sweep: {matrix: {EgoSpeed: [20.0, 24.0]}}\n"
        "  simulation: {stepSeconds: 0.05, maxSeconds: 1.0}\n"
        "  sensors:\n    - {type: lidar, name: top, entity: Ego, mount: {x: 1.0, z: 1.8, yaw: 90},"
        " channels: 8, verticalFov: [-15, 5], horizontalResolution: 180, rotationRate: 10}\n"
        "  recording: {enabled: true}\n"
    )
    result = carlos("run", manifest, "--output", f"file://{tmp}/out", "-j", "2")
    assert result.returncode == 0, result.stderr
    return tmp / "out" / "lidar-sweep"


def test_parquet_has_one_row_per_index(lidar_sweep: Path, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    done = carlos("export", lidar_sweep.as_uri(), "--format", "parquet", "--out", tmp_path / "runs.parquet")
    assert done.returncode == 0, done.stderr
    table = pq.read_table(tmp_path / "runs.parquet").to_pylist()
    assert [r["index"] for r in table] == [0, 1]
    assert [r["param.EgoSpeed"] for r in table] == [20.0, 24.0]
    assert all(r["status"] == "passed" and r["metric.maxSpeed"] > 0 and r["seed"] is not None for r in table)


def test_kitti_frames_labels_and_calibration(lidar_sweep: Path, tmp_path: Path) -> None:
    done = carlos("export", lidar_sweep.as_uri(), "--format", "kitti", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    for index in (0, 1):
        folder = tmp_path / "lidar-sweep" / str(index) / "Ego_top"
        bins = sorted((folder / "velodyne").glob("*.bin"))
        assert len(bins) >= 9  # 10 Hz over 1 s
        points = np.fromfile(bins[0], dtype="<f4").reshape(-1, 4)
        assert 0 < len(points) <= 8 * 180 and np.isfinite(points).all()
        labels = (folder / "label_2" / bins[0].with_suffix(".txt").name).read_text().splitlines()
        assert labels and all(len(line.split()) == 15 for line in labels)
        assert {line.split()[0] for line in labels} <= {
            "Car",
            "Van",
            "Truck",
            "Pedestrian",
            "Cyclist",
            "Misc",
        }
        calib = (folder / "calib" / "000000.txt").read_text().splitlines()
        assert [line.split(":")[0] for line in calib] == [
            "P0",
            "P1",
            "P2",
            "P3",
            "R0_rect",
            "Tr_velo_to_cam",
            "Tr_imu_to_velo",
        ]


def test_kitti_export_of_a_run_without_lidar_is_bad_input(tmp_path: Path) -> None:
    run = tmp_path / "r"
    run.mkdir()
    (run / "run.yaml").write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: r}\nspec:\n"
        "  scenarios: [{name: s, openscenario: s.xosc}]\n"
    )
    done = carlos("export", run.as_uri(), "--format", "kitti")
    assert done.returncode == 2 and "no lidar" in done.stderr


def test_kitti_label_of_a_car_ahead_and_left_facing_forward() -> None:
    q = SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0)
    detection = SimpleNamespace(
        bbox=SimpleNamespace(
            center=SimpleNamespace(position=SimpleNamespace(x=10.0, y=2.0, z=0.5), orientation=q),
            size=SimpleNamespace(x=4.5, y=1.8, z=1.5),
        ),
        results=[SimpleNamespace(hypothesis=SimpleNamespace(class_id="car"))],
    )
    fields = kitti_label(detection).split()
    assert fields[0] == "Car"
    h, w, length, x, y, z, ry = map(float, fields[8:15])
    assert (h, w, length) == (1.5, 1.8, 4.5)
    assert (x, y, z) == (-2.0, 0.25, 10.0)  # camera: left is -x, the bottom centre 0.25 m below the sensor
    assert ry == pytest.approx(-math.pi / 2, abs=0.01)


def test_index_rows_and_calibration_of_a_yawed_mount() -> None:
    rows = index_rows(
        [
            {
                "index": 3,
                "scenario": "s",
                "status": "failed",
                "parameters": {"a": 1},
                "metrics": {"m": 2},
                "criteria": [{"passed": False}, {"passed": True}],
            }
        ]
    )
    assert rows[0]["param.a"] == 1 and rows[0]["metric.m"] == 2.0 and rows[0]["criteriaFailed"] == 1
    mount = SimpleNamespace(x=1.0, y=0.0, z=2.0, roll=0.0, pitch=0.0, yaw=90.0)
    imu = np.array([float(v) for v in calib_text(mount).splitlines()[-1].split()[1:]]).reshape(3, 4)
    # a point 1 m ahead of the mount (base_link (2, 0, 2)) is on the sensor's -y axis
    assert imu @ np.array([2.0, 0.0, 2.0, 1.0]) == pytest.approx([0.0, -1.0, 0.0], abs=1e-9)


def test_compact_point_fields_record_less_and_export_the_same(tmp_path: Path) -> None:
    """spec.sensors[].pointFields [x, y, z, intensity]: 16-byte points in the recording (not 28), the same
    KITTI velodyne bytes as the full layout for the same seed."""
    from mcap.reader import make_reader

    from simcore.transport.messages import deserialize

    bins: dict[str, list[bytes]] = {}
    steps: dict[str, set[int]] = {}
    for name, fields in (("full", ""), ("xyzi", ", pointFields: [intensity, x, y, z]")):
        manifest = tmp_path / f"{name}.yaml"
        manifest.write_text(
            "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: " + name + "}\nspec:\n"
            f"  scenarios: [{{name: cut-in, openscenario: '{CUT_IN}'}}]\n"
            "  simulation: {stepSeconds: 0.05, maxSeconds: 0.5, seed: 7}\n"
            "  sensors:\n    - {type: lidar, name: top, entity: Ego, mount: {x: 1.0, z: 1.8},"
            f" channels: 8, verticalFov: [-15, 5], horizontalResolution: 180{fields}}}\n"
        )
        assert carlos("run", manifest, "-q", "--output", f"file://{tmp_path}/out").returncode == 0
        run = tmp_path / "out" / name
        with (run / "0" / "recording.mcap").open("rb") as f:
            for schema, _, message in make_reader(f).iter_messages(topics=["/carlos/Ego/top/points"]):
                assert schema is not None
                msg = deserialize(message.data, schema.name)
                steps.setdefault(name, set()).add(msg.point_step)
                if name == "xyzi":
                    assert [(p.name, p.offset) for p in msg.fields] == [
                        ("x", 0),
                        ("y", 4),
                        ("z", 8),
                        ("intensity", 12),
                    ]
        done = carlos("export", run.as_uri(), "--format", "kitti", "--out", tmp_path / "kitti")
        assert done.returncode == 0, done.stderr
        velodyne = tmp_path / "kitti" / name / "0" / "Ego_top" / "velodyne"
        bins[name] = [p.read_bytes() for p in sorted(velodyne.glob("*.bin"))]
    assert steps == {"full": {28}, "xyzi": {16}}
    assert bins["full"] and bins["full"] == bins["xyzi"]


def test_point_fields_need_xyz() -> None:
    from pydantic import ValidationError

    from simcore.spec import LidarSensor

    with pytest.raises(ValidationError, match="pointFields lacks z"):
        LidarSensor.model_validate({"type": "lidar", "name": "l", "entity": "Ego", "pointFields": ["x", "y"]})
    with pytest.raises(ValidationError, match="twice"):
        LidarSensor.model_validate(
            {"type": "lidar", "name": "l", "entity": "Ego", "pointFields": ["x", "y", "z", "x"]}
        )
