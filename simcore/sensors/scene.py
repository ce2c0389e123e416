"""What the sensors see: the road surface and every entity as an oriented box.

- The road surface is triangulated once per road network from the sampled lane borders of every lane with
  a width (`OpenDrive.sample_lane_boundaries`): lanes, not an infinite plane. It is the static part of the
  scene, one open3d `RaycastingScene` (Embree BVH) built once. Each triangle carries its class (`road` for
  drivable lanes, `roadside`/`sidewalk` for the others).
- Entities are oriented boxes with their OpenSCENARIO bounding boxes, refreshed every frame from the
  `WorldFrame` into a few numpy arrays (no BVH rebuild). Rays are intersected with them exactly (slab test
  in the box frame), but only the rays whose direction can reach a box: each sensor narrows every box to
  the ray columns (lidar azimuths, camera pixel columns/rows) its corners span, so the cost scales with
  what the box covers, not with the scan size. That also gives each box's unoccluded ray count
  (occlusion ratio) for free.

A sensor never sees the entity it is mounted on (its own box is left out of its scans).

Static scenery: the road file's `<object>` records with a height (poles, barriers, buildings, trees, …) are
boxes in the static scene (`static_objects`): `length`×`width`×`height`, or a square of side 2×`radius`
for round ones, at (s, t, zOffset) with `hdg` relative to the road; `<repeat>`, `<outline>` and flat types
(markings, parking spaces, crosswalks) are left out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from simcore.sensors.classes import CLASS_IDS, REFLECTIVITY, SCENERY_CLASSES, entity_class, lane_class
from simcore.world.opendrive import OpenDrive
from simcore.world.road_model import DRIVING_LANE_TYPES
from simcore.world.state import WorldFrame

FloatArray = np.ndarray


def rotation(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Rotation matrix of the intrinsic z-y'-x'' rotation (yaw, pitch, roll): columns are the rotated axes."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def rotations(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """`rotation` of N (yaw, pitch, roll) triples at once: (N, 3, 3)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    out = np.empty((len(yaw), 3, 3))
    out[:, 0, 0] = cy * cp
    out[:, 0, 1] = cy * sp * sr - sy * cr
    out[:, 0, 2] = cy * sp * cr + sy * sr
    out[:, 1, 0] = sy * cp
    out[:, 1, 1] = sy * sp * sr + cy * cr
    out[:, 1, 2] = sy * sp * cr - cy * sr
    out[:, 2, 0] = -sp
    out[:, 2, 1] = cp * sr
    out[:, 2, 2] = cp * cr
    return out


