"""The report's figures as inline SVG, written directly (no matplotlib: its import and layout cost seconds
per report): the bird's-eye plots, the sweep's heat map and the metric distributions.

Each function takes plain data and returns the `<svg>` element's text; nothing here reads the store.
"""

from __future__ import annotations

import bisect
import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

from simcore.report.trajectories import Recording, RoadOutline
from simcore.units import UNITS as UNITS  # the report reads plots.UNITS
from simcore.units import unit

PASSED_COLOUR = "#2e7d32"
FAILED_COLOUR = "#c62828"
ERROR_COLOUR = "#6a1b9a"
STATUS_COLOURS = {"passed": PASSED_COLOUR, "failed": FAILED_COLOUR, "error": ERROR_COLOUR}
_counter = iter(range(1, 1 << 62))


#: matplotlib's default line colours (tab10), so the plots look as they did when matplotlib drew them
LINE_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")


def _polyline_path(
    xs: Sequence[float], ys: Sequence[float], to_px: Any, keep: Sequence[bool] | None = None, tol: float = 0.6
) -> str:
    """An SVG path through the points (pixels via `to_px`), broken where `keep` is false and thinned to
    points at least `tol` pixels apart (pure)."""
    parts: list[str] = []
    last: tuple[float, float] | None = None
    pending: tuple[float, float] | None = None
    for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
        if (keep is not None and not keep[i]) or not (math.isfinite(x) and math.isfinite(y)):
            if pending is not None and last is not None:
                parts.append(f"L{pending[0]:.1f} {pending[1]:.1f}")
            last = pending = None
            continue
        px, py = to_px(float(x), float(y))
        if last is None:
            parts.append(f"M{px:.1f} {py:.1f}")
            last, pending = (px, py), None
        elif abs(px - last[0]) + abs(py - last[1]) >= tol:
            parts.append(f"L{px:.1f} {py:.1f}")
            last, pending = (px, py), None
        else:
            pending = (px, py)
    if pending is not None:
        parts.append(f"L{pending[0]:.1f} {pending[1]:.1f}")
    return "".join(parts)


