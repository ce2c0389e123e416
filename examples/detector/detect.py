"""The detection pipeline on a plain (N, 3) array of points in the sensor frame (x forward, z up)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class DetectorParams:
    max_range: float = 80.0  # m, BEV
    min_range: float = 1.0  # m: closer returns are the carrier itself
    ground_threshold: float = 0.25  # m above the ground plane still counted as ground
    max_height: float = 4.5  # m above the ground: higher returns are ignored (bridges, signs)
    ransac_iterations: int = 80
    ransac_sample: int = 4000  # points the plane is searched on
    cluster_tolerance: float = 0.8  # m, BEV distance that links two points into one cluster …
    cluster_tolerance_per_m: float = 0.12  # … along the line of sight, growing with range (sparser returns) …
    cluster_tolerance_across_per_m: float = 0.02  # … across it …
    max_cluster_tolerance: float = 3.0  # … up to this
    min_points: int = 5  # points a cluster needs to be reported
    merge_margin: float = 0.5  # m: a cluster centred this close to a vehicle's box is part of it
    keep_unknown: bool = False  # report clusters whose size fits no class (as "unknown")
    seed: int = 0


#: class → (length, width) prior of a full object, m
PRIORS: dict[str, tuple[float, float]] = {
    "car": (4.5, 1.85),
    "truck": (10.0, 2.5),
    "pedestrian": (0.6, 0.6),
}


@dataclass(frozen=True)
class Box:
    x: float
    y: float
    z: float
    length: float
    width: float
    height: float
    yaw: float
    label: str
    score: float
    points: int
    cluster_x: float = 0.0  # centroid of the cluster's points (BEV)
    cluster_y: float = 0.0


def fit_ground(xyz: np.ndarray, params: DetectorParams) -> np.ndarray | None:
    """RANSAC plane (a, b, c, d) with a·x + b·y + c·z + d = 0, c > 0 (unit normal, near vertical), refined
    by least squares on its inliers; None when there are too few points."""
    if len(xyz) < 3:
        return None
    rng = np.random.default_rng(params.seed)
    sample = (
        xyz
        if len(xyz) <= params.ransac_sample
        else xyz[rng.choice(len(xyz), params.ransac_sample, replace=False)]
    )
    best, best_count = None, -1
    idx = rng.integers(0, len(sample), size=(params.ransac_iterations, 3))
    p0, p1, p2 = sample[idx[:, 0]], sample[idx[:, 1]], sample[idx[:, 2]]
    normals = np.cross(p1 - p0, p2 - p0)
    norms = np.linalg.norm(normals, axis=1)
    for k in range(params.ransac_iterations):
        if norms[k] < 1e-6:
            continue
        n = normals[k] / norms[k]
        if n[2] < 0:
            n = -n
        if n[2] < 0.9:  # the ground is near horizontal
            continue
        d = -float(n @ p0[k])
        count = int(np.count_nonzero(np.abs(sample @ n + d) < params.ground_threshold * 0.6))
        if count > best_count:
            best, best_count = np.append(n, d), count
    if best is None:
        return None
    inliers = xyz[np.abs(xyz @ best[:3] + best[3]) < params.ground_threshold * 0.6]
    if len(inliers) >= 3:
        centroid = inliers.mean(axis=0)
        _, _, vt = np.linalg.svd(inliers - centroid, full_matrices=False)
        n = vt[2] if vt[2][2] > 0 else -vt[2]
        if n[2] >= 0.9:
            best = np.append(n, -float(n @ centroid))
    return best


def cluster(
    xy: np.ndarray,
    tolerance: float,
    per_m: float = 0.0,
    max_tolerance: float | None = None,
    cell: float = 0.2,
    across_per_m: float = 0.02,
) -> np.ndarray:
    """Euclidean clustering in BEV: labels (N,) of the connected components of the graph linking two
    points whose separation along the line of sight is within max(tolerance, per_m × range) (at most
    `max_tolerance`: returns get sparse along the line of sight far away and on grazing surfaces) and
    across it within max(tolerance, across_per_m × range). The points are first reduced to the occupied
    cells of a `cell`-sized grid (a cell's points share its label)."""
    if len(xy) == 0:
        return np.zeros(0, dtype=np.int64)
    keys = np.floor(xy / cell).astype(np.int64)
    cells, inverse = np.unique(keys, axis=0, return_inverse=True)
    centres = (cells + 0.5) * cell
    top = max(tolerance, max_tolerance or tolerance)
    pairs = cKDTree(centres).query_pairs(top, output_type="ndarray")
    if len(pairs) and top > tolerance:
        i, j = pairs[:, 0], pairs[:, 1]
        rng = np.hypot(centres[:, 0], centres[:, 1])
        near = np.minimum(rng[i], rng[j])
        sight = (centres[i] + centres[j]) / 2
        sight /= np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-9)
        delta = centres[i] - centres[j]
        along = np.abs(np.einsum("ij,ij->i", delta, sight))
        across = np.abs(delta[:, 0] * sight[:, 1] - delta[:, 1] * sight[:, 0])
        limit_along = np.clip(per_m * near, tolerance, top)
        limit_across = np.clip(across_per_m * near, tolerance, top)
        pairs = pairs[(along / limit_along) ** 2 + (across / limit_across) ** 2 <= 1.0]
    n = len(centres)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return labels[inverse.reshape(-1)]


