"""The world topics' direct CDR (simcore/transport/world_cdr.py) against rosbags' serialiser as the oracle:
the same bytes for every message of randomised frames and their edge cases, on every path that uses it."""

from __future__ import annotations

import math
import random
import struct
from pathlib import Path
from typing import Any

import pytest

from simcore.recorder import McapRecorder
from simcore.transport import messages, world_cdr
from simcore.transport.bus import InProcessBus, Message
from simcore.transport.world import WorldPublisher
from simcore.world.state import BoundingBox, EntityState, WorldFrame

#: floats that must keep their exact bits
SPECIAL = [
    0.0,
    -0.0,
    math.nan,
    -math.nan,
    math.inf,
    -math.inf,
    5e-324,
    -5e-324,
    1.7976931348623157e308,
    1e-300,
]
#: names and categories: empty, ASCII of every length mod 8, non-ASCII (multi-byte UTF-8), long, not ROS tokens
WORDS = [
    "",
    "a",
    "Ego",
    "car",
    "truck",
    "Ego_0_-1",
    "car 2",
    "3rd",
    "pedestrian",
    "Fußgänger",
    "車両",
    "🚗🚙",
    "x" * 255,
    "é" * 101,
]


def _float(rng: random.Random) -> float:
    pick = rng.random()
    if pick < 0.15:
        return rng.choice(SPECIAL)
    if pick < 0.3:
        return rng.uniform(-1e12, 1e12)
    return rng.uniform(-500.0, 500.0)


def _angle(rng: random.Random) -> float:
    """An angle: any float but ±inf (whose cosine is a math domain error, either way)."""
    value = _float(rng)
    return value if not math.isinf(value) else math.nan


def _word(rng: random.Random) -> str:
    if rng.random() < 0.5:
        return rng.choice(WORDS)
    alphabet = "abcXYZ09_- .äß中"
    return "".join(rng.choice(alphabet) for _ in range(rng.randrange(0, 40)))


def _entity(rng: random.Random, name: str) -> EntityState:
    return EntityState(
        name=name,
        object_type="vehicle",
        category=_word(rng),
        x=_float(rng),
        y=_float(rng),
        z=_float(rng),
        heading=_angle(rng),
        pitch=_angle(rng),
        roll=_angle(rng),
        speed=_float(rng),
        acceleration=_float(rng),
        yaw_rate=_float(rng),
        bbox=BoundingBox(*(_float(rng) for _ in range(6))),
    )


def _frame(rng: random.Random) -> WorldFrame:
    """A frame of 0–5 entities and 0–2 ghosts with distinct names (as `frame_builders` requires)."""
    names: list[str] = []
    while len(names) < rng.randrange(0, 8):
        name = _word(rng) or "entity"
        if all(messages.ros_name(name) != messages.ros_name(other) for other in names):
            names.append(name)
    ghosts = rng.randrange(0, min(2, len(names)) + 1)
    time_s = rng.choice(
        [0.0, 1e-9, 0.05 * rng.randrange(0, 10_000), rng.uniform(0, 2.0**31 - 1), 2.9999999995]
    )
    bodies = [_entity(rng, name) for name in names]
    return WorldFrame(
        step=rng.randrange(0, 1 << 31),
        time=time_s,
        entities=tuple(bodies[ghosts:]),
        ghosts=tuple(bodies[:ghosts]),
    )


def _both_ways(frame: WorldFrame) -> list[tuple[str, bytes, bytes]]:
    """(topic, rosbags' bytes, direct bytes) of every topic of the frame."""
    return [
        (topic, messages.serialize(build()), encode())
        for topic, _, build, encode in messages.frame_builders(frame)
    ]


def test_direct_cdr_equals_rosbags_for_random_frames() -> None:
    rng = random.Random(35)
    compared: dict[str, int] = {}
    paddings = set()
    for _ in range(400):
        frame = _frame(rng)
        for topic, expected, have in _both_ways(frame):
            assert have == expected, f"{topic} at t={frame.time!r}: {have.hex()} != {expected.hex()}"
            kind = topic if not topic.endswith("/odometry") else "odometry"
            compared[kind] = compared.get(kind, 0) + 1
        paddings.update(len(world_cdr.cdr_string(e.name)) % 8 for e in (*frame.entities, *frame.ghosts))
    # what the frames covered: every topic, many times; strings of every length mod 8 (all paddings)
    assert set(compared) == {"/clock", "/tf", "/carlos/objects", "odometry"}
    assert min(compared.values()) >= 400
    assert paddings == set(range(8))


