"""Live view: a foxglove.sdk.v1 client receives the advertised ROS 2 channels and their messages."""

from __future__ import annotations

import json
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from simcore.live import LiveServer
from simcore.transport import messages
from simcore.transport.bus import InProcessBus
from simcore.transport.world import WorldPublisher
from simcore.world.state import BoundingBox, EntityState, WorldFrame

BOX = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)


def frame(step: int) -> WorldFrame:
    t = step * 0.05
    cars = tuple(
        EntityState(name, "vehicle", "car", x0 + 20 * t, y, 0, 0, 0, 0, 20.0, 0, 0, BOX)
        for name, x0, y in (("Ego", 0.0, -5.25), ("Lead", 30.0, -5.25))
    )
    return WorldFrame(step=step, time=t, entities=cars, ego="Ego")


def test_foxglove_client_receives_channels_and_messages() -> None:
    server = LiveServer(port=0, speed=20.0).start()
    try:
        bus = InProcessBus()
        bus.subscribe("*", server)
        world = WorldPublisher(bus)
        world.publish(frame(0))  # advertises the channels
        with connect(server.url, subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            channels: dict[str, dict[str, Any]] = {}
            deadline = time.monotonic() + 10
            wanted = {"/clock", "/carlos/objects", "/tf", "/carlos/objects/markers"}
            while wanted - set(channels) and time.monotonic() < deadline:
                reply = ws.recv(timeout=5)
                if isinstance(reply, str):
                    message = json.loads(reply)
                    if message["op"] == "advertise":
                        channels.update({c["topic"]: c for c in message["channels"]})
            assert channels["/carlos/objects"]["schemaName"] == "vision_msgs/msg/Detection3DArray"
            assert channels["/carlos/objects"]["schemaEncoding"] == "ros2msg"
            assert channels["/clock"]["encoding"] == "cdr"
            assert channels["/carlos/objects/markers"]["schemaName"] == "visualization_msgs/msg/MarkerArray"
            subscriptions = {1: "/clock", 2: "/carlos/objects", 3: "/carlos/objects/markers"}
            ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [
                            {"id": sid, "channelId": channels[topic]["id"]}
                            for sid, topic in subscriptions.items()
                        ],
                    }
                )
            )
            time.sleep(0.2)
            started = time.monotonic()
            publisher = threading.Thread(target=lambda: [world.publish(frame(i)) for i in range(1, 41)])
            publisher.start()
            received: dict[str, list[Any]] = {topic: [] for topic in subscriptions.values()}
            while len(received["/clock"]) < 40 and time.monotonic() - started < 20:
                data = ws.recv(timeout=10)
                if isinstance(data, bytes) and data[0] == 0x01:
                    sid, log_time = struct.unpack_from("<IQ", data, 1)
                    topic = subscriptions[sid]
                    msg = messages.deserialize(data[13:], channels[topic]["schemaName"])
                    received[topic].append((log_time, msg))
            publisher.join(timeout=10)
    finally:
        server.stop()
    clocks = [m.clock.sec + m.clock.nanosec * 1e-9 for _, m in received["/clock"]]
    assert clocks == pytest.approx([i * 0.05 for i in range(1, 41)])
    assert all(len(m.detections) == 2 for _, m in received["/carlos/objects"])
    assert {d.id for d in received["/carlos/objects"][-1][1].detections} == {"Ego", "Lead"}
    boxes = received["/carlos/objects/markers"][-1][1].markers
    assert [m.action for m in boxes] == [3, 0, 0]  # DELETEALL, then one ADD per object
    lead = next(m for m in boxes if m.text == "Lead")
    assert (lead.scale.x, lead.scale.y, lead.scale.z) == (4.5, 1.8, 1.5)
    stamp = lead.header.stamp.sec + lead.header.stamp.nanosec * 1e-9
    assert lead.pose.position.x == pytest.approx(30.0 + 20 * stamp + 1.4)  # box centre: rear axle + 1.4 m