def l_shape_rectangle(xy: np.ndarray, step_deg: float = 1.0) -> tuple[np.ndarray, float, float, float]:
    """(centre (2,), extent along the axis, extent across it, axis angle) of the rectangle that fits the
    points best by the closeness criterion of L-shape fitting (Zhang et al., 2017): over axis angles in
    [0°, 90°), the sum over points of 1 / (distance to the nearest rectangle edge)."""
    angles = np.radians(np.arange(0.0, 90.0, step_deg))
    e1 = np.stack([np.cos(angles), np.sin(angles)])  # (2, A)
    e2 = np.stack([-np.sin(angles), np.cos(angles)])
    c1 = xy @ e1  # (N, A)
    c2 = xy @ e2
    d1 = np.minimum(c1.max(axis=0) - c1, c1 - c1.min(axis=0))
    d2 = np.minimum(c2.max(axis=0) - c2, c2 - c2.min(axis=0))
    closeness = (1.0 / np.maximum(np.minimum(d1, d2), 0.05)).sum(axis=0)
    k = int(np.argmax(closeness))
    a = float(angles[k])
    u0, u1 = c1[:, k].min(), c1[:, k].max()
    v0, v1 = c2[:, k].min(), c2[:, k].max()
    cu, cv = (u0 + u1) / 2, (v0 + v1) / 2
    c, s = math.cos(a), math.sin(a)
    return np.array([c * cu - s * cv, s * cu + c * cv]), float(u1 - u0), float(v1 - v0), a


def classify(length: float, width: float, height: float) -> str:
    """By size: length >= width are the BEV extents of the visible part, height above the ground."""
    if length < 1.2 and width < 1.2 and 0.9 <= height <= 2.2:
        return "pedestrian"
    if 0.8 <= height <= 2.4 and length <= 6.5 and width <= 2.6:
        return "car"
    if 2.0 <= height <= 4.5 and length <= 20.0 and width <= 3.2 and max(length, width) >= 2.0:
        return "truck"
    return "unknown"


def _complete(centre: np.ndarray, extent: float, axis: np.ndarray, prior: float) -> tuple[np.ndarray, float]:
    """Grow an extent to its prior, keeping the face nearest the sensor (the origin) in place."""
    if extent >= prior:
        return centre, extent
    away = 1.0 if float(centre @ axis) >= 0 else -1.0
    return centre + axis * away * (prior - extent) / 2, prior


