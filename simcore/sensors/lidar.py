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
lidar (no pitch or roll) culls whole channels and caches the index set (and a ray buffer) per channel set.
A box is intersected only with the columns its corners span and the channels whose elevation can reach it
(exact as well: the slab test still decides every ray kept), row-wise on x/y/z component rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simcore.sensors.scene import Boxes, RoadScene, intersect_box, intersect_box_rows, rotation
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


@dataclass(frozen=True, slots=True)
class LidarScan:
    """One sweep: `points` (structured, POINT_DTYPE) in the sensor frame; per box of the frame (entity
    order) the number of points on it and the number of rays that would hit it were nothing in front."""

    points: np.ndarray
    object_points: np.ndarray  # (N,) int: points in the cloud (after dropout)
    visible_rays: np.ndarray  # (N,) int: rays whose first return is the object (before dropout)
    unoccluded_rays: np.ndarray  # (N,) int: rays that would hit it were nothing in front
    rays: int


@dataclass(frozen=True, slots=True)
class _LevelRays:
    """The rays a level sweep casts (whole channels): their indices (None: every ray), the channels as a
    slice when contiguous, their sensor-frame directions (float32 rows) and a reusable (K, 6) float32 ray
    buffer whose z direction is already filled in (the scan writes origins and x, y directions)."""

    ids: np.ndarray | None
    block: slice | np.ndarray
    dirs: list[np.ndarray]
    rays: np.ndarray


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
        self._level_cache: dict[bytes, _LevelRays] = {}
        self._tan_elev = np.tan(self.elevations)
        self._mount_level = bool(self.mount_rot[2, 0] == 0.0 and self.mount_rot[2, 1] == 0.0)

    def _level_rays(self, kept: np.ndarray | None) -> _LevelRays:
        """The cast rays of a level sweep whose channels `kept` (None: all) can reach the scene: cached per
        channel set (a sensor keeps the same set while the ground below stays the same)."""
        key = b"all" if kept is None else kept.tobytes()
        entry = self._level_cache.get(key)
        if entry is not None:
            return entry
        if len(self._level_cache) >= 16:
            self._level_cache.clear()
        channels = np.arange(self.channels) if kept is None else kept
        ids = (np.arange(self.columns)[:, None] * self.channels + channels[None, :]).ravel()
        dirs = [row[ids] for row in self._dirs_t]
        rays = np.empty((len(ids), 6), np.float32)
        rays[:, 5] = dirs[2]  # level: the world z component is the sensor's
        contiguous = len(channels) > 0 and channels[-1] - channels[0] + 1 == len(channels)
        block: slice | np.ndarray = slice(int(channels[0]), int(channels[-1]) + 1) if contiguous else channels
        entry = self._level_cache[key] = _LevelRays(None if kept is None else ids, block, dirs, rays)
        return entry

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
        xy = corners_sensor[:, :2]
        center = xy.mean(axis=0)
        radius = float(np.max(np.hypot(*(xy - center).T)))
        rho_min = max(float(np.hypot(*center)) - radius - widen, 0.0)
        rho_max = float(np.max(np.hypot(*xy.T))) + widen
        zmin, zmax = float(corners_sensor[:, 2].min()), float(corners_sensor[:, 2].max())
        if rho_min <= 0.0:
            lo = -math.inf if zmin < 0.0 else zmin / rho_max
            hi = math.inf if zmax > 0.0 else zmax / rho_max
        else:
            lo = zmin / (rho_min if zmin < 0.0 else rho_max)
            hi = zmax / (rho_min if zmax > 0.0 else rho_max)
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

    def scan(self, road: RoadScene, boxes: Boxes, carrier: EntityState, carrier_index: int) -> LidarScan:
        cfg = self.config
        rot, pos = mount_pose(carrier, self.mount_rot, self.mount_pos)
        n_rays = len(self.dirs)
        r32 = rot.astype(np.float32)
        distort = cfg.motion_distortion and (carrier.speed != 0.0 or carrier.yaw_rate != 0.0)
        level_sweep = not distort and r32[2, 0] == 0.0 and r32[2, 1] == 0.0 and r32[2, 2] == 1.0
        block: slice | np.ndarray | None = None
        # the road cast: only the rays that can reach the static scene, (K, 6) float32 for open3d
        if distort:
            # per column: the carrier's pose at the column's firing time (constant speed and yaw rate)
            tau = self.column_time
            heading = carrier.heading + carrier.yaw_rate * tau
            vx, vy = carrier.velocity
            rots = np.stack([rotation(float(h), carrier.pitch, carrier.roll) for h in heading])  # (C,3,3)
            base = np.stack(
                [carrier.x + vx * tau, carrier.y + vy * tau, np.full_like(tau, carrier.z)], axis=1
            )
            col_rot = rots @ self.mount_rot
            col_pos = base + rots @ self.mount_pos
            d3 = self.dirs.reshape(self.columns, self.channels, 3)
            dirs_world = np.einsum("cij,ckj->cki", col_rot, d3).reshape(-1, 3)
            origins = np.repeat(col_pos, self.channels, axis=0)
            rays = np.empty((n_rays, 6), np.float32)
            rays[:, :3] = origins
            rays[:, 3:] = dirs_world
            cast = self._reachable(
                road, rays[:, 2], rays[:, 5], col_pos[:, :2].min(axis=0), col_pos[:, :2].max(axis=0)
            )
            if cast is not None:
                rays = rays[cast]
        elif level_sweep:
            # level (no pitch, no roll): a ray's world z component is its channel's, so the rays that can
            # reach the scene are whole channels; their index set, directions and ray buffer are cached
            kept = self._reachable(
                road, float(np.float32(pos[2])), self._dirs_t[2, : self.channels], pos[:2], pos[:2]
            )
            cached = self._level_rays(kept)
            cast, block, rays = cached.ids, cached.block, cached.rays
            for axis, value in enumerate(pos.astype(np.float32)):
                rays[:, axis] = value  # one scalar fill per column: faster than broadcasting the row
            d0, d1, d2 = cached.dirs
            for row, col in ((0, 3), (1, 4)):
                # r32[row, 2] is 0 for a level sensor (bar a float32 underflow): that term adds nothing
                a = d0 * r32[row, 0]
                a += d1 * r32[row, 1]
                if r32[row, 2] != 0.0:
                    a += d2 * r32[row, 2]
                rays[:, col] = a
        else:
            dz = self._world_dirs(r32, None, range(2, 3))[0]
            cast = self._reachable(road, float(np.float32(pos[2])), dz, pos[:2], pos[:2])
            rays = self._ray_array(n_rays if cast is None else len(cast), pos)
            dx, dy = self._world_dirs(r32, cast, range(2))
            rays[:, 3] = dx
            rays[:, 4] = dy
            rays[:, 5] = dz if cast is None else dz[cast]
        if not level_sweep:
            block = None
        t_cast, normals, classes_cast = road.cast(rays)
        # |cos(incidence)| of the road returns: direction . normal (a miss has a zero normal)
        cos_cast = rays[:, 3] * normals[:, 0]
        cos_cast += rays[:, 4] * normals[:, 1]
        cos_cast += rays[:, 5] * normals[:, 2]
        np.abs(cos_cast, out=cos_cast)
        if cast is None:
            t, classes, cos_inc = t_cast, classes_cast, cos_cast
        elif block is not None:  # whole channels: block copies into the (column, channel) grid
            shape = (self.columns, self.channels)
            t = np.full(shape, np.inf, np.float32)
            t[:, block] = t_cast.reshape(self.columns, -1)
            classes = np.zeros(shape, np.uint8)
            classes[:, block] = classes_cast.reshape(self.columns, -1)
            cos_inc = np.zeros(shape, np.float32)
            cos_inc[:, block] = cos_cast.reshape(self.columns, -1)
            t, classes, cos_inc = t.reshape(-1), classes.reshape(-1), cos_inc.reshape(-1)
        else:
            t = np.full(n_rays, np.inf, np.float32)
            t[cast] = t_cast
            classes = np.zeros(n_rays, np.uint8)
            classes[cast] = classes_cast
            cos_inc = np.zeros(n_rays, np.float32)
            cos_inc[cast] = cos_cast
        object_id = np.zeros(n_rays, np.uint32)
        nbox = len(boxes.names)
        unoccluded = np.zeros(nbox, np.int64)
        reach = cfg.range_max
        if nbox:
            rel = boxes.centers - pos
            radius = np.linalg.norm(boxes.half, axis=1)
            near = np.linalg.norm(rel, axis=1) - radius <= reach
            widen: float | None = (
                0.0  # how far the rays' origins are from `pos` horizontally; None: not level
            )
            if distort:
                shift = np.hypot(*carrier.velocity) * self.period
                level = self._mount_level and carrier.pitch == 0.0 and carrier.roll == 0.0
                widen = float(np.max(np.hypot(*(col_pos[:, :2] - pos[:2]).T))) if level else None
            for i in np.flatnonzero(near):
                if i == carrier_index:
                    continue  # a sensor does not see its own carrier
                corners = (boxes.corners(int(i)) - pos) @ rot
                pad = 1
                if distort:
                    dist = max(float(np.linalg.norm(rel[i])) - float(radius[i]), 0.5)
                    pad += math.ceil((shift / dist + abs(carrier.yaw_rate) * self.period) / self.col_width)
                cols = self._columns_of(corners, pad)
                chans = None if widen is None else self._channels_of(corners, widen)
                if cols is None and chans is None:
                    idx = np.arange(n_rays)
                else:
                    if cols is None:
                        cols = np.arange(self.columns)
                    if chans is None:
                        chans = np.arange(self.channels)
                    idx = (cols[:, None] * self.channels + chans[None, :]).ravel()
                if not len(idx):
                    continue
                if distort:
                    dw = dirs_world[idx]
                    tb, nb = intersect_box(
                        origins[idx], dw, boxes.centers[i], boxes.rotations[i], boxes.half[i]
                    )
                    cos_box = np.abs(np.einsum("ij,ij->i", dw, nb.astype(np.float32)))
                else:
                    tb, cos_box = intersect_box_rows(
                        pos, self._world_dirs(r32, idx), boxes.centers[i], boxes.rotations[i], boxes.half[i]
                    )
                in_range = (tb >= cfg.range_min) & (tb <= cfg.range_max)
                unoccluded[i] = int(np.count_nonzero(in_range))
                closer = tb < t[idx]
                if np.any(closer):
                    sel = idx[closer]
                    t[sel] = tb[closer]
                    cos_inc[sel] = cos_box[closer]
                    classes[sel] = boxes.classes[i]
                    object_id[sel] = boxes.ids[i]
        idx = np.flatnonzero((t >= cfg.range_min) & (t <= cfg.range_max))
        ids = object_id[idx]
        visible = np.bincount(ids, minlength=nbox + 1)[1 : nbox + 1]
        if cfg.dropout > 0.0:
            kept = self.rng.random(n_rays, dtype=np.float32)[idx] >= cfg.dropout
            idx = idx[kept]
            ids = ids[kept]
        rng_t = t[idx]
        if cfg.range_noise > 0.0:
            noise = self.rng.standard_normal(len(idx), dtype=np.float32)
            noise *= cfg.range_noise
            noise += rng_t
            rng_t = np.maximum(noise, 0.0, out=noise)
        cls = classes[idx]
        points = np.zeros(len(idx), POINT_DTYPE)  # zeros: the padding byte too (reproducible files)
        if distort:
            world = origins[idx] + dirs_world[idx] * rng_t[:, None]
            local = (world - pos) @ rot
            points["time"] = np.repeat(self.column_time, self.channels)[idx]
            points["x"] = local[:, 0]
            points["y"] = local[:, 1]
            points["z"] = local[:, 2]
        else:  # time: 0 (the zeros)
            points["x"] = self._dirs_t[0, idx] * rng_t
            points["y"] = self._dirs_t[1, idx] * rng_t
            points["z"] = self._dirs_t[2, idx] * rng_t
        points["intensity"] = road.reflectivity[cls] * cos_inc[idx]
        points["object_id"] = ids
        points["ring"] = self.ring[idx]
        points["label"] = cls
        counts = np.bincount(ids, minlength=nbox + 1)[1 : nbox + 1]
        points.flags.writeable = False  # immutable: messages and recordings reference it without a copy
        return LidarScan(
            points=points, object_points=counts, visible_rays=visible, unoccluded_rays=unoccluded, rays=n_rays
        )
