"""Line of sight between points of one frame: blocked by entity boxes and by the road scene (road surface and
OpenDRIVE objects, open3d raycasting), each as the sensors see them.

Boxes: a broad phase keeps the (segment, box) pairs whose box's bounding sphere comes within reach of the
segment, then one vectorised slab test runs on all of them (a segment starting inside a box is not blocked by
it, as for the sensors' rays)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from simcore.sensors.scene import Boxes

if TYPE_CHECKING:
    from simcore.sensors.scene import RoadScene

#: A segment's end this close to an obstacle does not count as blocked (m).
_EPS = 0.05


def _blocked_by_boxes(
    a: np.ndarray,
    dirs: np.ndarray,
    length: np.ndarray,
    boxes: Boxes,
    ignore_a: np.ndarray,
    ignore_b: np.ndarray,
) -> np.ndarray:
    k, n = len(a), len(boxes.names)
    blocked = np.zeros(k, dtype=bool)
    if n == 0:
        return blocked
    radius = np.sqrt((boxes.half**2).sum(axis=1))  # (N,) bounding spheres
    b = a + dirs * length[:, None]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    cx, cy, cz = boxes.centers[:, 0], boxes.centers[:, 1], boxes.centers[:, 2]
    # broad phase 1: the sphere's bounding cube overlaps the segment's bounding box (K, N)
    near = (cx + radius >= lo[:, 0:1]) & (cx - radius <= hi[:, 0:1])
    near &= (cy + radius >= lo[:, 1:2]) & (cy - radius <= hi[:, 1:2])
    near &= (cz + radius >= lo[:, 2:3]) & (cz - radius <= hi[:, 2:3])
    near[np.flatnonzero(ignore_a >= 0), ignore_a[ignore_a >= 0]] = False
    near[np.flatnonzero(ignore_b >= 0), ignore_b[ignore_b >= 0]] = False
    rows, cols = np.nonzero(near)
    if len(rows) == 0:
        return blocked
    # broad phase 2: the sphere comes within reach of the segment
    rel = boxes.centers[cols] - a[rows]
    along = np.clip((rel * dirs[rows]).sum(axis=1), 0.0, length[rows])
    gap = rel - along[:, None] * dirs[rows]
    keep = (gap**2).sum(axis=1) <= radius[cols] ** 2
    rows, cols = rows[keep], cols[keep]
    if len(rows) == 0:
        return blocked
    rot = boxes.rotations[cols]  # (P, 3, 3), columns are the box axes
    o = np.einsum("pi,pij->pj", a[rows] - boxes.centers[cols], rot)
    d = np.einsum("pi,pij->pj", dirs[rows], rot)
    half = boxes.half[cols]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (-half - o) * inv
        t2 = (half - o) * inv
    lo = np.fmin(t1, t2)  # fmin/fmax: a NaN (parallel, in the face's plane) sets no constraint
    hi = np.fmax(t1, t2)
    lo = np.where(np.isnan(lo), -np.inf, lo)
    hi = np.where(np.isnan(hi), np.inf, hi)
    tmin = lo.max(axis=1)
    tmax = hi.min(axis=1)
    hit = (tmax >= tmin) & (tmin > 0.0) & (tmin < length[rows] - _EPS)
    blocked[rows[hit]] = True
    return blocked


class Sight:
    """Line of sight in one frame: `clear(a, b, ignore_a, ignore_b)` for K segments a→b (K, 3), ignoring the
    boxes with indexes `ignore_a`/`ignore_b` (K,) (−1: none), e.g. the boxes the segment starts and ends in."""

    def __init__(self, boxes: Boxes, scene: RoadScene | None) -> None:
        self.boxes = boxes
        self.scene = scene

    def clear(
        self,
        a: np.ndarray,
        b: np.ndarray,
        ignore_a: np.ndarray | None = None,
        ignore_b: np.ndarray | None = None,
    ) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        k = len(a)
        if k == 0:
            return np.zeros(0, dtype=bool)
        ignore_a = np.full(k, -1) if ignore_a is None else np.asarray(ignore_a)
        ignore_b = np.full(k, -1) if ignore_b is None else np.asarray(ignore_b)
        delta = b - a
        length = np.linalg.norm(delta, axis=1)
        dirs = delta / np.maximum(length, 1e-12)[:, None]
        blocked = _blocked_by_boxes(a, dirs, length, self.boxes, ignore_a, ignore_b)
        if self.scene is not None and self.scene.triangle_count:
            rays = np.concatenate([a, dirs], axis=1).astype(np.float32)
            t_hit, _, _ = self.scene.cast(rays)
            blocked |= t_hit < length - _EPS
        return ~blocked
