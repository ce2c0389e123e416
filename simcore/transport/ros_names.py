"""ROS 2 names of the world's entities (DESIGN.md, "Topics"; see `simcore.transport.messages`): each entity's
name token, its frame `<entity>/base_link` and its odometry topic; the world frame is `map`."""

from __future__ import annotations

import re
from functools import cache

__all__ = ["MAP_FRAME", "base_link", "odometry_topic", "ros_name"]

MAP_FRAME = "map"

_INVALID = re.compile(r"[^A-Za-z0-9_]+")
_UNDERSCORES = re.compile(r"_{2,}")


@cache
def ros_name(name: str) -> str:
    """`name` as a valid ROS 2 name token (letters, digits, single `_`, not starting with a digit), one token
    per name: a name that needed changing carries a hash of itself (`car 2` → `car_2_4f1c2a`)."""
    token = _UNDERSCORES.sub("_", _INVALID.sub("_", name)).strip("_")
    if not token:
        token = "entity"
    if token[0].isdigit():
        token = "e" + token
    if token == name:
        return token
    import hashlib

    return f"{token}_{hashlib.sha256(name.encode()).hexdigest()[:6]}"


def base_link(entity: str) -> str:
    """The entity's body frame (REP-105): `<entity>/base_link`."""
    return f"{ros_name(entity)}/base_link"


def odometry_topic(entity: str) -> str:
    return f"/carlos/{ros_name(entity)}/odometry"
