"""Compiled per-ray passes of the lidar (numba): what `Lidar.scan` does with the rays around the open3d cast.

Each kernel is one loop over the rays doing what several numpy array passes did, with the same float32 /
float64 arithmetic in the same order, so the scan is bit for bit the one the numpy passes gave (the numpy
reference lives in tests/test_sensors.py). The random numbers stay numpy's, drawn by the caller.

Compiled on first use (`warm()`, called by the lidar's constructor; ~10 s with an empty cache) and cached on
disk next to this module or in `NUMBA_CACHE_DIR` (the pods set it to /tmp: their root filesystem is
read-only). An image ships the cache compiled at build time (for `NUMBA_CPU_NAME=generic`, so any x86-64
node loads it) in the read-only directory `CARLOS_NUMBA_CACHE_SEED`; importing this module copies it into an empty
`NUMBA_CACHE_DIR` first, so a pod loads the kernels instead of compiling them. `nogil`: they release the
GIL, so the recorder's writer thread can run while they do.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
from numba import njit


def seed_cache() -> bool:
    """Copy the cache shipped in `CARLOS_NUMBA_CACHE_SEED` into `NUMBA_CACHE_DIR` when that has none yet;
    True when it did. numba checks each entry against this module's source (path, size, modification time)
    and the CPU, and compiles whatever does not match: a stale seed costs time, never correctness."""
    seed, cache = os.environ.get("CARLOS_NUMBA_CACHE_SEED"), os.environ.get("NUMBA_CACHE_DIR")
    if not seed or not cache or not Path(seed).is_dir():
        return False
    target = Path(cache)
    if target.is_dir() and any(target.rglob("*.nbi")):
        return False
    shutil.copytree(seed, target, dirs_exist_ok=True)
    for path in (target, *target.rglob("*")):  # the seed is read-only; the copy must take new entries
        path.chmod(path.stat().st_mode | 0o200)
    return True


seed_cache()  # before the kernels are defined: numba sets up their cache directory then

#: cached on disk, the GIL released, IEEE division (x / 0 is inf, not an exception), no bounds checks
_kernel = njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
#: a small helper inlined into its callers (numba IR inlining: inlining the bigger helpers too made
#: `level_bounds` take 18 s to compile)
_inline = njit(cache=True, nogil=True, error_model="numpy", boundscheck=False, inline="always")


#: Slack of the reachability test (`level_bounds`) for the float32 rounding of the cast: metres, plus this
#: fraction of the distance (as `Lidar._reachable`), and the relative slack of a ray's slope.
_SLACK_M = 0.01
_SLACK_REL = 1e-4


@_kernel
def level_bounds(
    cell_start: np.ndarray,
    cell_groups: np.ndarray,
    grid: np.ndarray,
    groups: np.ndarray,
    group_start: np.ndarray,
    circles: np.ndarray,
    corners: np.ndarray,
    seen: np.ndarray,
    origin: np.ndarray,
    yaw: float,
    fov: float,
    full_circle: bool,
    range_max: float,
    lo: np.ndarray,
    hi: np.ndarray,
) -> int:  # pragma: no cover - compiled
    """Per column of a level sweep from `origin` (x, y, z; sensor heading `yaw`), the slopes (tan of the
    elevation) a ray needs to reach a static triangle within `range_max`: every ray of column c whose slope
    is outside [lo[c], hi[c]] misses the whole scene (lo > hi: every ray of the column misses).

    A ray with slope s from height z0 is at z0 + rho * s at horizontal distance rho. It can only hit a
    triangle whose xy projection it crosses at some rho in [rho_min, rho_max] (the distance of its nearest
    point, of its farthest; at most `range_max`: farther returns are out of range), in a column whose
    azimuth the triangle spans, with z0 + rho * s in the triangle's z range. Bounds are widened for the
    float32 rounding of the cast (`_SLACK_M`, `_SLACK_REL`) and by one column each side.

    The triangles come in groups of neighbours (`groups`: bounding circle x, y, radius and z min, z max;
    the group's triangles are group_start[g]..group_start[g + 1]), found through an xy grid of the groups
    (`grid` = x0, y0, cell size, cells in x, cells in y; `cell_start`/`cell_groups` the groups per cell).
    A far group (beyond 4 radii + 1 m) counts as its bounding circle; in a near one each triangle counts, as
    its bounding circle (`circles`, as `groups`) when far, else exactly (`corners`); one within 5 cm of the
    sensor spans every column. `seen` (one int per group, the last entry a stamp kept across calls) skips a
    group met in several cells. Returns the number of groups and triangles looked at."""
    columns = lo.shape[0]
    for c in range(columns):
        lo[c] = np.inf
        hi[c] = -np.inf
    blocks = (columns + _BLOCK - 1) // _BLOCK
    block_lo = np.full(blocks, np.inf)
    block_hi = np.full(blocks, -np.inf)
    every = np.array([np.inf, -np.inf])  # the bounds of every column
    ox, oy, oz = origin[0], origin[1], origin[2]
    x0, y0, size = grid[0], grid[1], grid[2]
    nx, ny = int(grid[3]), int(grid[4])
    reach = range_max
    width = fov / columns
    stamp = seen[seen.shape[0] - 1] + 1
    seen[seen.shape[0] - 1] = stamp
    cx0 = max(int(np.floor((ox - reach - x0) / size)), 0)
    cx1 = min(int(np.floor((ox + reach - x0) / size)), nx - 1)
    cy0 = max(int(np.floor((oy - reach - y0) / size)), 0)
    cy1 = min(int(np.floor((oy + reach - y0) / size)), ny - 1)
    looked = 0
    view = (ox, oy, oz, yaw, reach, fov, width)  # the sweep, as the helpers take it
    acc = (lo, hi, block_lo, block_hi, every)  # the bounds they widen
    for cx in range(cx0, cx1 + 1):
        for cy in range(cy0, cy1 + 1):
            cell = cx * ny + cy
            for k in range(cell_start[cell], cell_start[cell + 1]):
                g = cell_groups[k]
                if seen[g] == stamp:
                    continue
                seen[g] = stamp
                looked += 1
                if not _circle(groups, g, view, full_circle, acc):
                    continue
                for j in range(group_start[g], group_start[g + 1]):
                    looked += 1
                    if _circle(circles, j, view, full_circle, acc):
                        _triangle(corners, circles, j, view, full_circle, acc)
    for c in range(columns):
        b = c // _BLOCK
        lo[c] = min(lo[c], block_lo[b], every[0])
        hi[c] = max(hi[c], block_hi[b], every[1])
    return looked


@_kernel
def _circle(
    circles: np.ndarray,
    j: int,
    view: tuple[float, float, float, float, float, float, float],
    full_circle: bool,
    acc: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> bool:  # pragma: no cover - compiled
    """`level_bounds` for the bounding circle `circles[j]` (x, y, radius, z min, z max) when it is far
    (beyond 4 radii + 1 m): widens the bounds, returns False; out of reach: False; near: True (the caller
    looks closer). `view`: the sensor's x, y, z, heading, the range, the field of view and the column width;
    `acc`: the bounds (`_apply`)."""
    ox, oy, oz, yaw, reach, _, _ = view
    dist = np.hypot(circles[j, 0] - ox, circles[j, 1] - oy)
    radius = circles[j, 2]
    if dist - radius > reach + _SLACK_M + _SLACK_REL * reach:
        return False
    if dist <= 4.0 * radius + 1.0:
        return True
    a_mid = np.arctan2(circles[j, 1] - oy, circles[j, 0] - ox) - yaw
    a_half = np.arcsin(radius / dist)
    _apply(dist - radius, dist + radius, circles[j, 3] - oz, circles[j, 4] - oz, a_mid - a_half,
           a_mid + a_half, view, full_circle, acc)  # fmt: skip
    return False


@_kernel
def _triangle(
    corners: np.ndarray,
    circles: np.ndarray,
    j: int,
    view: tuple[float, float, float, float, float, float, float],
    full_circle: bool,
    acc: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> None:  # pragma: no cover - compiled
    """`level_bounds` for triangle j near the sensor: its own distances and arc."""
    ox, oy, oz, yaw, _, _, _ = view
    ax, ay = corners[j, 0, 0] - ox, corners[j, 0, 1] - oy
    bx, by = corners[j, 1, 0] - ox, corners[j, 1, 1] - oy
    qx, qy = corners[j, 2, 0] - ox, corners[j, 2, 1] - oy
    rho_max = max(np.hypot(ax, ay), np.hypot(bx, by), np.hypot(qx, qy))
    # the nearest point of the triangle's projection to the origin: 0 inside, else an edge's
    d1 = ax * by - ay * bx
    d2 = bx * qy - by * qx
    d3 = qx * ay - qy * ax
    inside = (d1 >= 0.0 and d2 >= 0.0 and d3 >= 0.0) or (d1 <= 0.0 and d2 <= 0.0 and d3 <= 0.0)
    rho_min = 0.0
    if not inside:
        rho_min = min(
            _segment_distance(ax, ay, bx, by),
            _segment_distance(bx, by, qx, qy),
            _segment_distance(qx, qy, ax, ay),
        )
    a_lo = a_hi = 0.0
    if rho_min > 0.05:  # the arc it spans (< pi: it does not hold the origin)
        a0 = np.arctan2(ay, ax)
        e1 = _wrap(np.arctan2(by, bx) - a0)
        e2 = _wrap(np.arctan2(qy, qx) - a0)
        a_lo = a0 + min(0.0, e1, e2) - yaw
        a_hi = a0 + max(0.0, e1, e2) - yaw
    _apply(rho_min, rho_max, circles[j, 3] - oz, circles[j, 4] - oz, a_lo, a_hi, view, full_circle, acc)


@_kernel
def _apply(
    rho_min: float,
    rho_max: float,
    dz_lo: float,
    dz_hi: float,
    a_lo: float,
    a_hi: float,
    view: tuple[float, float, float, float, float, float, float],
    full_circle: bool,
    acc: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> None:  # pragma: no cover - compiled
    """Widen the bounds `acc` (per column lo, hi; per block of columns lo, hi; for every column lo, hi) of
    the columns of azimuths a_lo..a_hi (sensor frame; every column when rho_min is within 5 cm) by the
    slopes from heights dz_lo..dz_hi (relative to the sensor) at horizontal distances rho_min..rho_max,
    with the slack for float32 rounding."""
    _, _, _, _, reach, fov, width = view
    lo, hi, block_lo, block_hi, every = acc
    rho_min -= _SLACK_M + _SLACK_REL * rho_min
    if rho_min > reach:
        return
    rho_max = min(rho_max, reach) + _SLACK_M + _SLACK_REL * reach
    zslack = _SLACK_M + _SLACK_REL * reach
    dz_lo -= zslack
    dz_hi += zslack
    if rho_min <= 0.0:
        s_lo = -np.inf if dz_lo < 0.0 else dz_lo / rho_max
        s_hi = np.inf if dz_hi > 0.0 else dz_hi / rho_max
    else:
        s_lo = dz_lo / (rho_min if dz_lo < 0.0 else rho_max)
        s_hi = dz_hi / (rho_min if dz_hi > 0.0 else rho_max)
    columns = lo.shape[0]
    if rho_min <= 0.05:  # (nearly) under the sensor: every column
        every[0] = min(every[0], s_lo)
        every[1] = max(every[1], s_hi)
        return
    half = fov / 2.0
    # column of azimuth a: (half - a) / width - 0.5 (decreasing in a)
    for shift in (0.0, -2.0 * np.pi, 2.0 * np.pi):
        b_lo, b_hi = a_lo + shift, a_hi + shift
        if not full_circle:
            b_lo, b_hi = max(b_lo, -half), min(b_hi, half)
            if b_lo > b_hi:
                continue
        c0 = int(np.floor((half - b_hi) / width - 0.5)) - 1
        c1 = int(np.ceil((half - b_lo) / width - 0.5)) + 1
        if full_circle:
            n = c1 - c0 + 1
            if n >= columns:
                every[0] = min(every[0], s_lo)
                every[1] = max(every[1], s_hi)
                return
            c0 %= columns
            c1 = c0 + n - 1
            if c1 < columns:
                _widen(lo, hi, block_lo, block_hi, c0, c1, s_lo, s_hi)
            else:
                _widen(lo, hi, block_lo, block_hi, c0, columns - 1, s_lo, s_hi)
                _widen(lo, hi, block_lo, block_hi, 0, c1 - columns, s_lo, s_hi)
            return  # one pass covers the arc, whatever its wrap
        c0, c1 = max(c0, 0), min(c1, columns - 1)
        if c0 <= c1:
            _widen(lo, hi, block_lo, block_hi, c0, c1, s_lo, s_hi)


#: Columns per block of `_widen` (a wide arc widens whole blocks, not each of their columns).
_BLOCK = 32


@_inline
def _widen(
    lo: np.ndarray,
    hi: np.ndarray,
    block_lo: np.ndarray,
    block_hi: np.ndarray,
    c0: int,
    c1: int,
    s_lo: float,
    s_hi: float,
) -> None:  # pragma: no cover - compiled
    """Widen the slope bounds of columns c0..c1 (0 <= c0 <= c1 < columns) to [s_lo, s_hi]: the blocks of
    `_BLOCK` columns wholly inside the range as blocks, the columns at its ends one by one."""
    b0 = (c0 + _BLOCK - 1) // _BLOCK  # the first block starting at or after c0
    b1 = (c1 + 1) // _BLOCK - 1  # the last block ending at or before c1
    if b0 > b1:
        for c in range(c0, c1 + 1):
            lo[c] = min(lo[c], s_lo)
            hi[c] = max(hi[c], s_hi)
        return
    for c in range(c0, b0 * _BLOCK):
        lo[c] = min(lo[c], s_lo)
        hi[c] = max(hi[c], s_hi)
    for b in range(b0, b1 + 1):
        block_lo[b] = min(block_lo[b], s_lo)
        block_hi[b] = max(block_hi[b], s_hi)
    for c in range((b1 + 1) * _BLOCK, c1 + 1):
        lo[c] = min(lo[c], s_lo)
        hi[c] = max(hi[c], s_hi)


@_inline
def _segment_distance(ax: float, ay: float, bx: float, by: float) -> float:  # pragma: no cover - compiled
    """Distance from the origin to the segment a-b."""
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    u = 0.0 if length2 <= 0.0 else min(max(-(ax * dx + ay * dy) / length2, 0.0), 1.0)
    return float(np.hypot(ax + u * dx, ay + u * dy))


@_inline
def _wrap(a: float) -> float:  # pragma: no cover - compiled
    """An angle in (-pi, pi]."""
    while a > np.pi:
        a -= 2.0 * np.pi
    while a <= -np.pi:
        a += 2.0 * np.pi
    return a


@_kernel
def fill_level_rays(
    rays: np.ndarray,
    ids: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    tan_elev: np.ndarray,
    dirs_t: np.ndarray,
    pos32: np.ndarray,
    r32: np.ndarray,
) -> int:  # pragma: no cover - compiled
    """The rays of a level sweep that can reach the static scene (`level_bounds`): writes their indices to
    the front of `ids` and their (K, 6) float32 rows to the front of `rays` (origin `pos32`, world direction
    x = d0 * r[0, 0] + d1 * r[0, 1] (+ d2 * r[0, 2] unless that is 0, as it is bar a float32 underflow), y
    alike, z = the sensor frame's: level); returns K. A ray of column c and channel k is kept when its
    slope tan_elev[k] is within [lo[c], hi[c]] widened by `_SLACK_REL`."""
    channels = tan_elev.shape[0]
    px, py, pz = pos32[0], pos32[1], pos32[2]
    r00, r01, r02 = r32[0, 0], r32[0, 1], r32[0, 2]
    r10, r11, r12 = r32[1, 0], r32[1, 1], r32[1, 2]
    z0 = r02 != 0.0
    z1 = r12 != 0.0
    n = 0
    for c in range(lo.shape[0]):
        s_lo, s_hi = lo[c], hi[c]
        if s_lo > s_hi:
            continue
        s_lo -= _SLACK_REL * (1.0 + abs(s_lo))
        s_hi += _SLACK_REL * (1.0 + abs(s_hi))
        for k in range(channels):
            s = tan_elev[k]
            if s < s_lo or s > s_hi:
                continue
            g = c * channels + k
            a = dirs_t[0, g]
            b = dirs_t[1, g]
            rays[n, 0] = px
            rays[n, 1] = py
            rays[n, 2] = pz
            x = a * r00
            x += b * r01
            y = a * r10
            y += b * r11
            if z0:
                x += dirs_t[2, g] * r02
            if z1:
                y += dirs_t[2, g] * r12
            rays[n, 3] = x
            rays[n, 4] = y
            rays[n, 5] = dirs_t[2, g]
            ids[n] = g
            n += 1
    return n


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
    columns the box axes, `half` its half sizes): the slab test of the numpy reference (tests/test_sensors.py
    `intersect_box_rows`), in the same float64 arithmetic. Where the box is closer than the return so far, it becomes the return (range, |cos|
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
def box_slopes(corner: np.ndarray, widen: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """The range (lo, hi) of slopes z / rho from the sensor to a box with these corners (8, 3; sensor frame,
    the sensor at the origin or, with `widen` > 0, anywhere within `widen` m of it horizontally at the same
    height): z within the corners' z range, rho from the nearest point of the box's bounding circle to its
    farthest corner. A ray whose elevation's tangent is outside cannot hit the box."""
    mx = my = 0.0
    zmin, zmax = np.inf, -np.inf
    for k in range(8):
        mx += corner[k, 0] / 8.0
        my += corner[k, 1] / 8.0
        zmin = min(zmin, corner[k, 2])
        zmax = max(zmax, corner[k, 2])
    radius = 0.0
    rho_max = 0.0
    for k in range(8):
        radius = max(radius, np.hypot(corner[k, 0] - mx, corner[k, 1] - my))
        rho_max = max(rho_max, np.hypot(corner[k, 0], corner[k, 1]))
    rho_min = max(np.hypot(mx, my) - radius - widen, 0.0)
    rho_max += widen
    if rho_min <= 0.0:
        return (-np.inf if zmin < 0.0 else zmin / rho_max), (np.inf if zmax > 0.0 else zmax / rho_max)
    return zmin / (rho_min if zmin < 0.0 else rho_max), zmax / (rho_min if zmax > 0.0 else rho_max)


@_kernel
def boxes_returns(
    t: np.ndarray,
    cos_inc: np.ndarray,
    classes: np.ndarray,
    object_id: np.ndarray,
    centers: np.ndarray,
    rotations: np.ndarray,
    halves: np.ndarray,
    box_classes: np.ndarray,
    box_ids: np.ndarray,
    skip: int,
    pos: np.ndarray,
    rot: np.ndarray,
    r32: np.ndarray,
    dirs_t: np.ndarray,
    tan_elev: np.ndarray,
    columns: int,
    fov: float,
    full_circle: bool,
    range_min: float,
    range_max: float,
    unoccluded: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """`box_returns` for every box of the frame but `skip` (the carrier) within `range_max` of a sweep from
    `pos` with rotation `rot` (float64; `r32` as float32): each box only with the columns its corners span
    (one column of slack each side; every column when they surround the sensor) and the channels whose
    elevation can reach it (`tan_elev`: the slope of each channel, with 1e-4 relative slack). Writes each
    box's rays hitting it within range to `unoccluded`."""
    channels = tan_elev.shape[0]
    width = fov / columns
    half_fov = fov / 2.0
    marks = np.zeros(columns, np.uint8)
    cols = np.empty(columns, np.int64)
    chans = np.empty(channels, np.int64)
    corner = np.empty((8, 3))
    angles = np.empty(8)
    for i in range(centers.shape[0]):
        unoccluded[i] = 0
        if i == skip:
            continue  # a sensor does not see its own carrier
        hx, hy, hz = halves[i, 0], halves[i, 1], halves[i, 2]
        rx = centers[i, 0] - pos[0]
        ry = centers[i, 1] - pos[1]
        rz = centers[i, 2] - pos[2]
        if np.sqrt(rx * rx + ry * ry + rz * rz) - np.sqrt(hx * hx + hy * hy + hz * hz) > range_max:
            continue
        # the corners in the sensor frame
        for k in range(8):
            sx = hx if k & 4 else -hx
            sy = hy if k & 2 else -hy
            sz = hz if k & 1 else -hz
            wx = rx + rotations[i, 0, 0] * sx + rotations[i, 0, 1] * sy + rotations[i, 0, 2] * sz
            wy = ry + rotations[i, 1, 0] * sx + rotations[i, 1, 1] * sy + rotations[i, 1, 2] * sz
            wz = rz + rotations[i, 2, 0] * sx + rotations[i, 2, 1] * sy + rotations[i, 2, 2] * sz
            for a in range(3):
                corner[k, a] = wx * rot[0, a] + wy * rot[1, a] + wz * rot[2, a]
            angles[k] = np.arctan2(corner[k, 1], corner[k, 0]) % (2.0 * np.pi)
        # columns: the smallest arc holding every corner's azimuth (none: they surround the sensor)
        for k in range(1, 8):  # insertion sort: 8 values (numpy's sort costs seconds of compile time)
            a = angles[k]
            m = k - 1
            while m >= 0 and angles[m] > a:
                angles[m + 1] = angles[m]
                m -= 1
            angles[m + 1] = a
        gap, j = angles[0] + 2.0 * np.pi - angles[7], 7
        for k in range(7):
            if angles[k + 1] - angles[k] > gap:
                gap, j = angles[k + 1] - angles[k], k
        n_cols = 0
        if gap <= np.pi:
            for c in range(columns):
                cols[c] = c
            n_cols = columns
        else:
            a_lo = angles[(j + 1) % 8]
            a_hi = a_lo + 2.0 * np.pi - gap
            if full_circle:
                c0 = int(np.floor((half_fov - a_hi) / width - 0.5)) - 1
                c1 = int(np.ceil((half_fov - a_lo) / width - 0.5)) + 1
                if c1 - c0 + 1 >= columns:
                    c0, c1 = 0, columns - 1
                for c in range(c0, c1 + 1):
                    cols[n_cols] = c % columns
                    n_cols += 1
            else:
                marks[:] = 0
                for shift in (0.0, -2.0 * np.pi, 2.0 * np.pi):
                    b_lo, b_hi = max(a_lo + shift, -half_fov), min(a_hi + shift, half_fov)
                    if b_lo > b_hi:
                        continue
                    c0 = max(int(np.floor((half_fov - b_hi) / width - 0.5)) - 1, 0)
                    c1 = min(int(np.ceil((half_fov - b_lo) / width - 0.5)) + 1, columns - 1)
                    for c in range(c0, c1 + 1):
                        marks[c] = 1
                for c in range(columns):
                    if marks[c]:
                        cols[n_cols] = c
                        n_cols += 1
        if n_cols == 0:
            continue
        s_lo, s_hi = box_slopes(corner, 0.0)
        s_lo -= _SLACK_REL * (1.0 + abs(s_lo))
        s_hi += _SLACK_REL * (1.0 + abs(s_hi))
        n_chans = 0
        for k in range(channels):
            if tan_elev[k] >= s_lo and tan_elev[k] <= s_hi:
                chans[n_chans] = k
                n_chans += 1
        if n_chans == 0:
            continue
        # the ray origin in the box frame
        o = np.empty(3)
        for a in range(3):
            o[a] = -(rx * rotations[i, 0, a] + ry * rotations[i, 1, a] + rz * rotations[i, 2, a])
        unoccluded[i] = box_returns(
            t, cos_inc, classes, object_id, cols[:n_cols], chans[:n_chans], channels, dirs_t, r32, o,
            rotations[i], halves[i], range_min, range_max, box_classes[i], box_ids[i],
        )  # fmt: skip


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
    one_f, ones = np.zeros(1), np.ones(1)
    level_bounds(
        np.zeros(2, i64), np.zeros(0, i64), np.array([0.0, 0.0, 1.0, 1.0, 1.0]), np.zeros((0, 5)),
        np.zeros(1, i64), np.zeros((0, 5)), np.zeros((0, 3, 3)), np.zeros(1, i64), np.zeros(3), 0.0, 1.0, True, 1.0, one_f, ones,
    )  # fmt: skip
    fill_level_rays(rays, np.zeros(1, i64), one_f, ones, one_f, np.zeros((3, 1), f32), np.zeros(3, f32),
                    np.eye(3, dtype=f32))  # fmt: skip
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
    box_slopes(np.ones((8, 3)), 0.0)
    boxes_returns(
        t, cos, classes, oid, np.zeros((1, 3)), np.eye(3)[None], np.ones((1, 3)), np.zeros(1, u8),
        np.ones(1, u32), 0, np.zeros(3), np.eye(3), np.eye(3, dtype=f32), np.zeros((3, 1), f32), np.zeros(1),
        1, 1.0, True, 0.0, 1.0, np.zeros(1, i64),
    )  # fmt: skip
    kept, counts = np.zeros(1, i64), np.zeros(2, i64)
    select_returns(t, oid, f32(0), f32(1), np.zeros(0, f32), f32(0), kept, counts)
    fill_points(
        np.zeros((1, 7), u32), kept, t, np.zeros(0, f32), f32(0), np.zeros((3, 1), f32), np.zeros((0, 3)),
        np.zeros(1), classes, cos, np.zeros(256, f32), oid, np.zeros(1, u16), 1, counts,
    )  # fmt: skip
