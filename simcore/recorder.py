"""MCAP recorder: the world state of every step as ROS 2 messages in one `recording.mcap`.

The file is what `ros2 bag record -s mcap` writes on jazzy: profile `ros2`, one schema per message type
(encoding `ros2msg`, the concatenated `.msg` text), one channel per topic (message encoding `cdr`,
`offered_qos_profiles` in the channel metadata), log and publish time = simulated time in ns from 0.
Metadata records (e.g. `carlos.spec`, `carlos.run`) carry the spec, parameters, seed and versions.

It is readable by `mcap` + `mcap_ros2`, Foxglove, `ros2 bag play/info` (a bare .mcap file is accepted
by rosbag2 since humble), and rosbags (`AnyReader([Path("recording.mcap")])`: rosbags ≥ 0.10 opens a
bare `.mcap` file, no metadata.yaml needed).

Layout (MCAP v0): header, metadata records (indexed), chunks of `chunk_size` bytes (4 MiB) holding the
schema and channel records where they are first used and the message records, each chunk followed by its
message indexes; a summary with the schemas, channels, statistics, chunk and metadata indexes and summary
offsets; every chunk carries the CRC-32 of its uncompressed records, the footer the summary's CRC.

Speed: the writer is this module's own (no per-message record objects): `write` serialises the message
(or takes CDR bytes as they are, see `write`; a PointCloud2 or Image is serialised around its data array,
which is referenced, not copied, when it is read-only, as a lidar's clouds are), packs the 31-byte record
header and appends both to the open chunk; full chunks go to a writer thread that checksums, compresses
(zstd level 1 by default, lz4, or none) and writes them in 128 KiB slices while the simulation goes on:
each slice is one call without the GIL, so the thread waits out open3d's GIL-holding cast instead of taking
a core from it. zstd compresses on its own native worker thread, which needs no GIL at all: the writer
thread only hands it the slices (a Python thread doing the compression itself got the GIL back too rarely
between slices and fell behind the simulation; bench/sensors.py). The writer thread fdatasyncs every
16 MiB, so `close` only waits for the tail. At most `_QUEUE_CHUNKS` chunks wait for the writer thread
(the caller blocks beyond that: bounded memory, nothing is dropped); `close`/`abort` write every chunk
before the summary.

Crash safety: the recorder writes `<path>.part` and renames it to `path` only in :meth:`McapRecorder.close`,
after an fsync; a run that dies never leaves a file under the final name. On an exception inside the
`with` block the partial recording is finished (a valid MCAP up to the last message) and kept as
`<path>.part` for debugging.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import os
import queue
import struct
import threading
import zlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Literal, Self

import numpy as np

from simcore.spec import Recording
from simcore.store import fsync_dir
from simcore.transport.bus import Message
from simcore.transport.messages import frame_builders, msgdef, serialize
from simcore.world.state import WorldFrame

__all__ = ["DEFAULT_QOS", "ZSTD_LEVEL", "Compression", "McapRecorder", "RecorderError"]

Compression = Literal["zstd", "lz4", "none"]
_COMPRESSIONS = ("zstd", "lz4", "none")

#: zstd level of the chunks: level 1 compresses point clouds as well as the default level 3 here
#: (float coordinates are the bulk and barely compress) at about 1.5x the speed.
ZSTD_LEVEL = 1
#: zstd worker threads of a recorder (native threads, outside the GIL; see `_compressor`).
ZSTD_WORKERS = 1
#: Bytes the writer thread writes between two fdatasync calls (see `_FileWriter._sync`).
_SYNC_EVERY = 16 * 1024 * 1024
#: fdatasync where there is one (Linux), else fsync (macOS).
_datasync: Callable[[int], None] = getattr(os, "fdatasync", os.fsync)
#: Chunks waiting for the writer thread before `write` blocks.
_QUEUE_CHUNKS = 4

#: The QoS every channel offers, in rosbag2's (metadata version 9, jazzy) YAML: reliable, volatile,
#: keep-last 10 (the rclcpp/rclpy default); zero durations mean "system default".
DEFAULT_QOS = (
    "- history: keep_last\n"
    "  depth: 10\n"
    "  reliability: reliable\n"
    "  durability: volatile\n"
    "  deadline:\n    sec: 0\n    nsec: 0\n"
    "  lifespan:\n    sec: 0\n    nsec: 0\n"
    "  liveliness: automatic\n"
    "  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n"
    "  avoid_ros_namespace_conventions: false"
)

# --- MCAP records (https://mcap.dev/spec) -------------------------------------------------------------

_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
_OP_MESSAGE_INDEX, _OP_CHUNK_INDEX, _OP_STATISTICS, _OP_METADATA = 0x07, 0x08, 0x0B, 0x0C
_OP_METADATA_INDEX, _OP_SUMMARY_OFFSET, _OP_DATA_END = 0x0D, 0x0E, 0x0F
#: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIXED = _MESSAGE_HEAD.size - 9  # content bytes before the data
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")


def _string(value: str) -> bytes:
    data = value.encode("utf-8")
    return _U32.pack(len(data)) + data


def _map(values: Mapping[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in values.items())
    return _U32.pack(len(body)) + body


def _record(opcode: int, content: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(content)) + content


def _library() -> str:
    from simcore import version

    return f"carlos {version()}"


def _ns(time_s: float) -> int:
    ns = round(time_s * 1e9)
    if ns < 0:
        raise RecorderError(f"negative simulation time {time_s}")
    return ns


class RecorderError(RuntimeError):
    """The recording cannot be written (bad arguments, closed recorder, I/O error)."""


#: A record piece: bytes, or a read-only view of a message's big array (taken as it is, not copied).
Piece = bytes | memoryview


def _compressor(compression: str) -> Callable[[list[Piece], int], list[Piece]] | None:
    """A function compressing a chunk's pieces (total `size` bytes) into one frame as a list of pieces:
    streamed piece by piece (the compressors release the GIL), never joined into one buffer first."""
    if compression == "zstd":
        import zstandard

        # zstd's own worker thread compresses (no GIL: it goes on while open3d's cast holds it); this thread
        # only hands it the slices. The frames are the same whatever the number of workers >= 1.
        context = zstandard.ZstdCompressor(level=ZSTD_LEVEL, threads=ZSTD_WORKERS)

        def zstd(pieces: list[Piece], size: int) -> list[Piece]:
            stream = context.compressobj(size=size)  # the frame records the size, as compress() would
            out: list[Piece] = [stream.compress(piece) for piece in pieces]
            out.append(stream.flush())
            return out

        return zstd
    if compression == "lz4":
        import lz4.frame

        def lz4_frame(pieces: list[Piece], size: int) -> list[Piece]:
            stream = lz4.frame.LZ4FrameCompressor()
            out: list[Piece] = [stream.begin(source_size=size)]
            out.extend(stream.compress(piece) for piece in pieces)
            out.append(stream.flush())
            return out

        return lz4_frame
    return None


#: Message types whose bulk is one uint8[] `data` field: serialised around it, the array itself is a piece
#: of the chunk (no copy when it is read-only), with the bytes the CDR has after the array.
_BLOB_TYPES = {"sensor_msgs/msg/PointCloud2": 1, "sensor_msgs/msg/Image": 0}
_NO_BYTES = np.zeros(0, np.uint8)


def _cdr_pieces(msg: Any, after: int) -> tuple[bytes, Piece, bytes]:
    """The CDR of a message with a big uint8[] `data` field as (before the array, the array, after it):
    the rosbags serialisation of the message with an empty array gives the rest. A read-only contiguous
    numpy array is taken as immutable and referenced (a lidar's clouds are read-only); anything else is
    copied once."""
    data = msg.data
    if isinstance(data, np.ndarray) and not data.flags.writeable and data.flags.c_contiguous:
        blob: Piece = data.data.cast("B")
    else:
        blob = bytes(np.ascontiguousarray(data, np.uint8)) if isinstance(data, np.ndarray) else bytes(data)
    empty = serialize(dataclasses.replace(msg, data=_NO_BYTES))
    cut = len(empty) - 4 - after  # the array's uint32 length (aligned the same whatever the length)
    return (
        empty[:cut] + _U32.pack(blob.nbytes if isinstance(blob, memoryview) else len(blob)),
        blob,
        empty[cut + 4 :],
    )


#: Pieces below this size are joined before they are checksummed, compressed or written; larger ones are
#: handed over in slices of at most this size.
_SLICE = 128 * 1024


def _slices(pieces: list[Piece]) -> list[Piece]:
    """The pieces as the writer thread feeds them to the checksum, the compressor and the file: runs of
    small ones joined, large ones (point clouds) cut into views of at most `_SLICE` bytes (no copy).

    Why slices: each of these calls releases the GIL while it works and needs it back to start, and the
    simulation thread holds the GIL through open3d's cast (which uses every core). With short calls the
    writer thread waits out the cast instead of taking a core from it, and works in the single-threaded
    phases of the step (scenario, labels, messages), where a core is idle."""
    out: list[Piece] = []
    run: list[Piece] = []
    for piece in pieces:
        if len(piece) < _SLICE:
            run.append(piece)
            continue
        if run:
            out.append(b"".join(run))
            run = []
        view = memoryview(piece)
        out.extend(view[i : i + _SLICE] for i in range(0, len(view), _SLICE))
    if run:
        out.append(b"".join(run))
    return out


@dataclass
class _Chunk:
    """An open chunk: its records as pieces (record heads and message data), message indexes per channel
    as flat [log time, offset, …] lists, the time range."""

    pieces: list[Piece] = field(default_factory=list)
    size: int = 0
    indexes: dict[int, list[int]] = field(default_factory=dict)
    start: int = 0
    end: int = 0
    messages: int = 0


@dataclass
class _Summary:
    schemas: list[bytes]
    channels: list[bytes]
    statistics: bytes


class _FileWriter(threading.Thread):
    """Owns the file: writes the records handed to it in order (chunks compressed here, off the
    simulation thread), keeps the chunk and metadata indexes, and writes the summary at the end."""

    def __init__(self, file: IO[bytes], compression: str) -> None:
        super().__init__(name="mcap-writer", daemon=True)
        self.file = file
        self.compression = "" if compression == "none" else compression
        self.compress = _compressor(compression)
        self.queue: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=_QUEUE_CHUNKS)
        self.error: BaseException | None = None
        self.position = 0
        self.synced = 0  # file position up to which the data was last handed to the disk
        self.chunk_indexes: list[bytes] = []
        self.metadata_indexes: list[bytes] = []

    def submit(self, kind: str, item: Any) -> None:
        self.queue.put((kind, item))

    def run(self) -> None:
        while True:
            kind, item = self.queue.get()
            if self.error is None:
                try:
                    if kind == "raw":
                        self._write(item)
                    elif kind == "metadata":
                        self._metadata(*item)
                    elif kind == "chunk":
                        self._chunk(item)
                    elif kind == "finish":
                        self._finish(item)
                except BaseException as exc:  # reported to the caller by the next write/close
                    self.error = exc
            if kind in ("finish", "stop"):
                return

    def _write(self, data: bytes) -> None:
        self.file.write(data)
        self.position += len(data)

    def _metadata(self, name: str, content: bytes) -> None:
        offset = self.position
        record = _record(_OP_METADATA, content)
        self._write(record)
        self.metadata_indexes.append(
            _record(_OP_METADATA_INDEX, struct.pack("<QQ", offset, len(record)) + _string(name))
        )

    def _chunk(self, chunk: _Chunk) -> None:
        pieces = _slices(chunk.pieces)
        crc = 0
        for piece in pieces:
            crc = zlib.crc32(piece, crc)
        if self.compress is None:
            data = pieces
            compressed_size = chunk.size
        else:
            data = self.compress(pieces, chunk.size)
            compressed_size = sum(len(piece) for piece in data)  # compressor output: bytes
        tail = _string(self.compression) + _U64.pack(compressed_size)
        content_length = 8 + 8 + 8 + 4 + len(tail) + compressed_size
        start = self.position
        self._write(
            struct.pack("<BQQQQI", _OP_CHUNK, content_length, chunk.start, chunk.end, chunk.size, crc) + tail
        )
        self.file.writelines(data)
        self.position += compressed_size
        end = self.position
        offsets: list[bytes] = []
        indexes: list[bytes] = []
        at = self.position
        for channel_id, flat in chunk.indexes.items():
            offsets.append(struct.pack("<HQ", channel_id, at))
            indexes.append(
                _record(
                    _OP_MESSAGE_INDEX,
                    struct.pack(f"<HI{len(flat)}Q", channel_id, 8 * len(flat), *flat),
                )
            )
            at += len(indexes[-1])
        index_data = b"".join(indexes)
        self._write(index_data)
        offset_map = b"".join(offsets)
        self.chunk_indexes.append(
            _record(
                _OP_CHUNK_INDEX,
                struct.pack("<QQQQ", chunk.start, chunk.end, start, end - start)
                + _U32.pack(len(offset_map))
                + offset_map
                + _U64.pack(len(index_data))
                + _string(self.compression)
                + struct.pack("<QQ", compressed_size, chunk.size),
            )
        )
        if self.position - self.synced >= _SYNC_EVERY:
            self._sync()

    def _sync(self) -> None:
        """Hand what is written so far to the disk (fdatasync, without the GIL, on this thread): the fsync
        in `close` then waits only for the tail instead of the whole recording (a 150 MB uncompressed
        recording took 60 ms to fsync at the end of a 1.3 s run)."""
        self.file.flush()
        _datasync(self.file.fileno())
        self.synced = self.position

    def _finish(self, summary: _Summary) -> None:
        self._write(_record(_OP_DATA_END, _U32.pack(0)))
        summary_start = self.position
        groups = [
            (_OP_SCHEMA, summary.schemas),
            (_OP_CHANNEL, summary.channels),
            (_OP_STATISTICS, [summary.statistics]),
            (_OP_CHUNK_INDEX, self.chunk_indexes),
            (_OP_METADATA_INDEX, self.metadata_indexes),
        ]
        parts: list[bytes] = []
        offsets: list[bytes] = []
        at = summary_start
        for opcode, records in groups:
            if not records:
                continue
            length = sum(len(r) for r in records)
            parts.extend(records)
            offsets.append(_record(_OP_SUMMARY_OFFSET, struct.pack("<BQQ", opcode, at, length)))
            at += length
        summary_offset_start = at
        body = b"".join(parts + offsets)
        footer_head = struct.pack("<BQQQ", _OP_FOOTER, 20, summary_start, summary_offset_start)
        crc = zlib.crc32(footer_head, zlib.crc32(body))
        self._write(body + footer_head + _U32.pack(crc) + _MAGIC)
        self.file.flush()
        os.fsync(self.file.fileno())


class McapRecorder:
    """Writes ROS 2 messages to an MCAP file; a context manager (close on success, abort on error).

    `topics` are shell-style globs (fnmatch, case-sensitive; `*` also matches `/`): a message is recorded
    when its topic matches any of them. `metadata` maps a metadata record name (e.g. `carlos.spec`) to its
    string → string map; the records are written before the first message."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        topics: Iterable[str] = ("*",),
        compression: Compression = "zstd",
        metadata: Mapping[str, Mapping[str, str]] | None = None,
        chunk_size: int = 4 * 1024 * 1024,
    ) -> None:
        if compression not in _COMPRESSIONS:
            raise RecorderError(f"unknown compression {compression!r}: use one of zstd, lz4, none")
        self.path = Path(path)
        self.part_path = self.path.with_name(self.path.name + ".part")
        self.topics: tuple[str, ...] = tuple(topics)
        if not self.topics:
            raise RecorderError("no topic patterns: use ['*'] to record every topic")
        if chunk_size <= 0:
            raise RecorderError(f"chunk_size must be positive, not {chunk_size}")
        self.compression: Compression = compression
        self.chunk_size = chunk_size
        self._schemas: dict[str, int] = {}
        self._schema_records: list[bytes] = []
        self._channels: dict[str, tuple[int, str]] = {}  # topic → (channel id, typename)
        self._channel_records: list[bytes] = []
        self._sequence: dict[int, int] = {}
        self._counts: dict[int, int] = {}
        self._wanted: dict[str, bool] = {}
        self._chunk = _Chunk()
        self._start = 0
        self._end = 0
        self._chunks = 0
        self._metadata_count = 0
        self.message_count = 0
        self._closed = False
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] = open(self.part_path, "wb", buffering=1024 * 1024)  # noqa: SIM115 - closed in close()/abort()
        self._writer = _FileWriter(self._file, compression)
        try:
            self._writer.submit("raw", _MAGIC + _record(_OP_HEADER, _string("ros2") + _string(_library())))
            self._writer.start()
            for name, data in (metadata or {}).items():
                self.add_metadata(name, data)
        except BaseException:
            self._writer.submit("stop", None)
            if self._writer.is_alive():
                self._writer.join()
            self._file.close()
            self.part_path.unlink(missing_ok=True)
            raise

    @classmethod
    def for_recording(
        cls,
        path: str | os.PathLike[str],
        recording: Recording,
        metadata: Mapping[str, Mapping[str, str]] | None = None,
    ) -> McapRecorder:
        """A recorder configured by the spec's `recording` section (topics, compression)."""
        return cls(path, topics=recording.topics, compression=recording.compression, metadata=metadata)

    # --- writing -----------------------------------------------------------------------------------------

    def wants(self, topic: str) -> bool:
        """Whether `topic` matches the topic patterns."""
        wanted = self._wanted.get(topic)
        if wanted is None:
            wanted = any(fnmatch.fnmatchcase(topic, pattern) for pattern in self.topics)
            self._wanted[topic] = wanted
        return wanted

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record: `name` → string map (values must be strings: serialise structures as JSON)."""
        self._check_open()
        bad = [key for key, value in data.items() if not isinstance(key, str) or not isinstance(value, str)]
        if bad:
            raise RecorderError(f"metadata {name!r}: keys and values must be strings (not: {bad!r})")
        self._submit("metadata", (name, _string(name) + _map(data)))
        self._metadata_count += 1

    def _channel(self, topic: str, typename: str) -> int:
        known = self._channels.get(topic)
        if known is not None:
            channel_id, known_type = known
            if known_type != typename:
                raise RecorderError(
                    f"topic {topic!r} has type {known_type!r}; cannot also record {typename!r}"
                )
            return channel_id
        try:
            text = msgdef(typename)
        except KeyError:
            raise RecorderError(f"topic {topic!r}: unknown message type {typename!r}") from None
        return self._new_channel(
            topic, typename, "ros2msg", text.encode("utf-8"), "cdr", {"offered_qos_profiles": DEFAULT_QOS}
        )

    def _new_channel(
        self,
        topic: str,
        schema_name: str,
        schema_encoding: str,
        schema_data: bytes,
        message_encoding: str,
        metadata: Mapping[str, str],
    ) -> int:
        """The schema record (once per schema name) and the channel record of a new topic, into the chunk."""
        chunk = self._chunk
        schema_id = self._schemas.get(schema_name)
        if schema_id is None:
            schema_id = self._schemas[schema_name] = len(self._schemas) + 1
            record = _record(
                _OP_SCHEMA,
                _U16.pack(schema_id)
                + _string(schema_name)
                + _string(schema_encoding)
                + _U32.pack(len(schema_data))
                + schema_data,
            )
            self._schema_records.append(record)
            chunk.pieces.append(record)
            chunk.size += len(record)
        channel_id = len(self._channels) + 1
        record = _record(
            _OP_CHANNEL,
            _U16.pack(channel_id)
            + _U16.pack(schema_id)
            + _string(topic)
            + _string(message_encoding)
            + _map(metadata),
        )
        self._channel_records.append(record)
        chunk.pieces.append(record)
        chunk.size += len(record)
        self._channels[topic] = (channel_id, schema_name)
        self._sequence[channel_id] = 0
        self._counts[channel_id] = 0
        return channel_id

    def add_channel(
        self,
        topic: str,
        schema_name: str,
        schema_encoding: str,
        schema_data: bytes,
        message_encoding: str,
        metadata: Mapping[str, str],
    ) -> None:
        """A channel of a schema other than a ROS 2 message (e.g. protobuf `osi3.GroundTruth`): `write(topic,
        schema_name, data, t)` then records encoded `data` on it. Recorded whatever the topic patterns say."""
        self._check_open()
        if topic in self._channels:
            raise RecorderError(f"topic {topic!r} already has a channel")
        self._new_channel(topic, schema_name, schema_encoding, schema_data, message_encoding, metadata)
        self._wanted[topic] = True

    def write(self, topic: str, typename: str, msg: Any, time_s: float) -> bool:
        """Record `msg` on `topic` at simulated time `time_s`: a rosbags message of `typename`, or its CDR
        serialisation (`bytes`, `bytearray` or `memoryview`, written as it is: what a transport received).
        Returns False when the topic is filtered out."""
        if self._closed:
            self._check_open()
        if not self.wants(topic):
            return False
        pieces: tuple[Piece, ...]
        if isinstance(msg, bytes):
            pieces = (msg,)
        elif isinstance(msg, bytearray | memoryview):
            pieces = (bytes(msg),)
        else:
            after = _BLOB_TYPES.get(typename)
            pieces = (serialize(msg),) if after is None else _cdr_pieces(msg, after)
        size = sum(len(piece) if isinstance(piece, bytes) else piece.nbytes for piece in pieces)
        channel_id = self._channel(topic, typename)
        ns = _ns(time_s)
        seq = self._sequence[channel_id] = (self._sequence[channel_id] + 1) & 0xFFFFFFFF
        self._counts[channel_id] += 1
        chunk = self._chunk
        index = chunk.indexes.get(channel_id)
        if index is None:
            index = chunk.indexes[channel_id] = []
        index.append(ns)
        index.append(chunk.size)
        head = _MESSAGE_HEAD.pack(_OP_MESSAGE, _MESSAGE_FIXED + size, channel_id, seq, ns, ns)
        chunk.pieces.append(head)
        chunk.pieces.extend(pieces)
        chunk.size += len(head) + size
        if chunk.messages == 0:
            chunk.start = chunk.end = ns
        elif ns < chunk.start:
            chunk.start = ns
        elif ns > chunk.end:
            chunk.end = ns
        chunk.messages += 1
        if self.message_count == 0:
            self._start = self._end = ns
        elif ns < self._start:
            self._start = ns
        elif ns > self._end:
            self._end = ns
        self.message_count += 1
        if chunk.size >= self.chunk_size:
            self._flush_chunk()
        return True

    def write_message(self, message: Message) -> None:
        """`write` of a bus message: its CDR bytes when it carries them; else its object, serialised here
        (kept on the message, so that a message object delivered on several topics is serialised once), but
        for point clouds and images, whose arrays are written without a copy."""
        if message.data is not None:
            payload: Any = message.data
        elif message.typename in _BLOB_TYPES:
            payload = message.obj()
        else:
            if not self.wants(message.topic):
                return
            payload = message.cdr()
        self.write(message.topic, message.typename, payload, message.time_s)

    def write_frame(self, frame: WorldFrame) -> int:
        """Record one step's messages (the topics of `frame_builders`, their CDR written straight from the
        frame); returns how many were recorded."""
        self._check_open()
        written = 0
        for topic, typename, _, encode in frame_builders(frame):
            if self.wants(topic) and self.write(topic, typename, encode(), frame.time):
                written += 1
        return written

    def _flush_chunk(self) -> None:
        chunk = self._chunk
        if not chunk.pieces:
            return
        self._chunk = _Chunk()
        self._chunks += 1
        self._submit("chunk", chunk)

    def _submit(self, kind: str, item: Any) -> None:
        error = self._writer.error
        if error is not None:
            raise RecorderError(f"cannot write {self.part_path}: {error}") from error
        self._writer.submit(kind, item)

    # --- ending ------------------------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise RecorderError(f"the recorder of {self.path} is closed")

    def _statistics(self) -> bytes:
        counts = b"".join(struct.pack("<HQ", cid, n) for cid, n in self._counts.items())
        return _record(
            _OP_STATISTICS,
            struct.pack(
                "<QHIIIIQQ",
                self.message_count,
                len(self._schemas),
                len(self._channels),
                0,  # attachments
                self._metadata_count,
                self._chunks,
                self._start,
                self._end,
            )
            + _U32.pack(len(counts))
            + counts,
        )

    def _finish(self) -> None:
        """Write the open chunk and the summary, wait for the writer thread; raise its error."""
        try:
            if self._writer.error is None:
                self._flush_chunk()
            self._writer.submit(
                "finish", _Summary(self._schema_records, self._channel_records, self._statistics())
            )
        finally:
            self._writer.join()
        if self._writer.error is not None:
            error = self._writer.error
            raise RecorderError(f"cannot write {self.part_path}: {error}") from error

    def close(self) -> None:
        """Finish the file, fsync it and rename `<path>.part` to `path` atomically. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._finish()
        finally:
            self._file.close()
        os.replace(self.part_path, self.path)
        fsync_dir(self.path.parent)

    def abort(self, *, keep_partial: bool = True) -> None:
        """End without publishing `path`: the partial recording stays as `<path>.part` (finished as far as
        possible, so it is readable) or is deleted when `keep_partial` is False."""
        if self._closed:
            return
        self._closed = True
        try:
            self._finish()
        except Exception:  # an abort keeps what could be written
            pass
        finally:
            self._file.close()
            if not keep_partial:
                self.part_path.unlink(missing_ok=True)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
