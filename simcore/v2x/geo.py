"""Map frame (OpenDRIVE inertial x/y/z, ENU) → WGS84 latitude/longitude/altitude.

The projection comes from the OpenDRIVE header's `<geoReference>` (a PROJ string, e.g.
`+proj=utm +zone=32 +ellps=WGS84`) shifted by the header's `<offset x y z hdg>` (OpenDRIVE 1.6: the
inertial frame is the projected frame translated by (x, y, z) and rotated by hdg), or from a configured
origin: a transverse Mercator projection centred on (latitude, longitude) at scale 1, so the map frame is
the local east/north plane at the origin. PROJ (via pyproj) does the projection math.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from simcore.errors import BadInput

#: A road file larger than this is not searched for its header.
MAX_ROAD_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class GeoReference:
    """How map coordinates become WGS84: `proj` projects (lon, lat) to the projected frame; the map frame
    is that frame shifted by (offset_x, offset_y, offset_z) and rotated by `offset_heading` (rad)."""

    proj: str
    offset_x: float = 0.0
    offset_y: float = 0.0
    offset_z: float = 0.0
    offset_heading: float = 0.0

    @classmethod
    def at_origin(cls, latitude: float, longitude: float, altitude: float = 0.0) -> GeoReference:
        """The map frame as the local east/north plane at (latitude, longitude) (degrees), z above `altitude`."""
        proj = (
            f"+proj=tmerc +lat_0={latitude!r} +lon_0={longitude!r} +k=1 +x_0=0 +y_0=0 "
            "+ellps=WGS84 +units=m +no_defs"
        )
        return cls(proj=proj, offset_z=altitude)

    @cached_property
    def _transformer(self) -> Any:
        from pyproj import CRS, Transformer
        from pyproj.exceptions import CRSError

        try:
            crs = CRS.from_user_input(self.proj)
        except CRSError as exc:
            raise ValueError(
                f"geoReference {self.proj!r} is not a PROJ string PROJ understands: {exc}"
            ) from None
        return Transformer.from_crs(crs, CRS.from_epsg(4326), always_xy=True)

    def to_wgs84(self, x: Any, y: Any, z: Any = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(latitude°, longitude°, altitude m) of map points (scalars or arrays)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        c, s = math.cos(self.offset_heading), math.sin(self.offset_heading)
        px = c * x - s * y + self.offset_x
        py = s * x + c * y + self.offset_y
        lon, lat = self._transformer.transform(px, py)
        return np.asarray(lat), np.asarray(lon), np.asarray(z, dtype=np.float64) + self.offset_z

    def north_angle(self, x: float, y: float) -> float:
        """The map-frame angle (rad, counter-clockwise from +x) of true north at (x, y): ETSI headings are
        clockwise from north, so heading_etsi = north_angle - heading_map."""
        return float(self.north_angles(np.array([x]), np.array([y]))[0])

    def north_angles(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """`north_angle` of many points at once."""
        return self.wgs84_and_north(x, y, np.zeros(np.shape(x)))[3]

    def wgs84_and_north(
        self, x: np.ndarray, y: np.ndarray, z: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`to_wgs84` and `north_angles` of many points in one transformation: (lat, lon, alt, north)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        lat, lon, _ = self.to_wgs84(np.concatenate([x, x]), np.concatenate([y, y + 1.0]))
        n = len(x)
        alt = np.asarray(z, dtype=np.float64) + self.offset_z
        # the direction of map +y in the geographic frame: map +y is this far clockwise from north
        east = (lon[n:] - lon[:n]) * np.cos(np.radians(lat[:n]))
        north = lat[n:] - lat[:n]
        return lat[:n], lon[:n], alt, np.asarray(math.pi / 2 + np.arctan2(east, north))


def geo_reference_of(road_file: Path) -> GeoReference | None:
    """The header's geoReference (and offset) of an OpenDRIVE file; None when it has none."""
    from simcore.scenario.xosc_xml import read_xml

    root = read_xml(road_file, what="OpenDRIVE file", max_bytes=MAX_ROAD_BYTES)
    header = root.find("header")
    if header is None:
        return None
    geo = header.find("geoReference")
    text = (geo.text or "").strip() if geo is not None else ""
    if not text:
        return None
    offset = header.find("offset")

    def number(name: str) -> float:
        raw = offset.get(name, "0") if offset is not None else "0"
        try:
            value = float(raw)
        except ValueError:
            raise BadInput(f"header/offset/@{name} is not a number: {raw!r}", file=str(road_file)) from None
        if not math.isfinite(value):
            raise BadInput(f"header/offset/@{name} is not finite", file=str(road_file))
        return value

    reference = GeoReference(
        proj=text,
        offset_x=number("x"),
        offset_y=number("y"),
        offset_z=number("z"),
        offset_heading=number("hdg"),
    )
    try:
        reference.to_wgs84(0.0, 0.0)
    except ValueError as exc:
        raise BadInput(str(exc), file=str(road_file)) from None
    return reference
