"""The detector as a program.

    python -m examples.detector --replay RECORDING.mcap --record DETECTIONS.mcap
        replay the point clouds of a recording into the node and record what it publishes (offline use,
        e.g. on a run's recording.mcap); prints one line per cloud with the number of detections
    python -m examples.detector --bus package.module:factory
        run on a live bus: `factory()` returns an object with `advertise`/`subscribe`/`close` (a transport
        of the pod's roles, say); runs until interrupted

Node parameters: --input-topic, --output-topic, and any DetectorParams field as --param name=value.
Exit codes: 0 done, 2 bad arguments or input file.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from examples.detector.detect import DetectorParams
from examples.detector.node import Detector


def _params(items: list[str]) -> dict[str, Any]:
    fields = {f.name: f for f in dataclasses.fields(DetectorParams)}
    out: dict[str, Any] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        if not sep or name not in fields:
            raise SystemExit(f"--param {item!r}: use NAME=VALUE with NAME one of {', '.join(fields)}")
        kind = type(getattr(DetectorParams(), name))
        try:
            out[name] = (raw.lower() in ("1", "true", "yes")) if kind is bool else kind(raw)
        except ValueError:
            raise SystemExit(f"--param {item!r}: {raw!r} is not a {kind.__name__}") from None
    return out


def replay(args: argparse.Namespace, params: dict[str, Any]) -> int:
    from rosbags.highlevel import AnyReader

    from simcore.recorder import McapRecorder
    from simcore.transport.bus import InProcessBus, Message
    from simcore.transport.messages import TYPESTORE

    source = Path(args.replay)
    if not source.is_file():
        print(f"error: {source}: no such recording", file=sys.stderr)
        return 2
    bus = InProcessBus()
    recorder = McapRecorder(args.record, topics=[args.output_topic]) if args.record else None
    if recorder is not None:

        def record(m: Message) -> None:
            recorder.write(m.topic, m.typename, m.obj(), m.time_s)

        bus.subscribe(args.output_topic, record)
    counts: list[int] = []
    bus.subscribe(args.output_topic, lambda m: counts.append(len(m.obj().detections)))
    node = Detector(bus, input_topic=args.input_topic, output_topic=args.output_topic, **params)
    try:
        with AnyReader([source], default_typestore=TYPESTORE) as reader:
            connections = [c for c in reader.connections if c.topic == args.input_topic]
            if not connections:
                print(f"error: {source} has no topic {args.input_topic}", file=sys.stderr)
                return 2
            publisher = bus.advertise(args.input_topic, connections[0].msgtype)
            for connection, timestamp, raw in reader.messages(connections=connections):
                publisher.publish(reader.deserialize(raw, connection.msgtype), timestamp / 1e9)
                print(f"{timestamp / 1e9:.3f} s: {counts[-1]} detections")
    finally:
        node.close()
        if recorder is not None:
            recorder.close()
    print(f"{node.clouds} clouds, {sum(counts)} detections" + (f" → {args.record}" if args.record else ""))
    return 0


def live(args: argparse.Namespace, params: dict[str, Any]) -> int:
    module_name, _, factory_name = args.bus.partition(":")
    try:
        factory = getattr(importlib.import_module(module_name), factory_name)
    except (ImportError, AttributeError) as exc:
        print(f"error: --bus {args.bus}: {exc}", file=sys.stderr)
        return 2
    bus = factory()
    node = Detector(bus, input_topic=args.input_topic, output_topic=args.output_topic, **params)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    finally:
        node.close()
        bus.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m examples.detector", description=__doc__.split("\n\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--replay", metavar="MCAP", help="recording whose point clouds to replay")
    mode.add_argument("--bus", metavar="MODULE:FACTORY", help="a live bus")
    parser.add_argument("--record", metavar="MCAP", help="with --replay: record the detections here")
    parser.add_argument("--input-topic", default="/carlos/Ego/lidar/points")
    parser.add_argument("--output-topic", default="/carlos/sut/detections")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args(argv)
    params = _params(args.param)
    return replay(args, params) if args.replay else live(args, params)


if __name__ == "__main__":
    sys.exit(main())