def birds_eye(recording: Recording, road: RoadOutline | None, title: str, subtitle: str = "") -> str:
    """Every entity's trajectory over the road outline (cropped to the trajectories), the start of each
    trajectory as a dot, the minimum-distance moment as a dashed line between the two boxes' centres and
    every collision as a red cross; axes x and y in metres. Written as SVG directly (matplotlib's import
    and layout took seconds, more than a short run itself)."""
    tracks = list(recording.trajectories.values())
    all_x = [v for tr in tracks for v in tr.x] or [0.0]
    all_y = [v for tr in tracks for v in tr.y] or [0.0]
    margin = 10.0
    x0, x1, y0, y1 = min(all_x) - margin, max(all_x) + margin, min(all_y) - margin, max(all_y) + margin
    width, height = 864.0, 356.0
    px, py, pw, ph = 64.0, 46.0, 580.0, 262.0
    dx, dy = x1 - x0, y1 - y0
    if max(dx, dy) <= 5 * min(dx, dy):  # equal scale: widen the narrower side of the window
        scale = min(pw / dx, ph / dy)
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        x0, x1 = cx - pw / scale / 2, cx + pw / scale / 2
        y0, y1 = cy - ph / scale / 2, cy + ph / scale / 2
    else:
        title += " (lateral scale exaggerated)" if dx > dy else " (longitudinal scale exaggerated)"

    def to_px(x: float, y: float) -> tuple[float, float]:
        return px + (x - x0) / (x1 - x0) * pw, py + ph - (y - y0) / (y1 - y0) * ph

    out = _open_svg(width, height, f"bird's-eye view: {title}")
    clip = f"be{next(_counter)}"
    out.append(
        f'<defs><clipPath id="{clip}"><rect x="{px}" y="{py}" width="{pw}" height="{ph}"/></clipPath></defs>'
    )
    out.append(f'<g clip-path="url(#{clip})" fill="none" stroke-linejoin="round" stroke-linecap="round">')
    if road is not None:
        for lines, style in (
            (road.lanes, 'stroke="#9e9e9e" stroke-width="0.8" stroke-dasharray="4 3"'),
            (road.edges, 'stroke="#424242" stroke-width="1.3"'),
        ):
            for lx, ly in lines:
                keep = [
                    x0 <= x <= x1 and y0 <= y <= y1 for x, y in zip(lx.tolist(), ly.tolist(), strict=True)
                ]
                if sum(keep) >= 2:
                    path = _polyline_path(lx.tolist(), ly.tolist(), to_px, keep)
                    out.append(f'<path d="{path}" {style}/>')
    legend: list[tuple[str, str]] = []
    for k, track in enumerate(tracks):
        colour = LINE_COLOURS[k % len(LINE_COLOURS)]
        is_ego = track.name == recording.ego
        path = _polyline_path(track.x, track.y, to_px)
        out.append(f'<path d="{path}" stroke="{colour}" stroke-width="{2.9 if is_ego else 2.0}"/>')
        legend.append((colour, f"{track.name} (ego)" if is_ego else track.name))
    out.append("</g>")
    for k, track in enumerate(tracks):
        if track.x:
            sx, sy = to_px(track.x[0], track.y[0])
            out.append(
                f'<circle cx="{sx:.1f}" cy="{sy:.1f}" r="3.5" fill="{LINE_COLOURS[k % len(LINE_COLOURS)]}"/>'
            )
    closest = recording.closest
    if closest is not None:
        (ex, ey), (ox, oy) = to_px(*closest.ego_xy), to_px(*closest.other_xy)
        out.append(
            f'<path d="M{ex:.1f} {ey:.1f}L{ox:.1f} {oy:.1f}" stroke="#000" stroke-width="1.2" '
            'stroke-dasharray="5 3"/>'
        )
        for cx_, cy_ in ((ex, ey), (ox, oy)):
            out.append(f'<circle cx="{cx_:.1f}" cy="{cy_:.1f}" r="2.8" fill="#000"/>')
        legend.append(("#000", f"closest: {closest.distance:.2f} m"))
        legend.append(("", f"to {closest.other}, t={closest.time:.2f} s"))
    for hit in recording.collisions:
        hx, hy = to_px(*hit.ego_xy)
        out.append(
            f'<path d="M{hx - 6:.1f} {hy - 6:.1f}l12 12M{hx - 6:.1f} {hy + 6:.1f}l12 -12" '
            f'stroke="{FAILED_COLOUR}" stroke-width="2.5"/>'
        )
    if recording.collisions:
        legend.append((FAILED_COLOUR, f"collision ({len(recording.collisions)})"))
    out.append(_frame(px, py, pw, ph))
    for tick in _ticks(x0, x1, 7):
        tx = to_px(tick, y0)[0]
        out.append(f'<path d="M{tx:.2f} {py + ph:.2f}v4" stroke="#212121" stroke-width="0.8"/>')
        out.append(_text(tx, py + ph + 15.0, f"{tick:g}", size=8))
    for tick in _ticks(y0, y1, 5):
        ty = to_px(x0, tick)[1]
        out.append(f'<path d="M{px:.2f} {ty:.2f}h-4" stroke="#212121" stroke-width="0.8"/>')
        out.append(_text(px - 7.0, ty + 3.0, f"{tick:g}", size=8, anchor="end"))
    out.append(_text(px + pw / 2, py + ph + 34.0, "x (m)", size=10))
    out.append(
        _text(18.0, py + ph / 2, "y (m)", size=10, extra=f' transform="rotate(-90 18 {py + ph / 2:.1f})"')
    )
    out.append(_text(8.0, 16.0, title, size=10, anchor="start", extra=' font-weight="bold"'))
    if subtitle:
        out.append(_text(8.0, 32.0, subtitle, size=9, anchor="start"))
    key_x = px + pw + 16.0
    for k, (colour, label) in enumerate(legend[:14]):
        key_y = py + 10.0 + k * 18.0
        if colour:
            out.append(f'<path d="M{key_x:.1f} {key_y:.1f}h18" stroke="{colour}" stroke-width="2.5"/>')
        out.append(_text(key_x + 24.0, key_y + 3.5, label, size=8.5, anchor="start"))
    out.append("</svg>")
    return "".join(out)


# --- the sweep's figures, written as SVG directly (matplotlib's import and layout cost seconds per report,
# more than the whole of a short sweep's runs)

_FONT = 'font-family="DejaVu Sans, Arial, sans-serif"'
#: the pass/fail colour scale: share passed 0 → 0.5 → 1
_SCALE = ((0xC6, 0x28, 0x28), (0xFD, 0xD8, 0x35), (0x2E, 0x7D, 0x32))


def share_colour(share: float) -> str:
    """The colour of a share of passed runs (0..1) on the failed → yellow → passed scale (pure)."""
    share = min(max(share, 0.0), 1.0)
    low, high, f = (
        (_SCALE[0], _SCALE[1], share * 2.0) if share <= 0.5 else (_SCALE[1], _SCALE[2], share * 2.0 - 1.0)
    )
    return "#" + "".join(f"{round(a + (b - a) * f):02x}" for a, b in zip(low, high, strict=True))


