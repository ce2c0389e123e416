"""Compiled per-ray passes of the lidar (numba): what `Lidar.scan` does with the rays around the open3d cast.

Each kernel is one loop over the rays doing what several numpy array passes did, with the same float32 /
float64 arithmetic in the same order, so the scan is bit for bit the one the numpy passes gave (the numpy
reference lives in tests/test_sensors.py). The random numbers stay numpy's, drawn by the caller.

Compiled on first use (`warm()`, called by the lidar's constructor) and cached on disk next to this module
or in `NUMBA_CACHE_DIR` (the pods set it to /tmp: their root filesystem is read-only). `nogil`: they release
the GIL, so the recorder's writer thread can run while they do.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: cached on disk, the GIL released, IEEE division (x / 0 is inf, not an exception), no bounds checks
_kernel = njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)


@_kernel
def fill_level_rays(
    rays: np.ndarray, d0: np.ndarray, d1: np.ndarray, d2: np.ndarray, pos32: np.ndarray, r32: np.ndarray
) -> None:  # pragma: no cover - compiled
    """A level sweep's (K, 6) float32 ray buffer: origins `pos32` and the world x, y direction components
    (d0 * r[row, 0] + d1 * r[row, 1] (+ d2 * r[row, 2] unless that is 0, as it is bar a float32 underflow);
    the z components are already in place)."""
    px, py, pz = pos32[0], pos32[1], pos32[2]
    r00, r01, r02 = r32[0, 0], r32[0, 1], r32[0, 2]
    r10, r11, r12 = r32[1, 0], r32[1, 1], r32[1, 2]
    z0 = r02 != 0.0
    z1 = r12 != 0.0
    for j in range(rays.shape[0]):
        a = d0[j]
        b = d1[j]
        rays[j, 0] = px
        rays[j, 1] = py
        rays[j, 2] = pz
        x = a * r00
        x += b * r01
        y = a * r10
        y += b * r11
        if z0:
            x += d2[j] * r02
        if z1:
            y += d2[j] * r12
        rays[j, 3] = x
        rays[j, 4] = y


@_kernel
def road_returns(
    every: bool,
    ids: np.ndarray,
    t_cast: np.ndarray,
    normals: np.ndarray,
    primitives: np.ndarray,
    rays: np.ndarray,
    class_table: np.ndarray,
    t: np.ndarray,
    classes: np.ndarray,
    cos_inc: np.ndarray,
    object_id: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Fill the sweep's per-ray range `t`, class, |cos(incidence)| and object id (0) from the cast of the
    rays `ids` (`every`: every ray, in order; `ids` is then ignored): inf / 0 / 0 for the rays not cast; a miss (primitive id
    2^32 - 1) takes the class table's last entry (0)."""
    last = class_table.shape[0] - 1
    if not every:
        for g in range(t.shape[0]):
            t[g] = np.inf
            classes[g] = 0
            cos_inc[g] = 0.0
    for g in range(t.shape[0]):
        object_id[g] = 0
    for j in range(t_cast.shape[0]):
        g = j if every else ids[j]
        t[g] = t_cast[j]
        p = primitives[j]
        classes[g] = class_table[p if p < last else last]
        c = rays[j, 3] * normals[j, 0]
        c += rays[j, 4] * normals[j, 1]
        c += rays[j, 5] * normals[j, 2]
        cos_inc[g] = abs(c)


@_kernel
def box_returns(
    t: np.ndarray,
    cos_inc: np.ndarray,
    classes: np.ndarray,
    object_id: np.ndarray,
    cols: np.ndarray,
    chans: np.ndarray,
    channels: int,
    dirs_t: np.ndarray,
    r32: np.ndarray,
    origin: np.ndarray,
    rot: np.ndarray,
    half: np.ndarray,
    range_min: float,
    range_max: float,
    cls: np.uint8,
    oid: np.uint32,
) -> int:  # pragma: no cover - compiled
    """Intersect the rays of columns `cols` × channels `chans` (one origin, sensor-frame directions `dirs_t`
    rotated by `r32` in float32) with one oriented box (`origin` = the ray origin in the box frame, `rot`'s
    columns the box axes, `half` its half sizes): the slab test of `scene.intersect_box_rows`, in the same
    float64 arithmetic. Where the box is closer than the return so far, it becomes the return (range, |cos|
    of the entry face, class `cls`, object id `oid`). Returns the rays that hit it within range."""
    hits = 0
    for c in cols:
        base = c * channels
        for ch in chans:
            g = base + ch
            x, y, z = dirs_t[0, g], dirs_t[1, g], dirs_t[2, g]
            w0 = x * r32[0, 0] + y * r32[0, 1] + z * r32[0, 2]
            w1 = x * r32[1, 0] + y * r32[1, 1] + z * r32[1, 2]
            w2 = x * r32[2, 0] + y * r32[2, 1] + z * r32[2, 2]
            tmin = -np.inf
            tmax = np.inf
            axis_d = 0.0
            for k in range(3):
                d = w0 * rot[0, k] + w1 * rot[1, k] + w2 * rot[2, k]
                inv = 1.0 / d
                t1 = (-half[k] - origin[k]) * inv
                t2 = (half[k] - origin[k]) * inv
                if np.isnan(t1) or np.isnan(t2):  # parallel to a face and in its plane: no constraint
                    near, far = -np.inf, np.inf
                elif t1 < t2:
                    near, far = t1, t2
                else:
                    near, far = t2, t1
                if near > tmin:  # the first axis of the largest entry wins
                    tmin = near
                    axis_d = d
                if far < tmax:
                    tmax = far
            if not (tmax >= tmin and tmin > 0.0):
                continue
            if tmin >= range_min and tmin <= range_max:
                hits += 1
            if tmin < t[g]:
                t[g] = tmin
                cos_inc[g] = np.float32(abs(axis_d))
                classes[g] = cls
                object_id[g] = oid
    return hits


