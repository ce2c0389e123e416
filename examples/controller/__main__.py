"""The cruise controller as its own program, on the loopback topic hub of `carlos run --transport loopback`.

    python -m examples.controller [--port 7447] [--entity Ego] [--speed 20] [--stop-after N]

Runs until the simulation publishes its end of run on /carlos/status (exit 0), or the hub goes away
(exit 0 after the end, 3 before it). Exit 2: bad arguments.
"""

from __future__ import annotations

import argparse
import os
import sys

from examples.controller.node import CruiseController


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m examples.controller", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=7447)
    parser.add_argument("--entity", default="Ego")
    parser.add_argument("--speed", type=float, default=20.0)
    parser.add_argument("--acceleration", type=float, default=2.0)
    parser.add_argument(
        "--stop-after", type=int, default=None, help="die (exit 1 at once, like a crash) after N commands"
    )
    parser.add_argument("--connect-timeout", type=float, default=30.0)
    args = parser.parse_args(argv)

    from simcore.transport.loopback import LoopbackBus, LoopbackError

    try:
        bus = LoopbackBus(args.host, args.port, connect_timeout=args.connect_timeout)
    except LoopbackError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    node = CruiseController(
        bus, entity=args.entity, speed=args.speed, acceleration=args.acceleration, stop_after=args.stop_after
    )
    print(f"controller: driving {args.entity} at {args.speed:g} m/s", flush=True)
    while not node.ended.wait(0.02):
        if args.stop_after is not None and node.sent >= args.stop_after:
            print(f"controller: dying after {node.sent} commands (--stop-after)", flush=True)
            os._exit(1)
        if bus.disconnected.is_set():
            print("controller: the topic hub went away before the end of the run", file=sys.stderr)
            return 3
    print(f"controller: end of run after {node.sent} commands", flush=True)
    bus.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
