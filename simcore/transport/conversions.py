"""The small conversions that the world topics' messages share, as plain numbers: the stamp of a simulated
time and the quaternion of an orientation. `simcore.transport.messages` builds rosbags objects from them and
`simcore.transport.world_cdr` writes them as CDR, so both carry the very same values."""

from __future__ import annotations

import math

__all__ = ["quaternion_xyzw", "stamp_parts"]


def stamp_parts(time_s: float) -> tuple[int, int]:
    """Simulated time in seconds as builtin_interfaces/Time's (sec, nanosec), rounded to the nanosecond."""
    ns = round(time_s * 1e9)
    if ns < 0:
        raise ValueError(f"negative simulation time {time_s}")
    return ns // 1_000_000_000, ns % 1_000_000_000


def quaternion_xyzw(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the intrinsic z-y'-x'' rotation (yaw, pitch, roll), as tf2's
    `setRPY(roll, pitch, yaw)`."""
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )
