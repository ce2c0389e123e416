"""A spinning lidar by raycasting (see `simcore.spec.LidarSensor` for the parameters).

Rays are laid out column by column (a column = one firing of every channel at one azimuth), so the rays a
box can reach are a contiguous run of columns. Column `c` points at azimuth `fov/2 - (c + 0.5) * fov/cols`
(clockwise from behind for 360°), channel `k` at its elevation; ring = channel index.

Per return: range with seeded Gaussian noise, seeded dropout, intensity = reflectivity of the class hit ×
|cos(incidence angle)|, the object id (1 + the entity's position in the frame, 0 for the road) and the
class id (`simcore.sensors.classes`). With motion distortion every column is fired from the pose its
carrier had at the column's firing time (constant speed and yaw rate over the sweep) and the points are
expressed in the sensor frame at the stamp (the sweep's end); other entities are taken at the stamp.

Speed: only the rays that can reach the static scene within `rangeMax` go to open3d (a ray whose height
over its range stays above or below every road triangle and scenery box within reach cannot hit; on a flat
road the rays at and above the horizon). This is exact: the scan is the one casting every ray would give
(tests/test_sensors.py checks it on hills, with scenery, tilted mounts and motion distortion). A level
lidar (no pitch or roll) culls per column: a column keeps the channels whose slope can meet a triangle its
azimuth spans (`kernels.level_bounds`, through an xy grid of the scene), so the rays to the side past the
road's edge (misses, a third of a highway sweep) are not cast either.
A box is intersected only with the columns its corners span and the channels whose elevation can reach it
(exact as well: the slab test still decides every ray kept).

Everything per ray around the open3d cast is one compiled pass each (`simcore.sensors.kernels`, numba,
GIL released): the level sweep's per-column bounds and its ray buffer, the road returns (class, |cos|)
into per-sweep buffers reused across sweeps, every box (its columns, channels and slab test over them) in
one call, the range/dropout selection and the point records. The random numbers are numpy's (the same draws as before, into reused buffers), so the cloud is
bit for bit the one of the numpy passes (tests/test_sensors.py keeps them as the reference). With motion
distortion the boxes and the point coordinates stay numpy (per-column poses, (M, 3) arrays).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simcore.sensors import kernels
from simcore.sensors.scene import Boxes, RoadScene, intersect_box, rotation
from simcore.spec import LidarSensor
from simcore.world.state import EntityState

#: PointCloud2 layout of a lidar point (little endian, 28 bytes).
POINT_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "intensity", "time", "object_id", "ring", "label"],
        "formats": ["<f4", "<f4", "<f4", "<f4", "<f4", "<u4", "<u2", "u1"],
        "offsets": [0, 4, 8, 12, 16, 20, 24, 26],
        "itemsize": 28,
    }
)
_ALL = np.zeros(0, np.int64)  # no index set: the cast rays are every ray, in order
_NONE32 = np.zeros(0, np.float32)  # no random numbers drawn
_NO_POINTS = np.zeros((0, 3))  # no motion distortion: the kernel computes the points


@dataclass(frozen=True, slots=True)
class LidarScan:
    """One sweep: `points` (structured, POINT_DTYPE) in the sensor frame; per box of the frame (entity
    order) the number of points on it and the number of rays that would hit it were nothing in front."""

    points: np.ndarray
    object_points: np.ndarray  # (N,) int: points in the cloud (after dropout)
    visible_rays: np.ndarray  # (N,) int: rays whose first return is the object (before dropout)
    unoccluded_rays: np.ndarray  # (N,) int: rays that would hit it were nothing in front
    rays: int


def mount_pose(
    entity: EntityState, mount_rot: np.ndarray, mount_pos: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, position) of a sensor in the map frame."""
    r = rotation(entity.heading, entity.pitch, entity.roll)
    return r @ mount_rot, np.array([entity.x, entity.y, entity.z]) + r @ mount_pos


def _angular_interval(angles: np.ndarray) -> tuple[float, float] | None:
    """Smallest arc (lo, hi), hi >= lo, containing every angle; None when the points surround the origin."""
    a = np.sort(np.mod(angles, 2 * math.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * math.pi]))
    j = int(np.argmax(gaps))
    if gaps[j] <= math.pi:
        return None
    lo = a[(j + 1) % len(a)]
    return float(lo), float(lo + 2 * math.pi - gaps[j])


