"""Tests for simcore.world.opendrive and its parts (road_geometry, road_model, opendrive_parse): hand-written
roads with exact answers, and the esmini reference corpus."""

from __future__ import annotations

import csv
import functools
import gzip
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from simcore.world.opendrive import OpenDrive, OpenDriveError
from simcore.world.opendrive_parse import MAX_FILE_BYTES
from tests.tooling import NO_CORPUS, corpus_dir


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _xodr(roads: str, junctions: str = "") -> str:
    return (
        f'<?xml version="1.0"?>\n<OpenDRIVE><header revMajor="1" revMinor="6"/>{roads}{junctions}</OpenDRIVE>'
    )


def _lanes(right: str = "", left: str = "", offsets: str = "", s: float = 0.0) -> str:
    return (
        f"<lanes>{offsets}<laneSection s='{s}'>"
        f"<left>{left}</left><center><lane id='0' type='none'/></center><right>{right}</right>"
        "</laneSection></lanes>"
    )


def _lane(lane_id: int, a: float = 3.5, b: float = 0.0, typ: str = "driving", link: str = "") -> str:
    return (
        f"<lane id='{lane_id}' type='{typ}'><link>{link}</link>"
        f"<width sOffset='0' a='{a}' b='{b}' c='0' d='0'/></lane>"
    )


def _road(
    rid: str, length: float, geometry: str, lanes: str, link: str = "", junction: str = "-1", extra: str = ""
) -> str:
    return (
        f"<road id='{rid}' length='{length}' junction='{junction}'><link>{link}</link>"
        f"<planView>{geometry}</planView>{extra}{lanes}</road>"
    )


# --------------------------------------------------------------------------------------- hand-written roads

STRAIGHT = _xodr(
    _road(
        "7",
        100.0,
        "<geometry s='0' x='10' y='5' hdg='0.3' length='100'><line/></geometry>",
        _lanes(
            right=_lane(-1, 3.5) + _lane(-2, 3.0, 0.01, typ="shoulder"),
            left=_lane(1, 3.25),
            offsets="<laneOffset s='0' a='0.5' b='0' c='0' d='0'/><laneOffset s='50' a='0.5' b='0.01' c='0' d='0'/>",
        ),
        extra="<elevationProfile><elevation s='0' a='2' b='0.05' c='0' d='0'/></elevationProfile>",
    )
)


@pytest.fixture(scope="module")
def straight() -> OpenDrive:
    return OpenDrive.from_string(STRAIGHT, "straight.xodr")


def test_straight_road_exact(straight: OpenDrive) -> None:
    od = straight
    assert list(od.roads) == ["7"]
    road = od.roads["7"]
    assert road.id == "7" and road.junction == "-1" and od.road_length("7") == 100.0
    c, s_ = math.cos(0.3), math.sin(0.3)
    for s in (0.0, 12.5, 50.0, 99.0, 100.0):
        for t in (-4.0, 0.0, 2.5):
            p = od.road_to_world("7", s, t)
            assert p.x == pytest.approx(10 + s * c - t * s_, abs=1e-9)
            assert p.y == pytest.approx(5 + s * s_ + t * c, abs=1e-9)
            assert p.z == pytest.approx(2 + 0.05 * s, abs=1e-9)
            assert p.heading == pytest.approx(0.3)
    ref = od.reference_pose("7", 20.0)
    assert (ref.x, ref.y) == pytest.approx((10 + 20 * c, 5 + 20 * s_))


def test_lane_widths_and_offset(straight: OpenDrive) -> None:
    od = straight
    # laneOffset 0.5 before s=50, then 0.5 + 0.01*(s-50)
    assert od.lane_center_t("7", 0, 10.0) == pytest.approx(0.5)
    assert od.lane_center_t("7", -1, 10.0) == pytest.approx(0.5 - 1.75)
    assert od.lane_center_t("7", 1, 10.0) == pytest.approx(0.5 + 3.25 / 2)
    # lane -2 width 3 + 0.01*s (sOffset relative to the section start at 0)
    assert od.lane_width("7", -2, 40.0) == pytest.approx(3.4)
    assert od.lane_center_t("7", -2, 40.0) == pytest.approx(0.5 - 3.5 - 3.4 / 2)
    assert od.lane_center_t("7", -1, 80.0) == pytest.approx(0.5 + 0.3 - 1.75)
    assert od.lane_width("7", 0, 80.0) == 0.0
    assert od.lane_ids("7", 30.0) == [-2, -1, 1]
    assert od.lane_ids("7", 30.0, driving_only=True) == [-1, 1]
    p = od.lane_to_world("7", -1, 30.0, offset=0.25)
    q = od.road_to_world("7", 30.0, 0.5 - 1.75 + 0.25)
    assert (p.x, p.y, p.z) == pytest.approx((q.x, q.y, q.z))
    # after s=50 the lanes drift left by 0.01 per m: the lane heading follows them
    assert od.lane_heading("7", -1, 80.0) == pytest.approx(0.3 + math.atan(0.01), abs=1e-6)
    with pytest.raises(OpenDriveError, match="no lane id=-3"):
        od.lane_width("7", -3, 10.0)
    with pytest.raises(OpenDriveError, match="no road id=nope"):
        od.road_length("nope")


def test_straight_world_to_road(straight: OpenDrive) -> None:
    od = straight
    for s, t, lane in ((5.0, -1.0, -1), (60.0, -5.0, -2), (99.5, 2.0, 1), (0.3, 0.51, 1), (0.3, 0.49, -1)):
        p = od.road_to_world("7", s, t)
        rc = od.world_to_road(p.x, p.y)
        assert rc is not None
        assert rc.road_id == "7" and rc.lane_id == lane
        assert rc.s == pytest.approx(s, abs=1e-6) and rc.t == pytest.approx(t, abs=1e-6)
        assert rc.offset == pytest.approx(t - od.lane_center_t("7", lane, s), abs=1e-6)
        assert rc.heading == pytest.approx(0.3)
    # just outside the outermost right lane (within half its width) still maps to it; far outside is off-road
    edge = 0.5 - 3.5 - od.lane_width("7", -2, 20.0)
    p = od.road_to_world("7", 20.0, edge - 1.0)
    rc = od.world_to_road(p.x, p.y)
    assert rc is not None and rc.lane_id == -2
    p = od.road_to_world("7", 20.0, edge - 3.0)
    assert od.world_to_road(p.x, p.y) is None
    p = od.road_to_world("7", 100.0, 0.0)
    assert od.world_to_road(p.x + 5 * math.cos(0.3), p.y + 5 * math.sin(0.3)) is None  # beyond the end


ARC_K = 0.02


@pytest.fixture(scope="module")
def arc() -> OpenDrive:
    return OpenDrive.from_string(
        _xodr(
            _road(
                "a",
                120.0,
                f"<geometry s='0' x='0' y='0' hdg='0' length='120'><arc curvature='{ARC_K}'/></geometry>",
                _lanes(right=_lane(-1), left=_lane(1)),
            )
        ),
        "arc.xodr",
    )


