"""Map → WGS84 against the OpenDRIVE geoReference, checked with an independent meridian-arc integral."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from simcore.errors import BadInput
from simcore.v2x.geo import GeoReference, geo_reference_of

A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
UTM_K0 = 0.9996


def meridian_arc(lat_deg: float) -> float:
    """Distance along the WGS84 meridian from the equator to `lat_deg` (m)."""
    return quad(lambda p: A * (1 - E2) / (1 - E2 * math.sin(p) ** 2) ** 1.5, 0.0, math.radians(lat_deg))[0]


def latitude_at_arc(arc: float) -> float:
    return brentq(lambda lat: meridian_arc(lat) - arc, -89.0, 89.0, xtol=1e-12)


def prime_vertical_radius(lat_deg: float) -> float:
    return A / math.sqrt(1 - E2 * math.sin(math.radians(lat_deg)) ** 2)


def _xodr(tmp_path: Path, geo: str, offset: str = "") -> Path:
    path = tmp_path / "road.xodr"
    path.write_text(
        f'<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="6">'
        f"<geoReference><![CDATA[{geo}]]></geoReference>{offset}</header></OpenDRIVE>"
    )
    return path


def test_utm_georeference_with_offset_on_the_central_meridian(tmp_path):
    northing = UTM_K0 * meridian_arc(52.0)
    road = _xodr(
        tmp_path,
        "+proj=utm +zone=32 +ellps=WGS84 +datum=WGS84 +units=m +no_defs",
        f'<offset x="500000" y="{northing!r}" z="100" hdg="0"/>',
    )
    ref = geo_reference_of(road)
    assert ref is not None
    lat, lon, alt = ref.to_wgs84(0.0, 0.0, 2.0)
    assert float(lat) == pytest.approx(52.0, abs=1e-9)
    assert float(lon) == pytest.approx(9.0, abs=1e-9)  # zone 32's central meridian
    assert float(alt) == pytest.approx(102.0)
    lat, lon, _ = ref.to_wgs84(0.0, 5000.0)  # 5 km north along the central meridian
    assert float(lat) == pytest.approx(latitude_at_arc(meridian_arc(52.0) + 5000.0 / UTM_K0), abs=1e-9)
    assert float(lon) == pytest.approx(9.0, abs=1e-9)


def test_offset_heading_rotates_the_map_frame(tmp_path):
    northing = UTM_K0 * meridian_arc(52.0)
    road = _xodr(
        tmp_path,
        "+proj=utm +zone=32 +datum=WGS84",
        f'<offset x="500000" y="{northing!r}" z="0" hdg="{math.pi / 2!r}"/>',
    )
    ref = geo_reference_of(road)
    assert ref is not None
    lat, lon, _ = ref.to_wgs84(5000.0, 0.0)  # map +x is north after a 90° rotation
    assert float(lat) == pytest.approx(latitude_at_arc(meridian_arc(52.0) + 5000.0 / UTM_K0), abs=1e-8)
    assert float(lon) == pytest.approx(9.0, abs=1e-8)
    assert ref.north_angle(0.0, 0.0) == pytest.approx(0.0, abs=1e-6)


def test_configured_origin_is_the_local_east_north_plane():
    ref = GeoReference.at_origin(48.0, 11.0, altitude=500.0)
    lat, lon, alt = ref.to_wgs84([0.0, 0.0, 1000.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1.0])
    assert lat[0] == pytest.approx(48.0, abs=1e-12) and lon[0] == pytest.approx(11.0, abs=1e-12)
    assert lat[1] == pytest.approx(latitude_at_arc(meridian_arc(48.0) + 1000.0), abs=1e-9)
    east = math.degrees(1000.0 / (prime_vertical_radius(48.0) * math.cos(math.radians(48.0))))
    assert lon[2] == pytest.approx(11.0 + east, abs=1e-7)
    assert alt.tolist() == [500.0, 500.0, 501.0]
    assert ref.north_angle(0.0, 0.0) == pytest.approx(math.pi / 2, abs=1e-9)


def test_road_without_georeference_and_bad_ones(tmp_path):
    plain = tmp_path / "plain.xodr"
    plain.write_text('<OpenDRIVE><header revMajor="1" revMinor="6"/></OpenDRIVE>')
    assert geo_reference_of(plain) is None
    with pytest.raises(BadInput, match="PROJ"):
        geo_reference_of(_xodr(tmp_path, "+proj=nonsense"))
    with pytest.raises(BadInput, match="offset/@x"):
        geo_reference_of(_xodr(tmp_path, "+proj=utm +zone=32", '<offset x="east"/>'))