def road_mesh(road: OpenDrive, step: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (V, 3) float32, triangles (T, 3) uint32, triangle classes (T,) uint8) of the road surface:
    two triangles per lane and sample interval, degenerate (zero-width) ones dropped."""
    verts: list[np.ndarray] = []
    tris: list[np.ndarray] = []
    classes: list[np.ndarray] = []
    base = 0
    for road_id in sorted(road.roads):
        for lane in road.sample_lane_boundaries(road_id, step=step):
            n = len(lane.s)
            if n < 2:
                continue
            width = np.linalg.norm(lane.outer - lane.inner, axis=1)
            if not np.any(width > 1e-3):
                continue
            v = np.concatenate([lane.inner, lane.outer])  # inner 0..n-1, outer n..2n-1
            k = np.arange(n - 1)
            a = np.stack([k, k + n, k + 1], axis=1)
            b = np.stack([k + 1, k + n, k + 1 + n], axis=1)
            t = np.concatenate([a, b])
            # drop triangles whose interval has zero width at both ends (zero area)
            keep = np.concatenate([(width[:-1] > 1e-3) | (width[1:] > 1e-3)] * 2)
            t = t[keep]
            if not len(t):
                continue
            cls = CLASS_IDS[lane_class(lane.lane_type, lane.lane_type.lower() in DRIVING_LANE_TYPES)]
            verts.append(v)
            tris.append(t + base)
            classes.append(np.full(len(t), cls, dtype=np.uint8))
            base += len(v)
    if not verts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32), np.zeros(0, np.uint8)
    return (
        np.concatenate(verts).astype(np.float32),
        np.concatenate(tris).astype(np.uint32),
        np.concatenate(classes),
    )


_CUBE = np.array(
    [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
     [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]],
    dtype=np.uint32,
)  # fmt: skip
_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)


@dataclass(frozen=True, slots=True)
class StaticObject:
    """A box of static scenery (world frame)."""

    name: str
    class_id: int
    center: np.ndarray
    rotation: np.ndarray
    half: np.ndarray

    def corners(self) -> np.ndarray:
        return self.center + (_SIGNS * self.half) @ self.rotation.T


def static_objects(road: OpenDrive, xml: bytes) -> list[StaticObject]:
    """The `<object>` records of an OpenDRIVE document (already parsed into `road`) as boxes."""
    import defusedxml.ElementTree as DET

    out: list[StaticObject] = []
    root = DET.fromstring(xml)
    for road_el in root.findall("road"):
        road_id = road_el.get("id", "")
        if road_id not in road.roads:
            continue
        for obj in road_el.findall("objects/object"):
            kind = (obj.get("type") or "").lower()
            cls = SCENERY_CLASSES.get(kind)
            try:
                s = float(obj.get("s", "0"))
                t = float(obj.get("t", "0"))
                z_offset = float(obj.get("zOffset", "0"))
                height = float(obj.get("height", "0"))
                radius = obj.get("radius")
                length = 2 * float(radius) if radius else float(obj.get("length", "0"))
                width = 2 * float(radius) if radius else float(obj.get("width", "0"))
                hdg = float(obj.get("hdg", "0"))
                pitch = float(obj.get("pitch", "0"))
                roll = float(obj.get("roll", "0"))
            except ValueError:
                continue  # a malformed record is scenery we cannot place; the road itself parsed
            if cls is None or min(height, length, width) <= 0:
                continue
            pose = road.road_to_world(road_id, min(max(s, 0.0), road.road_length(road_id)), t)
            rot = rotation(pose.heading + hdg, pitch, roll)
            center = np.array([pose.x, pose.y, pose.z + z_offset]) + rot @ np.array([0.0, 0.0, height / 2])
            out.append(
                StaticObject(
                    name=obj.get("name") or obj.get("id") or kind,
                    class_id=CLASS_IDS[cls],
                    center=center,
                    rotation=rot,
                    half=np.array([length / 2, width / 2, height / 2]),
                )
            )
    return out


@dataclass(frozen=True, slots=True)
class Boxes:
    """Every entity of one frame as an oriented box (world frame), in the frame's entity order.

    `ids` are the object ids of the labels: 1 + the entity's position in the frame (0 = no object)."""

    names: tuple[str, ...]
    ids: np.ndarray  # (N,) uint32
    classes: np.ndarray  # (N,) uint8
    class_names: tuple[str, ...]
    centers: np.ndarray  # (N, 3)
    rotations: np.ndarray  # (N, 3, 3) columns: the box's forward, left, up axes
    half: np.ndarray  # (N, 3) half length, width, height
    yaws: np.ndarray  # (N,)
    velocities: np.ndarray  # (N, 3) world frame

    @classmethod
    def of(cls, frame: WorldFrame) -> Boxes:
        n = len(frame.entities)
        # per entity: x, y, z, heading, pitch, roll, box centre x, y, z, length, width, height, speed
        table = np.array(
            [
                (
                    e.x,
                    e.y,
                    e.z,
                    e.heading,
                    e.pitch,
                    e.roll,
                    e.bbox.center_x,
                    e.bbox.center_y,
                    e.bbox.center_z,
                    e.bbox.length,
                    e.bbox.width,
                    e.bbox.height,
                    e.speed,
                )
                for e in frame.entities
            ],
            dtype=np.float64,
        ).reshape(n, 13)
        rots = rotations(table[:, 3], table[:, 4], table[:, 5])
        centers = table[:, 0:3] + np.einsum("nij,nj->ni", rots, table[:, 6:9])
        names = tuple(e.name for e in frame.entities)
        class_names = tuple(entity_class(e.object_type, e.category) for e in frame.entities)
        return cls(
            names=names,
            ids=np.arange(1, n + 1, dtype=np.uint32),
            classes=np.array([CLASS_IDS[c] for c in class_names], dtype=np.uint8).reshape(n),
            class_names=class_names,
            centers=centers,
            rotations=rots,
            half=table[:, 9:12] / 2,
            yaws=table[:, 3].copy(),
            velocities=rots[:, :, 0] * table[:, 12:13],
        )

    def corners(self, i: int) -> np.ndarray:
        """The 8 corners (8, 3) of box `i` in the world frame."""
        return self.centers[i] + (_SIGNS * self.half[i]) @ self.rotations[i].T


