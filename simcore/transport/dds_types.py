"""ROS 2 message types as cyclonedds IDL types, with ROS 2's DDS names (rosidl_generator_dds_idl conventions).

`idl_type("sensor_msgs/msg/PointCloud2")` is an `IdlStruct` named `sensor_msgs::msg::dds_::PointCloud2_`,
generated from the message definition in CARLOS' type store (rosbags' jazzy store + vision_msgs and
ackermann_msgs) and cached. Its fields map as rosidl maps them: `byte` → octet, `char` → uint8 (ROS 2's
`char` is an unsigned 8-bit integer), `bool`, the sized integers and floats, `string` / `string<=N` →
(bounded) string, `T[N]` → array, `T[]` / `T[<=N]` → (bounded) sequence, nested messages → nested structs
of the same naming, constants left out (they are not on the wire), `@final` extensibility, XCDR1.

The types are not used to (de)serialise CARLOS' own traffic (rosbags does that, byte for byte as ROS 2):
cyclonedds needs them to register the topic type (its name is what ROS 2 matches on), and it checks every
sample written or received against them (`dds_stream_normalize`), so a byte stream that does not have the
layout of the type is refused rather than sent.

Imports cyclonedds: import this module only where DDS is used.
"""

from __future__ import annotations

import threading
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as t
from rosbags.interfaces import Nodetype

from simcore.transport.messages import TYPESTORE

_BASE: dict[str, Any] = {
    "bool": bool,
    "byte": t.byte,
    "char": t.uint8,
    "int8": t.int8,
    "uint8": t.uint8,
    "int16": t.int16,
    "uint16": t.uint16,
    "int32": t.int32,
    "uint32": t.uint32,
    "int64": t.int64,
    "uint64": t.uint64,
    "float32": t.float32,
    "float64": t.float64,
    "string": str,
}

_cache: dict[str, type[IdlStruct]] = {}
_lock = threading.RLock()


class UnknownType(KeyError):
    """A message type that is not in CARLOS' type store."""


def dds_typename(typename: str) -> str:
    """`pkg/msg/Type` → `pkg::msg::dds_::Type_` (the DDS type name ROS 2 registers)."""
    parts = typename.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"not a ROS 2 message type name (pkg/msg/Type): {typename!r}")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_typename(dds_name: str) -> str | None:
    """`pkg::msg::dds_::Type_` → `pkg/msg/Type`; None for a type name that is not ROS 2's."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_") or len(parts[3]) < 2:
        return None
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def _base(detail: tuple[str, int]) -> Any:
    name, bound = detail
    if name == "string" and bound:
        return t.bounded_str[bound]  # type: ignore[misc]
    if name not in _BASE:
        raise UnknownType(f"base type {name!r} is not supported on DDS")
    return _BASE[name]


def _node(node: tuple[Any, Any]) -> Any:
    kind, detail = node
    if kind == Nodetype.BASE:
        return _base(detail)
    if kind == Nodetype.NAME:
        return idl_type(detail)
    sub, size = detail
    element = _node(sub)
    if kind == Nodetype.ARRAY:
        return t.array[element, size]  # type: ignore[misc]
    return t.sequence[element, size] if size else t.sequence[element]  # type: ignore[misc]


def idl_type(typename: str) -> type[IdlStruct]:
    """The cyclonedds IDL struct of the ROS 2 message type `typename` (`pkg/msg/Type`), cached."""
    with _lock:
        cls = _cache.get(typename)
        if cls is not None:
            return cls
        if typename not in TYPESTORE.fielddefs:
            raise UnknownType(f"message type {typename!r} is not in CARLOS' type store")
        _, fields = TYPESTORE.fielddefs[typename]
        members = {name: _node(node) for name, node in fields}
        cls = make_idl_struct(typename.rsplit("/", 1)[1] + "_", dds_typename(typename), members)
        _cache[typename] = cls
        return cls
