"""Pure-Python OpenDRIVE (1.4–1.7) road geometry.

Parses the road network of an ``.xodr`` file (planView geometry, elevation, lane offsets, lane sections,
lanes and their widths, road and lane links, junctions) and answers the geometric questions a scenario
engine needs: road/lane coordinates to world poses, world points back to road coordinates, lane topology
(what lane follows the end of a lane) and sampled lane borders for later triangulation.

Supported planView geometries: ``line``, ``arc``, ``spiral`` (clothoid, via Fresnel integrals, any
curvStart/curvEnd), ``poly3`` and ``paramPoly3`` (``pRange`` ``arcLength`` or ``normalized``). For
``poly3`` and ``paramPoly3`` the road ``s`` is mapped to the curve parameter through a numerically
integrated arc-length table, so ``s`` is a true arc length along the curve.

Deliberately not modelled (documented limitations):

* ``lateralProfile``: ``superelevation`` is applied as a roll of the whole cross section about the reference
  line (``t`` is measured in the tilted plane: horizontal offset ``t*cos(roll)``, height ``t*sin(roll)``,
  as esmini does); ``crossfall`` and ``shape`` are ignored. Pose headings never include pitch or roll.
* Lane ``height`` records, road marks, objects, signals and the header ``geoReference``/``offset`` are ignored.
* Lane ``border`` records are used only for lanes without ``width`` records; the border polynomial is taken
  as the outer border's distance from the centre lane (laneOffset-shifted reference line).

XML is parsed with :mod:`defusedxml` (files are untrusted), files over 64 MiB are refused, and every
problem in the input is reported as :class:`OpenDriveError` naming the file and the element.
"""

from __future__ import annotations

import bisect
import hashlib
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any
from xml.etree.ElementTree import Element

import defusedxml.ElementTree as DET
from defusedxml import DefusedXmlException

from simcore.world.frozen import builder

if TYPE_CHECKING:  # numpy is imported only where arrays are built (sample_lane_boundaries)
    import numpy as np

__all__ = [
    "MAX_FILE_BYTES",
    "Geometry",
    "Junction",
    "JunctionConnection",
    "Lane",
    "LaneBoundary",
    "LaneSection",
    "OpenDrive",
    "OpenDriveError",
    "Poly3",
    "Pose",
    "Road",
    "RoadCoordinates",
    "RoadLink",
]

MAX_FILE_BYTES = 64 * 1024 * 1024
"""Files (and strings) larger than this are refused."""

#: networks `OpenDrive.shared` keeps per process, by file name and content (the most recently used ones)
_SHARED_MAX = 4
_SHARED: dict[tuple[str, bytes], OpenDrive] = {}

MAX_GEOMETRIES = 100_000
"""planView geometry records per file; more are refused before parsing (netconvert would take minutes and
gigabytes on them, then silently make an empty network). Large real maps have a few ten thousand."""

DRIVING_LANE_TYPES = frozenset(
    {"driving", "entry", "exit", "onramp", "offramp", "connectingramp", "bidirectional", "sliplane"}
)
"""Lane types (lower case) counted as drivable by ``lane_ids(..., driving_only=True)``."""

_S_TOL = 1e-3  # m: s values this far outside [0, length] are clamped silently


class PointGrid:
    """Points in square cells of side `cell`, for `query_ball_point(p, r)` with r <= cell: the indices of
    the points within r of p, ascending (the set scipy's cKDTree finds; this index costs no scipy import,
    whose load outweighs a whole run on a small road, and no numpy import: a query looks at a few dozen
    points, which plain Python does faster than numpy's per-call overhead)."""

    def __init__(self, data: Sequence[Sequence[float]], cell: float) -> None:
        self.xs: list[float] = [float(p[0]) for p in data]
        self.ys: list[float] = [float(p[1]) for p in data]
        self.cell = max(cell, 1e-9)
        buckets: dict[tuple[int, int], list[int]] = {}
        c = self.cell
        for i, (x, y) in enumerate(zip(self.xs, self.ys, strict=True)):
            buckets.setdefault((math.floor(x / c), math.floor(y / c)), []).append(i)
        self._buckets = buckets

    def query_ball_point(self, point: Sequence[float], r: float) -> list[int]:
        x, y = float(point[0]), float(point[1])
        span = max(1, math.ceil(r / self.cell))
        kx, ky = math.floor(x / self.cell), math.floor(y / self.cell)
        xs, ys, r2 = self.xs, self.ys, r * r
        near = [
            i
            for gx in range(kx - span, kx + span + 1)
            for gy in range(ky - span, ky + span + 1)
            for i in self._buckets.get((gx, gy), ())
            if (xs[i] - x) ** 2 + (ys[i] - y) ** 2 <= r2
        ]
        near.sort()
        return near


def _linspace(start: float, stop: float, num: int) -> list[float]:
    """``num`` evenly spaced values from `start` to `stop` inclusive, the same floats as ``numpy.linspace``
    (``start + i * step``, the last value exactly `stop`)."""
    if num <= 0:
        return []
    if num == 1:
        return [float(start)]
    div = num - 1
    delta = stop - start
    step = delta / div
    if step == 0:
        out = [i / div * delta + start for i in range(num)]
    else:
        out = [i * step + start for i in range(num)]
    out[-1] = float(stop)
    return out


def _read_bounded(p: Path) -> bytes:
    """The bytes of the road file `p`, refused (OpenDriveError) if unreadable or larger than 64 MiB."""
    try:
        size = p.stat().st_size
    except OSError as e:
        raise OpenDriveError(f"{p}: cannot read: {e.strerror or e}") from None
    if size > MAX_FILE_BYTES:
        raise OpenDriveError(f"{p}: file is {size} bytes, larger than the {MAX_FILE_BYTES} byte limit")
    with p.open("rb") as fh:
        data = fh.read(MAX_FILE_BYTES + 1)
    if len(data) > MAX_FILE_BYTES:
        raise OpenDriveError(f"{p}: file is larger than the {MAX_FILE_BYTES} byte limit")
    return data


class OpenDriveError(ValueError):
    """A malformed, unsupported or unsafe OpenDRIVE input, or a query on something the file does not have."""


@dataclass(frozen=True)
class Pose:
    """A world pose. ``heading`` in rad, counter-clockwise from +x."""

    x: float
    y: float
    z: float
    heading: float


@dataclass(frozen=True)
class RoadCoordinates:
    """A position in road coordinates.

    ``offset`` is ``t`` minus the lane-centre ``t``; ``heading`` is the reference-line heading at ``s``.
    """

    road_id: str
    lane_id: int
    s: float
    t: float
    offset: float
    heading: float


_road_coordinates = builder(RoadCoordinates)  # RoadCoordinates(...), built as fast as a plain object


@dataclass(frozen=True)
class Poly3:
    """``a + b*ds + c*ds**2 + d*ds**3`` with ``ds = s - s0`` (``s0`` is ``s`` or ``sOffset`` in the file)."""

    s0: float
    a: float
    b: float
    c: float
    d: float

    def value(self, s: float) -> float:
        """The polynomial at ``s`` (absolute in the same frame as ``s0``)."""
        ds = s - self.s0
        return self.a + ds * (self.b + ds * (self.c + ds * self.d))

    def slope(self, s: float) -> float:
        """The first derivative at ``s``."""
        ds = s - self.s0
        return self.b + ds * (2.0 * self.c + ds * 3.0 * self.d)


def _constant(p: Poly3) -> bool:
    """Does the polynomial give the same number (``a``) at every ``s``? (``a + ds·(0 + ds·(0 + ds·0))`` is
    ``a`` for every finite ``ds``, unless ``a`` is -0.0.)"""
    return (
        p.b == 0.0
        and p.c == 0.0
        and p.d == 0.0
        and math.isfinite(p.a)
        and (p.a != 0.0 or math.copysign(1.0, p.a) > 0)
    )


def _fixed_value(polys: Sequence[Poly3]) -> float | None:
    """The value `_poly_at(polys, ...).value(s)` gives at every ``s`` (0.0 without records) when it is one
    number (no or one record, `_constant`), else None."""
    if not polys:
        return 0.0
    if len(polys) == 1 and _constant(polys[0]):
        return polys[0].a
    return None


def _poly_at(polys: Sequence[Poly3], starts: Sequence[float], s: float) -> Poly3 | None:
    """The record in effect at ``s`` (the last one starting at or before ``s``; the first one before it)."""
    if not polys:
        return None
    i = bisect.bisect_right(starts, s + 1e-12) - 1
    return polys[i if i > 0 else 0]


# --------------------------------------------------------------------------------------------------- geometry


class Geometry:
    """One planView geometry record. ``local(ds)`` gives ``(x, y, heading)`` at ``ds`` in ``[0, length]``."""

    kind = "geometry"
    #: zero curvature at every ``ds`` (`curvature` gives 0.0): a Newton step on it is the along-track error
    straight = False

    def __init__(self, s: float, x: float, y: float, hdg: float, length: float) -> None:
        self.s = s
        self.x = x
        self.y = y
        self.hdg = hdg
        self.length = length

    def local(self, ds: float) -> tuple[float, float, float]:
        """World ``(x, y, heading)`` at distance ``ds`` from the start of this geometry."""
        raise NotImplementedError

    def frame(self, ds: float) -> tuple[float, float, float, float, float]:
        """`local` with the heading's cosine and sine: ``(x, y, heading, cos, sin)``."""
        x, y, h = self.local(ds)
        return x, y, h, math.cos(h), math.sin(h)

    def curvature(self, ds: float) -> float:
        """Signed curvature (1/m, positive turns left) at ``ds``."""
        raise NotImplementedError


class Line(Geometry):
    """A straight line."""

    kind = "line"
    straight = True

    def __init__(self, s: float, x: float, y: float, hdg: float, length: float) -> None:
        super().__init__(s, x, y, hdg, length)
        self._cos, self._sin = math.cos(hdg), math.sin(hdg)  # of the constant heading, once

    def local(self, ds: float) -> tuple[float, float, float]:
        return self.x + ds * self._cos, self.y + ds * self._sin, self.hdg

    def frame(self, ds: float) -> tuple[float, float, float, float, float]:
        c, s = self._cos, self._sin  # cos and sin of the heading local gives, computed once
        return self.x + ds * c, self.y + ds * s, self.hdg, c, s

    def curvature(self, ds: float) -> float:
        return 0.0