def test_direct_cdr_edge_cases() -> None:
    bbox = BoundingBox(1.4, -0.0, 0.75, 4.5, 1.8, 1.5)
    angles = [a for a in SPECIAL if not math.isinf(a)]
    special = [
        EntityState(name, "vehicle", name, v, -v, v, a, -a, a, v, 0.0, -v, bbox)
        for name, v, a in zip(WORDS[1:], [*SPECIAL, *SPECIAL], [*angles, *angles], strict=False)
    ]
    frames = [
        WorldFrame(0, 0.0, ()),  # empty sequences
        WorldFrame(1, 0.05, (), ghosts=tuple(special[:1])),  # ghosts only: tf and odometry, no objects
        WorldFrame(2, 123456.789, tuple(special)),
        WorldFrame(3, 2.0**31 - 1, tuple(special[::-1])),
    ]
    for frame in frames:
        for topic, expected, have in _both_ways(frame):
            assert have == expected, topic
    negative = WorldFrame(0, -0.1, ())
    for _, _, build, encode in messages.frame_builders(negative):
        with pytest.raises(ValueError, match="negative simulation time"):
            build()
        with pytest.raises(ValueError, match="negative simulation time"):
            encode()
    beyond_int32 = WorldFrame(0, 2.0**31, (special[0],))  # builtin_interfaces/Time's sec is an int32
    for _, _, build, encode in messages.frame_builders(beyond_int32):
        with pytest.raises(struct.error):
            messages.serialize(build())
        with pytest.raises(struct.error):
            encode()


def test_bus_messages_carry_the_direct_cdr_and_build_objects_on_demand() -> None:
    frame = _frame(random.Random(7))
    bus = InProcessBus()
    got: list[Message] = []
    bus.subscribe("*", got.append)
    WorldPublisher(bus).publish(frame)
    assert len(got) == len(messages.frame_builders(frame))
    for message in got:
        assert message.msg is None and message.data is None  # nothing made before a consumer asks
        data = message.cdr()
        assert message.msg is None  # the bytes came without the object
        assert data == messages.serialize(message.obj())
        assert message.obj().__msgtype__ == message.typename


def test_a_world_publisher_publishes_only_while_someone_consumes_also_one_who_came_later() -> None:
    """`FrameReaders` reads `consumers` every step: an in-process bus's subscriptions as they grow."""
    from simcore.stepping import FrameReaders

    frame = _frame(random.Random(3))
    bus = InProcessBus()
    world = WorldPublisher(bus)
    readers = FrameReaders(world)
    assert not world.has_consumers() and not world.consumers
    readers.take(frame)  # nobody: nothing built, nothing sent
    got: list[Message] = []
    bus.subscribe("/clock", got.append)
    assert world.has_consumers()
    readers.take(frame)
    assert [m.topic for m in got] == ["/clock"]

    class Transport:  # a bus to other processes (loopback, DDS): its consumers are elsewhere
        def advertise(self, topic: str, typename: str) -> Any:
            raise AssertionError("not published here")

        def subscribe(self, pattern: str, callback: Any) -> None: ...

        def close(self) -> None: ...

    assert WorldPublisher(Transport()).has_consumers()


def _record(path: Path, frames: list[WorldFrame], write: Any) -> bytes:
    with McapRecorder(path, topics=["*"], compression="zstd") as recorder:
        for frame in frames:
            write(recorder, frame)
    return path.read_bytes()


def test_recordings_are_the_same_bytes_as_from_rosbags_objects(tmp_path: Path) -> None:
    rng = random.Random(11)
    names = ["Ego", "Fußgänger 1", "車両"]
    frames = [
        WorldFrame(
            step, step * 0.05, tuple(_entity(rng, n) for n in names[1:]), ghosts=(_entity(rng, names[0]),)
        )
        for step in range(300)
    ]

    def objects(recorder: McapRecorder, frame: WorldFrame) -> None:
        for topic, typename, msg in messages.frame_messages(frame):
            recorder.write(topic, typename, msg, frame.time)

    def direct(recorder: McapRecorder, frame: WorldFrame) -> None:
        recorder.write_frame(frame)

    def bus(recorder: McapRecorder, frame: WorldFrame) -> None:
        in_process = InProcessBus()
        in_process.subscribe("*", recorder.write_message, wants=recorder.wants)
        WorldPublisher(in_process).publish(frame)

    expected = _record(tmp_path / "objects.mcap", frames, objects)
    assert _record(tmp_path / "direct.mcap", frames, direct) == expected
    assert _record(tmp_path / "bus.mcap", frames, bus) == expected
