"""Point clouds through CARLOS' topic paths: messages/s and MB/s, and CDR serialisation cost per message.

One sensor_msgs/PointCloud2 of 65,536 points (x, y, z, intensity: float32; label: uint32; 20 bytes a point,
1.31 MB of CDR), published COUNT times as fast as the path takes it, through:

- in-process: `InProcessBus` (the embedded executor): the subscriber gets the object, nothing serialised;
  "+cdr" is the same with the subscriber asking for the CDR bytes (what the recorder does);
- loopback: publisher process → `LoopbackHub` + subscriber in another process (the pod's default transport);
- dds: publisher process → subscriber process over cyclonedds (`DdsBus`, 127.0.0.1, unicast discovery),
  the subscriber decoding every sample (`decode`: message object + exact bytes); "keep-last 10" is the same
  with ROS 2's default history on the writer: what a subscriber that cannot keep up loses ("received").

Cross-process rates run from the first publish to the subscriber's last receipt (CLOCK_MONOTONIC is
system-wide), after one warm-up message. "10 Hz eq." = messages/s ÷ 10: how many 65k-point lidars at 10 Hz
the path carries. Serialisation: rosbags' `serialize` (what every path uses; a memcpy of the point array)
versus building the cyclonedds IDL object of the generated type and letting cyclonedds serialise it (the
element-by-element path avoided), and the receiving side's `decode`.

Round trip: a small message (rosgraph_msgs/Clock) to another process that answers at once, through the
loopback hub and through DDS: the transport's share of a lockstep step (simulator → controller → simulator).

Prints a table and, as its last line, one JSON object with the figures. No assertions: machines are noisy.
"""

from __future__ import annotations

import json
import os
import random
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore.transport.bus import InProcessBus, Message  # noqa: E402
from simcore.transport.messages import TYPESTORE, serialize  # noqa: E402

POINTS = 65_536
COUNT = int(os.environ.get("BENCH_COUNT", "200"))
TOPIC = "/carlos/Ego/lidar/points"
TYPE = "sensor_msgs/msg/PointCloud2"

SUBSCRIBER = textwrap.dedent(
    """
    import sys, time, json
    sys.path.insert(0, sys.argv[1])
    mode, count, arg, topic, history = sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5], sys.argv[6]
    state = {"n": 0, "bytes": 0, "last": 0.0, "first": 0.0}

    def on_points(message):
        if mode == "dds":
            message.obj()  # decoded already: the object and the exact bytes
        state["n"] += 1
        state["bytes"] += len(message.cdr())
        if state["n"] == 2:
            state["first"] = time.monotonic()
        state["last"] = time.monotonic()

    if mode == "dds":
        from simcore.transport.dds import DdsBus, loopback_config
        bus = DdsBus(int(arg), config=loopback_config(), history=int(history) or None)
    else:
        from simcore.transport.loopback import LoopbackBus, LoopbackHub
        hub = LoopbackHub("127.0.0.1", 0).start()
        print(hub.port, flush=True)
        bus = LoopbackBus("127.0.0.1", hub.port)
    bus.subscribe(topic, on_points)
    print("READY", flush=True)
    deadline = time.monotonic() + 300
    while state["n"] < count + 1 and time.monotonic() < deadline:
        if state["n"] and time.monotonic() - state["last"] > 3.0:
            break  # nothing more for 3 s: the rest was lost
        time.sleep(0.005)
    print(json.dumps(state), flush=True)
    bus.close()
    """
)


