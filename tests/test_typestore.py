"""The type store: generated definitions match their sources; types are generated on first use and behave as
rosbags' fully built store."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import TypesysError
from rosbags.typesys.store import Typestore

from simcore.transport import msgdefs
from simcore.transport.typestore import LazyTypestore, definitions_from_sources, module_source

ROOT = Path(__file__).resolve().parents[1]


def test_generated_definitions_match_their_sources() -> None:
    """simcore/transport/msgdefs.py is what `make msgdefs` writes from rosbags' jazzy store and the .msg files."""
    expected = module_source(definitions_from_sources())
    have = (ROOT / "simcore" / "transport" / "msgdefs.py").read_text(encoding="utf-8")
    assert have == expected, "simcore/transport/msgdefs.py is stale: run `make msgdefs`"


def test_lazy_store_equals_the_fully_built_store() -> None:
    sources = definitions_from_sources()
    lazy = LazyTypestore(msgdefs.FIELDDEFS)
    assert "vision_msgs/msg/Detection3DArray" in lazy.types
    assert "no_such/msg/Type" not in lazy.fielddefs
    assert dict.__len__(lazy.fielddefs) == 0  # membership generates nothing
    header = lazy.types["std_msgs/msg/Header"]
    # a type and the types it nests, nothing else
    assert set(dict.keys(lazy.fielddefs)) == {"std_msgs/msg/Header", "builtin_interfaces/msg/Time"}
    assert header.__msgtype__ == "std_msgs/msg/Header"
    # rosbags' form: lists of fields, node types as Nodetype
    _consts, fields = lazy.fielddefs["geometry_msgs/msg/PoseWithCovariance"]
    assert isinstance(fields, list) and isinstance(fields[0][1][0], Nodetype)
    assert (
        lazy.fielddefs["geometry_msgs/msg/PoseWithCovariance"]
        == sources["geometry_msgs/msg/PoseWithCovariance"]
    )
    # iteration sees every type, in the sources' order
    assert list(lazy.fielddefs) == list(sources)
    assert {k: lazy.fielddefs[k] for k in sources} == sources
    with pytest.raises(KeyError):
        lazy.types["no_such/msg/Type"]


ODOMETRY = "nav_msgs/msg/Odometry"


def _odometry(store: Typestore) -> Any:
    t = store.types
    return t[ODOMETRY](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=3, nanosec=5), frame_id="map"
        ),
        child_frame_id="ego/base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
            covariance=np.zeros(36),
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=t["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0),
                angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.1),
            ),
            covariance=np.zeros(36),
        ),
    )


def test_lazy_store_serialises_as_rosbags_jazzy() -> None:
    lazy = LazyTypestore(msgdefs.FIELDDEFS)
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    ours, theirs = _odometry(lazy), _odometry(jazzy)
    cdr = bytes(jazzy.serialize_cdr(theirs, ODOMETRY))
    assert bytes(lazy.serialize_cdr(ours, ODOMETRY)) == cdr
    assert bytes(lazy.serialize_cdr(ours, ODOMETRY, little_endian=False)) == bytes(
        jazzy.serialize_cdr(theirs, ODOMETRY, little_endian=False)
    )
    # every serialiser rosbags generates, generated here when first used, gives rosbags' bytes
    ros1 = bytes(jazzy.serialize_ros1(theirs, ODOMETRY))
    assert bytes(lazy.serialize_ros1(ours, ODOMETRY)) == ros1
    as_ros1 = bytes(lazy.cdr_to_ros1(cdr, ODOMETRY))
    assert as_ros1 == bytes(jazzy.cdr_to_ros1(cdr, ODOMETRY))
    assert bytes(lazy.ros1_to_cdr(as_ros1, ODOMETRY)) == bytes(jazzy.ros1_to_cdr(as_ros1, ODOMETRY))
    assert lazy.deserialize_ros1(ros1, ODOMETRY).child_frame_id == "ego/base_link"
    assert lazy.generate_msgdef(ODOMETRY) == jazzy.generate_msgdef(ODOMETRY)
    back = lazy.deserialize_cdr(cdr, ODOMETRY)
    assert back.child_frame_id == "ego/base_link" and back.header.stamp.nanosec == 5


def test_register_adds_new_types_and_rejects_a_different_known_one() -> None:
    lazy = LazyTypestore(msgdefs.FIELDDEFS)
    lazy.register({"my_msgs/msg/Wrapped": ([], [("stamp", (Nodetype.NAME, "builtin_interfaces/msg/Time"))])})
    wrapped = lazy.types["my_msgs/msg/Wrapped"](
        stamp=lazy.types["builtin_interfaces/msg/Time"](sec=1, nanosec=0)
    )
    assert (
        bytes(lazy.serialize_cdr(wrapped, "my_msgs/msg/Wrapped"))[4:] == b"\x01\x00\x00\x00\x00\x00\x00\x00"
    )
    # the same definition again is fine; a different one for a known name is not
    lazy.register({"std_msgs/msg/Header": msgdefs.FIELDDEFS["std_msgs/msg/Header"]})
    with pytest.raises(TypesysError, match="std_msgs/msg/Header"):
        lazy.register({"std_msgs/msg/Header": ([], [("other", (Nodetype.BASE, ("int8", 0)))])})


def test_importing_the_messages_generates_only_what_they_use() -> None:
    """The reason for the lazy store: a run does not pay for the ~480 types it does not use (nor imports rosbags'
    jazzy store, which imports every earlier distribution's)."""
    code = (
        "import sys\n"
        "from simcore.transport.messages import TYPESTORE\n"
        "print(dict.__len__(TYPESTORE.types), 'rosbags.typesys.stores.ros2_jazzy' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    generated, jazzy_imported = out.stdout.split()
    assert int(generated) < 40 and jazzy_imported == "False"
