"""Which DDS domain and cyclonedds configuration a CARLOS participant uses (light: no cyclonedds import, so
the operator can build pod templates without it).

The rules are a ROS 2 node's with rmw_cyclonedds_cpp, so CARLOS and the user's nodes agree without extra
setup:

- domain: `ROS_DOMAIN_ID` (unset or empty: 0), an integer 0..232;
- configuration: `CYCLONEDDS_URI` when set (XML or file URI, used as is); else, when
  `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (Iron and later) or `ROS_LOCALHOST_ONLY=1` (Humble), the
  configuration rmw_cyclonedds_cpp makes for that (no multicast, unicast discovery of the participants on
  localhost); else cyclonedds' defaults (one network interface, multicast discovery: the machine and its
  network, what a ROS 2 node with rmw_cyclonedds_cpp and no settings uses).

`loopback_config()` is the configuration of one pod on a cluster (and of the tests): 127.0.0.1 only.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

from simcore.errors import BadInput

MAX_DOMAIN_ID = 232  # cyclonedds' default port mapping reaches 65535 at domain 232

#: rmw_cyclonedds_cpp's configuration for ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (rmw_init.cpp)
LOCALHOST_CONFIG = (
    "<CycloneDDS><Domain><General><AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
    '<Peers><Peer address="localhost"/></Peers></Discovery></Domain></CycloneDDS>'
)


def parse_domain_id(raw: str, field: str) -> int:
    """A domain id as text → int 0..232 (BadInput naming `field` otherwise)."""
    try:
        value = int(raw.strip())
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise BadInput(f"{field}={raw!r} is not a domain id (an integer 0..{MAX_DOMAIN_ID})", field=field)
    return value


def domain_id_from_env(env: Mapping[str, str] | None = None) -> int:
    """ROS_DOMAIN_ID as ROS 2 reads it: unset or empty → 0; otherwise an integer 0..232."""
    raw = (os.environ if env is None else env).get("ROS_DOMAIN_ID", "").strip()
    return parse_domain_id(raw, "ROS_DOMAIN_ID") if raw else 0


def loopback_config(max_participants: int = 32) -> str:
    """cyclonedds configuration (XML, for `config=` or CYCLONEDDS_URI) for 127.0.0.1 only: the loopback
    interface has no multicast, so discovery is unicast to the participant ports of 127.0.0.1 (up to
    `max_participants` per domain on this host). Large fragments: loopback's MTU is 64 KiB. Heartbeats every
    10 ms while a reliable writer has data not yet acknowledged (cyclonedds' default 100 ms): waiting for the
    acknowledgements (the simcore pod before each verdict, `DdsBus.flush`) takes ~0.02 s instead of ~0.15 s."""
    return (
        '<CycloneDDS><Domain Id="any"><General>'
        '<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
        "<AllowMulticast>false</AllowMulticast>"
        "<MaxMessageSize>65000B</MaxMessageSize><FragmentSize>62000B</FragmentSize>"
        "</General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
        f"<MaxAutoParticipantIndex>{max_participants - 1}</MaxAutoParticipantIndex>"
        '<Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
        '<Internal><SocketReceiveBufferSize min="default" max="4MB"/>'
        "<HeartbeatInterval>10ms</HeartbeatInterval></Internal>"
        "</Domain></CycloneDDS>"
    )


def localhost_only(env: Mapping[str, str] | None = None) -> bool:
    """Whether ROS 2 nodes with this environment discover only participants on this host."""
    env = os.environ if env is None else env
    return (
        env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper() == "LOCALHOST"
        or env.get("ROS_LOCALHOST_ONLY", "").strip() == "1"
    )


def config_from_env(env: Mapping[str, str] | None = None) -> str | None:
    """The cyclonedds configuration a ROS 2 node with this environment uses (module docstring); None:
    cyclonedds' defaults."""
    env = os.environ if env is None else env
    uri = env.get("CYCLONEDDS_URI", "").strip()
    if uri:
        return uri
    return LOCALHOST_CONFIG if localhost_only(env) else None


def describe(domain_id: int, env: Mapping[str, str] | None = None) -> str:
    """One line for the user: where the topics are and how a ROS 2 node gets there."""
    env = os.environ if env is None else env
    if env.get("CYCLONEDDS_URI", "").strip():
        scope = "config from CYCLONEDDS_URI"
        hint = "the same CYCLONEDDS_URI"
    elif localhost_only(env):
        scope = "this host only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)"
        hint = "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"
    else:
        scope = "cyclonedds defaults: this host and its network, multicast discovery"
        hint = "nothing else"
    return (
        f"DDS domain {domain_id}, {scope}; ROS 2 nodes: ROS_DOMAIN_ID={domain_id} "
        f"RMW_IMPLEMENTATION=rmw_cyclonedds_cpp, {hint}"
    )


__all__ = [
    "LOCALHOST_CONFIG",
    "MAX_DOMAIN_ID",
    "config_from_env",
    "describe",
    "domain_id_from_env",
    "localhost_only",
    "loopback_config",
    "parse_domain_id",
]
