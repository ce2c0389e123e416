"""The CDR of the world topics written straight from a frame, without rosbags' message objects.

Each function returns exactly the bytes `simcore.transport.messages.serialize` gives for the message the
builder of the same name in `simcore.transport.messages` makes (tests/test_world_cdr.py holds them to
rosbags' serialiser as the oracle): CDR, little endian, after the 4-byte encapsulation header `00 01 00 00`;
every primitive aligned to its size counted from the end of that header, padding zero; a string as its
uint32 length (with the NUL) then its UTF-8 bytes and a NUL; a sequence as its uint32 count then the
elements; a fixed array (a covariance) as its elements alone.

A message is one `struct.Struct.pack` of a format made for its layout: the layout depends only on the
lengths of its strings (entity names, categories), so the format of a run's frames is made once and cached;
constant parts (the `map` frame id, zero covariances, padding) are in the format or passed as prepared bytes.

Like the builders called through `frame_builders`, these expect `frame_builders`' check that entity names
map to distinct ROS names.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from struct import Struct

from simcore.transport.conversions import quaternion_xyzw, stamp_parts
from simcore.transport.ros_names import MAP_FRAME, base_link
from simcore.world.state import EntityState, WorldFrame

__all__ = ["ENCAPSULATION", "cdr_string", "clock", "objects", "odometry", "tf"]

#: The encapsulation header rosbags writes: CDR little endian (0x0001), options 0.
ENCAPSULATION = b"\x00\x01\x00\x00"

_CACHED_LAYOUTS = 256


@lru_cache(maxsize=4096)
def cdr_string(text: str) -> bytes:
    """A CDR string: uint32 length of the UTF-8 bytes plus the NUL, the bytes, the NUL (alignment apart)."""
    data = text.encode()
    return (len(data) + 1).to_bytes(4, "little") + data + b"\x00"


_MAP = cdr_string(MAP_FRAME)


class _Layout:
    """A struct format made field by field, each field aligned as CDR aligns it (offsets counted from the
    end of the encapsulation header, which is the format's first field)."""

    def __init__(self) -> None:
        self.parts = ["<4s"]
        self.pos = 0

    def field(self, code: str, align: int, size: int) -> None:
        pad = -self.pos % align
        if pad:
            self.parts.append(f"{pad}x")
        self.parts.append(code)
        self.pos += pad + size

    def string(self, size: int) -> None:
        """A string prepared by `cdr_string` (`size` bytes with its length)."""
        self.field(f"{size}s", 4, size)

    def header(self) -> None:
        """std_msgs/Header: stamp (int32 sec, uint32 nanosec), frame_id `map`."""
        self.field("iI", 4, 8)
        self.string(len(_MAP))

    def struct(self) -> Struct:
        return Struct("".join(self.parts))


def _pose_with_covariance(layout: _Layout) -> None:
    """geometry_msgs/PoseWithCovariance: position and orientation (7 float64), a zero covariance[36]."""
    layout.field("7d", 8, 56)
    layout.field("288x", 8, 288)


_CLOCK = Struct("<4siI")


def clock(frame: WorldFrame) -> bytes:
    """rosgraph_msgs/msg/Clock (see `messages.clock`)."""
    sec, nanosec = stamp_parts(frame.time)
    return _CLOCK.pack(ENCAPSULATION, sec, nanosec)


@lru_cache(maxsize=_CACHED_LAYOUTS)
def _tf_layout(children: tuple[int, ...]) -> Struct:
    layout = _Layout()
    layout.field("I", 4, 4)
    for size in children:  # TransformStamped: header, child_frame_id, translation + rotation
        layout.header()
        layout.string(size)
        layout.field("7d", 8, 56)
    return layout.struct()


def tf(frame: WorldFrame) -> bytes:
    """tf2_msgs/msg/TFMessage (see `messages.tf`)."""
    sec, nanosec = stamp_parts(frame.time)
    bodies = (*frame.entities, *frame.ghosts)
    children = [cdr_string(base_link(body.name)) for body in bodies]
    values: list[object] = [ENCAPSULATION, len(bodies)]
    for body, child in zip(bodies, children, strict=True):
        values += (sec, nanosec, _MAP, child, body.x, body.y, body.z)
        values += quaternion_xyzw(body.heading, body.pitch, body.roll)
    return _tf_layout(tuple(len(child) for child in children)).pack(*values)


@lru_cache(maxsize=_CACHED_LAYOUTS)
def _odometry_layout(child: int) -> Struct:
    layout = _Layout()
    layout.header()
    layout.string(child)
    _pose_with_covariance(layout)
    layout.field("6d", 8, 48)  # TwistWithCovariance: linear, angular
    layout.field("288x", 8, 288)
    return layout.struct()


def odometry(frame: WorldFrame, state: EntityState) -> bytes:
    """nav_msgs/msg/Odometry of one entity (see `messages.odometry`)."""
    sec, nanosec = stamp_parts(frame.time)
    child = cdr_string(base_link(state.name))
    qx, qy, qz, qw = quaternion_xyzw(state.heading, state.pitch, state.roll)
    return _odometry_layout(len(child)).pack(
        ENCAPSULATION,
        sec,
        nanosec,
        _MAP,
        child,
        state.x,
        state.y,
        state.z,
        qx,
        qy,
        qz,
        qw,
        state.speed,
        0.0,
        0.0,
        0.0,
        0.0,
        state.yaw_rate,
    )


@lru_cache(maxsize=_CACHED_LAYOUTS)
def _objects_layout(detections: tuple[tuple[int, int], ...]) -> Struct:
    layout = _Layout()
    layout.header()
    layout.field("I", 4, 4)
    for class_id, name in detections:  # Detection3D
        layout.header()
        layout.field("I", 4, 4)  # results: one ObjectHypothesisWithPose
        layout.string(class_id)
        layout.field("d", 8, 8)  # score
        _pose_with_covariance(layout)
        layout.field("10d", 8, 80)  # bbox: centre (position, orientation), size
        layout.string(name)  # id
    return layout.struct()


def objects(frame: WorldFrame) -> bytes:
    """vision_msgs/msg/Detection3DArray, the ground truth (see `messages.objects`)."""
    sec, nanosec = stamp_parts(frame.time)
    entities: Sequence[EntityState] = frame.entities
    values: list[object] = [ENCAPSULATION, sec, nanosec, _MAP, len(entities)]
    sizes = []
    for entity in entities:
        class_id, name = cdr_string(entity.category), cdr_string(entity.name)
        sizes.append((len(class_id), len(name)))
        cx, cy, cz = entity.box_center()
        qx, qy, qz, qw = quaternion_xyzw(entity.heading)
        bbox = entity.bbox
        values += (sec, nanosec, _MAP, 1, class_id, 1.0, cx, cy, cz, qx, qy, qz, qw)
        values += (cx, cy, cz, qx, qy, qz, qw, bbox.length, bbox.width, bbox.height, name)
    return _objects_layout(tuple(sizes)).pack(*values)
