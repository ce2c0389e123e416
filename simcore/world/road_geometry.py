"""OpenDRIVE reference-line geometry: the planView records (``line``, ``arc``, ``spiral``, ``poly3``,
``paramPoly3``) and the numerics they are evaluated with.

Each record maps a distance ``ds`` along it to a world ``(x, y, heading)`` and a curvature. Clothoids use the
Fresnel integrals (Cephes' ``fresnl``, the floats scipy gives, without importing scipy); ``poly3`` and
``paramPoly3`` map ``s`` to the curve parameter through a Gauss-Legendre arc-length table, so ``s`` is a true
arc length. Every operation is written in a fixed order: conformance against esmini depends on these floats.
"""

from __future__ import annotations

import itertools
import math
from typing import Final

from simcore.world.native_calls import atan2, bisect_right, hypot

__all__ = ["Arc", "Geometry", "Line", "ParamPoly3", "Spiral", "linspace"]


def linspace(start: float, stop: float, num: int) -> list[float]:
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

    def frame_k(self, ds: float) -> tuple[float, float, float, float, float, float]:
        """`frame` and `curvature` at ``ds``: ``(x, y, heading, cos, sin, curvature)``."""
        x, y, h, c, s = self.frame(ds)
        return x, y, h, c, s, self.curvature(ds)


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

    def frame_k(self, ds: float) -> tuple[float, float, float, float, float, float]:
        c, s = self._cos, self._sin
        return self.x + ds * c, self.y + ds * s, self.hdg, c, s, 0.0


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

    def frame(self, ds: float) -> tuple[float, float, float, float, float]:
        k = self.k  # as local, whose sine and cosine of the heading are the frame's
        h = self.hdg + k * ds
        c, s = math.cos(h), math.sin(h)
        if abs(k) < 1e-12:
            return self.x + ds * self._cos, self.y + ds * self._sin, h, c, s
        return self.x + (s - self._sin) / k, self.y - (c - self._cos) / k, h, c, s

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
_GL16: Final = tuple(zip(_GL16_X, _GL16_W, strict=True))


# Fresnel integrals (Cephes ``fresnl``, as scipy.special.fresnel evaluates them: the same rational
# approximations in the same operation order, so the same floats, without scipy's and numpy's import). Not
# Final: mypyc's check that a Final tuple of floats is set misreads it as unset (a NameError when read).
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
        edges = linspace(0.0, ds, n + 1)
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


# (not Final, as the Fresnel coefficients above)
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
    _coef: tuple[float, ...] | None = (
        None  # (u, v coefficients, 2·cu, 3·du, 6·du, 2·cv, 3·dv, 6·dv): `_uv_at`
    )

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
                if self._arclen(linspace(0.0, mid, 65))[-1] < length:
                    lo = mid
                else:
                    hi = mid
            p_max = 0.5 * (lo + hi)
        self.p_max = p_max
        n = int(min(max(64, math.ceil(length / 0.2)), 20000))
        ps = linspace(0.0, p_max, n + 1)
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

    def _uv_at(self, ds: float) -> tuple[float, float, float, float, float, float]:
        """``(u, v, u', v', u'', v'')`` at the parameter ``p`` of ``ds`` (interpolated in the arc length
        table); the last one kept (a projection asks for the point and then the curvature at the same
        ``ds``): one ``(ds, uv)`` tuple, replaced whole. One function: it runs for every entity on such a road
        at every step."""
        last = self._last
        if last[0] == ds:
            return last[1]
        ss, ps = self._ss, self._ps
        i = bisect_right(ss, ds) - 1
        top = len(ss) - 2
        i = 0 if i < 0 else top if i > top else i  # min(max(i, 0), top), top >= 0
        s0, s1 = ss[i], ss[i + 1]
        f = (ds - s0) / (s1 - s0) if s1 > s0 else 0.0
        p0 = ps[i]
        p = p0 + f * (ps[i + 1] - p0)
        coef = self._coef
        if coef is None:  # the coefficients and their multiples, once (2·c, 3·d, 6·d are the same floats)
            au, bu, cu, du = self.u
            av, bv, cv, dv = self.v
            coef = self._coef = (
                au,
                bu,
                cu,
                du,
                av,
                bv,
                cv,
                dv,
                2 * cu,
                3 * du,
                6 * du,
                2 * cv,
                3 * dv,
                6 * dv,
            )
        au, bu, cu, du, av, bv, cv, dv, cu2, du3, du6, cv2, dv3, dv6 = coef
        uv = (
            au + p * (bu + p * (cu + p * du)),
            av + p * (bv + p * (cv + p * dv)),
            bu + p * (cu2 + du3 * p),  # bu + p * (2 * cu + 3 * du * p)
            bv + p * (cv2 + dv3 * p),
            cu2 + du6 * p,  # 2 * cu + 6 * du * p
            cv2 + dv6 * p,
        )
        self._last = (ds, uv)
        return uv

    def local(self, ds: float) -> tuple[float, float, float]:
        u, v, up, vp, _, _ = self._uv_at(ds)
        return (
            self.x + u * self._cos - v * self._sin,
            self.y + u * self._sin + v * self._cos,
            self.hdg + atan2(vp, up),
        )

    def frame(self, ds: float) -> tuple[float, float, float, float, float]:
        u, v, up, vp, _, _ = self._uv_at(ds)  # as local, then the heading's cosine and sine
        c, s = self._cos, self._sin
        h = self.hdg + atan2(vp, up)
        return self.x + u * c - v * s, self.y + u * s + v * c, h, math.cos(h), math.sin(h)

    def curvature(self, ds: float) -> float:
        _, _, up, vp, upp, vpp = self._uv_at(ds)
        sp = hypot(up, vp)
        return 0.0 if sp == 0 else (up * vpp - vp * upp) / sp**3

    def frame_k(self, ds: float) -> tuple[float, float, float, float, float, float]:
        u, v, up, vp, upp, vpp = self._uv_at(ds)  # as frame and curvature
        c, s = self._cos, self._sin
        h = self.hdg + atan2(vp, up)
        sp = hypot(up, vp)
        k = 0.0 if sp == 0 else (up * vpp - vp * upp) / sp**3
        return self.x + u * c - v * s, self.y + u * s + v * c, h, math.cos(h), math.sin(h), k
