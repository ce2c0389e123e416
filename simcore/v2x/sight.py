"""Line of sight between points of one frame: blocked by entity boxes (slab test) and by the road scene
(road surface and OpenDRIVE objects, open3d raycasting), each as the sensors see them."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from simcore.sensors.scene import Boxes, intersect_box

if TYPE_CHECKING:
    from simcore.sensors.scene import RoadScene

#: A ray's end this close to an obstacle does not count as blocked (m).
_EPS = 0.05


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
        blocked = np.zeros(k, dtype=bool)
        boxes = self.boxes
        for i in range(len(boxes.names)):
            t, _ = intersect_box(a, dirs, boxes.centers[i], boxes.rotations[i], boxes.half[i])
            hit = (t < length - _EPS) & (ignore_a != i) & (ignore_b != i)
            blocked |= hit
        if self.scene is not None and self.scene.triangle_count:
            rays = np.concatenate([a, dirs], axis=1).astype(np.float32)
            t_hit, _, _ = self.scene.cast(rays)
            blocked |= t_hit < length - _EPS
        return ~blocked