def intersect_box(
    origins: np.ndarray, dirs: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Ray/oriented-box intersection (slab test). `origins` (M, 3) or (3,), `dirs` (M, 3) unit vectors.

    Returns (t (M,) with inf where the ray misses or starts inside the box, world normals (M, 3) of the
    faces hit)."""
    o = (origins - center) @ rot  # into the box frame
    d = dirs @ rot
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (-half - o) * inv
        t2 = (half - o) * inv
    near = np.minimum(t1, t2)
    far = np.maximum(t1, t2, out=t2)
    if not np.isfinite(inv).all():  # 0 * inf: parallel to a face and in its plane (NaN: no constraint)
        np.copyto(near, -np.inf, where=np.isnan(near))
        np.copyto(far, np.inf, where=np.isnan(far))
    axis = np.argmax(near, axis=1)
    tmin = np.take_along_axis(near, axis[:, None], axis=1)[:, 0]
    tmax = far.min(axis=1)
    hit = (tmax >= tmin) & (tmin > 0.0)
    t = np.where(hit, tmin, np.inf)
    rows = np.arange(len(d))
    local_normal = np.zeros_like(d)
    local_normal[rows, axis] = -np.sign(d[rows, axis])
    return t, local_normal @ rot.T


_Z_GRID = 16.0  # m: the grid of RoadScene.z_range's cache
_XY_CELL = 32.0  # m: the cells of RoadScene's triangle grid
_MAX_CELLS = 1 << 20  # at most about this many cells (a 32 km x 32 km map at 32 m)


def bounding_circles(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N, 5) float64 per box lo..hi (N, 3): the xy circle around it (centre x, y, radius: half the xy
    diagonal, a hair larger) and its z range (min, max)."""
    centre = (lo[:, :2] + hi[:, :2]) / 2.0
    radius = np.hypot(*(hi[:, :2] - lo[:, :2]).T) / 2.0 if len(lo) else np.zeros(0)
    return np.column_stack([centre, radius * (1.0 + 1e-9) + 1e-9, lo[:, 2], hi[:, 2]])


def triangle_groups(lo: np.ndarray, hi: np.ndarray, radius: float = 5.0, most: int = 64) -> np.ndarray:
    """Runs of consecutive triangles (by index: a road mesh lists a lane's triangles along it) whose joint xy
    bounding box has at most `radius` m half-diagonal, at most `most` each: the start index of each run and,
    last, the number of triangles."""
    starts = [0] if len(lo) else []
    x0, y0, x1, y1 = (lo[0, 0], lo[0, 1], hi[0, 0], hi[0, 1]) if len(lo) else (0.0, 0.0, 0.0, 0.0)
    limit = (2.0 * radius) ** 2
    rows = zip(lo[:, 0].tolist(), lo[:, 1].tolist(), hi[:, 0].tolist(), hi[:, 1].tolist(), strict=True)
    for i, (a, b, c, d) in enumerate(rows):
        nx0, ny0, nx1, ny1 = min(x0, a), min(y0, b), max(x1, c), max(y1, d)
        if i - starts[-1] >= most or (nx1 - nx0) ** 2 + (ny1 - ny0) ** 2 > limit:
            starts.append(i)
            nx0, ny0, nx1, ny1 = a, b, c, d
        x0, y0, x1, y1 = nx0, ny0, nx1, ny1
    return np.array([*starts, len(lo)], np.int64)


def xy_grid(
    lo: np.ndarray, hi: np.ndarray, cell: float = _XY_CELL
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A uniform xy grid over boxes (T, >= 2) `lo`..`hi`: (x0, y0, cell, cells in x, cells in y) as
    float64, and per cell (index cx * cells in y + cy) the boxes meeting it as CSR arrays (start (cells + 1,),
    box indices), each box listed in every cell its xy bounds meet. The cells grow beyond `cell` on maps so
    large that there would be more than `_MAX_CELLS` of them (bounded memory)."""
    if not len(lo):
        return np.array([0.0, 0.0, cell, 1.0, 1.0]), np.zeros(2, np.int64), np.zeros(0, np.int64)
    x0, y0 = float(lo[:, 0].min()), float(lo[:, 1].min())
    width, depth = float(hi[:, 0].max()) - x0, float(hi[:, 1].max()) - y0
    cell = max(cell, math.sqrt(max(width, 1.0) * max(depth, 1.0) / _MAX_CELLS))
    c_lo = np.floor((lo[:, :2] - (x0, y0)) / cell).astype(np.int64)
    c_hi = np.floor((hi[:, :2] - (x0, y0)) / cell).astype(np.int64)
    nx, ny = int(c_hi[:, 0].max()) + 1, int(c_hi[:, 1].max()) + 1
    span = c_hi - c_lo
    cells: list[np.ndarray] = []
    boxes: list[np.ndarray] = []
    for dx in range(int(span[:, 0].max()) + 1):
        for dy in range(int(span[:, 1].max()) + 1):
            here = np.flatnonzero((span[:, 0] >= dx) & (span[:, 1] >= dy))
            cells.append((c_lo[here, 0] + dx) * ny + c_lo[here, 1] + dy)
            boxes.append(here)
    cell_of, box = np.concatenate(cells), np.concatenate(boxes)
    order = np.argsort(cell_of, kind="stable")
    start = np.zeros(nx * ny + 1, np.int64)
    np.cumsum(np.bincount(cell_of, minlength=nx * ny), out=start[1:])
    return np.array([x0, y0, cell, float(nx), float(ny)]), start, box[order].astype(np.int64)


class RoadScene:
    """The static road surface as an open3d RaycastingScene (built once per road network)."""

    def __init__(
        self, road: OpenDrive | None, step: float = 1.0, scenery: Sequence[StaticObject] = ()
    ) -> None:
        import open3d as o3d  # heavy: only where the sensors are used

        self._o3d = o3d
        self.scene: Any = o3d.t.geometry.RaycastingScene()
        if road is not None:
            vertices, triangles, self.triangle_classes = road_mesh(road, step)
        else:
            vertices, triangles = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)
            self.triangle_classes = np.zeros(0, np.uint8)
        if scenery:
            verts, tris, classes = [vertices], [triangles], [self.triangle_classes]
            base = len(vertices)
            for obj in scenery:
                verts.append(obj.corners().astype(np.float32))
                tris.append(_CUBE + base)
                classes.append(np.full(12, obj.class_id, np.uint8))
                base += 8
            vertices, triangles = np.concatenate(verts), np.concatenate(tris)
            self.triangle_classes = np.concatenate(classes)
        self.scenery = tuple(scenery)
        self.class_table = np.append(self.triangle_classes, np.uint8(0))
        self.triangle_count = len(triangles)
        # per triangle: its xy bounding box and z range, for `z_range` (which rays can reach the scene)
        if len(triangles):
            corners = np.asarray(vertices, np.float64)[np.asarray(triangles, np.int64)]  # (T, 3, 3)
            self._lo = corners.min(axis=1)
            self._hi = corners.max(axis=1)
        else:
            corners = np.zeros((0, 3, 3))
            self._lo = self._hi = np.zeros((0, 3))
        # for `kernels.level_bounds` (which rays of a level sweep can reach the scene): the triangles'
        # corners (T, 3, 3) float64, as cast, and bounding circles; groups of neighbouring triangles, their
        # bounding circles and an xy grid of them; per group the stamp of the last sweep that looked at it
        self.corners = corners
        self.circles = bounding_circles(self._lo, self._hi)
        self.group_start = triangle_groups(self._lo, self._hi)
        first = self.group_start[:-1]
        if len(first):
            g_lo = np.minimum.reduceat(self._lo, first)
            g_hi = np.maximum.reduceat(self._hi, first)
        else:
            g_lo = g_hi = np.zeros((0, 3))
        self.groups = bounding_circles(g_lo, g_hi)
        self.grid, self.cell_start, self.cell_groups = xy_grid(g_lo, g_hi)
        self.seen = np.zeros(len(first) + 1, np.int64)
        self._z_cache: dict[tuple[int, int, int, int], tuple[float, float] | None] = {}
        if len(triangles):
            self.scene.add_triangles(
                o3d.core.Tensor.from_numpy(np.ascontiguousarray(vertices)),
                o3d.core.Tensor.from_numpy(np.ascontiguousarray(triangles)),
            )
        refl = np.zeros(256, np.float32)
        for cid, value in REFLECTIVITY.items():
            refl[cid] = value
        self.reflectivity = refl

    def z_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[float, float] | None:
        """(lowest, highest) z of the triangles whose xy bounding box meets the xy box [lo, hi] widened to
        a 16 m grid; None when none does. A ray that stays outside this z range within that box cannot hit
        the scene there. Cached per grid box (a sensor moves a few metres per sweep)."""
        key = (
            math.floor(lo[0] / _Z_GRID),
            math.floor(lo[1] / _Z_GRID),
            math.ceil(hi[0] / _Z_GRID),
            math.ceil(hi[1] / _Z_GRID),
        )
        try:
            return self._z_cache[key]
        except KeyError:
            pass
        if len(self._z_cache) >= 4096:
            self._z_cache.clear()
        bounds = self._z_cache[key] = self._z_range(
            np.array(key[:2], float) * _Z_GRID, np.array(key[2:], float) * _Z_GRID
        )
        return bounds

    def _z_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[float, float] | None:
        lo_t, hi_t = self._lo, self._hi
        near = (hi_t[:, 0] >= lo[0]) & (lo_t[:, 0] <= hi[0]) & (hi_t[:, 1] >= lo[1]) & (lo_t[:, 1] <= hi[1])
        if not near.any():
            return None
        return float(lo_t[near, 2].min()), float(hi_t[near, 2].max())

    def cast(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cast rays (M, 6) float32 (origin, unit direction) against the road.

        Returns (t (M,) float32, inf on a miss; normals (M, 3) float32; classes (M,) uint8, 0 on a miss)."""
        t, normals, primitives = self.cast_ids(rays)
        # a miss has the invalid primitive id 2^32 - 1: clipped to the table's last entry, class 0
        return t, normals, np.take(self.class_table, primitives, mode="clip")

    def cast_ids(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`cast` with the triangles' primitive ids (M,) uint32 (2^32 - 1 on a miss) instead of classes: the
        class of id i is `class_table[min(i, T)]` (entry T, past the triangles, is 0)."""
        m = len(rays)
        if self.triangle_count == 0:
            return (
                np.full(m, np.inf, np.float32),
                np.zeros((m, 3), np.float32),
                np.full(m, np.iinfo(np.uint32).max, np.uint32),
            )
        out = self.scene.cast_rays(self._o3d.core.Tensor.from_numpy(np.ascontiguousarray(rays, np.float32)))
        return out["t_hit"].numpy(), out["primitive_normals"].numpy(), out["primitive_ids"].numpy()