class Arc(Geometry):
    """A circular arc of constant curvature."""

    kind = "arc"

    def __init__(self, s: float, x: float, y: float, hdg: float, length: float, k: float) -> None:
        super().__init__(s, x, y, hdg, length)
        self.k = k
        self._cos, self._sin = math.cos(hdg), math.sin(hdg)  # of the start heading, once

    def local(self, ds: float) -> tuple[float, float, float]:
        k = self.k
        h = self.hdg + k * ds
        if abs(k) < 1e-12:
            return self.x + ds * self._cos, self.y + ds * self._sin, h
        return (
            self.x + (math.sin(h) - self._sin) / k,
            self.y - (math.cos(h) - self._cos) / k,
            h,
        )

    def curvature(self, ds: float) -> float:
        return self.k


# Gauss-Legendre nodes and weights on [-1, 1], as numpy.polynomial.legendre.leggauss(n) gives them (written
# out: computing them would import numpy; tests/test_opendrive.py checks they are numpy's)
_GL16_X = (
    -0.9894009349916499, -0.9445750230732326, -0.8656312023878318, -0.755404408355003,
    -0.6178762444026438, -0.45801677765722737, -0.2816035507792589, -0.09501250983763744,
    0.09501250983763744, 0.2816035507792589, 0.45801677765722737, 0.6178762444026438,
    0.755404408355003, 0.8656312023878318, 0.9445750230732326, 0.9894009349916499,
)  # fmt: skip
_GL16_W = (
    0.027152459411754176, 0.062253523938647456, 0.0951585116824926, 0.12462897125553407,
    0.1495959888165767, 0.16915651939500265, 0.18260341504492364, 0.18945061045506864,
    0.18945061045506864, 0.18260341504492364, 0.16915651939500265, 0.1495959888165767,
    0.12462897125553407, 0.0951585116824926, 0.062253523938647456, 0.027152459411754176,
)  # fmt: skip
_GL16 = tuple(zip(_GL16_X, _GL16_W, strict=True))


# Fresnel integrals (Cephes ``fresnl``, as scipy.special.fresnel evaluates them: the same rational
# approximations in the same operation order, so the same floats, without scipy's and numpy's import)
_FRESNEL_SN = (
    -2.99181919401019853726e3, 7.08840045257738576863e5, -6.29741486205862506537e7,
    2.54890880573376359104e9, -4.42979518059697779103e10, 3.18016297876567817986e11,
)  # fmt: skip
_FRESNEL_SD = (
    2.81376268889994315696e2, 4.55847810806532581675e4, 5.17343888770096400730e6,
    4.19320245898111231129e8, 2.24411795645340920940e10, 6.07366389490084639049e11,
)  # fmt: skip
_FRESNEL_CN = (
    -4.98843114573573548651e-8, 9.50428062829859605134e-6, -6.45191435683965050962e-4,
    1.88843319396703850064e-2, -2.05525900955013891793e-1, 9.99999999999999998822e-1,
)  # fmt: skip
_FRESNEL_CD = (
    3.99982968972495980367e-12, 9.15439215774657478799e-10, 1.25001862479598821474e-7,
    1.22262789024179030997e-5, 8.68029542941784300606e-4, 4.12142090722199792936e-2,
    1.00000000000000000118e0,
)  # fmt: skip
_FRESNEL_FN = (
    4.21543555043677546506e-1, 1.43407919780758885261e-1, 1.15220955073585758835e-2,
    3.45017939782574027900e-4, 4.63613749287867322088e-6, 3.05568983790257605827e-8,
    1.02304514164907233465e-10, 1.72010743268161828879e-13, 1.34283276233062758925e-16,
    3.76329711269987889006e-20,
)  # fmt: skip
_FRESNEL_FD = (
    7.51586398353378947175e-1, 1.16888925859191382142e-1, 6.44051526508858611005e-3,
    1.55934409164153020873e-4, 1.84627567348930545870e-6, 1.12699224763999035261e-8,
    3.60140029589371370404e-11, 5.88754533621578410010e-14, 4.52001434074129701496e-17,
    1.25443237090011264384e-20,
)  # fmt: skip
_FRESNEL_GN = (
    5.04442073643383265887e-1, 1.97102833525523411709e-1, 1.87648584092575249293e-2,
    6.84079380915393090172e-4, 1.15138826111884280931e-5, 9.82852443688422223854e-8,
    4.45344415861750144738e-10, 1.08268041139020870318e-12, 1.37555460633261799868e-15,
    8.36354435630677421531e-19, 1.86958710162783235106e-22,
)  # fmt: skip
_FRESNEL_GD = (
    1.47495759925128324529e0, 3.37748989120019970451e-1, 2.53603741420338795122e-2,
    8.14679107184306179049e-4, 1.27545075667729118702e-5, 1.04314589657571990585e-7,
    4.60680728146520428211e-10, 1.10273215066240270757e-12, 1.38796531259578871258e-15,
    8.39158816283118707363e-19, 1.86958710162783236342e-22,
)  # fmt: skip


def _polevl(x: float, coef: tuple[float, ...]) -> float:
    """``coef[0] * x**N + ... + coef[N]`` by Horner's rule."""
    ans = coef[0]
    for c in coef[1:]:
        ans = ans * x + c
    return ans


def _p1evl(x: float, coef: tuple[float, ...]) -> float:
    """As `_polevl` with a leading coefficient 1 not stored in `coef`."""
    ans = x + coef[0]
    for c in coef[1:]:
        ans = ans * x + c
    return ans


def _sinpi(x: float) -> float:
    s = 1.0
    if math.copysign(1.0, x) < 0:
        x, s = -x, -1.0
    r = math.fmod(x, 2.0)
    if r < 0.5:
        return s * math.sin(math.pi * r)
    if r > 1.5:
        return s * math.sin(math.pi * (r - 2.0))
    return -s * math.sin(math.pi * (r - 1.0))


def _cospi(x: float) -> float:
    r = math.fmod(abs(x), 2.0)
    if r == 0.5:
        return 0.0
    if r < 1.0:
        return -math.sin(math.pi * (r - 0.5))
    return math.sin(math.pi * (r - 1.5))


def _fresnel(xxa: float) -> tuple[float, float]:
    """The Fresnel integrals ``(S(x), C(x))`` of ``sin`` and ``cos(pi/2 t**2)`` from 0 to `xxa`."""
    if math.isinf(xxa):
        cc = ss = 0.5
    else:
        x = abs(xxa)
        x2 = x * x
        if x2 < 2.5625:  # every spiral of a road's size: `_polevl`/`_p1evl` written out (the same operations)
            t = x2 * x2
            sn0, sn1, sn2, sn3, sn4, sn5 = _FRESNEL_SN
            sd0, sd1, sd2, sd3, sd4, sd5 = _FRESNEL_SD
            cn0, cn1, cn2, cn3, cn4, cn5 = _FRESNEL_CN
            cd0, cd1, cd2, cd3, cd4, cd5, cd6 = _FRESNEL_CD
            sn = ((((sn0 * t + sn1) * t + sn2) * t + sn3) * t + sn4) * t + sn5
            sd = ((((t + sd0) * t + sd1) * t + sd2) * t + sd3) * t + sd4
            sd = sd * t + sd5
            cn = ((((cn0 * t + cn1) * t + cn2) * t + cn3) * t + cn4) * t + cn5
            cd = (((((cd0 * t + cd1) * t + cd2) * t + cd3) * t + cd4) * t + cd5) * t + cd6
            ss = x * x2 * sn / sd
            cc = x * cn / cd
        elif x > 36974.0:
            cc = 0.5 + 1 / (math.pi * x) * _sinpi(x * x / 2)
            ss = 0.5 - 1 / (math.pi * x) * _cospi(x * x / 2)
        else:
            t = math.pi * x2
            u = 1.0 / (t * t)
            t = 1.0 / t
            f = 1.0 - u * _polevl(u, _FRESNEL_FN) / _p1evl(u, _FRESNEL_FD)
            g = t * _polevl(u, _FRESNEL_GN) / _p1evl(u, _FRESNEL_GD)
            c = _cospi(x2 / 2)
            s = _sinpi(x2 / 2)
            t = math.pi * x
            cc = 0.5 + (f * s - g * c) / t
            ss = 0.5 - (f * c + g * s) / t
    if xxa < 0.0:
        cc, ss = -cc, -ss
    return ss, cc


class Spiral(Geometry):
    """A clothoid whose curvature changes linearly from ``k0`` to ``k1`` over its length.

    Evaluated on the standard clothoid ``k(u) = c*u`` (``c = (k1-k0)/length``) between ``u0 = k0/c`` and
    ``u0 + length`` using Fresnel integrals, then shifted and rotated onto the record's start pose.
    """

    kind = "spiral"

    def __init__(self, s: float, x: float, y: float, hdg: float, length: float, k0: float, k1: float) -> None:
        super().__init__(s, x, y, hdg, length)
        self.k0 = k0
        self.k1 = k1
        self.c = (k1 - k0) / length if length > 0 else 0.0
        self._cos, self._sin = math.cos(hdg), math.sin(hdg)  # of the start heading, once
        # a clothoid with negligible curvature change over the record is an arc to double precision
        self._as_arc = abs(self.c) * max(length, 1.0) ** 3 < 1e-9 or abs(self.c) < 1e-15
        # for tiny curvature change (huge standard-clothoid scale) the Fresnel difference loses digits:
        # integrate the exact heading polynomial numerically instead
        self._numeric = not self._as_arc and abs(self.c) < 1e-6
        if not self._as_arc and not self._numeric:
            self._scale = math.sqrt(math.pi / abs(self.c))
            self._sign = 1.0 if self.c > 0 else -1.0
            self._u0 = k0 / self.c
            self._x0, self._y0 = self._std(self._u0)
            self._th0 = 0.5 * self.c * self._u0 * self._u0
            self._cos0 = math.cos(self._th0)
            self._sin0 = math.sin(self._th0)

    def _std(self, u: float) -> tuple[float, float]:
        sf, cf = _fresnel(u / self._scale)
        return self._scale * cf, self._sign * self._scale * sf

    def local(self, ds: float) -> tuple[float, float, float]:
        h = self.hdg + self.k0 * ds + 0.5 * self.c * ds * ds
        if self._as_arc:
            k = self.k0 + 0.5 * self.c * ds  # mean curvature: exact heading, position to < 1e-9 m
            if abs(k) < 1e-12:
                return self.x + ds * self._cos, self.y + ds * self._sin, h
            return (
                self.x + (math.sin(self.hdg + k * ds) - self._sin) / k,
                self.y - (math.cos(self.hdg + k * ds) - self._cos) / k,
                h,
            )
        if self._numeric:
            return (*self._integrate(ds), h)
        xs, ys = self._std(self._u0 + ds)
        dx, dy = xs - self._x0, ys - self._y0
        # rotate out the standard clothoid's heading at u0, then into the record's start heading
        lx = dx * self._cos0 + dy * self._sin0
        ly = -dx * self._sin0 + dy * self._cos0
        ch, sh = self._cos, self._sin
        return self.x + lx * ch - ly * sh, self.y + lx * sh + ly * ch, h

    def _integrate(self, ds: float) -> tuple[float, float]:
        """Composite Gauss-Legendre integration of (cos, sin)(heading) from 0 to ``ds``."""
        turn = max(abs(self.k0), abs(self.k0 + self.c * ds)) * abs(ds)
        n = max(1, math.ceil(turn / 0.25), math.ceil(abs(ds) / 100.0))
        edges = _linspace(0.0, ds, n + 1)
        hdg, k0, hc = self.hdg, self.k0, 0.5 * self.c
        sx = sy = 0.0
        for a, b in itertools.pairwise(edges):
            half = 0.5 * (b - a)
            mid = 0.5 * (b + a)
            cx = cy = 0.0
            for node, w in _GL16:
                u = mid + half * node
                h = hdg + k0 * u + hc * u * u
                cx += math.cos(h) * w
                cy += math.sin(h) * w
            sx += half * cx
            sy += half * cy
        return self.x + sx, self.y + sy

    def curvature(self, ds: float) -> float:
        return self.k0 + self.c * ds


_GL_X = (
    -0.9324695142031519, -0.6612093864662645, -0.2386191860831969,
    0.2386191860831969, 0.6612093864662645, 0.9324695142031519,
)  # fmt: skip
_GL_W = (
    0.17132449237917027, 0.3607615730481387, 0.46791393457269104,
    0.46791393457269104, 0.3607615730481387, 0.17132449237917027,
)  # fmt: skip


class ParamPoly3(Geometry):
    """A parametric cubic ``u(p), v(p)`` in the record's local frame (also used for ``poly3``, with ``u = p``).

    ``s`` is mapped to ``p`` through a table of the numerically integrated arc length, scaled so that the
    table's total equals the record's ``length``.
    """

    kind = "paramPoly3"

    def __init__(
        self,
        s: float,
        x: float,
        y: float,
        hdg: float,
        length: float,
        u: tuple[float, float, float, float],
        v: tuple[float, float, float, float],
        p_max: float | None,
    ) -> None:
        super().__init__(s, x, y, hdg, length)
        self.u = u
        self.v = v
        self._cos = math.cos(hdg)
        self._sin = math.sin(hdg)
        if p_max is None:  # poly3: find the u at which the arc length reaches ``length``
            lo, hi = 0.0, max(length, 1e-9)
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if self._arclen(_linspace(0.0, mid, 65))[-1] < length:
                    lo = mid
                else:
                    hi = mid
            p_max = 0.5 * (lo + hi)
        self.p_max = p_max
        n = int(min(max(64, math.ceil(length / 0.2)), 20000))
        ps = _linspace(0.0, p_max, n + 1)
        cum = self._arclen(ps)
        total = cum[-1]
        if total > 0:
            scale = length / total
            cum = [c * scale for c in cum]
        self._ps: list[float] = ps
        self._ss: list[float] = cum
        self._last: tuple[float, tuple[float, float, float, float, float, float]] = (math.nan, (0.0,) * 6)

    def _arclen(self, ps: list[float]) -> list[float]:
        """Cumulative arc length at the grid ``ps`` (6-point Gauss-Legendre on each interval)."""
        _, bu, cu, du = self.u
        _, bv, cv, dv = self.v
        cu2, du3, cv2, dv3 = 2 * cu, 3 * du, 2 * cv, 3 * dv
        x0, x1, x2, x3, x4, x5 = _GL_X
        w0, w1, w2, w3, w4, w5 = _GL_W
        hypot = math.hypot
        out = [0.0]
        total = 0.0
        for a, b in itertools.pairwise(ps):
            half = 0.5 * (b - a)
            mid = 0.5 * (a + b)
            p0, p1, p2 = mid + half * x0, mid + half * x1, mid + half * x2
            p3, p4, p5 = mid + half * x3, mid + half * x4, mid + half * x5
            total += half * (
                hypot(bu + p0 * (cu2 + du3 * p0), bv + p0 * (cv2 + dv3 * p0)) * w0
                + hypot(bu + p1 * (cu2 + du3 * p1), bv + p1 * (cv2 + dv3 * p1)) * w1
                + hypot(bu + p2 * (cu2 + du3 * p2), bv + p2 * (cv2 + dv3 * p2)) * w2
                + hypot(bu + p3 * (cu2 + du3 * p3), bv + p3 * (cv2 + dv3 * p3)) * w3
                + hypot(bu + p4 * (cu2 + du3 * p4), bv + p4 * (cv2 + dv3 * p4)) * w4
                + hypot(bu + p5 * (cu2 + du3 * p5), bv + p5 * (cv2 + dv3 * p5)) * w5
            )
            out.append(total)
        return out

    def _p_of(self, ds: float) -> float:
        ss, ps = self._ss, self._ps
        i = bisect.bisect_right(ss, ds) - 1
        i = min(max(i, 0), len(ss) - 2)
        s0, s1 = ss[i], ss[i + 1]
        f = (ds - s0) / (s1 - s0) if s1 > s0 else 0.0
        return ps[i] + f * (ps[i + 1] - ps[i])

    def _uv_at(self, ds: float) -> tuple[float, float, float, float, float, float]:
        """`_uv` at the parameter of ``ds``; the last one kept (a projection asks for the point and then the
        curvature at the same ``ds``): one ``(ds, uv)`` tuple, replaced whole."""
        last = self._last
        if last[0] == ds:
            return last[1]
        uv = self._uv(self._p_of(ds))
        self._last = (ds, uv)
        return uv

    def _uv(self, p: float) -> tuple[float, float, float, float, float, float]:
        au, bu, cu, du = self.u
        av, bv, cv, dv = self.v
        u = au + p * (bu + p * (cu + p * du))
        v = av + p * (bv + p * (cv + p * dv))
        up = bu + p * (2 * cu + 3 * du * p)
        vp = bv + p * (2 * cv + 3 * dv * p)
        upp = 2 * cu + 6 * du * p
        vpp = 2 * cv + 6 * dv * p
        return u, v, up, vp, upp, vpp

    def local(self, ds: float) -> tuple[float, float, float]:
        u, v, up, vp, _, _ = self._uv_at(ds)
        return (
            self.x + u * self._cos - v * self._sin,
            self.y + u * self._sin + v * self._cos,
            self.hdg + math.atan2(vp, up),
        )

    def curvature(self, ds: float) -> float:
        _, _, up, vp, upp, vpp = self._uv_at(ds)
        sp = math.hypot(up, vp)
        return 0.0 if sp == 0 else (up * vpp - vp * upp) / sp**3


# ------------------------------------------------------------------------------------------------ road model


@dataclass(frozen=True)
class RoadLink:
    """A road's predecessor or successor: ``element_type`` is ``"road"`` or ``"junction"``."""

    element_type: str
    element_id: str
    contact_point: str | None  # "start" / "end" for roads, None for junctions


@dataclass
class Lane:
    """One lane of a lane section."""

    id: int
    type: str
    widths: list[Poly3] = field(default_factory=list)  # s0 = sOffset (relative to the section start)
    borders: list[Poly3] = field(default_factory=list)
    predecessor: int | None = None
    successor: int | None = None
    level: bool = False

    def __post_init__(self) -> None:
        self.widths.sort(key=lambda p: p.s0)
        self.borders.sort(key=lambda p: p.s0)
        self._wstarts = [p.s0 for p in self.widths]
        self._bstarts = [p.s0 for p in self.borders]

    def width_at(self, ds: float) -> float:
        """The width at ``ds`` from the section start (0 for the centre lane and lanes without widths)."""
        widths = self.widths
        if not widths:
            return 0.0
        if len(widths) == 1:  # the common case: one record, in effect before its start too
            p = widths[0]
        else:
            i = bisect.bisect_right(self._wstarts, ds + 1e-12) - 1
            p = widths[i if i > 0 else 0]
        d = ds - p.s0  # Poly3.value, inline (a hot path of every step)
        return p.a + d * (p.b + d * (p.c + d * p.d))

    def border_at(self, ds: float) -> float | None:
        """The ``border`` record value at ``ds`` (only used for lanes without widths)."""
        p = _poly_at(self.borders, self._bstarts, ds)
        return None if p is None else p.value(ds)


@dataclass
class LaneSection:
    """A lane section starting at ``s`` (ending at ``end``). ``left`` ids 1, 2, ...; ``right`` -1, -2, ..."""

    s: float
    end: float
    left: list[Lane]
    right: list[Lane]
    center: Lane | None
    single_side: bool = False

    def lane(self, lane_id: int) -> Lane | None:
        """The lane with ``lane_id`` in this section, or None."""
        if lane_id == 0:
            return self.center
        side = self.left if lane_id > 0 else self.right
        for lane in side:
            if lane.id == lane_id:
                return lane
        return None


class LaneCross:
    """The lane borders across a stretch of a road where they do not change with ``s`` (the same lane
    section on each side, each with constant widths and a constant or no laneOffset), and the look-ups that
    the per-step queries make on them, derived once (the same floats the per-``s`` loops compute)."""

    __slots__ = ("around", "borders", "centres", "driving_ids", "ids", "inside")

    def __init__(self, right: list[tuple[Lane, float, float]], left: list[tuple[Lane, float, float]]) -> None:
        #: every non-centre lane's ``(lane, t_inner, t_outer)``, right side first (`Road.all_borders`)
        self.borders = right + left
        #: lane id -> ``t`` of its centre (`OpenDrive.lane_center_t`: the first lane of that id on its side)
        self.centres: dict[int, float] = {}
        for side, borders in ((-1, right), (1, left)):
            for lane, inner, outer in borders:
                if lane.id != 0 and (lane.id > 0) == (side > 0) and lane.id not in self.centres:
                    self.centres[lane.id] = 0.5 * (inner + outer)
        #: ``(lane id, t_low, t_high, t_centre)`` of the lanes wider than 1e-9, in `borders` order
        self.inside: tuple[tuple[int, float, float, float], ...] = tuple(
            (lane.id, min(inner, outer), max(inner, outer), 0.5 * (inner + outer))
            for lane, inner, outer in self.borders
            if abs(outer - inner) > 1e-9
        )
        #: the same for lanes (not 0) of any width but zero, their ``t`` range widened by 1e-9 each way
        self.around: tuple[tuple[int, float, float, float], ...] = tuple(
            (lane.id, lo - 1e-9, hi + 1e-9, 0.5 * (inner + outer))
            for lane, inner, outer in self.borders
            if lane.id != 0 and inner != outer
            for lo, hi in ((inner, outer) if inner < outer else (outer, inner),)
        )
        #: `OpenDrive.lane_ids`: the lanes of positive width, ascending; the drivable ones among them
        wide = [(lane.id, lane.type) for lane, inner, outer in self.borders if not abs(outer - inner) <= 1e-9]
        self.ids: tuple[int, ...] = tuple(sorted(lane_id for lane_id, _ in wide))
        self.driving_ids: tuple[int, ...] = tuple(
            sorted(lane_id for lane_id, kind in wide if kind.lower() in DRIVING_LANE_TYPES)
        )

    def lane_at(self, t: float) -> tuple[int, float]:
        """The lane containing lateral position ``t`` (else the one with the closest centre) and the offset
        from its centre: `simcore.scenario.motion.lane_at_t` on this stretch of road."""
        best_lane, best_offset, best = 0, t, math.inf
        for lane_id, lo, hi, centre in self.around:
            if lo <= t <= hi:
                return lane_id, t - centre
            if abs(t - centre) < best:
                best, best_lane, best_offset = abs(t - centre), lane_id, t - centre
        return best_lane, best_offset


@dataclass
class Road:
    """One ``<road>``: reference line, elevation, lane offset, lane sections and links."""

    id: str
    name: str
    length: float
    junction: str
    geometries: list[Geometry]
    elevations: list[Poly3]
    lane_offsets: list[Poly3]
    lane_sections: list[LaneSection]
    predecessor: RoadLink | None = None
    successor: RoadLink | None = None
    superelevations: list[Poly3] = field(default_factory=list)
    rule: str = "RHT"  # traffic rule: RHT (right-hand traffic) or LHT
    speeds: list[tuple[float, float]] = field(default_factory=list)  # (s, max m/s) of <type><speed>

    def speed_limit(self, s: float) -> float | None:
        """The road type's speed limit at ``s`` (m/s), None where no <type> record gives one."""
        value = None
        for start, limit in self.speeds:
            if start <= s + 1e-9:
                value = limit
        return value

    def __post_init__(self) -> None:
        self._gstarts = [g.s for g in self.geometries]
        self._estarts = [p.s0 for p in self.elevations]
        self._ostarts = [p.s0 for p in self.lane_offsets]
        self._rstarts = [p.s0 for p in self.superelevations]
        # per side: the sections defining that side (a singleSide section only defines the side it has)
        self._side_sections: dict[int, list[LaneSection]] = {}
        for side in (1, -1):
            secs = [
                sec
                for sec in self.lane_sections
                if not sec.single_side or (sec.left if side > 0 else sec.right)
            ]
            self._side_sections[side] = secs or list(self.lane_sections)
        self._side_starts = {k: [sec.s for sec in v] for k, v in self._side_sections.items()}
        # the planView record `geometry_at` gives for each s in [lo, hi)
        n = len(self.geometries)
        self._gspans = [
            (g, self._gstarts[i] if i > 0 else -math.inf, self._gstarts[i + 1] if i + 1 < n else math.inf)
            for i, g in enumerate(self.geometries)
        ]
        # elevation and laneOffset where one record gives the same number at every s (else None)
        self._z_fixed = _fixed_value(self.elevations)
        self._offset_fixed = _fixed_value(self.lane_offsets)
        # where both sides' lane sections change (`cross_at`); the crosses themselves are built on first use
        self._cross_starts = sorted(set(self._side_starts[1]) | set(self._side_starts[-1]))
        self._crosses: list[LaneCross | None] | None = None
        self._uniform: LaneCross | None = None  # the cross of every s, where there is one

    # -- reference line
    def geometry_at(self, s: float) -> Geometry:
        """The planView record containing ``s``."""
        i = bisect.bisect_right(self._gstarts, s) - 1
        geometries = self.geometries
        return geometries[0 if i < 0 else i if i < len(geometries) else len(geometries) - 1]

    def geometry_span(self, s: float) -> tuple[Geometry, float, float]:
        """``(record, lo, hi)``: the planView record `geometry_at` gives at ``s``, and the range ``[lo, hi)``
        of every ``s`` it gives that record for (a caller moving along the road asks again only on leaving it)."""
        i = bisect.bisect_right(self._gstarts, s) - 1
        return self._gspans[i if i > 0 else 0]

    def reference_xyh(self, s: float) -> tuple[float, float, float]:
        """``(x, y, heading)`` of the reference line at ``s``."""
        i = bisect.bisect_right(self._gstarts, s) - 1  # as geometry_at (inline: every step)
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        return g.local(ds if ds >= 0.0 else 0.0)

    def curvature(self, s: float) -> float:
        """Reference-line curvature at ``s``."""
        i = bisect.bisect_right(self._gstarts, s) - 1  # as geometry_at (inline: every step)
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        return g.curvature(ds if ds >= 0.0 else 0.0)

    def elevation(self, s: float) -> float:
        """``z`` of the reference line at ``s`` (0 without an elevationProfile)."""
        z = self._z_fixed
        if z is not None:
            return z
        p = _poly_at(self.elevations, self._estarts, s)
        return 0.0 if p is None else p.value(s)

    def roll(self, s: float) -> float:
        """Superelevation (roll about the reference line, rad) at ``s``; 0 without lateralProfile."""
        p = _poly_at(self.superelevations, self._rstarts, s)
        return 0.0 if p is None else p.value(s)

    def world_xyz(self, s: float, t: float) -> tuple[float, float, float, float]:
        """World ``(x, y, z, reference heading)`` of road coordinates ``(s, t)``."""
        i = bisect.bisect_right(self._gstarts, s) - 1  # as reference_xyh, with the heading's cos and sin
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        x, y, h, cos_h, sin_h = g.frame(ds if ds >= 0.0 else 0.0)
        z = self._z_fixed
        if z is None:
            z = self.elevation(s)
        if self.superelevations:
            r = self.roll(s)
            th = t * math.cos(r)
            z += t * math.sin(r)
        else:
            th = t
        return x - th * sin_h, y + th * cos_h, z, h

    def world_points(self, s: float, ts: Sequence[float]) -> list[tuple[float, float, float]]:
        """World ``(x, y, z)`` of ``(s, t)`` for every ``t`` in ``ts``: :meth:`world_xyz` with the reference
        frame at ``s`` computed once (sampling every lane border at one ``s``)."""
        i = bisect.bisect_right(self._gstarts, s) - 1
        g = self.geometries[i if i > 0 else 0]
        ds = s - g.s
        x, y, _h, cos_h, sin_h = g.frame(ds if ds >= 0.0 else 0.0)
        z = self._z_fixed
        if z is None:
            z = self.elevation(s)
        if self.superelevations:
            r = self.roll(s)
            cos_r, sin_r = math.cos(r), math.sin(r)
            return [(x - t * cos_r * sin_h, y + t * cos_r * cos_h, z + t * sin_r) for t in ts]
        return [(x - t * sin_h, y + t * cos_h, z) for t in ts]

    def lane_offset(self, s: float) -> float:
        """``t`` of the centre lane (laneOffset) at ``s``."""
        off = self._offset_fixed
        if off is not None:
            return off
        p = _poly_at(self.lane_offsets, self._ostarts, s)
        return 0.0 if p is None else p.value(s)

    # -- lanes
    def section_at(self, s: float, side: int = -1) -> LaneSection:
        """The lane section in effect at ``s`` for the lanes of ``side`` (+1 left, -1 right)."""
        key = 1 if side > 0 else -1
        i = bisect.bisect_right(self._side_starts[key], s + 1e-9) - 1
        return self._side_sections[key][i if i > 0 else 0]

    def side_sections(self, side: int) -> list[LaneSection]:
        """The lane sections defining the lanes of ``side`` (+1 left, -1 right), in ``s`` order."""
        return self._side_sections[1 if side > 0 else -1]

    def side_borders(self, s: float, side: int) -> list[tuple[Lane, float, float]]:
        """``(lane, t_inner, t_outer)`` for the lanes of ``side`` at ``s``, innermost first (memoised: the
        same road position is asked for several times per simulation step; callers must not mutate)."""
        cache: dict[tuple[float, int], list[tuple[Lane, float, float]]] | None = self.__dict__.get("_borders")
        if cache is None:
            cache = self.__dict__["_borders"] = {}
        hit = cache.get((s, side))
        if hit is not None:
            return hit
        if len(cache) > 256:
            cache.clear()
        out = cache[(s, side)] = self._side_borders(s, side)
        return out

    def _side_borders(self, s: float, side: int) -> list[tuple[Lane, float, float]]:
        sec = self.section_at(s, side)
        lanes = sec.left if side > 0 else sec.right
        if not lanes:
            return []
        fixed = self._fixed_borders(sec, side)
        return fixed if fixed is not None else self._borders_in(sec, lanes, s, side)

    def _fixed_borders(self, sec: LaneSection, side: int) -> list[tuple[Lane, float, float]] | None:
        """The borders of a section's side where they are the same at every ``s`` of it (constant widths,
        constant or no laneOffset: the sums below give the same numbers at every ``s``), else None."""
        fixed: dict[tuple[int, int], list[tuple[Lane, float, float]] | None] | None = self.__dict__.get(
            "_fixed"
        )
        if fixed is None:
            fixed = self.__dict__["_fixed"] = {}
        key = (id(sec), side)
        if key in fixed:
            return fixed[key]
        lanes = sec.left if side > 0 else sec.right
        constant = len(self.lane_offsets) <= 1 and all(_constant(p) for p in self.lane_offsets)
        constant = constant and all(len(lane.widths) == 1 and _constant(lane.widths[0]) for lane in lanes)
        out = fixed[key] = self._borders_in(sec, lanes, sec.s, side) if constant else None
        return out

    def _borders_in(
        self, sec: LaneSection, lanes: list[Lane], s: float, side: int
    ) -> list[tuple[Lane, float, float]]:
        ds = s - sec.s
        off = self.lane_offset(s)
        out: list[tuple[Lane, float, float]] = []
        acc = 0.0
        for lane in lanes:
            widths = lane.widths
            if len(widths) == 1:  # the common case, as Lane.width_at (inline: every step, every lane)
                p = widths[0]
                d = ds - p.s0
                w = p.a + d * (p.b + d * (p.c + d * p.d))
            elif widths:
                w = lane.width_at(ds)
            else:
                b = lane.border_at(ds)
                w = 0.0 if b is None else abs(b) - acc
            inner = off + side * acc
            acc += w
            out.append((lane, inner, off + side * acc))
        return out

    def cross_at(self, s: float) -> LaneCross | None:
        """The lane borders at ``s`` with their derived look-ups where they are the same over the whole
        stretch between lane section changes around ``s`` (see `LaneCross`), else None. Built once per
        road on first use, from the parsed road (which is never changed afterwards)."""
        crosses = self._crosses
        if crosses is None:
            crosses = self._crosses = self._build_crosses()
            first = crosses[0]
            self._uniform = first if all(c is first for c in crosses) else None
        uniform = self._uniform
        if uniform is not None:  # one lane section on each side, the same borders all along the road
            return uniform
        # index 0: before every section start; k + 1: from the k-th start (as section_at's s + 1e-9)
        return crosses[bisect.bisect_right(self._cross_starts, s + 1e-9)]

    def centre_t(self, lane_id: int, s: float) -> float | None:
        """``t`` of the centre of lane `lane_id` (not 0) at ``s`` in ``[0, length]`` from the lane borders'
        table of the stretch of road around ``s`` (`cross_at`); None where there is none: the caller asks
        `OpenDrive.lane_center_t`, which gives the same float here."""
        if lane_id == 0 or not 0.0 <= s <= self.length:
            return None
        cross = self._uniform
        if cross is None:
            cross = self.cross_at(s)
            if cross is None:
                return None
        return cross.centres.get(lane_id)

    def _build_crosses(self) -> list[LaneCross | None]:
        def index(key: int, q: float) -> int:  # as section_at
            i = bisect.bisect_right(self._side_starts[key], q) - 1
            return i if i > 0 else 0

        made: dict[tuple[int, int], LaneCross | None] = {}
        out: list[LaneCross | None] = []
        for right, left in [(0, 0)] + [(index(-1, q), index(1, q)) for q in self._cross_starts]:
            if (right, left) not in made:
                r, le = self._fixed_side(-1, right), self._fixed_side(1, left)
                made[(right, left)] = None if r is None or le is None else LaneCross(r, le)
            out.append(made[(right, left)])
        return out

    def _fixed_side(self, key: int, index: int) -> list[tuple[Lane, float, float]] | None:
        """`_side_borders` of the `index`-th section of side `key` where it is the same at every s."""
        sec = self._side_sections[key][index]
        if not (sec.left if key > 0 else sec.right):
            return []
        return self._fixed_borders(sec, key)

    def all_borders(self, s: float) -> list[tuple[Lane, float, float]]:
        """Borders of every non-centre lane at ``s`` (right side first, then left; memoised as
        `side_borders`: callers must not mutate)."""
        cross = self.cross_at(s)
        if cross is not None:
            return cross.borders
        cache: dict[float, list[tuple[Lane, float, float]]] | None = self.__dict__.get("_all_borders")
        if cache is None:
            cache = self.__dict__["_all_borders"] = {}
        hit = cache.get(s)
        if hit is not None:
            return hit
        if len(cache) > 256:
            cache.clear()
        out = cache[s] = self.side_borders(s, -1) + self.side_borders(s, 1)
        return out


