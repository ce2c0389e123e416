"""MCAP write rate: `simcore.recorder.McapRecorder` against rosbags' own MCAP writer on the same messages.

Both writers get the same CDR bytes (serialised once, before the clock starts), in the same order:

- `clouds`: a 64 × 1024 lidar at 10 Hz as `sensor_msgs/PointCloud2` (65,536 points of 28 bytes, 1.8 MB;
  8 different clouds cycled, coordinates as a lidar sees a road and cars) interleaved with the world
  messages of a 20 Hz simulation with 10 entities (`/clock`, `/tf`, 10 × odometry, `/carlos/objects`);
- `small`: only the world messages (13 per step, 70 B to 5 KB): per-message overhead.

Each workload is written uncompressed and with the compression the recorder uses by default (zstd: level
`simcore.recorder.ZSTD_LEVEL` for McapRecorder, rosbags' `CompressionMode.STORAGE` = zstd at its default
level 3). Wall time from opening the writer to the file being closed; McapRecorder's close includes an
fsync, so the rosbags figure includes an fsync of its file too (the same work). The files go to /dev/shm
(tmpfs: the writers' own cost, not the disk's, which other jobs on a shared machine make erratic; set
BENCH_DIR to measure a disk). Best of REPEAT (env BENCH_REPEAT, default 3). MB/s counts message payload
bytes (CDR) per wall second.

Prints a table and, as its last line, one JSON object with the figures (ratio = McapRecorder / rosbags,
goal ≥ 0.9). No assertions: machines are noisy.

Measured 2026-11-22, taskset -c 0,1 on a 2-core machine shared with other jobs (load 6-8), best of 5, MB/s
of CDR payload (McapRecorder / rosbags):

| workload, compression | before (mcap-python Writer, zstd 3) | after (own writer + thread, zstd 1) |
|---|---|---|
| clouds, none | 319 / 400 = 0.80 | 690 / 339 = 2.03 |
| clouds, zstd | 106 / 100 = 1.05 | 168 / 88 = 1.90 |
| small, none | 117 / 137 = 0.85 | 272 / 130 = 2.09 |
| small, zstd | 162 / 211 = 0.77 | 200 / 109 = 1.83 |

(messages/s: clouds none 10,000 vs 4,900; small none 273,000 vs 130,000.) Goal ≥ 0.9: met in every row.
"Before" is the previous McapRecorder (mcap-python's Writer: record objects per message, compression on
the calling thread) fed the same CDR bytes.

Chunk size x zstd level (BENCH_TUNING=1), 2026-11-28, `BENCH_TUNING=1 BENCH_REPEAT=2 BENCH_SECONDS=5
taskset -c 0,1 .venv/bin/python bench/recorder.py` (2 cores, load 7-10; CPU s of every thread, 50 sweeps of
the synthetic clouds):

| chunk | level -1: CPU s, bytes/sweep | level 1 | level 3 |
|---|---|---|---|
| 1 MiB | 0.226, 1,054,094 | 0.298, 986,656 | 0.590, 1,031,143 |
| 4 MiB | 0.250, 1,055,677 | 0.315, 989,202 | 0.487, 1,030,938 |
| 16 MiB | 0.260, 1,055,947 | 0.343, 988,618 | 0.530, 1,030,882 |

Level 1 makes the smallest files (level 3 is larger here: float coordinates); -1 saves ~1.3 CPU ms a sweep
for 7% more bytes; the chunk size changes little. The defaults (4 MiB, level 1) stay: recordings keep their
bytes.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore.recorder import ZSTD_LEVEL, McapRecorder  # noqa: E402
from simcore.sensors import ros  # noqa: E402
from simcore.sensors.lidar import POINT_DTYPE  # noqa: E402
from simcore.transport.messages import TYPESTORE, frame_messages, serialize  # noqa: E402
from simcore.world.state import BoundingBox, EntityState, WorldFrame  # noqa: E402

REPEAT = int(os.environ.get("BENCH_REPEAT", "3"))
SECONDS = float(os.environ.get("BENCH_SECONDS", "20"))  # simulated seconds of the cloud workload
SMALL_STEPS = int(os.environ.get("BENCH_SMALL_STEPS", "4000"))
BENCH_DIR = os.environ.get("BENCH_DIR") or ("/dev/shm" if os.path.isdir("/dev/shm") else None)
POINTS = 64 * 1024
Workload = list[tuple[str, str, bytes, int]]  # topic, type, CDR, log time ns


def cloud(seed: int) -> np.ndarray:
    """A lidar-like cloud: ground returns and two boxes, float coordinates, small integer labels."""
    rng = np.random.default_rng(seed)
    az = np.repeat(np.linspace(-np.pi, np.pi, 1024, endpoint=False), 64)
    el = np.tile(np.radians(np.linspace(-25, 10, 64)), 1024)
    rng_m = np.where(el < 0, 2.0 / np.maximum(np.sin(-el), 0.02), rng.uniform(5, 100, len(el)))
    rng_m = np.minimum(rng_m, 100.0) + rng.normal(0, 0.02, len(el))
    points = np.zeros(POINTS, POINT_DTYPE)
    points["x"] = rng_m * np.cos(el) * np.cos(az)
    points["y"] = rng_m * np.cos(el) * np.sin(az)
    points["z"] = rng_m * np.sin(el)
    points["intensity"] = rng.uniform(0, 0.6, POINTS)
    obj = (np.abs(az) < 0.2) & (el > -0.1)
    points["object_id"] = np.where(obj, 2, 0)
    points["ring"] = np.tile(np.arange(64, dtype=np.uint16), 1024)
    points["label"] = np.where(obj, 10, 1)
    return points


def world_frame(step: int, entities: int = 10) -> WorldFrame:
    t = step * 0.05
    box = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)
    states = tuple(
        EntityState(f"car{i}", "vehicle", "car", 20.0 * t + 10 * i, 3.5 * (i % 3), 0.0, 0.01 * i, 0.0, 0.0,
                    20.0, 0.1, 0.01, box)
        for i in range(entities)
    )  # fmt: skip
    return WorldFrame(step, t, states, ego="car0")


def small_messages(steps: int) -> Workload:
    out: Workload = []
    for step in range(steps):
        frame = world_frame(step)
        ns = round(frame.time * 1e9)
        out.extend((topic, typename, serialize(msg), ns) for topic, typename, msg in frame_messages(frame))
    return out


def cloud_messages(seconds: float) -> Workload:
    clouds = [serialize(ros.pointcloud2(cloud(seed), 0.0, "car0/lidar")) for seed in range(8)]
    steps = round(seconds / 0.05)
    world = small_messages(steps)
    out: Workload = []
    per_step = len(world) // steps
    for step in range(steps):
        out.extend(world[step * per_step : (step + 1) * per_step])
        if step % 2 == 0:
            ns = world[step * per_step][3]
            out.append(("/carlos/car0/lidar/points", ros.POINTCLOUD2, clouds[(step // 2) % 8], ns))
    return out


def write_recorder(path: Path, messages: Workload, compression: str) -> None:
    with McapRecorder(path / "recording.mcap", compression=compression) as rec:  # type: ignore[arg-type]
        write = rec.write
        for topic, typename, data, ns in messages:
            write(topic, typename, data, ns * 1e-9)


def tuning(messages: Workload) -> list[dict[str, float]]:
    """McapRecorder on the cloud workload over chunk sizes and zstd levels (env BENCH_TUNING=1): wall and
    CPU seconds (every thread: the writer thread and zstd's worker count) and the file's bytes, best of
    REPEAT. The recorder's defaults (4 MiB chunks, level ZSTD_LEVEL) come from this table."""
    import simcore.recorder as recorder_module

    out = []
    default_level = recorder_module.ZSTD_LEVEL
    try:
        for chunk_mib in (1, 4, 16):
            for level in (-1, 1, 3):
                recorder_module.ZSTD_LEVEL = level
                best_wall = best_cpu = float("inf")
                size = 0
                for _ in range(REPEAT):
                    with tempfile.TemporaryDirectory(dir=BENCH_DIR) as tmp:
                        path = Path(tmp) / "recording.mcap"
                        started, cpu = time.perf_counter(), time.process_time()
                        with McapRecorder(path, compression="zstd", chunk_size=chunk_mib << 20) as rec:
                            for topic, typename, data, ns in messages:
                                rec.write(topic, typename, data, ns * 1e-9)
                        best_wall = min(best_wall, time.perf_counter() - started)
                        best_cpu = min(best_cpu, time.process_time() - cpu)
                        size = path.stat().st_size
                out.append(
                    {"chunkMiB": chunk_mib, "level": level, "wall": best_wall, "cpu": best_cpu, "bytes": size}
                )
    finally:
        recorder_module.ZSTD_LEVEL = default_level
    return out


def write_rosbags(path: Path, messages: Workload, compression: str) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    bag = path / "bag"
    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    if compression == "zstd":
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    connections: dict[str, object] = {}
    with writer:
        for topic, typename, data, ns in messages:
            conn = connections.get(topic)
            if conn is None:
                conn = connections[topic] = writer.add_connection(topic, typename, typestore=TYPESTORE)
            writer.write(conn, ns, data)  # type: ignore[arg-type]
    for file in bag.iterdir():
        with file.open("rb") as f:
            os.fsync(f.fileno())


def timed(write: Callable[[Path], None]) -> float:
    folder = Path(tempfile.mkdtemp(prefix="bench-recorder-", dir=BENCH_DIR))
    try:
        started = time.perf_counter()
        write(folder)
        return time.perf_counter() - started
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def main() -> None:
    workloads = {"clouds": cloud_messages(SECONDS), "small": small_messages(SMALL_STEPS)}
    rows: list[dict[str, object]] = []
    for name, messages in workloads.items():
        payload = sum(len(m[2]) for m in messages)
        for compression in ("none", "zstd"):
            writers: dict[str, Callable[[Path], None]] = {
                "McapRecorder": partial(write_recorder, messages=messages, compression=compression),
                "rosbags": partial(write_rosbags, messages=messages, compression=compression),
            }
            times: dict[str, list[float]] = {key: [] for key in writers}
            for _ in range(REPEAT):  # alternating, so a busy moment hits both
                for key, w in writers.items():
                    times[key].append(timed(w))
            best = {key: min(values) for key, values in times.items()}
            for writer, seconds in best.items():
                rows.append(
                    {
                        "workload": name,
                        "compression": compression,
                        "writer": writer,
                        "seconds": seconds,
                        "MBps": payload / seconds / 1e6,
                        "messagesPerSecond": len(messages) / seconds,
                        "messages": len(messages),
                        "payloadMB": payload / 1e6,
                    }
                )
    print(
        f"MCAP write rate, best of {REPEAT}; cores={len(os.sched_getaffinity(0))}; files in "
        f"{BENCH_DIR or tempfile.gettempdir()}; McapRecorder zstd level {ZSTD_LEVEL}, rosbags zstd (STORAGE) "
        "default level"
    )
    header = (
        f"{'workload':<8}{'compr.':>7}  {'writer':<20}{'msgs':>8}{'MB':>9}{'s':>8}{'MB/s':>9}{'msg/s':>11}"
    )
    print(header)
    print("-" * len(header))
    for r in rows:
        print(
            f"{r['workload']:<8}{r['compression']:>7}  {r['writer']:<20}{r['messages']:>8}{r['payloadMB']:>9.1f}"
            f"{r['seconds']:>8.3f}{r['MBps']:>9.0f}{r['messagesPerSecond']:>11.0f}"
        )
    ratios: dict[str, dict[str, float]] = {}
    for name in workloads:
        for compression in ("none", "zstd"):

            def rate(writer: str, name: str = name, compression: str = compression) -> float:
                return next(
                    float(r["MBps"])  # type: ignore[arg-type]
                    for r in rows
                    if r["workload"] == name and r["compression"] == compression and r["writer"] == writer
                )

            ratios[f"{name}/{compression}"] = {
                "recorderMBps": round(rate("McapRecorder"), 1),
                "rosbagsMBps": round(rate("rosbags"), 1),
                "ratio": round(rate("McapRecorder") / rate("rosbags"), 3),
            }
    tuned: list[dict[str, float]] = []
    if os.environ.get("BENCH_TUNING") == "1":
        clouds = workloads["clouds"]
        sweeps = sum(1 for m in clouds if m[1] == "sensor_msgs/msg/PointCloud2")
        table = tuned = tuning(clouds)
        print(f"McapRecorder zstd tuning on the cloud workload ({sweeps} sweeps), best of {REPEAT}:")
        print(f"{'chunk MiB':>9}{'level':>7}{'wall s':>9}{'CPU s':>8}{'MB':>8}{'bytes/sweep':>13}")
        for t in table:
            print(
                f"{t['chunkMiB']:>9}{t['level']:>7}{t['wall']:>9.3f}{t['cpu']:>8.3f}{t['bytes'] / 1e6:>8.1f}"
                f"{t['bytes'] / sweeps:>13,.0f}"
            )
    for key, ratio in ratios.items():
        print(f"{key:<14} McapRecorder / rosbags: {ratio['ratio']:.2f} (goal >= 0.9)")
    print(
        json.dumps(
            {
                "bench": "recorder",
                "repeat": REPEAT,
                "cores": len(os.sched_getaffinity(0)),
                "zstdLevel": ZSTD_LEVEL,
                "dir": BENCH_DIR or tempfile.gettempdir(),
                "goalRatio": 0.9,
                "minRatio": min(r["ratio"] for r in ratios.values()),
                "ratios": ratios,
                "tuning": [{k: round(v, 4) for k, v in t.items()} for t in tuned],
                "rows": [
                    {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()} for r in rows
                ],
            }
        )
    )


if __name__ == "__main__":
    main()