def test_arc_road_exact(arc: OpenDrive) -> None:
    r = 1.0 / ARC_K  # circle centred at (0, 50)
    for s in np.linspace(0.0, 120.0, 13):
        for t in (-3.0, -0.01, 0.01, 1.75):
            p = arc.road_to_world("a", float(s), t)
            phi = s * ARC_K
            assert p.x == pytest.approx((r - t) * math.sin(phi), abs=1e-9)
            assert p.y == pytest.approx(r - (r - t) * math.cos(phi), abs=1e-9)
            assert p.heading == pytest.approx(phi)
            rc = arc.world_to_road(p.x, p.y)
            assert rc is not None and rc.road_id == "a"
            assert rc.s == pytest.approx(s, abs=1e-6) and rc.t == pytest.approx(t, abs=1e-6)
            assert rc.lane_id == (-1 if t < 0 else 1)


def _integrate_clothoid(
    x0: float, y0: float, h0: float, k0: float, c: float, ds: float
) -> tuple[float, float]:
    def hdg(u: float) -> float:
        return h0 + k0 * u + 0.5 * c * u * u

    x = quad(lambda u: math.cos(hdg(u)), 0.0, ds, epsabs=1e-11, epsrel=1e-12, limit=400)[0]
    y = quad(lambda u: math.sin(hdg(u)), 0.0, ds, epsabs=1e-11, epsrel=1e-12, limit=400)[0]
    return x0 + x, y0 + y


@pytest.mark.parametrize(
    ("k0", "k1", "length"),
    [
        (0.0, 0.05, 80.0),
        (0.03, -0.02, 150.0),
        (-0.1, -0.01, 60.0),
        (0.01, 0.0100000001, 200.0),
        (0.01, 0.0101, 200.0),
        (-0.01, -0.0105, 300.0),
        (0.2, 0.2, 10.0),
    ],
)
def test_spiral_matches_numerical_integration(k0: float, k1: float, length: float) -> None:
    geo = f"<geometry s='0' x='3' y='-4' hdg='1.1' length='{length}'><spiral curvStart='{k0}' curvEnd='{k1}'/></geometry>"
    od = OpenDrive.from_string(_xodr(_road("s", length, geo, _lanes(right=_lane(-1)))), "spiral.xodr")
    c = (k1 - k0) / length
    for ds in np.linspace(0.0, length, 9):
        p = od.reference_pose("s", float(ds))
        x, y = _integrate_clothoid(3.0, -4.0, 1.1, k0, c, float(ds))
        assert math.hypot(p.x - x, p.y - y) < 1e-7
        assert _wrap(p.heading - (1.1 + k0 * ds + 0.5 * c * ds * ds)) == pytest.approx(0.0, abs=1e-12)


def test_param_poly3_ranges_and_poly3() -> None:
    # the same cubic written with normalized and arcLength parameters; poly3 with u = p
    v = (0.0, 0.0, 0.004, -0.00002)
    length_guess = 60.0
    geo_poly3 = f"<geometry s='0' x='1' y='2' hdg='0.5' length='{{L}}'><poly3 a='0' b='0' c='{v[2]}' d='{v[3]}'/></geometry>"
    # arc length of the poly3 from u = 0 to u = 60
    arclen = quad(
        lambda q: math.hypot(1.0, 2 * v[2] * q + 3 * v[3] * q * q), 0.0, length_guess, epsabs=1e-12
    )[0]
    od3 = OpenDrive.from_string(
        _xodr(_road("p", arclen, geo_poly3.replace("{L}", repr(arclen)), _lanes(right=_lane(-1))))
    )
    end = od3.reference_pose("p", arclen)
    ev = v[2] * 60.0**2 + v[3] * 60.0**3
    ex = 1 + 60.0 * math.cos(0.5) - ev * math.sin(0.5)
    ey = 2 + 60.0 * math.sin(0.5) + ev * math.cos(0.5)
    assert math.hypot(end.x - ex, end.y - ey) < 1e-6
    slope = 2 * v[2] * 60 + 3 * v[3] * 3600
    assert end.heading == pytest.approx(0.5 + math.atan(slope), abs=1e-9)
    # normalized: p in [0, 1] -> u = 60 p, v scaled accordingly
    nu = (0.0, 60.0, 0.0, 0.0)
    nv = (0.0, 0.0, v[2] * 3600, v[3] * 216000)
    pp = (
        f"<geometry s='0' x='1' y='2' hdg='0.5' length='{arclen!r}'><paramPoly3 pRange='normalized' "
        f"aU='{nu[0]}' bU='{nu[1]}' cU='{nu[2]}' dU='{nu[3]}' aV='{nv[0]}' bV='{nv[1]}' cV='{nv[2]}' dV='{nv[3]}'/></geometry>"
    )
    odn = OpenDrive.from_string(_xodr(_road("n", arclen, pp, _lanes(right=_lane(-1)))))
    # arcLength: p in [0, length]; u(p) = p * 60/length
    k = 60.0 / arclen
    au = (0.0, k, 0.0, 0.0)
    av = (0.0, 0.0, v[2] * k**2, v[3] * k**3)
    pa = (
        f"<geometry s='0' x='1' y='2' hdg='0.5' length='{arclen!r}'><paramPoly3 pRange='arcLength' "
        f"aU='{au[0]}' bU='{au[1]}' cU='{au[2]}' dU='{au[3]}' aV='{av[0]}' bV='{av[1]}' cV='{av[2]}' dV='{av[3]}'/></geometry>"
    )
    oda = OpenDrive.from_string(_xodr(_road("m", arclen, pa, _lanes(right=_lane(-1)))))
    for s in np.linspace(0.0, arclen, 7):
        a = od3.reference_pose("p", float(s))
        b = odn.reference_pose("n", float(s))
        c = oda.reference_pose("m", float(s))
        assert math.hypot(a.x - b.x, a.y - b.y) < 1e-6 and math.hypot(a.x - c.x, a.y - c.y) < 1e-6
        assert a.heading == pytest.approx(b.heading, abs=1e-9) and a.heading == pytest.approx(
            c.heading, abs=1e-9
        )
    # s is a true arc length: consecutive samples 1 m apart in s are ~1 m apart in space
    pts = [od3.reference_pose("p", s) for s in np.arange(0.0, 50.0, 1.0)]
    gaps = [math.hypot(q.x - p.x, q.y - p.y) for p, q in itertools.pairwise(pts)]
    assert max(abs(g - 1.0) for g in gaps) < 1e-4


