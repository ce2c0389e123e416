"""`carlos export`: a run's results in the formats data pipelines read.

- `parquet` (pyarrow): one row per index: `index`, `scenario`, `seed`, `status`, `optional`,
  `simSeconds`, `wallSeconds`, `error`, `criteriaFailed`, then `param.<name>` and `metric.<name>` columns
  (null where an index lacks one).
- `kitti`: per index and lidar, a KITTI object-detection layout: `velodyne/NNNNNN.bin` (float32 x, y, z,
  intensity per point, sensor frame; intensity 0 when the lidar's `pointFields` leave it out),
  `label_2/NNNNNN.txt` (the sweep's ground truth, one object per line in KITTI's label format, camera
  coordinates of the KITTI convention: x right, y down, z forward, location = bottom centre of the box)
  and `calib/NNNNNN.txt` (no camera: P0–P3 and R0_rect identity, Tr_velo_to_cam the axis change of that
  convention, Tr_imu_to_velo the sensor mount inverted).
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from simcore.results import RunResults
from simcore.store import FileStore

#: velodyne (x forward, y left, z up) → KITTI camera (x right, y down, z forward)
VELO_TO_CAM = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
KITTI_TYPES = {
    "car": "Car",
    "van": "Van",
    "truck": "Truck",
    "pedestrian": "Pedestrian",
    "bicycle": "Cyclist",
    "cyclist": "Cyclist",
    "motorbike": "Cyclist",
    "tram": "Tram",
    "bus": "Truck",
}


def index_rows(indexes: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One flat row per index (pure; the column order of first appearance)."""
    rows = []
    for s in indexes:
        row: dict[str, Any] = {
            "index": int(s["index"]),
            "scenario": s["scenario"],
            "seed": s.get("seed"),
            "status": s["status"],
            "optional": bool(s.get("optional", False)),
            "simSeconds": s.get("simSeconds"),
            "wallSeconds": s.get("wallSeconds"),
            "error": s.get("error"),
            "criteriaFailed": sum(1 for c in s.get("criteria", []) if not c["passed"]),
        }
        row.update({f"param.{k}": v for k, v in (s.get("parameters") or {}).items()})
        row.update({f"metric.{k}": float(v) for k, v in (s.get("metrics") or {}).items()})
        rows.append(row)
    return rows


def parquet_bytes(indexes: Sequence[Mapping[str, Any]]) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = index_rows(indexes)
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    table = pa.table({name: [row.get(name) for row in rows] for name in columns})
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    return buffer.getvalue()


def export_parquet(results: RunResults, out: Path) -> Path:
    """Write `<run>.parquet` (or `out` when it ends in .parquet); its path."""
    target = out if out.suffix == ".parquet" else out / f"{results.name}.parquet"
    target = target.expanduser().absolute()
    FileStore(target.parent).put_bytes(target.name, parquet_bytes(results.indexes))
    return target


def _yaw(q: Any) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def kitti_label(detection: Any) -> str:
    """One ground-truth box (vision_msgs/Detection3D in the lidar frame) as a KITTI label line (pure)."""
    centre, size = detection.bbox.center.position, detection.bbox.size
    length, width, height = float(size.x), float(size.y), float(size.z)
    bottom = np.array([float(centre.x), float(centre.y), float(centre.z) - height / 2, 1.0])
    x, y, z = VELO_TO_CAM @ bottom
    rotation_y = -_yaw(detection.bbox.center.orientation) - math.pi / 2
    rotation_y = math.atan2(math.sin(rotation_y), math.cos(rotation_y))
    alpha = rotation_y - math.atan2(x, z)
    alpha = math.atan2(math.sin(alpha), math.cos(alpha))
    cls = detection.results[0].hypothesis.class_id if detection.results else ""
    kind = KITTI_TYPES.get(str(cls).lower(), "Misc")
    return (
        f"{kind} 0.00 0 {alpha:.2f} 0.00 0.00 0.00 0.00 {height:.2f} {width:.2f} {length:.2f} "
        f"{x:.2f} {y:.2f} {z:.2f} {rotation_y:.2f}"
    )