@_kernel
def select_returns(
    t: np.ndarray,
    object_id: np.ndarray,
    range_min: np.float32,
    range_max: np.float32,
    drop: np.ndarray,
    dropout: np.float32,
    kept: np.ndarray,
    visible: np.ndarray,
) -> int:  # pragma: no cover - compiled
    """Write the indices of the returns kept (within range and, with `drop` (one uniform number per ray;
    empty: no dropout), drop >= dropout) to the front of `kept` and count them; `visible[i]` (zeroed here):
    the rays of object id i whose return is within range, before dropout."""
    visible[:] = 0
    dropping = drop.shape[0] > 0
    k = 0
    for g in range(t.shape[0]):
        v = t[g]
        if v >= range_min and v <= range_max:
            visible[object_id[g]] += 1
            if dropping and not drop[g] >= dropout:
                continue
            kept[k] = g
            k += 1
    return k


@_kernel
def fill_points(
    words: np.ndarray,
    kept: np.ndarray,
    t: np.ndarray,
    noise: np.ndarray,
    sigma: np.float32,
    dirs_t: np.ndarray,
    local: np.ndarray,
    column_time: np.ndarray,
    classes: np.ndarray,
    cos_inc: np.ndarray,
    reflectivity: np.ndarray,
    object_id: np.ndarray,
    ring: np.ndarray,
    channels: int,
    counts: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Fill the (N, 7) uint32 words of the point records (POINT_DTYPE) of the returns `kept`; returns the
    points per object id 1..nbox.

    Range = t + noise * sigma clipped at 0 (`noise` empty: no noise); x, y, z = the sensor-frame direction
    (`dirs_t` rows) × range and time 0, or, with `local` (N, 3) float64 given (motion distortion; empty
    otherwise), x, y, z from it and time = the column's firing time (column = index // `channels`);
    intensity = reflectivity[class] × |cos|; object id; `ring` of the ray; label = class; the padding byte 0.
    `counts[i]` (zeroed here): the points of object id i."""
    f32 = words.view(np.float32)
    counts[:] = 0
    noisy = noise.shape[0] > 0
    distorted = local.shape[0] > 0
    for j in range(kept.shape[0]):
        g = kept[j]
        cls = classes[g]
        oid = object_id[g]
        if distorted:
            f32[j, 0] = np.float32(local[j, 0])
            f32[j, 1] = np.float32(local[j, 1])
            f32[j, 2] = np.float32(local[j, 2])
            f32[j, 4] = np.float32(column_time[g // channels])
        else:
            r = t[g]
            if noisy:
                r = noise[j] * sigma + r
                if not r >= 0.0:
                    r = np.float32(0.0)
            f32[j, 0] = dirs_t[0, g] * r
            f32[j, 1] = dirs_t[1, g] * r
            f32[j, 2] = dirs_t[2, g] * r
            f32[j, 4] = np.float32(0.0)
        f32[j, 3] = reflectivity[cls] * cos_inc[g]
        words[j, 5] = oid
        words[j, 6] = np.uint32(ring[g]) | (np.uint32(cls) << np.uint32(16))
        counts[oid] += 1


def warm() -> None:
    """Compile (or load from the cache) every kernel for the argument types the lidar passes."""
    f32, u8, u16, u32, i64 = np.float32, np.uint8, np.uint16, np.uint32, np.int64
    rays = np.zeros((1, 6), f32)
    fill_level_rays(rays, *(np.zeros(1, f32),) * 3, np.zeros(3, f32), np.eye(3, dtype=f32))
    t, cos, classes, oid = np.zeros(1, f32), np.zeros(1, f32), np.zeros(1, u8), np.zeros(1, u32)
    for every in (True, False):
        road_returns(
            every,
            np.zeros(1, i64),
            t,
            np.zeros((1, 3), f32),
            np.zeros(1, u32),
            rays,
            np.zeros(2, u8),
            t,
            classes,
            cos,
            oid,
        )
    one = np.zeros(1, i64)
    box_returns(
        t, cos, classes, oid, one, one, 1, np.zeros((3, 1), f32), np.eye(3, dtype=f32),
        np.zeros(3), np.eye(3), np.ones(3), 0.0, 1.0, u8(1), u32(1),
    )  # fmt: skip
    kept, counts = np.zeros(1, i64), np.zeros(2, i64)
    select_returns(t, oid, f32(0), f32(1), np.zeros(0, f32), f32(0), kept, counts)
    fill_points(
        np.zeros((1, 7), u32), kept, t, np.zeros(0, f32), f32(0), np.zeros((3, 1), f32), np.zeros((0, 3)),
        np.zeros(1), classes, cos, np.zeros(256, f32), oid, np.zeros(1, u16), 1, counts,
    )  # fmt: skip