def fit_box(points: np.ndarray, ground: np.ndarray) -> Box:
    """An oriented box around a cluster (sensor frame), completed to its class's prior size."""
    xy = points[:, :2]
    centre, du, dv, angle = l_shape_rectangle(xy)
    axis_u = np.array([math.cos(angle), math.sin(angle)])
    axis_v = np.array([-axis_u[1], axis_u[0]])
    a, b, c, d = ground
    height = float((points @ ground[:3] + d).max())  # above the ground plane (unit normal)
    if du < dv:
        du, dv, axis_u, axis_v = dv, du, axis_v, axis_u
    label = classify(du, dv, height)
    if label in ("car", "truck") and du <= PRIORS[label][1] + 0.5:
        # neither visible side is longer than the object is wide: only its back or front (and perhaps a
        # little of a side) is visible, so it extends along the line of sight
        sight = centre / max(float(np.linalg.norm(centre)), 1e-9)
        if abs(float(sight @ axis_v)) > abs(float(sight @ axis_u)):
            du, dv, axis_u, axis_v = dv, du, axis_v, axis_u
    if label in PRIORS:
        prior_l, prior_w = PRIORS[label]
        centre, du = _complete(centre, du, axis_u, prior_l)
        centre, dv = _complete(centre, dv, axis_v, prior_w)
    yaw = math.atan2(axis_u[1], axis_u[0])
    if yaw > math.pi / 2:
        yaw -= math.pi
    elif yaw <= -math.pi / 2:
        yaw += math.pi
    ground_z = -(d + a * centre[0] + b * centre[1]) / c
    return Box(
        x=float(centre[0]),
        y=float(centre[1]),
        z=float(ground_z + height / 2),
        length=float(du),
        width=float(dv),
        height=height,
        yaw=yaw,
        label=label,
        score=min(1.0, len(points) / 50.0),
        points=len(points),
        cluster_x=float(xy[:, 0].mean()),
        cluster_y=float(xy[:, 1].mean()),
    )


def detect(xyz: np.ndarray, params: DetectorParams | None = None) -> list[Box]:
    """Objects in a point cloud (N, 3), sensor frame."""
    params = params or DetectorParams()
    xyz = np.asarray(xyz, dtype=np.float64)
    xyz = xyz[np.all(np.isfinite(xyz), axis=1)]
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    xyz = xyz[(r <= params.max_range) & (r >= params.min_range)]
    ground = fit_ground(xyz, params)
    if ground is None:
        return []
    height = xyz @ ground[:3] + ground[3]
    objects = xyz[(height > params.ground_threshold) & (height < params.max_height)]
    labels = cluster(
        objects[:, :2],
        params.cluster_tolerance,
        params.cluster_tolerance_per_m,
        params.max_cluster_tolerance,
        across_per_m=params.cluster_tolerance_across_per_m,
    )
    candidates = []
    for k in np.unique(labels):
        pts = objects[labels == k]
        if len(pts) < params.min_points:
            continue
        box = fit_box(pts, ground)
        if box.label == "unknown" and not params.keep_unknown:
            continue
        candidates.append(box)
    # a fragment of a vehicle (its roof beyond an unsampled stretch, a sparse side) lies within the
    # vehicle's completed box: keep the box with the most points
    boxes: list[Box] = []
    for box in sorted(candidates, key=lambda b: -b.points):
        owner = next(
            (
                k
                for k, kept in enumerate(boxes)
                if kept.label in ("car", "truck")
                and _inside(box.cluster_x, box.cluster_y, kept, params.merge_margin)
            ),
            None,
        )
        if owner is None:
            boxes.append(box)
            continue
        kept = boxes[owner]  # the fragment's points belong to it: it may be taller than its own points said
        if box.height > kept.height:
            bottom = kept.z - kept.height / 2
            boxes[owner] = replace(
                kept, z=bottom + box.height / 2, height=box.height, points=kept.points + box.points
            )
        else:
            boxes[owner] = replace(kept, points=kept.points + box.points)
    return boxes


def _inside(x: float, y: float, box: Box, margin: float) -> bool:
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    u = (x - box.x) * c + (y - box.y) * s
    v = -(x - box.x) * s + (y - box.y) * c
    return abs(u) <= box.length / 2 + margin and abs(v) <= box.width / 2 + margin