def _open_svg(width: float, height: float, label: str) -> list[str]:
    return [
        f'<svg role="img" aria-label="{html.escape(label)}" class="plot" xmlns="http://www.w3.org/2000/svg" '
        f'width="{width:.0f}" height="{height:.0f}" viewBox="0 0 {width:.0f} {height:.0f}">',
        f'<rect width="{width:.0f}" height="{height:.0f}" fill="white"/>',
    ]


def _text(x: float, y: float, text: str, *, size: float = 10, anchor: str = "middle", extra: str = "") -> str:
    return (
        f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size:g}" text-anchor="{anchor}" {_FONT}{extra}>'
        f"{html.escape(text)}</text>"
    )


def _box(x: float, y: float, w: float, h: float, fill: str, extra: str = "") -> str:
    return f'<path d="M{x:.2f} {y:.2f}h{w:.2f}v{h:.2f}h{-w:.2f}z" fill="{fill}"{extra}/>'


def _ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    """Round tick values within [lo, hi] (pure)."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    raw = (hi - lo) / max(count - 1, 1)
    magnitude = 10 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    return [round(first + i * step, 12) for i in range(int((hi - first) / step + 1e-9) + 1)]


def _frame(x: float, y: float, w: float, h: float) -> str:
    return f'<path d="M{x:.2f} {y:.2f}h{w:.2f}v{h:.2f}h{-w:.2f}z" fill="none" stroke="#212121" stroke-width="0.8"/>'


def axis_label(metric: str) -> str:
    """`minDistance (m)`: the metric with its unit when known (pure)."""
    u = unit(metric)
    return f"{metric} ({u})" if u else metric


def histogram(values: Sequence[float], bins: int) -> tuple[list[int], list[float]]:
    """(counts, edges) of `bins` equal bins from the least to the greatest value: what `numpy.histogram(values,
    bins)` gives, the same edges (`numpy.linspace`'s: ``i * step + least``, the last the greatest) and counts
    (each bin half-open but the last), without importing numpy (a report of a sweep without recordings
    needs it for nothing else: ~0.07 s of `carlos run`'s end). One value: the bins span it ± 0.5. A value
    that is not finite is a ValueError, as numpy raises."""
    if bins < 1:
        raise ValueError(f"bins must be positive, not {bins}")
    if not values:
        least, greatest = 0.0, 1.0
    else:
        if not all(math.isfinite(v) for v in values):
            raise ValueError("autodetected range of the values is not finite")
        least, greatest = float(min(values)), float(max(values))
    if least == greatest:
        least, greatest = least - 0.5, greatest + 0.5
    step = (greatest - least) / bins
    edges = [i * step + least for i in range(bins)] + [greatest]
    counts = [0] * bins
    for value in values:
        i = bisect.bisect_right(edges, value) - 1
        counts[min(i, bins - 1)] += 1  # the greatest value: in the last bin, which is closed
    return counts, edges


def distributions(values: Mapping[str, Sequence[float]], columns: int = 4) -> str:
    """One histogram per metric (small multiples): x the metric's value with its unit, y the number of
    runs."""
    names = list(values)
    rows = max(1, math.ceil(len(names) / columns))
    cell_w, cell_h = 864.0 / columns, 196.0
    out = _open_svg(864.0, cell_h * rows, "metric distributions")
    for i, name in enumerate(names):
        ox, oy = (i % columns) * cell_w, (i // columns) * cell_h
        px, py, pw, ph = ox + 40.0, oy + 24.0, cell_w - 52.0, cell_h - 64.0
        data = [float(v) for v in values[name]]
        counts, edges = histogram(data, bins=min(20, max(5, len(data) // 2)))
        top = max(max(counts), 1)
        span = float(edges[-1] - edges[0]) or 1.0
        out.append(_text(ox + cell_w / 2, oy + 14.0, name, size=9))
        out.append(_text(px + pw / 2, py + ph + 26.0, axis_label(name), size=8))
        label_x, label_y = ox + 10.0, py + ph / 2
        out.append(
            _text(
                label_x,
                label_y,
                "runs",
                size=8,
                extra=f' transform="rotate(-90 {label_x:.1f} {label_y:.1f})"',
            )
        )
        for count, left, right in zip(counts, edges[:-1], edges[1:], strict=True):
            if count:
                bx = px + (float(left) - float(edges[0])) / span * pw
                bw = (float(right) - float(left)) / span * pw
                bh = count / top * ph
                out.append(_box(bx, py + ph - bh, bw, bh, "#1565c0"))
        out.append(_frame(px, py, pw, ph))
        for tick in _ticks(float(edges[0]), float(edges[-1]), 4):
            tx = px + (tick - float(edges[0])) / span * pw
            out.append(f'<path d="M{tx:.2f} {py + ph:.2f}v3" stroke="#212121" stroke-width="0.8"/>')
            out.append(_text(tx, py + ph + 12.0, f"{tick:g}", size=7))
        for tick in _ticks(0.0, float(top), 3):
            ty = py + ph - tick / top * ph
            out.append(f'<path d="M{px:.2f} {ty:.2f}h-3" stroke="#212121" stroke-width="0.8"/>')
            out.append(_text(px - 5.0, ty + 2.5, f"{tick:g}", size=7, anchor="end"))
    out.append("</svg>")
    return "".join(out)


def heat_map(
    x_name: str,
    y_name: str,
    points: Sequence[tuple[float, float, bool]],
) -> str:
    """Share of passed runs over two swept parameters: one cell per value pair (the runs of the other
    parameters pooled, `passed/runs` written in it), or a scatter when either parameter has many values."""
    width, height = 576.0, 384.0
    px, py, pw, ph = 72.0, 30.0, 400.0, 300.0
    out = _open_svg(width, height, f"pass/fail heat map over {x_name} and {y_name}")
    out.append(_text(px + pw / 2, 18.0, f"pass/fail over {x_name} × {y_name}"))
    xs = sorted({p[0] for p in points})
    ys = sorted({p[1] for p in points})
    if len(xs) <= 12 and len(ys) <= 12:
        tally: dict[tuple[int, int], list[int]] = {}
        for x, y, ok in points:
            cell = tally.setdefault((xs.index(x), ys.index(y)), [0, 0])
            cell[0] += ok
            cell[1] += 1
        cw, ch = pw / len(xs), ph / len(ys)
        for (j, i), (passed, runs) in sorted(tally.items()):
            cx, cy = px + j * cw, py + ph - (i + 1) * ch
            out.append(_box(cx, cy, cw, ch, share_colour(passed / runs)))
            out.append(_text(cx + cw / 2, cy + ch / 2 + 3.5, f"{passed}/{runs}", size=9))
        x_ticks = [(px + (j + 0.5) * cw, f"{v:g}") for j, v in enumerate(xs)]
        y_ticks = [(py + ph - (i + 0.5) * ch, f"{v:g}") for i, v in enumerate(ys)]
    else:

        def scale(v: float, lo: float, hi: float, size: float) -> float:
            return (v - lo) / (hi - lo) * size if hi > lo else size / 2

        x_lo, x_hi, y_lo, y_hi = xs[0], xs[-1], ys[0], ys[-1]
        for x, y, ok in points:
            cx, cy = px + 6 + scale(x, x_lo, x_hi, pw - 12), py + ph - 6 - scale(y, y_lo, y_hi, ph - 12)
            out.append(
                f'<path d="M{cx - 2.4:.2f} {cy:.2f}a2.4 2.4 0 1 0 4.8 0a2.4 2.4 0 1 0 -4.8 0z" '
                f'fill="{share_colour(1.0 if ok else 0.0)}"/>'
            )
        x_ticks = [(px + 6 + scale(v, x_lo, x_hi, pw - 12), f"{v:g}") for v in _ticks(x_lo, x_hi)]
        y_ticks = [(py + ph - 6 - scale(v, y_lo, y_hi, ph - 12), f"{v:g}") for v in _ticks(y_lo, y_hi)]
    out.append(_frame(px, py, pw, ph))
    for tx, label in x_ticks:
        out.append(f'<path d="M{tx:.2f} {py + ph:.2f}v4" stroke="#212121" stroke-width="0.8"/>')
        out.append(_text(tx, py + ph + 15.0, label, size=8))
    for ty, label in y_ticks:
        out.append(f'<path d="M{px:.2f} {ty:.2f}h-4" stroke="#212121" stroke-width="0.8"/>')
        out.append(_text(px - 7.0, ty + 3.0, label, size=8, anchor="end"))
    out.append(_text(px + pw / 2, height - 10.0, x_name))
    out.append(_text(16.0, py + ph / 2, y_name, extra=f' transform="rotate(-90 16 {py + ph / 2:.1f})"'))
    # the colour bar
    bx, bw, steps = px + pw + 24.0, 14.0, 20
    for k in range(steps):
        out.append(_box(bx, py + ph - (k + 1) * ph / steps, bw, ph / steps, share_colour((k + 0.5) / steps)))
    out.append(_frame(bx, py, bw, ph))
    for value in (0.0, 0.5, 1.0):
        out.append(_text(bx + bw + 4.0, py + ph - value * ph + 3.0, f"{value:g}", size=8, anchor="start"))
    out.append(
        _text(bx + bw + 36.0, py + ph / 2, "share passed", size=9,
              extra=f' transform="rotate(90 {bx + bw + 36.0:.1f} {py + ph / 2:.1f})"')
    )  # fmt: skip
    out.append("</svg>")
    return "".join(out)