def test_lane_section_offsets_and_single_side() -> None:
    lanes = (
        "<lanes><laneSection s='0'><center><lane id='0' type='none'/></center>"
        "<right>" + _lane(-1, 3.0) + "</right><left>" + _lane(1, 3.0) + "</left></laneSection>"
        "<laneSection s='40'><center><lane id='0' type='none'/></center><right>"
        "<lane id='-1' type='driving'><width sOffset='0' a='3' b='0' c='0' d='0'/>"
        "<width sOffset='10' a='3' b='0.1' c='0' d='0'/></lane>"
        "<lane id='-2' type='driving'><width sOffset='0' a='0' b='0.2' c='0' d='0'/></lane></right></laneSection>"
        "<laneSection s='70' singleSide='true'><center><lane id='0' type='none'/></center>"
        "<left>" + _lane(1, 4.0) + _lane(2, 2.0, typ="sidewalk") + "</left></laneSection></lanes>"
    )
    od = OpenDrive.from_string(
        _xodr(_road("r", 100.0, "<geometry s='0' x='0' y='0' hdg='0' length='100'><line/></geometry>", lanes))
    )
    assert od.lane_width("r", -1, 45.0) == pytest.approx(3.0)
    assert od.lane_width("r", -1, 55.0) == pytest.approx(3.5)  # sOffset is relative to the section start
    assert od.lane_width("r", -2, 45.0) == pytest.approx(1.0)
    assert od.lane_center_t("r", -2, 45.0) == pytest.approx(-3.5)
    assert od.lane_ids("r", 20.0) == [-1, 1]
    assert od.lane_ids("r", 40.0) == [-1]  # lane -2 has zero width at its section start
    # the singleSide section at 70 only replaces the left side: the right side continues from s=40
    assert od.lane_ids("r", 80.0) == [-2, -1, 1, 2]
    assert od.lane_width("r", -1, 80.0) == pytest.approx(3 + 0.1 * 30)
    assert od.lane_center_t("r", 2, 80.0) == pytest.approx(5.0)
    strips = od.sample_lane_boundaries("r", step=2.0)
    by_key = {(b.section_index, b.lane_id): b for b in strips}
    m = by_key[(1, -2)]
    assert m.inner.shape == m.outer.shape == (m.s.shape[0], 3)
    assert np.allclose(m.inner, by_key[(1, -1)].outer)
    assert np.allclose(
        m.outer[:, 1], -(3 + np.where(m.s - 40 >= 10, 0.1 * (m.s - 50), 0.0)) - 0.2 * (m.s - 40)
    )
    assert m.s[0] == 40.0 and m.s[-1] == 70.0 and np.all(np.diff(m.s) <= 2.0 + 1e-9)


# ------------------------------------------------------------------------------------------------- topology

LINE = "<geometry s='0' x='{x}' y='0' hdg='0' length='50'><line/></geometry>"
TOPO = _xodr(
    _road(
        "1",
        50.0,
        LINE.format(x=0),
        _lanes(right=_lane(-1, link="<successor id='1'/>"), left=_lane(1, link="<predecessor id='1'/>")),
        link="<successor elementType='road' elementId='2' contactPoint='end'/>",
    )
    + _road(
        "2",
        50.0,
        "<geometry s='0' x='100' y='0' hdg='3.141592653589793' length='50'><line/></geometry>",
        _lanes(right=_lane(-1, link="<successor id='1'/>"), left=_lane(1, link="<successor id='-1'/>")),
        link="<successor elementType='road' elementId='1' contactPoint='end'/>"
        "<predecessor elementType='junction' elementId='9'/>",
    )
    + _road(
        "3",
        20.0,
        LINE.format(x=100).replace("length='50'", "length='20'"),
        _lanes(right=_lane(-1, link="<predecessor id='1'/><successor id='-1'/>")),
        link="<predecessor elementType='road' elementId='2' contactPoint='start'/>"
        "<successor elementType='road' elementId='4' contactPoint='start'/>",
        junction="9",
    )
    + _road(
        "5",
        20.0,
        LINE.format(x=100).replace("length='50'", "length='20'"),
        _lanes(right=_lane(-1, link="<predecessor id='2'/>")),
        junction="9",
    )
    + _road("4", 50.0, LINE.format(x=120), _lanes(right=_lane(-1))),
    "<junction id='9' name='j'>"
    "<connection id='0' incomingRoad='2' connectingRoad='5' contactPoint='start'><laneLink from='2' to='-1'/></connection>"
    "<connection id='1' incomingRoad='2' connectingRoad='3' contactPoint='start'><laneLink from='1' to='-1'/></connection>"
    "</junction>",
)


def test_successor_road_link_and_junction() -> None:
    od = OpenDrive.from_string(TOPO, "topo.xodr")
    assert od.roads["3"].junction == "9"
    assert od.junctions["9"].connections[1].connecting_road == "3"
    # road 1 lane -1 ends at road 2's end: continue on road 2 lane 1 toward decreasing s
    assert od.successor("1", -1, 1) == ("2", 1, -1)
    # road 2 lane 1 travelling toward s=0 enters junction 9: the first connection with a laneLink from 1
    assert od.successor("2", 1, -1) == ("3", -1, 1)
    # through the connecting road to road 4 (contactPoint start -> increasing s)
    assert od.successor("3", -1, 1) == ("4", -1, 1)
    # road 2 lane -1 leaving its end: road 1 lane 1, travelling toward decreasing s on road 1
    assert od.successor("2", -1, 1) == ("1", 1, -1)
    # dead ends: no predecessor link on road 1, no links on road 4, no laneLink from lane -1 in the junction
    assert od.successor("1", -1, -1) is None
    assert od.successor("4", -1, 1) is None
    assert od.successor("2", -1, -1) is None
    with pytest.raises(ValueError):
        od.successor("1", -1, 0)


# ------------------------------------------------------------------------------------------- bad input

GOOD_GEOM = "<geometry s='0' x='0' y='0' hdg='0' length='10'><line/></geometry>"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            _xodr(
                _road("1", 10, GOOD_GEOM, _lanes(right=_lane(-1)))
                + _road(
                    "3",
                    10,
                    GOOD_GEOM + "<geometry s='0' x='0' y='0' hdg='0' length='10'><foo/></geometry>",
                    _lanes(),
                )
            ),
            "roads/x.xodr: road id=3: geometry 1: unsupported type 'foo'",
        ),
        (
            _xodr(
                _road(
                    "4", 10, "<geometry s='0' x='0' y='0' hdg='zero' length='10'><line/></geometry>", _lanes()
                )
            ),
            "roads/x.xodr: road id=4: geometry 0: <geometry> attribute hdg='zero' is not a number",
        ),
        (
            _xodr(
                _road("5", 10, "<geometry s='0' x='0' y='0' hdg='0' length='10'><arc/></geometry>", _lanes())
            ),
            "roads/x.xodr: road id=5: geometry 0: <arc> is missing attribute 'curvature'",
        ),
        (
            _xodr(_road("6", 10, GOOD_GEOM, _lanes(right=_lane(-1) + _lane(-3)))),
            "roads/x.xodr: road id=6: laneSection 0: lane ids [-1, -3] are not consecutive from -1",
        ),
        (
            _xodr(_road("7", 10, GOOD_GEOM, _lanes(right=_lane(-1).replace("a='3.5'", "a='x'")))),
            "roads/x.xodr: road id=7: laneSection 0: lane id=-1: width 0: <width> attribute a='x' is not a number",
        ),
        (
            _xodr(
                _road("8", 10, GOOD_GEOM, _lanes()),
                "<junction id='1'><connection id='0' incomingRoad='8'/></junction>",
            ),
            "roads/x.xodr: junction id=1: connection 0: <connection> is missing attribute 'connectingRoad'",
        ),
        (_xodr(""), "roads/x.xodr: no <road> elements"),
        ("<OpenDRIVE><road", "roads/x.xodr: not well-formed XML"),
        ("<Other/>", "roads/x.xodr: root element is <Other>, expected <OpenDRIVE>"),
    ],
)
def test_malformed_input_names_file_and_element(text: str, message: str) -> None:
    with pytest.raises(OpenDriveError) as exc:
        OpenDrive.from_string(text, "roads/x.xodr")
    assert message in str(exc.value)


