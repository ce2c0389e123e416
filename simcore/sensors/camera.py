"""A pinhole depth and semantic camera by raycasting (see `simcore.spec.CameraSensor`).

One ray per pixel centre through an ideal pinhole (no distortion), square pixels, principal point in the
image centre. Depth is the distance along the optical axis (REP-118: 32FC1 metres, NaN without a return
within range); the label image holds the class id of every pixel (0: nothing). Boxes are intersected only
on the pixel rectangle their corners project to (exact for a convex box in front of the camera).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simcore.sensors.lidar import mount_pose
from simcore.sensors.scene import Boxes, RoadScene, intersect_box, rotation
from simcore.spec import CameraSensor
from simcore.world.state import EntityState

#: columns: the optical frame's axes (x right, y down, z forward) in the sensor frame (x forward, y left, z up)
OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True, slots=True)
class CameraImage:
    depth: np.ndarray  # (H, W) float32, m along the optical axis, NaN = no return
    labels: np.ndarray  # (H, W) uint8 class ids
    object_ids: np.ndarray  # (H, W) uint32, 0 = no object


class Camera:
    def __init__(self, config: CameraSensor) -> None:
        self.config = config
        w, h = config.width, config.height
        self.fx = self.fy = (w / 2) / math.tan(math.radians(config.horizontal_fov) / 2)
        self.cx, self.cy = (w - 1) / 2, (h - 1) / 2
        u, v = np.meshgrid(np.arange(w), np.arange(h))
        d_opt = np.stack(
            [(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u, dtype=float)], axis=-1
        )
        d_opt /= np.linalg.norm(d_opt, axis=-1, keepdims=True)
        self.axial = d_opt[..., 2].reshape(-1)  # cos of the angle to the optical axis
        self.dirs = d_opt.reshape(-1, 3) @ OPTICAL.T  # sensor frame, row-major pixels
        m = config.mount
        self.mount_rot = rotation(math.radians(m.yaw), math.radians(m.pitch), math.radians(m.roll))
        self.mount_pos = np.array([m.x, m.y, m.z])
        self.period = 1.0 / config.rate
        self._rays = np.empty((len(self.dirs), 6), np.float32)

    def _pixels_of(self, corners_sensor: np.ndarray) -> np.ndarray | None:
        """Pixel indices a box (corners in the sensor frame) can cover; None = all; empty = none."""
        opt = corners_sensor @ OPTICAL  # into the optical frame
        z = opt[:, 2]
        if np.all(z <= 1e-6):
            return np.zeros(0, np.int64)
        if np.any(z <= 1e-3):
            return None
        u = self.fx * opt[:, 0] / z + self.cx
        v = self.fy * opt[:, 1] / z + self.cy
        w, h = self.config.width, self.config.height
        u0, u1 = max(math.floor(u.min()) - 1, 0), min(math.ceil(u.max()) + 1, w - 1)
        v0, v1 = max(math.floor(v.min()) - 1, 0), min(math.ceil(v.max()) + 1, h - 1)
        if u0 > u1 or v0 > v1:
            return np.zeros(0, np.int64)
        rows = np.arange(v0, v1 + 1)
        cols = np.arange(u0, u1 + 1)
        return (rows[:, None] * w + cols[None, :]).ravel()

    def capture(self, road: RoadScene, boxes: Boxes, carrier: EntityState, carrier_index: int) -> CameraImage:
        cfg = self.config
        rot, pos = mount_pose(carrier, self.mount_rot, self.mount_pos)
        dirs_world = self.dirs @ rot.T
        self._rays[:, :3] = pos
        self._rays[:, 3:] = dirs_world
        t, _, classes = road.cast(self._rays)
        t = t.astype(np.float64)
        object_id = np.zeros(len(t), np.uint32)
        for i in range(len(boxes.names)):
            if i == carrier_index:
                continue
            rel = boxes.centers[i] - pos
            if np.linalg.norm(rel) - np.linalg.norm(boxes.half[i]) > cfg.range_max:
                continue
            idx = self._pixels_of((boxes.corners(i) - pos) @ rot)
            if idx is None:
                idx = np.arange(len(t))
            if not len(idx):
                continue
            tb, _ = intersect_box(pos, dirs_world[idx], boxes.centers[i], boxes.rotations[i], boxes.half[i])
            closer = tb < t[idx]
            sel = idx[closer]
            t[sel] = tb[closer]
            classes[sel] = boxes.classes[i]
            object_id[sel] = boxes.ids[i]
        valid = (t >= cfg.range_min) & (t <= cfg.range_max)
        depth = np.where(valid, t * self.axial, np.nan).astype(np.float32)
        classes = np.where(valid, classes, 0).astype(np.uint8)
        object_id = np.where(valid, object_id, 0).astype(np.uint32)
        shape = (cfg.height, cfg.width)
        return CameraImage(depth.reshape(shape), classes.reshape(shape), object_id.reshape(shape))