class Lidar:
    """One lidar on one entity. `scan()` casts a full sweep against the road and the boxes."""

    def __init__(self, config: LidarSensor, seed: int) -> None:
        self.config = config
        self.channels = config.channels
        self.columns = config.horizontal_resolution
        self.period = 1.0 / config.rotation_rate
        self.fov = math.radians(config.horizontal_fov)
        self.full_circle = config.horizontal_fov >= 360.0
        self.col_width = self.fov / self.columns
        if config.vertical_angles is not None:
            elev = np.radians(np.asarray(config.vertical_angles, dtype=float))
        else:
            low, high = config.vertical_fov
            elev = (
                np.radians(np.linspace(low, high, config.channels))
                if config.channels > 1
                else np.radians([low])
            )
        self.elevations = elev
        az = self.fov / 2 - (np.arange(self.columns) + 0.5) * self.col_width
        ce, se = np.cos(elev), np.sin(elev)
        dirs = np.empty((self.columns, self.channels, 3))
        dirs[..., 0] = np.cos(az)[:, None] * ce[None, :]
        dirs[..., 1] = np.sin(az)[:, None] * ce[None, :]
        dirs[..., 2] = se[None, :]
        self.dirs = dirs.reshape(-1, 3)  # sensor frame, column-major
        self._dirs_t = np.ascontiguousarray(self.dirs.T, dtype=np.float32)  # (3, M): row operations are fast
        self.ring = np.tile(np.arange(self.channels, dtype=np.uint16), self.columns)
        self.column_time = -self.period + (np.arange(self.columns) + 0.5) / self.columns * self.period
        m = config.mount
        self.mount_rot = rotation(math.radians(m.yaw), math.radians(m.pitch), math.radians(m.roll))
        self.mount_pos = np.array([m.x, m.y, m.z])
        self.rng = np.random.default_rng(seed)
        self._tan_elev = np.tan(self.elevations)
        self._mount_level = bool(self.mount_rot[2, 0] == 0.0 and self.mount_rot[2, 1] == 0.0)
        n_rays = len(self.dirs)
        # per-sweep buffers (a Lidar scans one sweep at a time)
        self._t = np.empty(n_rays, np.float32)
        self._classes = np.empty(n_rays, np.uint8)
        self._cos = np.empty(n_rays, np.float32)
        self._object_id = np.empty(n_rays, np.uint32)
        self._drop = np.empty(n_rays, np.float32)
        self._noise = np.empty(n_rays, np.float32)
        self._kept = np.empty(n_rays, np.int64)
        self._cast_ids = np.empty(n_rays, np.int64)
        self._cast_rays = np.empty((n_rays, 6), np.float32)
        self._slope_lo = np.empty(self.columns)
        self._slope_hi = np.empty(self.columns)
        self._all_columns = np.arange(self.columns)
        self._all_channels = np.arange(self.channels)
        kernels.warm()  # compiled (or loaded from numba's cache) here, not in the first sweep

    def _level_rays(self, road: RoadScene, pos: np.ndarray, r32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rays of a level sweep (no pitch, no roll: a ray's slope is its channel's) that can reach the
        static scene within range, as (indices, (K, 6) float32 rays): per column, only the channels whose
        slope can meet a triangle the column's azimuth spans (`kernels.level_bounds`; exact, the rays left
        out miss). On a road, the rays to the side beyond the road's edge are left out, not only those
        above the horizon."""
        if road.triangle_count == 0:
            return self._cast_ids[:0], self._cast_rays[:0]
        pos32 = pos.astype(np.float32)
        kernels.level_bounds(
            road.cell_start,
            road.cell_groups,
            road.grid,
            road.groups,
            road.group_start,
            road.circles,
            road.corners,
            road.seen,
            pos32.astype(np.float64),
            math.atan2(float(r32[1, 0]), float(r32[0, 0])),
            self.fov,
            self.full_circle,
            float(self.config.range_max),
            self._slope_lo,
            self._slope_hi,
        )
        n = kernels.fill_level_rays(
            self._cast_rays, self._cast_ids, self._slope_lo, self._slope_hi, self._tan_elev, self._dirs_t,
            pos32, r32,
        )  # fmt: skip
        return self._cast_ids[:n], self._cast_rays[:n]

    @property
    def ray_count(self) -> int:
        return len(self.dirs)

    def _columns_of(self, corners_sensor: np.ndarray, pad: int) -> np.ndarray | None:
        """Columns whose azimuth can reach the points (sensor frame), or None for every column."""
        interval = _angular_interval(np.arctan2(corners_sensor[:, 1], corners_sensor[:, 0]))
        if interval is None:
            return None
        lo, hi = interval
        half = self.fov / 2
        # column index of azimuth a: (half - a) / w - 0.5 (decreasing in a)
        if self.full_circle:
            c0 = math.floor((half - hi) / self.col_width - 0.5) - pad
            c1 = math.ceil((half - lo) / self.col_width - 0.5) + pad
            if c1 - c0 + 1 >= self.columns:
                return None
            return np.mod(np.arange(c0, c1 + 1), self.columns)
        # limited fov: azimuths in (-pi, pi]; the arc may wrap
        cols: list[np.ndarray] = []
        for shift in (0.0, -2 * math.pi, 2 * math.pi):
            a_lo, a_hi = max(lo + shift, -half), min(hi + shift, half)
            if a_lo > a_hi:
                continue
            c0 = max(math.floor((half - a_hi) / self.col_width - 0.5) - pad, 0)
            c1 = min(math.ceil((half - a_lo) / self.col_width - 0.5) + pad, self.columns - 1)
            if c0 <= c1:
                cols.append(np.arange(c0, c1 + 1))
        if not cols:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate(cols))

    def _channels_of(self, corners_sensor: np.ndarray, widen: float) -> np.ndarray | None:
        """Channels whose elevation can reach a box with these corners (sensor frame, the sensor at the origin
        or, with `widen` > 0, anywhere within `widen` m of it horizontally at the same height), or None for
        every channel. A point of the box is at height z in [min, max of the corners' z] and horizontal
        distance rho in [rho_min, rho_max] (rho_min from the box's bounding circle), so its elevation's tangent
        z / rho lies between the extremes of those; a ray outside them cannot hit the box (exact: the slab
        test still decides every ray kept)."""
        lo, hi = kernels.box_slopes(np.ascontiguousarray(corners_sensor, np.float64), widen)
        if lo == -math.inf and hi == math.inf:
            return None
        margin = 1e-4  # float rounding of the directions, with room to spare
        tan = self._tan_elev
        return np.flatnonzero((tan >= lo - margin * (1.0 + abs(lo))) & (tan <= hi + margin * (1.0 + abs(hi))))

    def _world_dirs(
        self, r32: np.ndarray, cols: np.ndarray | None, rows: range = range(3)
    ) -> list[np.ndarray]:
        """World-frame direction components (float32 rows) of the rays `cols` (None: all) for rotation
        `r32`: the 3x3 rotation as row operations, no BLAS call, no strided casts."""
        d = self._dirs_t if cols is None else [row[cols] for row in self._dirs_t]
        return [d[0] * r32[k, 0] + d[1] * r32[k, 1] + d[2] * r32[k, 2] for k in rows]

    @staticmethod
    def _ray_array(k: int, pos: np.ndarray) -> np.ndarray:
        """(k, 6) float32 rays with their origins at `pos` (directions to fill in)."""
        rays = np.empty((k, 6), np.float32)
        for i, p in enumerate(pos.astype(np.float32)):
            rays[:, i] = p  # one scalar fill per column: 3x faster than broadcasting the row
        return rays

    def _reachable(
        self, road: RoadScene, z0: np.ndarray | float, dz: np.ndarray, lo: np.ndarray, hi: np.ndarray
    ) -> np.ndarray | None:
        """Indices of the rays that can hit the static scene within the maximum range (None: all of them):
        a ray whose height over [0, range_max] stays above or below every triangle within reach misses."""
        if road.triangle_count == 0:
            return np.zeros(0, np.int64)
        reach = self.config.range_max
        bounds = road.z_range(lo - reach, hi + reach)
        if bounds is None:
            return np.zeros(0, np.int64)
        margin = 0.01 + 1e-4 * reach  # float32 rounding of the cast, with room to spare
        zmin, zmax = bounds[0] - margin, bounds[1] + margin
        if isinstance(z0, float):
            if z0 > zmax:
                return np.flatnonzero(dz <= np.float32((zmax - z0) / reach))
            if z0 < zmin:
                return np.flatnonzero(dz >= np.float32((zmin - z0) / reach))
            return None
        low = z0 + reach * np.minimum(dz, 0.0)
        high = z0 + reach * np.maximum(dz, 0.0)
        reachable = (low <= zmax) & (high >= zmin)
        return None if reachable.all() else np.flatnonzero(reachable)

    def _distorted_rays(
        self, road: RoadScene, carrier: EntityState
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """A sweep with motion distortion: every column fired from the carrier's pose at its firing time
        (constant speed and yaw rate). Returns the rays to cast ((K, 6) float32, only those that can reach
        the static scene), their indices (None: all), and per column its origin, per ray its origin and
        world direction."""
        tau = self.column_time
        heading = carrier.heading + carrier.yaw_rate * tau
        vx, vy = carrier.velocity
        rots = np.stack([rotation(float(h), carrier.pitch, carrier.roll) for h in heading])  # (C,3,3)
        base = np.stack([carrier.x + vx * tau, carrier.y + vy * tau, np.full_like(tau, carrier.z)], axis=1)
        col_rot = rots @ self.mount_rot
        col_pos = base + rots @ self.mount_pos
        d3 = self.dirs.reshape(self.columns, self.channels, 3)
        dirs_world = np.einsum("cij,ckj->cki", col_rot, d3).reshape(-1, 3)
        origins = np.repeat(col_pos, self.channels, axis=0)
        rays = np.empty((len(self.dirs), 6), np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = dirs_world
        cast = self._reachable(
            road, rays[:, 2], rays[:, 5], col_pos[:, :2].min(axis=0), col_pos[:, :2].max(axis=0)
        )
        if cast is not None:
            rays = rays[cast]
        return rays, cast, col_pos, origins, dirs_world

    def scan(self, road: RoadScene, boxes: Boxes, carrier: EntityState, carrier_index: int) -> LidarScan:
        cfg = self.config
        rot, pos = mount_pose(carrier, self.mount_rot, self.mount_pos)
        n_rays = len(self.dirs)
        r32 = rot.astype(np.float32)
        distort = cfg.motion_distortion and (carrier.speed != 0.0 or carrier.yaw_rate != 0.0)
        level_sweep = not distort and r32[2, 0] == 0.0 and r32[2, 1] == 0.0 and r32[2, 2] == 1.0
        # the road cast: only the rays that can reach the static scene, (K, 6) float32 for open3d
        if distort:
            rays, cast, col_pos, origins, dirs_world = self._distorted_rays(road, carrier)
        elif level_sweep:
            cast, rays = self._level_rays(road, pos, r32)
        else:
            dz = self._world_dirs(r32, None, range(2, 3))[0]
            cast = self._reachable(road, float(np.float32(pos[2])), dz, pos[:2], pos[:2])
            rays = self._ray_array(n_rays if cast is None else len(cast), pos)
            dx, dy = self._world_dirs(r32, cast, range(2))
            rays[:, 3] = dx
            rays[:, 4] = dy
            rays[:, 5] = dz if cast is None else dz[cast]
        t_cast, normals, primitives = road.cast_ids(rays)
        # per ray of the sweep (buffers reused across sweeps): range, class, |cos(incidence)|, object id
        t, classes, cos_inc, object_id = self._t, self._classes, self._cos, self._object_id
        kernels.road_returns(
            cast is None,
            _ALL if cast is None else cast,
            t_cast,
            normals,
            primitives,
            rays,
            road.class_table,
            t,
            classes,
            cos_inc,
            object_id,
        )
        nbox = len(boxes.names)
        unoccluded = np.zeros(nbox, np.int64)
        reach = cfg.range_max
        if nbox and not distort:
            kernels.boxes_returns(
                t, cos_inc, classes, object_id, boxes.centers, boxes.rotations, boxes.half, boxes.classes,
                boxes.ids, carrier_index, pos, rot, r32, self._dirs_t, self._tan_elev, self.columns,
                self.fov, self.full_circle, float(cfg.range_min), float(reach), unoccluded,
            )  # fmt: skip
        elif nbox:  # motion distortion: per-column origins, numpy
            rel = boxes.centers - pos
            radius = np.linalg.norm(boxes.half, axis=1)
            near = np.linalg.norm(rel, axis=1) - radius <= reach
            shift = np.hypot(*carrier.velocity) * self.period
            level = self._mount_level and carrier.pitch == 0.0 and carrier.roll == 0.0
            # how far the rays' origins are from `pos` horizontally; None: not level
            widen = float(np.max(np.hypot(*(col_pos[:, :2] - pos[:2]).T))) if level else None
            for i in np.flatnonzero(near):
                if i == carrier_index:
                    continue  # a sensor does not see its own carrier
                corners = (boxes.corners(int(i)) - pos) @ rot
                dist = max(float(np.linalg.norm(rel[i])) - float(radius[i]), 0.5)
                pad = 1 + math.ceil((shift / dist + abs(carrier.yaw_rate) * self.period) / self.col_width)
                cols = self._columns_of(corners, pad)
                chans = None if widen is None else self._channels_of(corners, widen)
                if cols is None and chans is None:
                    idx = np.arange(n_rays)
                else:
                    if cols is None:
                        cols = self._all_columns
                    if chans is None:
                        chans = self._all_channels
                    idx = (cols[:, None] * self.channels + chans[None, :]).ravel()
                if not len(idx):
                    continue
                dw = dirs_world[idx]
                tb, nb = intersect_box(origins[idx], dw, boxes.centers[i], boxes.rotations[i], boxes.half[i])
                cos_box = np.abs(np.einsum("ij,ij->i", dw, nb.astype(np.float32)))
                in_range = (tb >= cfg.range_min) & (tb <= cfg.range_max)
                unoccluded[i] = int(np.count_nonzero(in_range))
                closer = tb < t[idx]
                if np.any(closer):
                    sel = idx[closer]
                    t[sel] = tb[closer]
                    cos_inc[sel] = cos_box[closer]
                    classes[sel] = boxes.classes[i]
                    object_id[sel] = boxes.ids[i]
        drop = self.rng.random(dtype=np.float32, out=self._drop) if cfg.dropout > 0.0 else _NONE32
        visible = np.empty(nbox + 1, np.int64)
        n = kernels.select_returns(
            t,
            object_id,
            np.float32(cfg.range_min),
            np.float32(cfg.range_max),
            drop,
            np.float32(cfg.dropout),
            self._kept,
            visible,
        )
        kept = self._kept[:n]
        noise = (
            self.rng.standard_normal(dtype=np.float32, out=self._noise[:n])
            if cfg.range_noise > 0.0
            else _NONE32
        )
        local = _NO_POINTS
        if distort:
            rng_t = t[kept]
            if len(noise):
                noisy = noise * np.float32(cfg.range_noise)
                noisy += rng_t
                rng_t = np.maximum(noisy, 0.0, out=noisy)
            world = origins[kept] + dirs_world[kept] * rng_t[:, None]
            local = np.ascontiguousarray((world - pos) @ rot)
        points = np.empty(n, POINT_DTYPE)  # every byte written, the padding byte 0 (reproducible files)
        counts = np.empty(nbox + 1, np.int64)
        kernels.fill_points(
            points.view(np.uint32).reshape(n, 7),
            kept,
            t,
            noise,
            np.float32(cfg.range_noise),
            self._dirs_t,
            local,
            self.column_time,
            classes,
            cos_inc,
            road.reflectivity,
            object_id,
            self.ring,
            self.channels,
            counts,
        )
        points.flags.writeable = False  # immutable: messages and recordings reference it without a copy
        return LidarScan(
            points=points,
            object_points=counts[1:],
            visible_rays=visible[1:],
            unoccluded_rays=unoccluded,
            rays=n_rays,
        )