@dataclass(frozen=True)
class JunctionConnection:
    """One junction ``<connection>``; ``lane_links`` are ``(from, to)`` lane ids.

    For a direct junction (OpenDRIVE 1.7 ``type="direct"``) ``connecting_road`` is the ``linkedRoad``.
    """

    id: str
    incoming_road: str
    connecting_road: str
    contact_point: str
    lane_links: tuple[tuple[int, int], ...]


@dataclass
class Junction:
    """A ``<junction>`` and its connections (in file order)."""

    id: str
    name: str
    connections: list[JunctionConnection]


@dataclass(frozen=True)
class LaneBoundary:
    """Samples of one lane's inner and outer border within one lane section (for triangulation).

    ``s`` has shape (N,), ``inner``/``outer`` shape (N, 3) of world x, y, z.
    """

    road_id: str
    section_index: int
    lane_id: int
    lane_type: str
    s: np.ndarray
    inner: np.ndarray
    outer: np.ndarray


# ------------------------------------------------------------------------------------------------------ parsing


class _Ctx:
    """Error-message context: file name plus a path of element descriptions."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.parts: list[str] = []

    def error(self, msg: str) -> OpenDriveError:
        return OpenDriveError(": ".join([self.name, *self.parts, msg]))

    def num(self, el: Element, attr: str, default: float | None = None) -> float:
        raw = el.get(attr)
        if raw is None:
            if default is not None:
                return default
            raise self.error(f"<{el.tag}> is missing attribute '{attr}'")
        try:
            val = float(raw)
        except ValueError:
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not a number") from None
        if not math.isfinite(val):
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not finite")
        return val

    def integer(self, el: Element, attr: str) -> int:
        raw = el.get(attr)
        if raw is None:
            raise self.error(f"<{el.tag}> is missing attribute '{attr}'")
        try:
            f = float(raw)
        except ValueError:
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not an integer") from None
        if not f.is_integer():
            raise self.error(f"<{el.tag}> attribute {attr}={raw!r} is not an integer")
        return int(f)

    def string(self, el: Element, attr: str) -> str:
        raw = el.get(attr)
        if raw is None:
            raise self.error(f"<{el.tag}> is missing attribute '{attr}'")
        return raw.strip()

    def poly(self, el: Element, s_attr: str) -> Poly3:
        return Poly3(
            self.num(el, s_attr),
            self.num(el, "a", 0.0),
            self.num(el, "b", 0.0),
            self.num(el, "c", 0.0),
            self.num(el, "d", 0.0),
        )


def _parse_geometry(ctx: _Ctx, el: Element) -> Geometry:
    s, x, y = ctx.num(el, "s"), ctx.num(el, "x"), ctx.num(el, "y")
    hdg, length = ctx.num(el, "hdg"), ctx.num(el, "length")
    if length < 0:
        raise ctx.error(f"negative length {length}")
    kids = list(el)
    if not kids:
        raise ctx.error("no geometry type (expected line, arc, spiral, poly3 or paramPoly3)")
    g = kids[0]
    if g.tag == "line":
        return Line(s, x, y, hdg, length)
    if g.tag == "arc":
        return Arc(s, x, y, hdg, length, ctx.num(g, "curvature"))
    if g.tag == "spiral":
        return Spiral(s, x, y, hdg, length, ctx.num(g, "curvStart"), ctx.num(g, "curvEnd"))
    if g.tag == "poly3":
        v = (ctx.num(g, "a"), ctx.num(g, "b"), ctx.num(g, "c"), ctx.num(g, "d"))
        return ParamPoly3(s, x, y, hdg, length, (0.0, 1.0, 0.0, 0.0), v, None)
    if g.tag == "paramPoly3":
        u = (ctx.num(g, "aU"), ctx.num(g, "bU"), ctx.num(g, "cU"), ctx.num(g, "dU"))
        v = (ctx.num(g, "aV"), ctx.num(g, "bV"), ctx.num(g, "cV"), ctx.num(g, "dV"))
        prange = (g.get("pRange") or "normalized").strip()
        if prange == "arcLength":
            p_max = length
        elif prange == "normalized":
            p_max = 1.0
        else:
            raise ctx.error(f"paramPoly3 has unsupported pRange {prange!r}")
        return ParamPoly3(s, x, y, hdg, length, u, v, p_max)
    raise ctx.error(f"unsupported type {g.tag!r}")


def _parse_link(ctx: _Ctx, el: Element | None) -> RoadLink | None:
    if el is None:
        return None
    etype = ctx.string(el, "elementType")
    if etype not in ("road", "junction"):
        raise ctx.error(f"<{el.tag}> has unsupported elementType {etype!r}")
    cp = el.get("contactPoint")
    if etype == "road":
        if cp not in ("start", "end"):
            raise ctx.error(
                f"<{el.tag}> to road {el.get('elementId')!r} needs contactPoint start/end, got {cp!r}"
            )
    else:
        cp = None
    return RoadLink(etype, ctx.string(el, "elementId"), cp)


def _parse_lane(ctx: _Ctx, el: Element) -> Lane:
    lane_id = ctx.integer(el, "id")
    ctx.parts.append(f"lane id={lane_id}")
    widths = []
    for i, w in enumerate(el.findall("width")):
        ctx.parts.append(f"width {i}")
        widths.append(ctx.poly(w, "sOffset"))
        ctx.parts.pop()
    borders = []
    for i, b in enumerate(el.findall("border")):
        ctx.parts.append(f"border {i}")
        borders.append(ctx.poly(b, "sOffset"))
        ctx.parts.pop()
    pred = succ = None
    link = el.find("link")
    if link is not None:
        p = link.find("predecessor")
        if p is not None:
            pred = ctx.integer(p, "id")
        q = link.find("successor")
        if q is not None:
            succ = ctx.integer(q, "id")
    level = (el.get("level") or "false").strip().lower() in ("true", "1")
    ctx.parts.pop()
    return Lane(lane_id, (el.get("type") or "none").strip(), widths, borders, pred, succ, level)


def _parse_road(ctx: _Ctx, el: Element) -> Road:
    rid = ctx.string(el, "id")
    ctx.parts.append(f"road id={rid}")
    length = ctx.num(el, "length")
    if length <= 0:
        raise ctx.error(f"non-positive length {length}")
    junction = (el.get("junction") or "-1").strip()
    plan = el.find("planView")
    if plan is None:
        raise ctx.error("no <planView>")
    geoms = []
    for i, g in enumerate(plan.findall("geometry")):
        ctx.parts.append(f"geometry {i}")
        geoms.append(_parse_geometry(ctx, g))
        ctx.parts.pop()
    if not geoms:
        raise ctx.error("<planView> has no <geometry>")
    geoms.sort(key=lambda g: g.s)
    elevs = []
    ep = el.find("elevationProfile")
    if ep is not None:
        for i, e in enumerate(ep.findall("elevation")):
            ctx.parts.append(f"elevation {i}")
            elevs.append(ctx.poly(e, "s"))
            ctx.parts.pop()
    elevs.sort(key=lambda p: p.s0)
    supers = []
    lp = el.find("lateralProfile")
    if lp is not None:
        for i, e in enumerate(lp.findall("superelevation")):
            ctx.parts.append(f"superelevation {i}")
            supers.append(ctx.poly(e, "s"))
            ctx.parts.pop()
    supers.sort(key=lambda p: p.s0)
    lanes_el = el.find("lanes")
    if lanes_el is None:
        raise ctx.error("no <lanes>")
    offsets = []
    for i, o in enumerate(lanes_el.findall("laneOffset")):
        ctx.parts.append(f"laneOffset {i}")
        offsets.append(ctx.poly(o, "s"))
        ctx.parts.pop()
    offsets.sort(key=lambda p: p.s0)
    sections: list[LaneSection] = []
    sec_els = lanes_el.findall("laneSection")
    if not sec_els:
        raise ctx.error("<lanes> has no <laneSection>")
    for i, sec in enumerate(sec_els):
        ctx.parts.append(f"laneSection {i}")
        s0 = ctx.num(sec, "s")
        single = (sec.get("singleSide") or "false").strip().lower() in ("true", "1")
        left: list[Lane] = []
        right: list[Lane] = []
        center: Lane | None = None
        for side_name in ("left", "center", "right"):
            side_el = sec.find(side_name)
            if side_el is None:
                continue
            for lane_el in side_el.findall("lane"):
                lane = _parse_lane(ctx, lane_el)
                if side_name == "left" and lane.id > 0:
                    left.append(lane)
                elif side_name == "right" and lane.id < 0:
                    right.append(lane)
                elif side_name == "center" and lane.id == 0:
                    center = lane
                else:
                    raise ctx.error(f"lane id={lane.id} does not belong in <{side_name}>")
        left.sort(key=lambda ln: ln.id)
        right.sort(key=lambda ln: -ln.id)
        for side_lanes, sign in ((left, 1), (right, -1)):
            if [ln.id for ln in side_lanes] != [sign * (k + 1) for k in range(len(side_lanes))]:
                raise ctx.error(f"lane ids {[ln.id for ln in side_lanes]} are not consecutive from {sign}")
        sections.append(LaneSection(s0, length, left, right, center, single))
        ctx.parts.pop()
    sections.sort(key=lambda sc: sc.s)
    for a, b in itertools.pairwise(sections):
        a.end = b.s
    link = el.find("link")
    pred = succ = None
    if link is not None:
        ctx.parts.append("link")
        pred = _parse_link(ctx, link.find("predecessor"))
        succ = _parse_link(ctx, link.find("successor"))
        ctx.parts.pop()
    ctx.parts.pop()
    rule = (el.get("rule") or "RHT").strip().upper()
    speeds = []
    for kind in el.findall("type"):
        record = kind.find("speed")
        if record is None or record.get("max") in (None, "", "no limit", "undefined"):
            continue
        scale = _SPEED_UNITS.get((record.get("unit") or "m/s").strip(), 1.0)
        try:
            speeds.append((ctx.num(kind, "s", 0.0), float(record.get("max", "")) * scale))
        except ValueError:
            continue  # a speed record that is not a number: no limit from it
    road = Road(
        rid,
        el.get("name") or "",
        length,
        junction,
        geoms,
        elevs,
        offsets,
        sections,
        pred,
        succ,
        supers,
        "LHT" if rule == "LHT" else "RHT",
    )
    road.speeds = sorted(speeds)
    return road


_SPEED_UNITS = {"m/s": 1.0, "km/h": 1 / 3.6, "mph": 0.44704}


def _parse_junction(ctx: _Ctx, el: Element) -> Junction:
    jid = ctx.string(el, "id")
    ctx.parts.append(f"junction id={jid}")
    conns = []
    for i, c in enumerate(el.findall("connection")):
        ctx.parts.append(f"connection {c.get('id', i)}")
        links = tuple((ctx.integer(ll, "from"), ctx.integer(ll, "to")) for ll in c.findall("laneLink"))
        cp = (c.get("contactPoint") or "start").strip()
        if cp not in ("start", "end"):
            raise ctx.error(f"unsupported contactPoint {cp!r}")
        conns.append(
            JunctionConnection(
                (c.get("id") or str(i)).strip(),
                ctx.string(c, "incomingRoad"),
                ctx.string(
                    c,
                    "linkedRoad"
                    if c.get("connectingRoad") is None and c.get("linkedRoad")
                    else "connectingRoad",
                ),
                cp,
                links,
            )
        )
        ctx.parts.pop()
    ctx.parts.pop()
    return Junction(jid, el.get("name") or "", conns)


# ------------------------------------------------------------------------------------------------- the network


class OpenDrive:
    """A parsed OpenDRIVE road network with geometric queries. Build with :meth:`from_file` / :meth:`from_string`."""

    def __init__(
        self, roads: dict[str, Road], junctions: dict[str, Junction], name: str = "<string>"
    ) -> None:
        self.name = name
        self.roads = roads
        self.junctions = junctions
        self._index: Any = None
        self.signals: dict[str, str] = {}  # <signal> id → name (traffic signals are otherwise not modelled)

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_file(cls, path: str | Path) -> OpenDrive:
        """Parse an ``.xodr`` file (refused if larger than 64 MiB)."""
        return cls._from_bytes(_read_bounded(Path(path)), str(path))

    @classmethod
    def shared(cls, path: str | Path) -> OpenDrive:
        """:meth:`from_file`, parsed once per process for the same file content: a worker running run after
        run on one road (a sweep) parses it and builds its spatial index once. Callers treat the network as
        read-only (its lazily built index and memos are pure functions of the file)."""
        data = _read_bounded(Path(path))
        key = (str(path), hashlib.sha256(data).digest())
        network = _SHARED.pop(key, None)
        if network is None:
            network = cls._from_bytes(data, str(path))
        _SHARED[key] = network  # most recently used last
        while len(_SHARED) > _SHARED_MAX:
            del _SHARED[next(iter(_SHARED))]
        return network

    @classmethod
    def from_string(cls, text: str, name: str = "<string>") -> OpenDrive:
        """Parse OpenDRIVE XML text; ``name`` is used in error messages."""
        data = text.encode("utf-8")
        if len(data) > MAX_FILE_BYTES:
            raise OpenDriveError(f"{name}: input is larger than the {MAX_FILE_BYTES} byte limit")
        return cls._from_bytes(data, name)

    @classmethod
    def _from_bytes(cls, data: bytes, name: str) -> OpenDrive:
        geometries = data.count(b"<geometry")
        if geometries > MAX_GEOMETRIES:
            raise OpenDriveError(
                f"{name}: {geometries} <geometry> records, more than the {MAX_GEOMETRIES} allowed: "
                "split the road network"
            )
        try:
            root = DET.fromstring(data, forbid_dtd=False, forbid_entities=True, forbid_external=True)
        except DefusedXmlException as e:
            raise OpenDriveError(f"{name}: unsafe XML rejected: {e}") from None
        except Exception as e:  # xml.etree.ElementTree.ParseError and friends
            raise OpenDriveError(f"{name}: not well-formed XML: {e}") from None
        if root.tag != "OpenDRIVE":
            raise OpenDriveError(f"{name}: root element is <{root.tag}>, expected <OpenDRIVE>")
        ctx = _Ctx(name)
        roads: dict[str, Road] = {}
        for el in root.findall("road"):
            road = _parse_road(ctx, el)
            if road.id in roads:
                raise OpenDriveError(f"{name}: road id={road.id}: duplicate road id")
            roads[road.id] = road
        junctions: dict[str, Junction] = {}
        for el in root.findall("junction"):
            j = _parse_junction(ctx, el)
            junctions[j.id] = j
        if not roads:
            raise OpenDriveError(f"{name}: no <road> elements")
        network = cls(roads, junctions, name)
        for road_el in root.findall("road"):
            for signal in road_el.iterfind("signals/signal"):
                network.signals[signal.get("id", "")] = signal.get("name", "")
        return network

    # ---------------------------------------------------------------- basic queries
    def road(self, road_id: str) -> Road:
        """The road with ``road_id``; :class:`OpenDriveError` if there is none."""
        road = self.roads.get(road_id)
        if road is not None:
            return road
        try:
            return self.roads[str(road_id)]
        except KeyError:
            raise OpenDriveError(f"{self.name}: no road id={road_id}") from None

    def road_length(self, road_id: str) -> float:
        """Length of the road's reference line."""
        return self.road(road_id).length

    def _check_s(self, road: Road, s: float) -> float:
        if -_S_TOL <= s <= road.length + _S_TOL:
            return min(max(s, 0.0), road.length)
        raise OpenDriveError(f"{self.name}: road id={road.id}: s={s} outside [0, {road.length}]")

    def reference_pose(self, road_id: str, s: float) -> Pose:
        """Pose of the reference line at ``s`` (no lane offset)."""
        road = self.road(road_id)
        s = self._check_s(road, s)
        x, y, h = road.reference_xyh(s)
        return Pose(x, y, road.elevation(s), h)

    def road_to_world(self, road_id: str, s: float, t: float) -> Pose:
        """World pose of road coordinates ``(s, t)``; the heading is the reference-line heading."""
        road = self.road(road_id)
        s = self._check_s(road, s)
        return Pose(*road.world_xyz(s, t))

    def road_xyzh(self, road_id: str, s: float, t: float) -> tuple[float, float, float, float]:
        """`road_to_world` as a plain ``(x, y, z, heading)`` tuple (for the per-step motion)."""
        road = self.roads.get(road_id)
        if road is None:
            road = self.road(road_id)
        if not 0.0 <= s <= road.length:
            s = self._check_s(road, s)
        return road.world_xyz(s, t)

    def road_z(self, road_id: str, s: float, t: float) -> float:
        """``z`` of road coordinates ``(s, t)`` (the one `road_to_world` gives)."""
        road = self.roads.get(road_id)
        if road is None:
            road = self.road(road_id)
        if not 0.0 <= s <= road.length:
            s = self._check_s(road, s)
        z = road.elevation(s)
        if road.superelevations:
            z += t * math.sin(road.roll(s))
        return z

    def _lane_borders(self, road: Road, lane_id: int, s: float) -> tuple[Lane, float, float]:
        if lane_id == 0:
            off = road.lane_offset(s)
            sec = road.section_at(s)
            lane = sec.center or Lane(0, "none")
            return lane, off, off
        for lane, inner, outer in road.side_borders(s, 1 if lane_id > 0 else -1):
            if lane.id == lane_id:
                return lane, inner, outer
        raise OpenDriveError(f"{self.name}: road id={road.id}: no lane id={lane_id} at s={s:.3f}")

    def lane_center_t(self, road_id: str, lane_id: int, s: float) -> float:
        """``t`` of the lane's centre at ``s`` (includes laneOffset; lane 0 gives the laneOffset)."""
        road = self.roads.get(road_id)
        if road is None:
            road = self.road(road_id)
        if not 0.0 <= s <= road.length:
            s = self._check_s(road, s)
        centre = road.centre_t(lane_id, s)
        if centre is not None:
            return centre
        if lane_id == 0:
            return road.lane_offset(s)
        centers: dict[tuple[float, int], float] | None = road.__dict__.get("_centers")
        if centers is None:
            centers = road.__dict__["_centers"] = {}
        hit = centers.get((s, lane_id))
        if hit is not None:
            return hit
        if len(centers) > 256:
            centers.clear()
        for lane, inner, outer in road.side_borders(s, 1 if lane_id > 0 else -1):
            if lane.id == lane_id:
                centers[(s, lane_id)] = t = 0.5 * (inner + outer)
                return t
        raise OpenDriveError(f"{self.name}: road id={road.id}: no lane id={lane_id} at s={s:.3f}")

    def lane_width(self, road_id: str, lane_id: int, s: float) -> float:
        """Width of the lane at ``s`` (0 for lane 0)."""
        road = self.road(road_id)
        _, inner, outer = self._lane_borders(road, lane_id, self._check_s(road, s))
        return abs(outer - inner)

    def lane_type(self, road_id: str, lane_id: int, s: float) -> str:
        """The lane's ``type`` attribute at ``s``."""
        road = self.road(road_id)
        lane, _, _ = self._lane_borders(road, lane_id, self._check_s(road, s))
        return lane.type

    def lane_to_world(self, road_id: str, lane_id: int, s: float, offset: float = 0.0) -> Pose:
        """World pose ``offset`` m to the left (+t) of the lane centre at ``s``.

        The heading is the direction of the curve of constant ``offset`` from the lane centre in the
        direction of increasing ``s`` (the reference heading plus the slope of lane widths / laneOffset);
        add pi for travel toward decreasing ``s``.
        """
        road = self.road(road_id)
        s = self._check_s(road, s)
        t = self.lane_center_t(road_id, lane_id, s) + offset
        x, y, z, h = road.world_xyz(s, t)
        return Pose(x, y, z, h + self._lane_slope_angle(road, lane_id, s, t))

    def drives_backward(self, road_id: str, lane_id: int) -> bool:
        """Whether traffic in the lane travels toward decreasing s (left lanes in right-hand traffic)."""
        return (lane_id > 0) != (self.road(road_id).rule == "LHT")

    def lane_heading(self, road_id: str, lane_id: int, s: float) -> float:
        """Heading (toward increasing ``s``) of the lane centre line at ``s``."""
        return self.lane_to_world(road_id, lane_id, s).heading

    def _lane_slope_angle(self, road: Road, lane_id: int, s: float, t: float) -> float:
        """Angle between the lane-centre curve and the reference line at ``s`` (from dt/ds and curvature)."""
        sec = road.section_at(s, 1 if lane_id > 0 else -1)
        eps = 1e-3
        lo = max(sec.s, s - eps, 0.0)
        hi = min(sec.end, s + eps, road.length)
        if hi <= lo:
            return 0.0
        hi_q = hi - 1e-9 if hi >= sec.end and sec.end < road.length else hi
        _, i0, o0 = self._lane_borders(road, lane_id, lo)
        _, i1, o1 = self._lane_borders(road, lane_id, hi_q)
        c0 = c1 = c = 1.0
        if road.superelevations:  # horizontal offsets: t is measured in the rolled cross section
            c0, c1, c = math.cos(road.roll(lo)), math.cos(road.roll(hi_q)), math.cos(road.roll(s))
        _, ic, oc = self._lane_borders(road, lane_id, s)
        off = t - 0.5 * (ic + oc)
        dt = ((0.5 * (i1 + o1) + off) * c1 - (0.5 * (i0 + o0) + off) * c0) / (hi_q - lo)
        return math.atan2(dt, 1.0 - road.curvature(s) * t * c)

    def speed_limit(self, road_id: str, s: float) -> float | None:
        """The speed limit (m/s) of the road's type at ``s``; None without a speed record."""
        return self.road(road_id).speed_limit(s)

    def lane_ids(self, road_id: str, s: float, driving_only: bool = False) -> list[int]:
        """Ids of the lanes (not 0) with positive width at ``s``, right to left; optionally drivable ones only."""
        road = self.road(road_id)
        s = self._check_s(road, s)
        cross = road.cross_at(s)
        if cross is not None:
            return list(cross.driving_ids if driving_only else cross.ids)
        out = []
        for lane, inner, outer in road.all_borders(s):
            if abs(outer - inner) <= 1e-9:
                continue
            if driving_only and lane.type.lower() not in DRIVING_LANE_TYPES:
                continue
            out.append(lane.id)
        return sorted(out)

    # ---------------------------------------------------------------- topology
    def successor(self, road_id: str, lane_id: int, s_direction: int) -> tuple[str, int, int] | None:
        """Where an entity goes when it leaves the end of ``road_id``/``lane_id`` travelling in ``s_direction``.

        ``s_direction`` +1 leaves at ``s = length`` via the road's successor, -1 leaves at ``s = 0`` via its
        predecessor; ``lane_id`` is the lane in the last (first) lane section. Follows the lane's own link
        for a road link, and for a junction the first connection from this road with a laneLink from
        ``lane_id``. Returns ``(road_id, lane_id, new_s_direction)`` or None at a dead end.
        """
        road = self.road(road_id)
        if s_direction not in (1, -1):
            raise ValueError(f"s_direction must be +1 or -1, got {s_direction}")
        link = road.successor if s_direction > 0 else road.predecessor
        if link is None:
            return None
        if link.element_type == "road":
            if link.element_id not in self.roads:
                return None
            sec = road.lane_sections[-1] if s_direction > 0 else road.lane_sections[0]
            lane = sec.lane(lane_id)
            if lane is None:
                raise OpenDriveError(f"{self.name}: road id={road.id}: no lane id={lane_id} at its end")
            target = lane.successor if s_direction > 0 else lane.predecessor
            if target is None:
                return None
            return link.element_id, target, 1 if link.contact_point == "start" else -1
        junction = self.junctions.get(link.element_id)
        if junction is None:
            return None
        for conn in junction.connections:
            if conn.incoming_road != road.id or conn.connecting_road not in self.roads:
                continue
            for frm, to in conn.lane_links:
                if frm == lane_id:
                    return conn.connecting_road, to, 1 if conn.contact_point == "start" else -1
        return None

    def connections(self, road_id: str, lane_id: int | None, s_direction: int) -> list[tuple[str, int, int]]:
        """Every way on from the end of ``road_id`` in ``s_direction`` (all junction connections, not only the
        first): ``(road_id, lane_id, new_s_direction)``. ``lane_id`` None: from any lane of the road."""
        road = self.road(road_id)
        link = road.successor if s_direction > 0 else road.predecessor
        if link is None:
            return []
        out: list[tuple[str, int, int]] = []
        if link.element_type == "road":
            if link.element_id not in self.roads:
                return []
            sec = road.lane_sections[-1] if s_direction > 0 else road.lane_sections[0]
            lanes = [ln for ln in sec.left + sec.right if lane_id is None or ln.id == lane_id]
            for lane in lanes:
                target = lane.successor if s_direction > 0 else lane.predecessor
                if target is not None:
                    out.append((link.element_id, target, 1 if link.contact_point == "start" else -1))
            return out
        junction = self.junctions.get(link.element_id)
        if junction is None:
            return []
        for conn in junction.connections:
            if conn.incoming_road != road.id or conn.connecting_road not in self.roads:
                continue
            for frm, to in conn.lane_links:
                if lane_id is None or frm == lane_id:
                    out.append((conn.connecting_road, to, 1 if conn.contact_point == "start" else -1))
        return out

    # ---------------------------------------------------------------- sampling
    def sample_lane_boundaries(self, road_id: str, step: float = 1.0) -> list[LaneBoundary]:
        """Inner/outer border points of every lane (not lane 0) of each lane section, every ``step`` m or less.

        Each section is sampled from its start to its end inclusive; zero-width stretches are kept so the
        arrays of one lane stay aligned (triangulation can drop degenerate triangles).
        """
        import numpy as np  # here only: arrays for sensors' scene meshes and report plots

        if step <= 0:
            raise ValueError("step must be positive")
        road = self.road(road_id)
        out: list[LaneBoundary] = []
        for si, sec in enumerate(road.lane_sections):
            n = max(1, math.ceil((sec.end - sec.s) / step))
            ss = np.linspace(sec.s, sec.end, n + 1)
            lane_ids = [ln.id for ln in sec.right + sec.left]
            if not lane_ids:
                continue
            inner = {lid: np.zeros((len(ss), 3)) for lid in lane_ids}
            outer = {lid: np.zeros((len(ss), 3)) for lid in lane_ids}
            for k, s in enumerate(ss):
                s = float(s)
                q = min(s, sec.end - 1e-9) if sec.end > sec.s else s
                borders = [
                    border
                    for side in (-1, 1)
                    if road.section_at(q, side) is sec
                    for border in road.side_borders(q, side)
                ]
                points = road.world_points(s, [t for _, ti, to in borders for t in (ti, to)])
                for j, (lane, _, _) in enumerate(borders):
                    inner[lane.id][k] = points[2 * j]
                    outer[lane.id][k] = points[2 * j + 1]
            for lane in sec.right + sec.left:
                out.append(LaneBoundary(road.id, si, lane.id, lane.type, ss, inner[lane.id], outer[lane.id]))
        return out

    # ---------------------------------------------------------------- world -> road
    def _build_index(self) -> dict[str, Any]:

        xs: list[float] = []
        ys: list[float] = []
        rix: list[int] = []
        ss: list[float] = []
        reach: list[float] = []
        road_list = list(self.roads.values())
        spacing: list[float] = []
        for ri, road in enumerate(road_list):
            n = max(2, math.ceil(road.length / 2.0) + 1)
            sp = road.length / (n - 1)
            spacing.append(sp)
            for s in _linspace(0.0, road.length, n):
                x, y, _ = road.reference_xyh(s)
                ext = 0.0
                for _lane, inner, outer in road.all_borders(s):
                    ext = max(ext, abs(inner), abs(outer) + 0.5 * abs(outer - inner))
                xs.append(x)
                ys.append(y)
                rix.append(ri)
                ss.append(s)
                reach.append(ext + sp + 0.5)
        return {
            "tree": PointGrid(list(zip(xs, ys, strict=True)), float(max(reach))),
            "roads": road_list,
            "rix": rix,
            "s": ss,
            "reach": reach,
            "max_reach": float(max(reach)),
            "spacing": spacing,
        }

    def _project(
        self, road: Road, px: float, py: float, s0: float, spacing: float
    ) -> tuple[float, float, float, float]:
        """Newton projection of ``(px, py)`` on the reference line from ``s0``: ``(s, t, along_residual,
        reference heading at s)``."""
        s = s0
        along = 0.0
        t = 0.0
        h = 0.0
        at = math.nan  # the s that h is the heading at
        length = road.length
        most = 2.0 * spacing + 1.0  # the longest Newton step either way
        least = -2.0 * spacing - 1.0
        g, lo, hi = road.geometry_span(s)
        g_s, frame, straight = g.s, g.frame, g.straight  # the record's, asked again only on leaving it
        for _ in range(30):
            if not lo <= s < hi:  # left the record: as road.reference_xyh(s) and road.curvature(s)
                g, lo, hi = road.geometry_span(s)
                g_s, frame, straight = g.s, g.frame, g.straight
            ds = s - g_s
            x, y, h, c, sn = frame(ds if ds >= 0.0 else 0.0)
            at = s
            dx, dy = px - x, py - y
            along = dx * c + dy * sn
            t = -dx * sn + dy * c
            if -1e-9 < along < 1e-9:  # abs(along) < 1e-9 (False for NaN either way)
                break
            if straight:  # 1.0 - 0.0 * t is 1.0 (or NaN where t is not finite): either way the step is along
                step = along
            else:
                denom = 1.0 - g.curvature(ds if ds >= 0.0 else 0.0) * t
                step = along / denom if denom > 0.2 else along
            # max(least, min(most, step)) and min(max(s + step, 0.0), length), without the calls
            step = step if step < most else most
            step = step if step > least else least
            s_new = s + step
            s_new = 0.0 if s_new < 0.0 else s_new
            s_new = length if length < s_new else s_new
            moved = s_new - s
            if -1e-10 < moved < 1e-10:  # abs(s_new - s) < 1e-10
                break
            s = s_new
        if at != s:
            _, _, h = road.reference_xyh(s)
        return s, t, along, h

    def world_to_road(
        self, x: float, y: float, z: float | None = None, road_hint: str | None = None
    ) -> RoadCoordinates | None:
        """The road and lane containing world point ``(x, y)`` (``z`` disambiguates stacked roads).

        Candidates come from a k-d tree of reference-line samples (every <= 2 m); ``s`` is refined by
        Newton projection. A point laterally outside the outermost lane by up to half that lane's width is
        still mapped (to that lane); beyond that, or more than 5 cm past the road ends, it is off the road.
        Candidates strictly inside a lane and inside the road's s range come first; among several such roads
        (junctions), one within 2 m of ``z`` (if given) wins, then ``road_hint``, then the nearest
        elevation, then the smallest ``|offset|`` relative to the lane width. All lane types count.
        Returns None when the point is on no road.
        """
        if self._index is None:
            self._index = self._build_index()
        idx = self._index
        cand = idx["tree"].query_ball_point([x, y], idx["max_reach"])
        if not cand:
            return None
        tree: PointGrid = idx["tree"]
        reach: list[float] = idx["reach"]
        near = [(d, ci) for ci in cand if (d := math.hypot(tree.xs[ci] - x, tree.ys[ci] - y)) <= reach[ci]]
        near.sort()  # by distance, ties by index
        seeds: dict[int, list[float]] = {}
        for _, ci in near:
            ri = idx["rix"][ci]
            s0 = idx["s"][ci]
            lst = seeds.setdefault(ri, [])
            if len(lst) < 3 and all(abs(s0 - o) > 3.0 * idx["spacing"][ri] for o in lst):
                lst.append(s0)
        best: tuple[tuple[float, ...], RoadCoordinates] | None = None
        for ri, starts in seeds.items():
            road: Road = idx["roads"][ri]
            sp = idx["spacing"][ri]
            for s0 in starts:
                s, t, along, h = self._project(road, x, y, s0, sp)
                if road.superelevations:
                    t /= max(math.cos(road.roll(s)), 1e-6)
                if abs(along) > 0.05:  # beyond the road's ends (or not converged)
                    continue
                borders = [b for b in road.all_borders(s) if abs(b[2] - b[1]) > 1e-9]
                if not borders:
                    continue
                lane_hit: tuple[Lane, float, float] | None = None
                outside = math.inf
                for b in borders:
                    lo, hi = min(b[1], b[2]), max(b[1], b[2])
                    dist = 0.0 if lo <= t <= hi else min(abs(t - lo), abs(t - hi))
                    if dist < outside or (
                        dist == outside and lane_hit is not None and abs(b[0].id) < abs(lane_hit[0].id)
                    ):
                        outside, lane_hit = dist, b
                assert lane_hit is not None
                lane, inner, outer = lane_hit
                width = abs(outer - inner)
                if outside > 0.5 * width:
                    continue
                offset = t - 0.5 * (inner + outer)
                dz = abs(z - road.world_xyz(s, t)[2]) if z is not None else 0.0
                key = (
                    0.0 if outside == 0.0 and abs(along) < 1e-6 else 1.0,
                    0.0 if dz < 2.0 else 1.0,
                    0.0 if road.id == road_hint else 1.0,
                    dz,
                    outside + abs(along),
                    abs(offset) / max(width, 1e-6),
                )
                rc = _road_coordinates(road.id, lane.id, s, t, offset, h)
                if best is None or key < best[0]:
                    best = (key, rc)
        return None if best is None else best[1]

    def world_to_road_near(
        self, x: float, y: float, road_id: str, s_previous: float
    ) -> RoadCoordinates | None:
        """Fast path for tracking a moving entity: project onto `road_id` from its previous `s`. Returns None
        (use :meth:`world_to_road`) when the point is not strictly inside a lane of that road, e.g. after it
        left the road or where roads overlap in a junction."""
        near = self.near_lane(x, y, road_id, s_previous)
        return None if near is None else _road_coordinates(self.roads[road_id].id, *near)

    def near_lane(
        self, x: float, y: float, road_id: str, s_previous: float
    ) -> tuple[int, float, float, float, float] | None:
        """`world_to_road_near` as a plain ``(lane_id, s, t, offset, heading)`` (for the per-step tracking)."""
        road = self.roads.get(road_id)
        if road is None or road.junction != "-1":
            return None
        s0 = 0.0 if s_previous < 0.0 else s_previous  # min(max(s_previous, 0.0), road.length)
        s0 = road.length if road.length < s0 else s0
        s, t, along, h = self._project(road, x, y, s0, 2.0)
        if road.superelevations:
            t /= max(math.cos(road.roll(s)), 1e-6)
        if along > 1e-6 or along < -1e-6:  # abs(along) > 1e-6 (False for NaN either way)
            return None
        cross = road.cross_at(s)
        if cross is not None:
            for lane_id, lo, hi, centre in cross.inside:
                if lo <= t <= hi:
                    return lane_id, s, t, t - centre, h
            return None
        for lane, inner, outer in road.all_borders(s):
            if inner < outer:
                if outer - inner > 1e-9 and inner <= t <= outer:
                    return lane.id, s, t, t - 0.5 * (inner + outer), h
            elif inner - outer > 1e-9 and outer <= t <= inner:
                return lane.id, s, t, t - 0.5 * (inner + outer), h
        return None


def load(path: str | Path) -> OpenDrive:
    """Shorthand for :meth:`OpenDrive.from_file`."""
    return OpenDrive.from_file(path)