@pytest.mark.parametrize("speed", [10.0, 40.0])
def test_publishing_is_paced_to_the_requested_speed(speed: float) -> None:
    server = LiveServer(port=0, speed=speed).start()
    try:
        bus = InProcessBus()
        bus.subscribe("*", server)
        world = WorldPublisher(bus)
        started = time.monotonic()
        for i in range(41):  # 2 simulated seconds
            world.publish(frame(i))
        elapsed = time.monotonic() - started
    finally:
        server.stop()
    assert elapsed >= 2.0 / speed * 0.95
    assert elapsed < 2.0 / speed + 1.0


def test_carlos_run_live_serves_the_run_and_still_writes_results(tmp_path: Path) -> None:
    import re
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "simcore.cli",
            "run",
            str(root / "examples" / "runs" / "prototyping.yaml"),
            "--live",
            "--live-port",
            "0",
            "--live-speed",
            "2",  # the 20.7 s scenario in ~10 s: time for a client on a loaded machine to subscribe (at 8x,
            # 2.6 s, the run once ended before the subscription: ConnectionClosedOK; at 4x, once under a load
            # of 13 on 2 cores)
            "-o",
            f"file://{tmp_path}",
        ],
        cwd=root,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stderr is not None
        line = process.stderr.readline()
        match = re.search(r"live view: (ws://127\.0\.0\.1:\d+)", line)
        assert match, line
        clocks = 0
        topics: set[str] = set()
        with connect(match.group(1), subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            subscribed = False
            deadline = time.monotonic() + 20
            while clocks < 10 and time.monotonic() < deadline:
                reply = ws.recv(timeout=10)
                if isinstance(reply, str):
                    message = json.loads(reply)
                    if message["op"] == "advertise":
                        topics |= {c["topic"] for c in message["channels"]}
                        clock = next((c for c in message["channels"] if c["topic"] == "/clock"), None)
                        if clock and not subscribed:
                            ws.send(
                                json.dumps(
                                    {
                                        "op": "subscribe",
                                        "subscriptions": [{"id": 1, "channelId": clock["id"]}],
                                    }
                                )
                            )
                            subscribed = True
                elif reply[0] == 0x01:
                    clocks += 1
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    assert clocks >= 10
    assert {"/clock", "/tf", "/carlos/objects", "/carlos/objects/markers", "/carlos/Ego/odometry"} <= topics
    assert (tmp_path / "prototyping" / "0" / "recording.mcap").is_file()
    assert (tmp_path / "prototyping" / "summary.json").is_file()


def test_spec_live_is_refused_for_more_than_one_run(tmp_path: Path) -> None:
    import subprocess
    import sys

    import yaml

    root = Path(__file__).resolve().parents[1]
    body = yaml.safe_load((root / "examples" / "runs" / "data-generation.yaml").read_text())
    body["spec"]["live"] = True
    for scenario in body["spec"]["scenarios"]:
        scenario["openscenario"] = str((root / "examples" / "runs" / scenario["openscenario"]).resolve())
    manifest = tmp_path / "live.yaml"
    manifest.write_text(yaml.safe_dump(body))
    done = subprocess.run(
        [sys.executable, "-m", "simcore.cli", "run", str(manifest), "-o", f"file://{tmp_path}"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "spec.live" in done.stderr and "choose one with --index N" in done.stderr


def test_live_runs_a_finished_index_again_and_keeps_the_others(tmp_path: Path) -> None:
    """After `make demo`, `--live -i 4` has something to watch: the finished index runs again (it is not
    resumed), and the sweep's other indexes keep their results."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    manifest = str(root / "examples" / "runs" / "data-generation.yaml")

    def carlos(*args: str) -> subprocess.CompletedProcess[str]:
        command = [sys.executable, "-m", "simcore.cli", "run", manifest, "-o", f"file://{tmp_path}", *args]
        return subprocess.run(command, capture_output=True, text=True, timeout=600)

    first = carlos("-i", "4", "-i", "5", "-q")
    assert first.returncode == 0, first.stderr
    before = (tmp_path / "data-generation" / "5" / "summary.json").read_bytes()
    live = carlos("--live", "-i", "4", "--live-port", "0", "--live-speed", "0")
    assert live.returncode == 0, live.stderr
    assert "resuming" not in live.stdout + live.stderr and "(0 resumed)" in live.stdout
    assert (tmp_path / "data-generation" / "5" / "summary.json").read_bytes() == before
    assert json.loads((tmp_path / "data-generation" / "summary.json").read_text())["counts"]["total"] == 2