def _mount_matrix(mount: Any) -> np.ndarray:
    """base_link → sensor as a 3×4 matrix (the mount pose, angles in degrees, inverted)."""
    roll, pitch, yaw = (math.radians(a) for a in (mount.roll, mount.pitch, mount.yaw))
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rotation = np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
    inverse = rotation.T
    return np.hstack([inverse, -(inverse @ np.array([mount.x, mount.y, mount.z]))[:, None]])


def calib_text(mount: Any | None) -> str:
    def row(name: str, matrix: np.ndarray) -> str:
        return f"{name}: " + " ".join(f"{v:.12e}" for v in matrix.ravel())

    projection = np.hstack([np.eye(3), np.zeros((3, 1))])
    imu = _mount_matrix(mount) if mount is not None else projection
    lines = [row(f"P{i}", projection) for i in range(4)]
    lines += [row("R0_rect", np.eye(3)), row("Tr_velo_to_cam", VELO_TO_CAM), row("Tr_imu_to_velo", imu)]
    return "\n".join(lines) + "\n"


def _sweeps(data: bytes, points_topic: str, objects_topic: str) -> Iterator[tuple[bytes, list[str]]]:
    """(velodyne .bin bytes, label lines) per sweep with ground truth, in time order."""
    from mcap.reader import make_reader

    from simcore.sensors.ros import read_pointcloud2
    from simcore.transport.messages import deserialize

    clouds: dict[int, bytes] = {}
    labels: dict[int, list[str]] = {}
    reader = make_reader(io.BytesIO(data))
    for schema, channel, message in reader.iter_messages(topics=[points_topic, objects_topic]):
        if schema is None:
            continue
        msg = deserialize(message.data, schema.name)
        stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        if channel.topic == points_topic:
            points = read_pointcloud2(msg)  # by field name: any layout of spec.sensors[].pointFields
            names = points.dtype.names or ()
            columns = [
                points[k] if k in names else np.zeros(len(points)) for k in ("x", "y", "z", "intensity")
            ]
            xyzi = np.stack(columns, axis=1).astype("<f4")
            clouds[stamp] = xyzi.tobytes()
        else:
            labels[stamp] = [kitti_label(d) for d in msg.detections]
    for stamp in sorted(clouds):
        if stamp in labels:
            yield clouds[stamp], labels[stamp]


def export_kitti(results: RunResults, out: Path) -> tuple[Path, int]:
    """Write the KITTI layout under `out/<run>/<index>/<entity>_<sensor>/`; (that folder, frames written)."""
    from simcore.errors import BadInput

    if results.spec is None or not [s for s in results.spec.spec.sensors if s.type == "lidar"]:
        raise BadInput("the run has no lidar (spec.sensors): nothing to export as KITTI", field="--format")
    lidars = [s for s in results.spec.spec.sensors if s.type == "lidar"]
    root = out.expanduser().absolute() / results.name
    store = FileStore(root)
    frames = 0
    for summary in results.indexes:
        key = f"{summary['index']}/recording.mcap"
        if not results.store.exists(key):
            continue
        data = results.store.get_bytes(key)
        for lidar in lidars:
            base = f"/carlos/{lidar.entity}/{lidar.name}"
            folder = f"{summary['index']}/{lidar.entity}_{lidar.name}"
            for n, (cloud, labels) in enumerate(_sweeps(data, f"{base}/points", f"{base}/objects")):
                store.put_bytes(f"{folder}/velodyne/{n:06d}.bin", cloud)
                store.put_bytes(
                    f"{folder}/label_2/{n:06d}.txt", "".join(line + "\n" for line in labels).encode()
                )
                store.put_bytes(f"{folder}/calib/{n:06d}.txt", calib_text(lidar.mount).encode())
                frames += 1
    return root, frames