ECHO = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, sys.argv[1])
    mode, arg = sys.argv[2], sys.argv[3]
    if mode == "dds":
        from simcore.transport.dds import DdsBus, loopback_config
        bus = DdsBus(int(arg), config=loopback_config())
    else:
        from simcore.transport.loopback import LoopbackBus
        bus = LoopbackBus("127.0.0.1", int(arg))
    pong = bus.advertise("/pong", "rosgraph_msgs/msg/Clock")
    bus.subscribe("/ping", lambda m: pong.publish(m.obj(), m.time_s))
    print("READY", flush=True)
    sys.stdin.read()
    bus.close()
    """
)
ROUND_TRIPS = 300


def round_trip(mode: str) -> float:
    """Median ms of publish → other process → reply received (a lockstep step's transport overhead)."""
    import threading

    hub = None
    if mode == "dds":
        from simcore.transport.dds import DdsBus, loopback_config

        arg = str(random.randrange(200, 232))
    else:
        from simcore.transport.loopback import LoopbackBus, LoopbackHub

        hub = LoopbackHub("127.0.0.1", 0).start()
        arg = str(hub.port)
    proc = subprocess.Popen(
        [sys.executable, "-c", ECHO, str(ROOT), mode, arg],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stdin is not None
    assert proc.stdout.readline().strip() == "READY"
    bus: Any = (
        DdsBus(int(arg), config=loopback_config()) if mode == "dds" else LoopbackBus("127.0.0.1", int(arg))
    )
    got = threading.Event()
    bus.subscribe("/pong", lambda m: got.set())
    if mode == "dds" and not bus.wait_for_subscribers("/ping", 1, timeout=30):
        raise RuntimeError("the echo process did not subscribe")
    ping = bus.advertise("/ping", "rosgraph_msgs/msg/Clock")
    clock = TYPESTORE.types["rosgraph_msgs/msg/Clock"]
    stamp = TYPESTORE.types["builtin_interfaces/msg/Time"]
    times = []
    for i in range(ROUND_TRIPS + 10):
        got.clear()
        start = time.perf_counter()
        ping.publish(clock(clock=stamp(sec=i, nanosec=0)), float(i))
        if not got.wait(10):
            raise RuntimeError(f"{mode}: no reply to ping {i}")
        if i >= 10:
            times.append(time.perf_counter() - start)
    proc.stdin.close()
    proc.wait(30)
    bus.close()
    if hub is not None:
        hub.close()
    return statistics.median(times) * 1e3


def point_cloud(seed: int = 0) -> Any:
    t = TYPESTORE.types
    from simcore.transport.messages import Header, stamp

    rng = np.random.default_rng(seed)
    points = np.zeros(POINTS, dtype=[(n, "<f4") for n in ("x", "y", "z", "intensity")] + [("label", "<u4")])
    for name in ("x", "y", "z", "intensity"):
        points[name] = rng.random(POINTS, dtype=np.float32)
    points["label"] = rng.integers(0, 20, POINTS)
    fields = [
        t["sensor_msgs/msg/PointField"](name=name, offset=4 * i, datatype=7 if i < 4 else 6, count=1)
        for i, name in enumerate(("x", "y", "z", "intensity", "label"))
    ]
    return t[TYPE](
        header=Header(stamp=stamp(0.1), frame_id="Ego/lidar"),
        height=1,
        width=POINTS,
        fields=fields,
        is_bigendian=False,
        point_step=20,
        row_step=20 * POINTS,
        data=points.view(np.uint8).reshape(-1),
        is_dense=True,
    )


def in_process(msg: Any, cdr: bool) -> float:
    bus = InProcessBus()
    seen = []

    def on_points(message: Message) -> None:
        seen.append(len(message.cdr()) if cdr else message.msg.width)

    bus.subscribe("*", on_points)
    publisher = bus.advertise(TOPIC, TYPE)
    publisher.publish(msg, 0.0)
    start = time.perf_counter()
    for i in range(COUNT):
        publisher.publish(msg, 0.1 * i)
    elapsed = time.perf_counter() - start
    assert len(seen) == COUNT + 1
    return elapsed


def cross_process(mode: str, msg: Any, history: int = 0) -> tuple[float, int, int]:
    """(seconds from the first measured publish to the last receipt, bytes received, messages received);
    `history`: the DDS writers' keep-last depth (0: keep-all, CARLOS' default)."""
    arg = str(random.randrange(200, 232)) if mode == "dds" else "0"
    env = dict(os.environ)
    proc = subprocess.Popen(
        [sys.executable, "-c", SUBSCRIBER, str(ROOT), mode, str(COUNT), arg, TOPIC, str(history)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None
    if mode == "dds":
        from simcore.transport.dds import DdsBus, loopback_config

        assert proc.stdout.readline().strip() == "READY"
        bus: Any = DdsBus(int(arg), config=loopback_config(), history=history or None)
        if not bus.wait_for_subscribers(TOPIC, 1, timeout=30):
            raise RuntimeError("the DDS subscriber did not appear")
    else:
        from simcore.transport.loopback import LoopbackBus

        port = int(proc.stdout.readline())
        assert proc.stdout.readline().strip() == "READY"
        bus = LoopbackBus("127.0.0.1", port)
    publisher = bus.advertise(TOPIC, TYPE)
    publisher.publish(msg, 0.0)  # warm-up (and the DDS match)
    time.sleep(0.5)
    start = time.monotonic()
    for i in range(COUNT):
        publisher.publish(msg, 0.1 * (i + 1))
    result = json.loads(proc.stdout.readline())
    proc.wait(60)
    bus.close()
    received = result["n"] - 1  # without the warm-up message
    return result["last"] - start, result["bytes"] - result["bytes"] // result["n"], received


def serialisation(msg: Any) -> dict[str, float]:
    from simcore.transport.dds import decode
    from simcore.transport.dds_types import idl_type

    def per_call(fn: Any, repeat: int) -> float:
        fn()
        times = []
        for _ in range(repeat):
            start = time.perf_counter()
            fn()
            times.append(time.perf_counter() - start)
        return statistics.median(times) * 1e3

    data = serialize(msg)
    padded = data + bytes(-len(data) % 4)
    rosbags_ms = per_call(lambda: serialize(msg), 20)
    decode_ms = per_call(lambda: decode(padded, TYPE), 20)
    cls = idl_type(TYPE)
    point_field = idl_type("sensor_msgs/msg/PointField")
    header = idl_type("std_msgs/msg/Header")
    time_type = idl_type("builtin_interfaces/msg/Time")

    def via_idl() -> bytes:
        obj = cls(
            header=header(stamp=time_type(sec=0, nanosec=100_000_000), frame_id="Ego/lidar"),
            height=1,
            width=POINTS,
            fields=[
                point_field(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                for f in msg.fields
            ],
            is_bigendian=False,
            point_step=20,
            row_step=20 * POINTS,
            data=msg.data.tolist(),
            is_dense=True,
        )
        out: bytes = obj.serialize(use_version_2=False)
        return out

    assert via_idl() == data
    idl_ms = per_call(via_idl, 2)
    return {"rosbagsSerializeMs": rosbags_ms, "cycloneddsIdlSerializeMs": idl_ms, "decodeMs": decode_ms}


def main() -> None:
    msg = point_cloud()
    size = len(serialize(msg))
    rows: list[dict[str, Any]] = []
    for name, seconds, nbytes, received in (
        ("in-process", in_process(msg, cdr=False), 0, COUNT),
        ("in-process+cdr", in_process(msg, cdr=True), size * COUNT, COUNT),
        ("loopback", *cross_process("loopback", msg)),
        ("dds", *cross_process("dds", msg)),
        ("dds keep-last 10", *cross_process("dds", msg, history=10)),
    ):
        rate = received / seconds
        rows.append(
            {
                "path": name,
                "seconds": round(seconds, 4),
                "received": received,
                "messagesPerSecond": round(rate, 1),
                "MBPerSecond": round(size * rate / 1e6, 1),
                "tenHzEquivalents": round(rate / 10, 1),
                "bytesChecked": nbytes in (size * received, 0),
            }
        )
    base = next(r for r in rows if r["path"] == "in-process+cdr")["messagesPerSecond"]
    for row in rows:
        row["ratioToInProcessCdr"] = round(row["messagesPerSecond"] / base, 3)
    ser = serialisation(msg)
    rtt = {mode: round(round_trip(mode), 3) for mode in ("loopback", "dds")}
    print(f"PointCloud2, {POINTS} points, {size / 1e6:.2f} MB CDR, {COUNT} messages per path")
    header = (
        f"{'path':<18}{'s':>8}{'received':>10}{'msg/s':>11}{'MB/s':>11}{'10 Hz eq.':>11}{'÷ in-proc+cdr':>15}"
    )
    print(header)
    print("-" * len(header))
    for r in rows:
        print(
            f"{r['path']:<18}{r['seconds']:>8}{r['received']:>10}{r['messagesPerSecond']:>11}"
            f"{r['MBPerSecond']:>11}{r['tenHzEquivalents']:>11}{r['ratioToInProcessCdr']:>15}"
        )
    print()
    print("CDR per message (ms, median):")
    print(f"  rosbags serialize (every path)            {ser['rosbagsSerializeMs']:9.3f}")
    print(f"  cyclonedds IDL object + serialize (avoided){ser['cycloneddsIdlSerializeMs']:9.1f}")
    print(f"  decode on receipt (object + exact bytes)  {ser['decodeMs']:9.3f}")
    print()
    print(
        f"round trip, /ping → other process → /pong (ms, median of {ROUND_TRIPS}; lockstep overhead per step):"
    )
    for mode, ms in rtt.items():
        print(f"  {mode:<10}{ms:9.3f}")
    figures = {
        "bench": "bridge",
        "points": POINTS,
        "messageBytes": size,
        "count": COUNT,
        "paths": rows,
        "serialisationMs": {k: round(v, 3) for k, v in ser.items()},
        "roundTripMs": rtt,
        "ddsMessagesPerSecond": next(r for r in rows if r["path"] == "dds")["messagesPerSecond"],
        "ddsMBPerSecond": next(r for r in rows if r["path"] == "dds")["MBPerSecond"],
        "ddsToLoopback": round(
            next(r for r in rows if r["path"] == "dds")["messagesPerSecond"]
            / next(r for r in rows if r["path"] == "loopback")["messagesPerSecond"],
            2,
        ),
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
