"""McapRecorder: what it writes is read back by mcap + mcap_ros2 and by rosbags' AnyReader."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from simcore.recorder import McapRecorder, RecorderError
from simcore.spec import Recording
from simcore.transport import messages
from simcore.world.state import BoundingBox, EntityState, WorldFrame

CAR_BOX = BoundingBox(center_x=1.4, center_y=0.0, center_z=0.75, length=4.5, width=1.8, height=1.5)
TRUCK_BOX = BoundingBox(center_x=3.0, center_y=0.0, center_z=1.9, length=10.0, width=2.5, height=3.8)
STEP = 0.05
N_FRAMES = 20


def _frame(step: int) -> WorldFrame:
    t = step * STEP
    ego = EntityState(
        name="Ego",
        object_type="vehicle",
        category="car",
        x=10.0 * t,
        y=0.0,
        z=0.0,
        heading=0.0,
        pitch=0.0,
        roll=0.0,
        speed=10.0,
        acceleration=0.0,
        yaw_rate=0.0,
        bbox=CAR_BOX,
    )
    heading = 0.1 * t
    truck = EntityState(
        name="lead_truck",
        object_type="vehicle",
        category="truck",
        x=50.0 + 20.0 * t,
        y=3.5,
        z=0.0,
        heading=heading,
        pitch=0.0,
        roll=0.0,
        speed=20.0,
        acceleration=0.5,
        yaw_rate=0.1,
        bbox=TRUCK_BOX,
    )
    return WorldFrame(step=step, time=t, entities=(ego, truck), ego="Ego")


FRAMES = [_frame(i) for i in range(N_FRAMES)]
METADATA = {
    "carlos.spec": {"yaml": "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\n"},
    "carlos.run": {"index": "3", "seed": "42", "parameters": json.dumps({"speed": 10})},
}


def _record(path: Path, **kwargs: Any) -> None:
    with McapRecorder(path, metadata=METADATA, **kwargs) as rec:
        for frame in FRAMES:
            rec.write_frame(frame)
        rec.write(
            messages.STATUS_TOPIC,
            "diagnostic_msgs/msg/DiagnosticStatus",
            messages.status(FRAMES[-1], "ended"),
            FRAMES[-1].time,
        )


def _read_mcap(path: Path) -> tuple[list[tuple[str, str, int, Any]], dict[str, dict[str, str]], str]:
    out = []
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header_profile = reader.get_header().profile
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema is not None
            assert schema.encoding == "ros2msg"
            assert channel.message_encoding == "cdr"
            assert message.log_time == message.publish_time
            out.append((channel.topic, schema.name, message.log_time, decoded))
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return out, meta, header_profile


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_mcap_reader_decodes_values(tmp_path: Path, compression: Any) -> None:
    path = tmp_path / "run" / "0" / "recording.mcap"
    _record(path, compression=compression)
    assert path.exists()
    assert not path.with_name("recording.mcap.part").exists()

    msgs, meta, profile = _read_mcap(path)
    assert profile == "ros2"
    assert meta == METADATA
    per_frame = 2 + 2 + 1  # clock, tf, 2 × odometry, objects
    assert len(msgs) == N_FRAMES * per_frame + 1

    topics = {topic: typename for topic, typename, _, _ in msgs}
    assert topics == {
        "/clock": "rosgraph_msgs/msg/Clock",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/carlos/Ego/odometry": "nav_msgs/msg/Odometry",
        "/carlos/lead_truck/odometry": "nav_msgs/msg/Odometry",
        "/carlos/objects": "vision_msgs/msg/Detection3DArray",
        "/carlos/status": "diagnostic_msgs/msg/DiagnosticStatus",
    }

    clocks = [(t, m) for topic, _, t, m in msgs if topic == "/clock"]
    assert [t for t, _ in clocks] == [round(f.time * 1e9) for f in FRAMES]
    sec, ns = clocks[7][1].clock.sec, clocks[7][1].clock.nanosec
    assert sec * 1_000_000_000 + ns == round(7 * STEP * 1e9)

    tfs = [m for topic, _, _, m in msgs if topic == "/tf"]
    last = tfs[-1]
    assert [t.child_frame_id for t in last.transforms] == ["Ego/base_link", "lead_truck/base_link"]
    assert all(t.header.frame_id == "map" for t in last.transforms)
    truck = FRAMES[-1].entity("lead_truck")
    tr = last.transforms[1].transform
    assert tr.translation.x == pytest.approx(truck.x)
    assert tr.translation.y == pytest.approx(3.5)
    # yaw from the quaternion
    q = tr.rotation
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    assert yaw == pytest.approx(truck.heading)

    odo = [m for topic, _, _, m in msgs if topic == "/carlos/lead_truck/odometry"]
    assert len(odo) == N_FRAMES
    assert odo[-1].header.frame_id == "map"
    assert odo[-1].child_frame_id == "lead_truck/base_link"
    assert odo[-1].twist.twist.linear.x == pytest.approx(20.0)
    assert odo[-1].twist.twist.angular.z == pytest.approx(0.1)
    assert odo[-1].pose.pose.position.x == pytest.approx(truck.x)
    assert list(odo[-1].pose.covariance) == [0.0] * 36

    dets = [m for topic, _, _, m in msgs if topic == "/carlos/objects"]
    arr = dets[-1]
    assert arr.header.frame_id == "map"
    assert [d.id for d in arr.detections] == ["Ego", "lead_truck"]
    d = arr.detections[1]
    assert d.results[0].hypothesis.class_id == "truck"
    assert d.results[0].hypothesis.score == 1.0
    assert (d.bbox.size.x, d.bbox.size.y, d.bbox.size.z) == (10.0, 2.5, 3.8)
    cx, cy, cz = truck.box_center()
    assert (d.bbox.center.position.x, d.bbox.center.position.y, d.bbox.center.position.z) == pytest.approx(
        (cx, cy, cz)
    )
    assert arr.detections[0].results[0].hypothesis.class_id == "car"

    status = next(m for topic, _, _, m in msgs if topic == "/carlos/status")
    assert status.message == "ended"
    assert {kv.key: kv.value for kv in status.values} == {
        "state": "ended",
        "time": repr(FRAMES[-1].time),
        "step": "19",
    }


def test_anyreader_reads_bare_mcap(tmp_path: Path) -> None:
    """rosbags 0.11: AnyReader (rosbag2 Reader) opens a bare `.mcap` file by its suffix; no metadata.yaml.
    Types come from the schemas embedded in the file; we decode with them and with our own TYPESTORE."""
    path = tmp_path / "recording.mcap"
    _record(path)
    with AnyReader([path], default_typestore=messages.TYPESTORE) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/carlos/objects"] == "vision_msgs/msg/Detection3DArray"
        assert reader.message_count == N_FRAMES * 5 + 1
        assert reader.start_time == 0
        conns = [c for c in reader.connections if c.topic in ("/carlos/objects", "/carlos/Ego/odometry")]
        seen: dict[str, list[Any]] = {"/carlos/objects": [], "/carlos/Ego/odometry": []}
        for conn, timestamp, raw in reader.messages(connections=conns):
            embedded: Any = reader.deserialize(raw, conn.msgtype)
            ours = messages.deserialize(raw, conn.msgtype)
            assert embedded.header.stamp.sec * 10**9 + embedded.header.stamp.nanosec == timestamp
            seen[conn.topic].append((embedded, ours))
    assert len(seen["/carlos/objects"]) == N_FRAMES
    embedded, ours = seen["/carlos/objects"][-1]
    assert embedded.detections[1].bbox.size.x == ours.detections[1].bbox.size.x == 10.0
    assert embedded.detections[1].results[0].hypothesis.class_id == "truck"
    embedded, ours = seen["/carlos/Ego/odometry"][5]
    assert embedded.twist.twist.linear.x == ours.twist.twist.linear.x == 10.0
    assert embedded.pose.pose.position.x == pytest.approx(10.0 * 5 * STEP)


def test_schema_text_matches_typestore(tmp_path: Path) -> None:
    path = tmp_path / "recording.mcap"
    _record(path)
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schemas = {s.name: s.data.decode() for s in summary.schemas.values()}
    text = schemas["vision_msgs/msg/Detection3DArray"]
    assert text.startswith("std_msgs/Header header\nvision_msgs/Detection3D[] detections\n")
    assert "=" * 80 + "\nMSG: vision_msgs/ObjectHypothesis\nstring class_id\nfloat64 score\n" in text
    for channel in summary.channels.values():
        assert "offered_qos_profiles" in channel.metadata


def test_topic_filter(tmp_path: Path) -> None:
    path = tmp_path / "filtered.mcap"
    with McapRecorder(path, topics=["/carlos/*/odometry", "/clock"]) as rec:
        for frame in FRAMES[:3]:
            assert rec.write_frame(frame) == 3
        assert not rec.write("/tf", "tf2_msgs/msg/TFMessage", messages.tf(FRAMES[0]), 0.0)
    msgs, meta, _ = _read_mcap(path)
    assert meta == {}
    assert {m[0] for m in msgs} == {"/clock", "/carlos/Ego/odometry", "/carlos/lead_truck/odometry"}
    assert len(msgs) == 9


def test_for_recording_uses_the_spec(tmp_path: Path) -> None:
    recording = Recording.model_validate({"topics": ["/carlos/objects"], "compression": "lz4"})
    path = tmp_path / "recording.mcap"
    with McapRecorder.for_recording(path, recording, METADATA) as rec:
        assert rec.compression == "lz4"
        for frame in FRAMES[:4]:
            assert rec.write_frame(frame) == 1
    msgs, meta, _ = _read_mcap(path)
    assert {m[0] for m in msgs} == {"/carlos/objects"} and len(msgs) == 4
    assert meta == METADATA
    with path.open("rb") as f:
        assert {c.compression for c in make_reader(f).get_summary().chunk_indexes} == {"lz4"}  # type: ignore[union-attr]


def test_crash_leaves_no_final_file(tmp_path: Path) -> None:
    path = tmp_path / "recording.mcap"
    with pytest.raises(RuntimeError, match="simulator died"), McapRecorder(path, metadata=METADATA) as rec:
        for frame in FRAMES[:5]:
            rec.write_frame(frame)
        raise RuntimeError("simulator died")
    assert not path.exists()
    part = tmp_path / "recording.mcap.part"
    assert part.exists()  # kept for debugging, finished as far as it got: still a readable MCAP
    with part.open("rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == 5 * 5
    with pytest.raises(RecorderError, match="closed"):
        rec.write_frame(FRAMES[0])


def test_abort_without_partial(tmp_path: Path) -> None:
    path = tmp_path / "recording.mcap"
    rec = McapRecorder(path)
    rec.write_frame(FRAMES[0])
    rec.abort(keep_partial=False)
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(RecorderError, match="compression"):
        McapRecorder(tmp_path / "x.mcap", compression="gzip")  # type: ignore[arg-type]
    with pytest.raises(RecorderError, match="strings"):
        McapRecorder(tmp_path / "y.mcap", metadata={"carlos.run": {"seed": 42}})  # type: ignore[dict-item]
    assert not (tmp_path / "y.mcap.part").exists()
    with McapRecorder(tmp_path / "z.mcap") as rec:
        rec.write("/a", "rosgraph_msgs/msg/Clock", messages.clock(FRAMES[0]), 0.0)
        with pytest.raises(RecorderError, match="type"):
            rec.write("/a", "tf2_msgs/msg/TFMessage", messages.tf(FRAMES[0]), 0.0)


def test_entity_names_map_to_ros_names_injectively() -> None:
    """`lead_truck` and `lead-truck` are two vehicles with two frames and two topics; a valid name is kept."""
    a = FRAMES[0].entities[1]
    assert a.name == "lead_truck"
    b = EntityState(**{**{s: getattr(a, s) for s in a.__slots__}, "name": "lead-truck"})
    frame = WorldFrame(step=0, time=0.0, entities=(a, b))
    topics = {topic for topic, _, _ in messages.frame_messages(frame)}
    assert {"/carlos/lead_truck/odometry", f"/carlos/{messages.ros_name('lead-truck')}/odometry"} <= topics
    assert messages.ros_name("lead-truck").startswith("lead_truck_")
    assert messages.ros_name("Ego") == "Ego"
    assert messages.ros_name("1st car").startswith("e1st_car_")
    names = ["Ego_0_-1", "Ego_0_1", "car-2", "car 2", "car_2", "a//b--c", "a_b_c", "", "entity"]
    tokens = [messages.ros_name(n) for n in names]
    assert len(set(tokens)) == len(names)
    assert all(re.fullmatch(r"[A-Za-z][A-Za-z0-9]*(_[A-Za-z0-9]+)*", t) for t in tokens), tokens


def test_bytes_per_frame(tmp_path: Path) -> None:
    """Size of the recording per step for two entities (printed with -s; a loose upper bound asserted)."""
    sizes = {}
    for compression in ("zstd", "none"):
        path = tmp_path / f"{compression}.mcap"
        with McapRecorder(path, compression=compression) as rec:
            for i in range(1000):
                rec.write_frame(_frame(i))
        sizes[compression] = path.stat().st_size / 1000
    print(f"bytes per frame (2 entities): {sizes}")
    assert sizes["zstd"] < sizes["none"] < 4000


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_records_indexes_and_checksums_are_valid(tmp_path: Path, compression: Any) -> None:
    """Every record parses with CRC validation on; each message index entry points at a message record of
    its channel with its log time inside the (decompressed) chunk; small chunks (many of them go through the
    writer thread's bounded queue) and a message larger than a chunk lose nothing."""
    import struct

    import lz4.frame
    import zstandard
    from mcap.records import Channel, Chunk, ChunkIndex, Message, MessageIndex, Statistics
    from mcap.stream_reader import StreamReader

    path = tmp_path / "r.mcap"
    big = bytes(range(256)) * 1000  # 256 kB of CDR-like payload, given as bytes
    with McapRecorder(path, compression=compression, chunk_size=4096, metadata=METADATA) as rec:
        for i, frame in enumerate(FRAMES):
            rec.write_frame(frame)
            if i % 5 == 0:
                rec.write("/big", "std_msgs/msg/UInt8MultiArray", big, frame.time)
    with path.open("rb") as f:
        inner = list(StreamReader(f, validate_crcs=True).records)  # the chunks' records
    with path.open("rb") as f:
        records = list(StreamReader(f, validate_crcs=True, emit_chunks=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    indexes = [r for r in records if isinstance(r, MessageIndex)]
    messages_ = [r for r in inner if isinstance(r, Message)]
    channels = {r.id: r.topic for r in inner if isinstance(r, Channel)}
    assert len(chunks) > 10
    assert len(messages_) == N_FRAMES * 5 + 4
    assert sum(1 for m in messages_ if channels[m.channel_id] == "/big" and m.data == big) == 4
    stats = next(r for r in records if isinstance(r, Statistics))
    assert stats.message_count == len(messages_) and stats.chunk_count == len(chunks)
    assert stats.message_start_time == 0 and stats.message_end_time == round(FRAMES[-1].time * 1e9)
    assert sum(1 for r in records if isinstance(r, ChunkIndex)) == len(chunks)
    # message indexes follow their chunk: check each entry against the chunk's records
    decompress = {
        "zstd": lambda d, n: zstandard.ZstdDecompressor().decompress(d, max_output_size=n),
        "lz4": lambda d, n: lz4.frame.decompress(d),
        "": lambda d, n: d,
    }
    checked = 0
    for record in records:
        if isinstance(record, Chunk):
            data = decompress[record.compression](record.data, record.uncompressed_size)
            assert len(data) == record.uncompressed_size
        elif isinstance(record, MessageIndex):
            for log_time, offset in record.records:
                opcode, _, channel_id, _, log = struct.unpack_from("<BQHIQ", data, offset)
                assert (opcode, channel_id, log) == (0x05, record.channel_id, log_time)
                checked += 1
    assert checked == len(messages_) and indexes


def test_cdr_bytes_are_written_as_given(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    tf = messages.tf(FRAMES[3])
    with McapRecorder(path, compression="none") as rec:
        rec.write("/tf", "tf2_msgs/msg/TFMessage", tf, 1.0)
        rec.write("/tf", "tf2_msgs/msg/TFMessage", messages.serialize(tf), 2.0)
        rec.write("/tf", "tf2_msgs/msg/TFMessage", memoryview(messages.serialize(tf)), 3.0)
    with path.open("rb") as f:
        data = [m.data for _, _, m in make_reader(f).iter_messages()]
    assert data == [messages.serialize(tf)] * 3


def test_write_errors_reach_the_caller(tmp_path: Path) -> None:
    """An I/O error in the writer thread surfaces as RecorderError on a later write or on close."""
    path = tmp_path / "r.mcap"
    rec = McapRecorder(path, chunk_size=1024)

    def broken(data: Any) -> int:
        raise OSError(28, "No space left on device")

    rec._file.write = broken  # type: ignore[method-assign]
    with pytest.raises(RecorderError, match="No space left"):
        for i in range(1000):
            rec.write_frame(_frame(i))
    with pytest.raises(RecorderError, match="No space left"):
        rec.close()
    assert not path.exists()


@pytest.mark.parametrize("frame_id", ["", "a", "Ego/lidar", "ego_car/front_lidar"])
@pytest.mark.parametrize("n", [0, 1, 3, 1000])
def test_big_arrays_are_serialised_around_as_rosbags_does(frame_id: str, n: int) -> None:
    """PointCloud2 and Image are written as (CDR before the array, the array, CDR after it): the same
    bytes as rosbags' serialisation, whatever the lengths (alignment)."""
    import numpy as np

    from simcore.recorder import _BLOB_TYPES, _cdr_pieces
    from simcore.sensors import ros
    from simcore.sensors.lidar import POINT_DTYPE

    points = np.zeros(n, POINT_DTYPE)
    points["x"] = np.arange(n)
    points.flags.writeable = False
    cloud = ros.pointcloud2(points, 1.25, frame_id)
    image = ros.image(np.arange(n * 3, dtype=np.float32).reshape(-1, 3), "32FC1", 2.5, frame_id)
    for msg, typename in ((cloud, ros.POINTCLOUD2), (image, ros.IMAGE)):
        pieces = _cdr_pieces(msg, _BLOB_TYPES[typename])
        assert b"".join(bytes(p) for p in pieces) == messages.serialize(msg)
    assert isinstance(_cdr_pieces(cloud, 1)[1], memoryview)  # read-only: referenced, not copied


def test_a_writable_array_is_copied_when_written(tmp_path: Path) -> None:
    """A cloud whose array is changed after `write` is recorded as it was written (read-only arrays are
    referenced until the chunk is written; anything else is copied)."""
    import numpy as np

    from simcore.sensors import ros
    from simcore.sensors.lidar import POINT_DTYPE

    path = tmp_path / "clouds.mcap"
    points = np.zeros(100, POINT_DTYPE)
    frozen = np.zeros(100, POINT_DTYPE)
    frozen["x"] = 7.0
    frozen.flags.writeable = False
    with McapRecorder(path, compression="zstd") as rec:
        rec.write("/a", ros.POINTCLOUD2, ros.pointcloud2(points, 0.0, "a"), 0.0)
        rec.write("/b", ros.POINTCLOUD2, ros.pointcloud2(frozen, 0.0, "b"), 0.0)
        points["x"] = 5.0  # after the write, before the chunk is compressed
    got = {topic: ros.read_pointcloud2(msg) for topic, _, _, msg in _read_mcap(path)[0]}
    assert np.all(got["/a"]["x"] == 0.0) and np.all(got["/b"]["x"] == 7.0)


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_the_same_messages_make_the_same_file(tmp_path: Path, compression: Any) -> None:
    """A recording is a function of its messages: zstd's worker threads split a chunk into jobs, and the
    frames still come out byte for byte the same (clouds of several MiB, chunks of 4 MiB)."""
    import numpy as np

    from simcore.sensors import ros
    from simcore.sensors.lidar import POINT_DTYPE

    rng = np.random.default_rng(5)
    clouds = []
    for _ in range(4):
        points = np.zeros(60_000, POINT_DTYPE)
        points["x"] = rng.normal(size=len(points))
        points.flags.writeable = False
        clouds.append(points)
    for name in ("a.mcap", "b.mcap"):
        with McapRecorder(tmp_path / name, compression=compression, metadata=METADATA) as rec:
            for step, points in enumerate(clouds):
                rec.write_frame(_frame(step))
                rec.write("/cloud", ros.POINTCLOUD2, ros.pointcloud2(points, step * 0.1, "lidar"), step * 0.1)
    first, second = (tmp_path / "a.mcap").read_bytes(), (tmp_path / "b.mcap").read_bytes()
    assert len(first) > 500_000 and first == second
    assert len(_read_mcap(tmp_path / "a.mcap")[0]) > 4


def test_add_channel_records_encoded_messages_of_its_own_schema(tmp_path: Path) -> None:
    path = tmp_path / "mixed.mcap"
    with McapRecorder(path, topics=["/tf"]) as rec:
        rec.add_channel("/osi", "osi3.GroundTruth", "protobuf", b"\x0a\x03abc", "protobuf", {"k": "v"})
        rec.write_frame(_frame(0))
        assert rec.write("/osi", "osi3.GroundTruth", b"\x01\x02\x03", 0.05)  # not in the topic patterns
        with pytest.raises(RecorderError, match="already has a channel"):
            rec.add_channel("/osi", "osi3.GroundTruth", "protobuf", b"", "protobuf", {})
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        osi = next(c for c in summary.channels.values() if c.topic == "/osi")
        schema = summary.schemas[osi.schema_id]
        assert (schema.name, schema.encoding, schema.data) == ("osi3.GroundTruth", "protobuf", b"\x0a\x03abc")
        assert osi.message_encoding == "protobuf" and osi.metadata == {"k": "v"}
        got = [(m.log_time, m.data) for _, c, m in reader.iter_messages() if c.topic == "/osi"]
    assert got == [(50_000_000, b"\x01\x02\x03")]
