"""The cruise controller as its own program, on the topics of `carlos run --transport loopback|dds`.

    python -m examples.controller [--transport loopback] [--port 7447] [--entity Ego] [--speed 20] [--stop-after N]
    python -m examples.controller --transport dds [--ros-domain-id N] [--entity Ego] [--speed 20]

`--transport loopback` (default) connects to the topic hub on --host:--port. `--transport dds` joins the DDS
domain (--ros-domain-id, else ROS_DOMAIN_ID, else 0) configured as a ROS 2 node with rmw_cyclonedds_cpp
would be in this environment (CYCLONEDDS_URI, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST): the same topics a
real ROS 2 node sees. Runs until the simulation publishes its end of run on /carlos/status (exit 0), or the
simulation goes away (hub closed / its DDS participant gone: exit 0 after the end, 3 before it); no
simulation within --connect-timeout: exit 3. Exit 2: bad arguments.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from typing import Any

from examples.controller.node import CruiseController


def _connect(args: argparse.Namespace) -> tuple[Any, Callable[[], bool]]:
    """(bus, gone): `gone()` is true once the simulation went away (raises ConnectionError when there is
    none within --connect-timeout)."""
    if args.transport == "loopback":
        from simcore.transport.loopback import LoopbackBus

        bus = LoopbackBus(args.host, args.port, connect_timeout=args.connect_timeout)
        return bus, bus.disconnected.is_set
    from simcore.transport.dds import DdsBus
    from simcore.transport.dds_config import domain_id_from_env

    domain = domain_id_from_env() if args.ros_domain_id is None else args.ros_domain_id
    dds = DdsBus(domain)
    topic = f"/carlos/{args.entity}/odometry"
    deadline = time.monotonic() + args.connect_timeout
    seen = False

    def gone() -> bool:
        # the simulator's writer of the entity's odometry: it appears once we subscribed (lockstep waits
        # for the subscription first), and disappears with the simulator's participant
        nonlocal seen
        if dds.publishers(topic):
            seen = True
            return False
        if not seen and time.monotonic() > deadline:
            raise ConnectionError(
                f"no simulation published {topic} on DDS domain {domain} within {args.connect_timeout:g} s "
                "(start `carlos run … --transport dds` with the same ROS_DOMAIN_ID and CYCLONEDDS_URI)"
            )
        return seen

    return dds, gone


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m examples.controller", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--transport", choices=("loopback", "dds"), default="loopback")
    parser.add_argument("--host", default="127.0.0.1", help="loopback: the hub's host")
    parser.add_argument("--port", type=int, default=7447, help="loopback: the hub's port")
    parser.add_argument(
        "--ros-domain-id", type=int, default=None, help="dds: the domain (default ROS_DOMAIN_ID, else 0)"
    )
    parser.add_argument("--entity", default="Ego")
    parser.add_argument("--speed", type=float, default=20.0)
    parser.add_argument("--acceleration", type=float, default=2.0)
    parser.add_argument(
        "--stop-after", type=int, default=None, help="die (exit 1 at once, like a crash) after N commands"
    )
    parser.add_argument("--connect-timeout", type=float, default=30.0)
    args = parser.parse_args(argv)
    if args.ros_domain_id is not None and not 0 <= args.ros_domain_id <= 232:
        parser.error(f"--ros-domain-id {args.ros_domain_id}: a domain id is 0..232")

    from simcore.errors import BadInput

    try:
        bus, gone = _connect(args)
    except BadInput as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except ConnectionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    node = CruiseController(
        bus, entity=args.entity, speed=args.speed, acceleration=args.acceleration, stop_after=args.stop_after
    )
    print(f"controller: driving {args.entity} at {args.speed:g} m/s ({args.transport})", flush=True)
    while not node.ended.wait(0.02):
        if args.stop_after is not None and node.sent >= args.stop_after:
            print(f"controller: dying after {node.sent} commands (--stop-after)", flush=True)
            os._exit(1)
        try:
            away = gone()
        except ConnectionError as exc:
            print(f"error: {exc}", file=sys.stderr)
            bus.close()
            return 3
        if away:
            bus.drain()  # what arrived before it went away (its end of run, maybe)
            if node.ended.is_set():
                break
            print("controller: the simulation went away before the end of the run", file=sys.stderr)
            bus.close()
            return 3
    print(f"controller: end of run after {node.sent} commands", flush=True)
    bus.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