BOMB = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
]>
<OpenDRIVE><header name="&lol4;"/></OpenDRIVE>"""

EXTERNAL = """<?xml version="1.0"?>
<!DOCTYPE r [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>
<OpenDRIVE><header name="&xxe;"/></OpenDRIVE>"""


@pytest.mark.parametrize("text", [BOMB, EXTERNAL])
def test_entity_expansion_rejected(text: str, tmp_path: Path) -> None:
    with pytest.raises(OpenDriveError, match=r"bomb\.xodr: unsafe XML rejected"):
        OpenDrive.from_string(text, "bomb.xodr")
    f = tmp_path / "bomb.xodr"
    f.write_text(text)
    with pytest.raises(OpenDriveError, match="unsafe XML rejected"):
        OpenDrive.from_file(f)


def test_oversized_and_missing_files_refused(tmp_path: Path) -> None:
    big = tmp_path / "big.xodr"
    with big.open("wb") as fh:  # sparse: no real disk use
        fh.truncate(MAX_FILE_BYTES + 1)
    with pytest.raises(OpenDriveError, match=r"big\.xodr: file is .* larger than"):
        OpenDrive.from_file(big)
    with pytest.raises(OpenDriveError, match=r"missing\.xodr: cannot read"):
        OpenDrive.from_file(tmp_path / "missing.xodr")


def test_s_out_of_range(straight: OpenDrive) -> None:
    assert straight.road_to_world("7", 100.0005, 0.0).x == pytest.approx(
        straight.road_to_world("7", 100.0, 0.0).x
    )
    with pytest.raises(OpenDriveError, match="s=101"):
        straight.road_to_world("7", 101.0, 0.0)


# --------------------------------------------------------------------------------- esmini reference corpus

# scenario -> what it exercises
REFERENCE_SCENARIOS = {
    "xosc/cut-in_cr": "curves_elevation: spirals (curvStart != 0), arcs, elevation",
    "xosc/acc-toggle": "curves_elevation: the whole road",
    "xosc/cut-in": "e6mini: paramPoly3 arcLength, elevation",
    "xosc/left-hand-traffic_using_road_rule": "e6mini-lht",
    "xosc/lane_change": "jolengatan: paramPoly3",
    "xosc/highway_merge": "soderleden: direct junction, laneOffset",
    "xosc/traffic_lights": "fabriksgatan: junction, paramPoly3, laneOffset",
    "xosc/pedestrian_collision": "fabriksgatan: junction connecting roads",
    "xosc/routing-test": "multi_intersections: spirals, junctions",
    "xosc/sumo-test": "multi_intersections: junctions",
    "xosc/lane_change_crest": "crest-curve: spiral, elevation",
    "xosc/alks-test": "curve_r100: arc",
    "xosc/light_state": "circle_300m: arc",
    "xosc/velodrome": "velodrome: superelevation, spirals",
    "xosc/tunnels": "tunnels: spirals, elevation",
    "xosc/two_plus_one_road": "two_plus_one: laneOffset",
    "xosc/parking_demo": "parking_demo: spirals, junction",
    "xosc/straight_500m": "straight_500m: line",
    "scenario_construct_examples/scenario_runner_with_acts": "spirals",
}
MAX_ROWS = 3000  # deterministic sample per scenario (most have fewer rows: all of them are checked)


@functools.cache
def _index() -> dict[str, dict[str, str]]:
    with (corpus_dir() / "INDEX.tsv").open() as fh:
        return {
            row["path"].removeprefix("resources/").removesuffix(".xosc"): row
            for row in csv.DictReader(fh, delimiter="\t")
        }


@functools.cache
def _network(path: str) -> OpenDrive:
    return OpenDrive.from_file(path)


def _reference(scenario: str) -> tuple[OpenDrive, list[dict[str, str]]]:
    corpus = corpus_dir()
    if not (corpus / "INDEX.tsv").is_file():
        pytest.skip(NO_CORPUS)
    row = _index()[scenario]
    xodr = (corpus / "resources" / scenario).parent / row["road_file"]
    with gzip.open(corpus / row["reference_csv"], "rt") as fh:
        rows = list(csv.DictReader(fh))
    # lane following: on the lane centre at this and the entity's neighbouring samples (not crossing the
    # centre during a lane change or lane-offset manoeuvre)
    by_entity: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        by_entity.setdefault(r["id"], []).append(r)
    for track in by_entity.values():
        for i, r in enumerate(track):
            near = track[max(i - 1, 0) : i + 2]
            r["steady"] = str(
                all(abs(float(q["offset"])) <= 1e-3 and q["roadId"] == r["roadId"] for q in near)
            )
    return _network(str(xodr.resolve())), rows[:: max(1, len(rows) // MAX_ROWS)]


@pytest.mark.parametrize("scenario", sorted(REFERENCE_SCENARIOS))
def test_against_esmini_reference(scenario: str) -> None:
    """Rows where the entity follows its lane centre (esmini offset 0, also at its neighbouring samples)
    inside the road: the pose computed
    from esmini's (road, s, t) must match esmini's world pose (heading: for moving entities, modulo pi), and world_to_road must give back the road
    coordinates (or, where roads overlap in a junction, another road mapping to the same point)."""
    od, rows = _reference(scenario)
    checked = 0
    for row in rows:
        road_id, lane_id = row["roadId"], int(row["laneId"])
        s, t, offset = float(row["s"]), float(row["t"]), float(row["offset"])
        x, y, z, h = (float(row[k]) for k in "xyzh")
        assert road_id in od.roads, f"{scenario}: esmini road {road_id} not in the network"
        if row["steady"] != "True" or abs(offset) > 1e-3 or not 0.05 < s < od.road_length(road_id) - 0.05:
            continue  # lane changes, off-road motion, road ends: not lane following
        where = f"{scenario} t={row['time']} {row['name']} road {road_id} lane {lane_id} s={s} t={t}"
        p = od.road_to_world(road_id, s, t)
        assert math.hypot(p.x - x, p.y - y) < 0.02, f"{where}: ({p.x:.4f}, {p.y:.4f}) vs ({x}, {y})"
        assert abs(p.z - z) < 0.02, f"{where}: z {p.z:.4f} vs {z}"
        assert od.lane_center_t(road_id, lane_id, s) == pytest.approx(t, abs=2e-3), where
        lane_h = od.lane_heading(road_id, lane_id, s)
        if float(row["speed"]) > 0.5:  # parked objects may be placed at an angle to the lane
            assert abs(_wrap(2 * (lane_h - h))) / 2 < 0.01, (
                f"{where}: lane heading {lane_h:.4f} vs {h} (mod pi)"
            )
        rc = od.world_to_road(x, y, z)
        assert rc is not None, f"{where}: world_to_road found no road"
        if rc.road_id == road_id:
            assert (rc.lane_id, rc.s, rc.t) == (
                lane_id,
                pytest.approx(s, abs=0.02),
                pytest.approx(t, abs=0.02),
            ), where
        else:  # overlapping roads (junction): must be a point of that road and lane
            q = od.road_to_world(rc.road_id, rc.s, rc.t)
            assert math.hypot(q.x - x, q.y - y) < 0.02, f"{where}: mapped to road {rc.road_id}"
            assert od.roads[rc.road_id].junction != "-1" or od.roads[road_id].junction != "-1", where
        checked += 1
    assert checked >= 20, f"{scenario}: only {checked} lane-following rows"


def _corpus_network(name: str) -> OpenDrive:
    path = corpus_dir() / "resources" / "xodr" / name
    if not path.is_file():
        pytest.skip(NO_CORPUS)
    return _network(str(path.resolve()))


@pytest.mark.parametrize(
    "name", ["fabriksgatan.xodr", "multi_intersections.xodr", "soderleden.xodr", "parking_demo.xodr"]
)
def test_successor_links_are_geometrically_continuous(name: str) -> None:
    """Every successor() step of every driving lane in real junction networks lands where the lane left off,
    with the same direction of travel."""
    od = _corpus_network(name)
    followed = 0
    for road_id, road in od.roads.items():
        for direction in (1, -1):
            sec = road.lane_sections[-1] if direction > 0 else road.lane_sections[0]
            for lane in sec.left + sec.right:
                if lane.type != "driving":
                    continue
                nxt = od.successor(road_id, lane.id, direction)
                if nxt is None:
                    continue
                road2, lane2, direction2 = nxt
                p = od.lane_to_world(road_id, lane.id, road.length if direction > 0 else 0.0)
                q = od.lane_to_world(road2, lane2, 0.0 if direction2 > 0 else od.road_length(road2))
                where = f"{name}: road {road_id} lane {lane.id} dir {direction} -> {nxt}"
                assert math.hypot(p.x - q.x, p.y - q.y) < 0.05, where
                hp = p.heading + (0.0 if direction > 0 else math.pi)
                hq = q.heading + (0.0 if direction2 > 0 else math.pi)
                assert abs(_wrap(hp - hq)) < 0.02, where
                followed += 1
    assert followed >= 5


@pytest.mark.parametrize("name", ["fabriksgatan.xodr", "multi_intersections.xodr", "velodrome.xodr"])
def test_world_to_road_round_trip(name: str) -> None:
    """Random points inside lanes map back to a road position at the same world point (same road: same lane)."""
    od = _corpus_network(name)
    rng = np.random.default_rng(7)
    for road_id, road in od.roads.items():
        for s in rng.uniform(0.01, road.length - 0.01, 6):
            ids = od.lane_ids(road_id, float(s))
            if not ids:
                continue
            lane_id = ids[int(rng.integers(len(ids)))]
            offset = float(rng.uniform(-0.45, 0.45)) * od.lane_width(road_id, lane_id, float(s))
            p = od.lane_to_world(road_id, lane_id, float(s), offset)
            rc = od.world_to_road(p.x, p.y, p.z)
            where = f"{name}: road {road_id} lane {lane_id} s={s:.3f} offset={offset:.3f}"
            assert rc is not None, where
            q = od.road_to_world(rc.road_id, rc.s, rc.t)
            assert math.hypot(q.x - p.x, q.y - p.y) < 1e-3 and abs(q.z - p.z) < 1e-3, f"{where}: {rc}"
            if rc.road_id == road_id:
                assert rc.lane_id == lane_id and rc.offset == pytest.approx(offset, abs=1e-3), (
                    f"{where}: {rc}"
                )


def test_world_to_road_near_agrees_with_world_to_road() -> None:
    """The tracking fast path gives the same coordinates as the full search wherever it answers."""
    import random

    from simcore.world.opendrive import OpenDrive

    road = OpenDrive.from_file(Path(__file__).resolve().parents[1] / "examples" / "maps" / "highway.xodr")
    rng = random.Random(3)
    answered = 0
    for _ in range(300):
        s = rng.uniform(0, road.road_length("1"))
        t = rng.uniform(-12.0, 1.0)
        pose = road.road_to_world("1", s, t)
        full = road.world_to_road(pose.x, pose.y)
        near = road.world_to_road_near(pose.x, pose.y, "1", max(s - rng.uniform(0, 3), 0.0))
        if near is None:
            continue
        answered += 1
        assert full is not None
        assert (near.road_id, near.lane_id) == (full.road_id, full.lane_id)
        assert near.s == pytest.approx(full.s, abs=1e-6) and near.t == pytest.approx(full.t, abs=1e-6)
    assert answered > 250


def test_shared_parses_a_file_once_per_content(tmp_path: Path) -> None:
    """A worker's runs on one road share its parse and spatial index; a changed file is parsed again."""
    source = Path(__file__).resolve().parents[1] / "examples" / "maps" / "highway.xodr"
    road = tmp_path / "road.xodr"
    road.write_bytes(source.read_bytes())
    first = OpenDrive.shared(road)
    assert first.world_to_road(100.0, -5.0) is not None  # builds the index on the shared network
    assert OpenDrive.shared(road) is first
    assert OpenDrive.shared(road).world_to_road(100.0, -5.0) == OpenDrive.from_file(road).world_to_road(
        100.0, -5.0
    )
    road.write_bytes(source.read_bytes().replace(b'length="2000.0"', b'length="1500.0"', 1))
    changed = OpenDrive.shared(road)
    assert changed is not first and changed.roads["1"].length == 1500.0
    road.write_text("<OpenDRIVE>")
    with pytest.raises(OpenDriveError, match=r"road\.xodr: not well-formed XML"):
        OpenDrive.shared(road)


def test_constant_lane_borders_are_the_ones_computed_at_every_s() -> None:
    """A section side with constant widths and laneOffset has its borders computed once: they are, to the
    bit, the ones the per-s sums give at any s of the section; widths that change are computed at each s."""
    from simcore.world.road_model import Poly3, _constant

    od = OpenDrive.from_string(
        _xodr(
            _road(
                "1",
                120.0,
                "<geometry s='0' x='0' y='0' hdg='0.2' length='120'><line/></geometry>",
                "<lanes><laneOffset s='0' a='0.25' b='0' c='0' d='0'/>"
                "<laneSection s='0'><left>"
                + _lane(1, 3.25)
                + "</left><center><lane id='0' type='none'/></center>"
                "<right>" + _lane(-1, 3.5) + _lane(-2, 3.1) + "</right></laneSection>"
                "<laneSection s='60'><left>" + _lane(1, 3.25, 0.01) + "</left>"
                "<center><lane id='0' type='none'/></center><right>"
                + _lane(-1, 3.4)
                + "</right></laneSection></lanes>",
            )
        ),
        "constant.xodr",
    )
    road = od.roads["1"]
    for s in (0.0, 0.1, 17.3, 59.99, 60.0, 75.5, 119.0, 120.0):
        for side in (1, -1):
            sec = road.section_at(s, side)
            lanes = sec.left if side > 0 else sec.right
            assert road.side_borders(s, side) == road._borders_in(sec, lanes, s, side), (s, side)
        assert road.all_borders(s) == road.side_borders(s, -1) + road.side_borders(s, 1)
    first = road.section_at(10.0, -1)
    assert road._fixed_borders(first, -1) is not None and road._fixed_borders(first, 1) is not None
    second = road.section_at(70.0, 1)
    assert road._fixed_borders(second, 1) is None  # the left lane widens along the section
    assert road.side_borders(70.0, 1) != road.side_borders(80.0, 1)
    assert _constant(Poly3(0.0, 3.5, 0.0, 0.0, 0.0)) and _constant(Poly3(5.0, -1.0, 0.0, 0.0, 0.0))
    assert not _constant(Poly3(0.0, -0.0, 0.0, 0.0, 0.0)) and not _constant(Poly3(0.0, 3.5, 0.0, 1e-9, 0.0))


# ------------------------------------------------------------------ no numpy on the run path


def test_quadrature_constants_are_numpys_leggauss() -> None:
    """The Gauss-Legendre nodes and weights written out in the module are exactly numpy's."""
    from simcore.world import road_geometry as rg

    for n, xs, ws in ((6, rg._GL_X, rg._GL_W), (16, rg._GL16_X, rg._GL16_W)):
        x, w = np.polynomial.legendre.leggauss(n)
        assert list(xs) == x.tolist() and list(ws) == w.tolist()


@pytest.mark.parametrize(
    ("start", "stop", "num"),
    [
        (0.0, 1.0, 65),
        (0.0, 123.59443842600000, 619),
        (3.5, -2.25, 7),
        (2.0, 2.0, 5),
        (1.0, 9.0, 1),
        (0.0, 1e-300, 3),
    ],
)
def test_linspace_gives_numpys_floats(start: float, stop: float, num: int) -> None:
    from simcore.world.road_geometry import linspace

    assert linspace(start, stop, num) == np.linspace(start, stop, num).tolist()


def test_fresnel_integrals_are_scipys() -> None:
    """The module's Fresnel integrals (no scipy import) give scipy.special.fresnel's floats exactly."""
    from scipy.special import fresnel

    from simcore.world.road_geometry import _fresnel

    rng = np.random.default_rng(3)
    xs = np.concatenate(
        [
            rng.uniform(-3.0, 3.0, 4000),
            rng.uniform(-200.0, 200.0, 4000),
            rng.uniform(-6e4, 6e4, 500),
            10.0 ** rng.uniform(-9.0, 5.0, 1000),
            [0.0, -0.0, 1.6, -1.6, math.sqrt(2.5625), 36974.0, -36975.5, math.inf, -math.inf],
        ]
    )
    s, c = fresnel(xs)
    assert [_fresnel(x) for x in xs.tolist()] == list(zip(s.tolist(), c.tolist(), strict=True))


def _numpy_arclen(u: tuple[float, ...], v: tuple[float, ...], ps: np.ndarray) -> np.ndarray:
    """The arc-length table as computed with numpy arrays (the module's former implementation)."""
    x, w = np.polynomial.legendre.leggauss(6)
    a, b = ps[:-1], ps[1:]
    half, mid = 0.5 * (b - a), 0.5 * (a + b)
    p = mid[:, None] + half[:, None] * x[None, :]
    speed = np.hypot(u[1] + p * (2 * u[2] + 3 * u[3] * p), v[1] + p * (2 * v[2] + 3 * v[3] * p))
    return np.concatenate(([0.0], np.cumsum(half * (speed @ w))))


@pytest.mark.parametrize(
    ("u", "v", "p_max", "length"),
    [
        ((0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 0.004, -0.00002), 60.0, 60.4),
        ((0.0, 123.5, -4.2, 1.1), (0.0, 0.3, 35.0, -20.0), 1.0, 130.0),
        ((0.0, 0.9, 0.001, -1e-5), (0.0, 0.1, 0.002, 3e-6), 4000.0, 4000.0),
    ],
)
def test_param_poly3_table_matches_the_numpy_computation(
    u: tuple[float, float, float, float], v: tuple[float, float, float, float], p_max: float, length: float
) -> None:
    from simcore.world.road_geometry import ParamPoly3

    geo = ParamPoly3(0.0, 1.0, 2.0, 0.5, length, u, v, p_max)
    ps = np.linspace(0.0, p_max, len(geo._ps))
    assert geo._ps == ps.tolist()
    expected = _numpy_arclen(u, v, ps)
    expected = expected * (length / expected[-1])
    assert np.max(np.abs(np.asarray(geo._ss) - expected)) <= 1e-9
    for ds in np.linspace(0.0, length, 11):  # the pose differs from the numpy table's by far less than 1e-9 m
        assert math.isfinite(geo.local(float(ds))[0])


@pytest.mark.parametrize(("k0", "k1", "length"), [(0.01, 0.0100000001, 200.0), (-0.3, -0.3000002, 900.0)])
def test_numeric_spiral_matches_the_numpy_computation(k0: float, k1: float, length: float) -> None:
    from simcore.world.road_geometry import Spiral

    geo = Spiral(0.0, 3.0, -4.0, 1.1, length, k0, k1)
    assert geo._numeric
    x, w = np.polynomial.legendre.leggauss(16)
    for ds in np.linspace(0.0, length, 9)[1:]:
        n = max(1, math.ceil(max(abs(k0), abs(k0 + geo.c * ds)) * ds / 0.25), math.ceil(ds / 100.0))
        edges = np.linspace(0.0, ds, n + 1)
        half = 0.5 * (edges[1:] - edges[:-1])
        q = 0.5 * (edges[1:] + edges[:-1])[:, None] + half[:, None] * x[None, :]
        h = 1.1 + k0 * q + 0.5 * geo.c * q * q
        ex, ey = 3.0 + float(np.sum(half * (np.cos(h) @ w))), -4.0 + float(np.sum(half * (np.sin(h) @ w)))
        gx, gy, _ = geo.local(float(ds))
        assert math.hypot(gx - ex, gy - ey) <= 1e-9


def test_loading_and_querying_a_road_imports_no_numpy() -> None:
    """numpy's import costs more than a small scenario's whole run: parsing, poses and world→road (every
    geometry kind) run without it, and without scipy; only the sampled lane outlines (sensors, report plots)
    import numpy."""
    import subprocess
    import sys

    maps = Path(__file__).resolve().parent.parent / "examples" / "maps"
    code = (
        "import sys, math\n"
        "from simcore.world.opendrive import OpenDrive\n"
        "geo = ''.join([\n"
        "  \"<geometry s='0' x='0' y='0' hdg='0' length='50'><line/></geometry>\",\n"
        "  \"<geometry s='50' x='50' y='0' hdg='0' length='40'><spiral curvStart='0' curvEnd='0.02'/></geometry>\",\n"
        "  \"<geometry s='90' x='89.5' y='5.3' hdg='0.4' length='30'><spiral curvStart='0.01' curvEnd='0.0100000001'/></geometry>\",\n"
        "  \"<geometry s='120' x='117' y='17' hdg='0.7' length='40'><paramPoly3 pRange='normalized' aU='0' bU='40' cU='0' dU='0' aV='0' bV='0' cV='3' dV='-1'/></geometry>\",\n"
        "  \"<geometry s='160' x='150' y='45' hdg='0.8' length='30'><poly3 a='0' b='0' c='0.001' d='0'/></geometry>\"])\n"
        "lanes = \"<lanes><laneSection s='0'><center><lane id='0' type='none'/></center><right><lane id='-1' type='driving'><width sOffset='0' a='3.5' b='0' c='0' d='0'/></lane></right></laneSection></lanes>\"\n"
        "od = OpenDrive.from_string(f\"<OpenDRIVE><header revMajor='1' revMinor='6'/><road id='r' length='190' junction='-1'><planView>{geo}</planView>{lanes}</road></OpenDRIVE>\")\n"
        "for s in range(0, 190, 7):\n"
        "    p = od.reference_pose('r', float(s))\n"
        "    rc = od.world_to_road(p.x + 1.0 * math.sin(p.heading), p.y - 1.0 * math.cos(p.heading))\n"
        "    assert rc is not None and rc.lane_id == -1, (s, rc)\n"
        f"for name in ('highway', 'rural'):\n"
        f"    net = OpenDrive.from_file({str(maps)!r} + '/' + name + '.xodr')\n"
        "    for road in net.roads.values():\n"
        "        p = net.reference_pose(road.id, road.length / 2)\n"
        "        assert net.world_to_road(p.x, p.y) is not None\n"
        "print('numpy' in sys.modules or 'scipy' in sys.modules)\n"
        "od.sample_lane_boundaries('r')\n"
        "print('numpy' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True"]


def _two_section_road(offsets: str, second: bool = True) -> OpenDrive:
    """Three geometry records (line, spiral, arc) and two lane sections: constant widths in the first (one
    of them 0), a widening left lane in the second (unless not `second`)."""
    return OpenDrive.from_string(
        _xodr(
            _road(
                "1",
                120.0,
                "<geometry s='0' x='0' y='0' hdg='0.2' length='40'><line/></geometry>"
                "<geometry s='40' x='39.2' y='7.9' hdg='0.2' length='40'>"
                "<spiral curvStart='0' curvEnd='0.01'/></geometry>"
                "<geometry s='80' x='77.5' y='19.4' hdg='0.4' length='40'><arc curvature='0.01'/></geometry>",
                f"<lanes>{offsets}<laneSection s='0'><left>"
                + _lane(1, 3.29)
                + "</left><center><lane id='0' type='none'/></center>"
                "<right>"
                + _lane(-1, 0.0)
                + _lane(-2, 3.37, typ="Driving")
                + _lane(-3, 3.1, typ="shoulder")
                + "</right></laneSection>"
                + (
                    "<laneSection s='60'><left>" + _lane(1, 3.25, 0.01) + "</left>"
                    "<center><lane id='0' type='none'/></center><right>"
                    + _lane(-1, 3.4)
                    + "</right></laneSection>"
                    if second
                    else ""
                )
                + "</lanes>",
                extra="<elevationProfile><elevation s='0' a='1.5' b='0' c='0' d='0'/></elevationProfile>",
            )
        ),
        "sections.xodr",
    )


def _lookups(od: OpenDrive) -> list[str]:
    """Every per-step road query along the road, on a grid of s and t (repr: the floats to the bit)."""
    from simcore.scenario.motion import lane_at_t

    out = []
    for s in [k * 0.37 for k in range(325)] + [0.0, 59.999999999, 60.0, 120.0]:
        out.append(repr(od.roads["1"].all_borders(s)))
        out.append(repr((od.lane_ids("1", s), od.lane_ids("1", s, driving_only=True))))
        for lane_id in (-3, -2, -1, 1):
            try:
                out.append(repr(od.lane_center_t("1", lane_id, s)))
            except OpenDriveError as e:
                out.append(str(e))
        edges = [t for _, inner, outer in od.roads["1"].all_borders(s) for t in (inner, outer)]
        near_edges = [t + d for t in edges for d in (-2e-9, -5e-10, 0.0, 5e-10, 2e-9)]
        for t in [-9.0, -6.6, -6.0, -3.5, -1.0, 0.0, 0.3, 2.0, 3.5, 4.0, 7.0, *near_edges]:
            out.append(repr(lane_at_t(od, "1", s, t)))
            pose = od.road_to_world("1", s, t)
            out.append(repr(od.world_to_road_near(pose.x, pose.y, "1", s + 0.8)))
            out.append(repr(od.road_xyzh("1", s, t)))
    return out


@pytest.mark.parametrize("offsets", ["", "<laneOffset s='0' a='0.25' b='0' c='0' d='0'/>"])
def test_lane_cross_lookups_give_what_the_per_s_sums_give(offsets: str) -> None:
    """Where the lane borders are the same over a stretch of road, lane centres, the lane containing a t,
    world -> road tracking and all borders come from tables made once: to the bit what the borders summed
    at each s give (the same queries with the tables switched off)."""
    fast = _two_section_road(offsets)
    road = fast.roads["1"]
    assert road.cross_at(10.0) is not None and road.cross_at(59.0) is not None
    assert road.cross_at(60.0) is None and road.cross_at(100.0) is None  # the left lane widens there
    slow = _two_section_road(offsets)
    slow.roads["1"]._crosses = [None] * (len(slow.roads["1"]._cross_starts) + 1)
    assert _lookups(fast) == _lookups(slow)


def test_one_lane_cross_serves_a_road_of_one_lane_section() -> None:
    fast = _two_section_road("", second=False)
    assert fast.roads["1"].cross_at(0.0) is fast.roads["1"].cross_at(120.0) is not None
    slow = _two_section_road("", second=False)
    slow.roads["1"]._crosses = [None] * (len(slow.roads["1"]._cross_starts) + 1)
    assert _lookups(fast) == _lookups(slow)


def test_lane_cross_is_off_where_the_lane_offset_varies() -> None:
    od = _two_section_road("<laneOffset s='0' a='0.25' b='0.01' c='0' d='0'/>")
    assert od.roads["1"].cross_at(10.0) is None
    assert od.lane_center_t("1", -2, 10.0) == pytest.approx(0.25 + 0.1 - 3.37 / 2)


def test_geometry_span_is_the_range_geometry_at_gives_its_record_for() -> None:
    road = _two_section_road("").roads["1"]
    for s in [-1.0, 0.0, 39.999999, 40.0, 40.000001, 79.9, 80.0, 120.0, 130.0] + [
        k * 0.5 for k in range(241)
    ]:
        g, lo, hi = road.geometry_span(s)
        assert g is road.geometry_at(s) and lo <= s < hi, s
        for probe in (lo, math.nextafter(hi, -math.inf)):
            if math.isfinite(probe):
                assert road.geometry_at(probe) is g, (s, probe)


def test_a_constant_elevation_is_the_polynomial_value_at_every_s() -> None:
    from simcore.world.road_model import Poly3, _fixed_value

    road = _two_section_road("").roads["1"]
    assert [road.elevation(s) for s in (0.0, 33.3, 120.0)] == [1.5, 1.5, 1.5]
    assert _fixed_value([]) == 0.0 and _fixed_value([Poly3(0.0, 2.0, 0.0, 0.0, 0.0)]) == 2.0
    assert _fixed_value([Poly3(0.0, 2.0, 0.1, 0.0, 0.0)]) is None
    assert _fixed_value([Poly3(0.0, 2.0, 0.0, 0.0, 0.0), Poly3(5.0, 2.0, 0.0, 0.0, 0.0)]) is None
    for p in (Poly3(3.0, 2.0, 0.0, 0.0, 0.0), Poly3(3.0, 1e-300, -0.0, 0.0, -0.0)):
        assert all(p.value(s) == _fixed_value([p]) for s in (-5.0, 0.0, 3.0, 1e6))


def test_a_param_poly3_answers_the_same_whatever_it_was_asked_before() -> None:
    """A paramPoly3 keeps its last evaluation: the point and curvature at a ``ds`` are the ones a fresh
    record gives, in any order of questions."""
    from simcore.world.road_geometry import ParamPoly3

    def record() -> ParamPoly3:
        return ParamPoly3(0.0, 1.0, 2.0, 0.3, 50.0, (0.0, 1.0, 0.01, -0.0002), (0.0, 0.0, 0.02, 0.0001), None)

    kept = record()
    for ds in (0.0, 10.0, 10.0, 3.3, 49.9, 10.0, -0.0, 0.0, 25.0):
        fresh = record()
        assert kept.local(ds) == fresh.local(ds) and kept.curvature(ds) == record().curvature(ds), ds
        assert kept.curvature(ds) == fresh.curvature(ds) and kept.local(ds) == record().local(ds), ds


@pytest.mark.parametrize("second", [True, False])
def test_lane_point_is_the_lane_centre_and_the_lane_at_its_t(second: bool) -> None:
    """`motion.lane_point` (one look-up of the lane table for a body's state) gives to the bit what
    `lane_center_t` + offset and `lane_at_t` at that t give, with the tables on and off, and raises where
    they raise."""
    from simcore.scenario.motion import lane_at_t, lane_point

    def answers(od: OpenDrive, use: str) -> list[str]:
        out = []
        for s in [k * 0.37 for k in range(325)] + [-0.0005, -0.0, 0.0, 59.999999999, 60.0, 120.0, 120.0005]:
            for lane_id in (-3, -2, -1, 0, 1):
                for offset in (0.0, -0.0, 0.4, -2.1, 5.0, math.nan):
                    try:
                        if use == "fused":
                            out.append(repr(lane_point(od, "1", lane_id, s, offset)))
                        else:
                            t = od.lane_center_t("1", lane_id, s) + offset
                            out.append(repr((t, *lane_at_t(od, "1", s, t))))
                    except OpenDriveError as e:
                        out.append(str(e))
        return out

    fast = _two_section_road("", second=second)
    slow = _two_section_road("", second=second)
    slow.roads["1"]._crosses = [None] * (len(slow.roads["1"]._cross_starts) + 1)
    expected = answers(fast, "two calls")
    assert answers(fast, "fused") == expected and answers(slow, "fused") == expected
    assert answers(slow, "two calls") == expected


def test_a_newton_step_on_a_straight_record_is_its_along_track_error() -> None:
    """`_project` steps by the along-track error on a line (no curvature asked): what the general step
    gives there, to the bit."""
    from simcore.world.road_geometry import Line

    class Bent(Line):  # a line taken for a curve: the general Newton step
        straight = False

    od = _two_section_road("")
    general = _two_section_road("")
    road = general.roads["1"]
    road.geometries[0] = bent = Bent(0.0, 0.0, 0.0, 0.2, 40.0)
    road._gspans[0] = (bent, *road._gspans[0][1:])
    assert od.roads["1"].geometries[0].straight and not bent.straight
    for s0 in (0.0, 3.0, 17.5, 39.0, 41.0):
        for s, t in ((5.0, -2.0), (20.0, 3.3), (38.5, -7.0), (0.0, 0.1), (45.0, 1.0)):
            x, y, _, _ = od.road_xyzh("1", s, t)
            for px, py in ((x, y), (x + 1e-7, y), (x + 1e5, y), (x, math.inf), (math.nan, y)):
                assert repr(od._project(od.roads["1"], px, py, s0, 2.0)) == repr(
                    general._project(road, px, py, s0, 2.0)
                ), (s0, s, t, px, py)


def test_fresnel_small_arguments_are_the_polynomials_by_horner_loops() -> None:
    """The small-argument Fresnel branch (every road spiral's) is `_polevl`/`_p1evl` written out: the same
    floats to the bit, signs of zero included."""
    import random

    from simcore.world import road_geometry as rg

    def looped(xxa: float) -> tuple[float, float]:
        x = abs(xxa)
        x2 = x * x
        t = x2 * x2
        ss = x * x2 * rg._polevl(t, rg._FRESNEL_SN) / rg._p1evl(t, rg._FRESNEL_SD)
        cc = x * rg._polevl(t, rg._FRESNEL_CN) / rg._polevl(t, rg._FRESNEL_CD)
        return (-ss, -cc) if xxa < 0.0 else (ss, cc)

    rng = random.Random(5)
    xs = [rng.uniform(-1.6, 1.6) for _ in range(20000)] + [10 ** rng.uniform(-300, 0.2) for _ in range(2000)]
    for x in [*xs, 0.0, -0.0, 1.6, -1.6, 5e-324, -5e-324]:
        assert repr(rg._fresnel(x)) == repr(looped(x)), x
