"""MCAP recorder: the world state of every step as ROS 2 messages in one `recording.mcap`.

The file is what `ros2 bag record -s mcap` writes on jazzy: profile `ros2`, one schema per message type
(encoding `ros2msg`, the concatenated `.msg` text), one channel per topic (message encoding `cdr`,
`offered_qos_profiles` in the channel metadata), log and publish time = simulated time in ns from 0.
Metadata records (e.g. `carlos.spec`, `carlos.run`) carry the spec, parameters, seed and versions.

It is readable by `mcap` + `mcap_ros2`, Foxglove, `ros2 bag play/info` (a bare .mcap file is accepted
by rosbag2 since humble), and rosbags (`AnyReader([Path("recording.mcap")])`: rosbags ≥ 0.10 opens a
bare `.mcap` file, no metadata.yaml needed).

Crash safety: the recorder writes `<path>.part` and renames it to `path` only in :meth:`McapRecorder.close`,
after an fsync; a run that dies never leaves a file under the final name. On an exception inside the
`with` block the partial recording is finished (a valid MCAP up to the last message) and kept as
`<path>.part` for debugging.
"""

from __future__ import annotations

import contextlib
import fnmatch
import os
from collections.abc import Iterable, Mapping
from importlib import metadata as importlib_metadata
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Literal, Self

from mcap.writer import CompressionType, Writer

from simcore.spec import Recording
from simcore.store import fsync_dir
from simcore.transport.messages import frame_messages, msgdef, serialize
from simcore.world.state import WorldFrame

__all__ = ["DEFAULT_QOS", "Compression", "McapRecorder", "RecorderError"]

Compression = Literal["zstd", "lz4", "none"]

_COMPRESSION: dict[str, CompressionType] = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}

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


class RecorderError(RuntimeError):
    """The recording cannot be written (bad arguments, closed recorder, I/O error)."""


def _library() -> str:
    try:
        carlos = importlib_metadata.version("carlos")
    except importlib_metadata.PackageNotFoundError:
        carlos = "unknown"
    try:
        mcap = importlib_metadata.version("mcap")
    except importlib_metadata.PackageNotFoundError:
        mcap = "unknown"
    return f"carlos {carlos} (mcap-python {mcap})"


def _ns(time_s: float) -> int:
    ns = round(time_s * 1e9)
    if ns < 0:
        raise RecorderError(f"negative simulation time {time_s}")
    return ns


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
        chunk_size: int = 1024 * 1024,
    ) -> None:
        if compression not in _COMPRESSION:
            raise RecorderError(f"unknown compression {compression!r}: use one of zstd, lz4, none")
        self.path = Path(path)
        self.part_path = self.path.with_name(self.path.name + ".part")
        self.topics: tuple[str, ...] = tuple(topics)
        if not self.topics:
            raise RecorderError("no topic patterns: use ['*'] to record every topic")
        self.compression: Compression = compression
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}  # topic → (channel id, typename)
        self._sequence: dict[int, int] = {}
        self._wanted: dict[str, bool] = {}
        self.message_count = 0
        self._closed = False
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] = open(self.part_path, "wb")  # noqa: SIM115 - closed in close()/abort()
        try:
            self._writer = Writer(self._file, chunk_size=chunk_size, compression=_COMPRESSION[compression])
            self._writer.start(profile="ros2", library=_library())
            for name, data in (metadata or {}).items():
                self.add_metadata(name, data)
        except BaseException:
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
        self._writer.add_metadata(name, dict(data))

    def _channel(self, topic: str, typename: str) -> int:
        known = self._channels.get(topic)
        if known is not None:
            channel_id, known_type = known
            if known_type != typename:
                raise RecorderError(
                    f"topic {topic!r} has type {known_type!r}; cannot also record {typename!r}"
                )
            return channel_id
        schema_id = self._schemas.get(typename)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=typename, encoding="ros2msg", data=msgdef(typename).encode("utf-8")
            )
            self._schemas[typename] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic,
            message_encoding="cdr",
            schema_id=schema_id,
            metadata={"offered_qos_profiles": DEFAULT_QOS},
        )
        self._channels[topic] = (channel_id, typename)
        self._sequence[channel_id] = 0
        return channel_id

    def write(self, topic: str, typename: str, msg: Any, time_s: float) -> bool:
        """Record `msg` (a rosbags message of `typename`) on `topic` at simulated time `time_s`.
        Returns False when the topic is filtered out."""
        self._check_open()
        if not self.wants(topic):
            return False
        data = serialize(msg)
        channel_id = self._channel(topic, typename)
        ns = _ns(time_s)
        self._sequence[channel_id] += 1
        self._writer.add_message(
            channel_id=channel_id,
            log_time=ns,
            publish_time=ns,
            data=data,
            sequence=self._sequence[channel_id],
        )
        self.message_count += 1
        return True

    def write_frame(self, frame: WorldFrame) -> int:
        """Record one step's messages (`frame_messages`); returns how many were recorded."""
        self._check_open()
        written = 0
        for topic, typename, msg in frame_messages(frame):
            if self.write(topic, typename, msg, frame.time):
                written += 1
        return written

    # --- ending ------------------------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise RecorderError(f"the recorder of {self.path} is closed")

    def _finish(self) -> None:
        self._writer.finish()
        self._file.flush()
        os.fsync(self._file.fileno())

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
            with contextlib.suppress(Exception):
                self._finish()
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
