"""The report's figures as inline SVG: the bird's-eye plots drawn with matplotlib (object API, no pyplot
state), the sweep's heat map and metric distributions written directly.

Each function takes plain data and returns the `<svg>` element's text; nothing here reads the store.
"""

from __future__ import annotations

import html
import io
import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from simcore.report.trajectories import Recording, RoadOutline

if TYPE_CHECKING:  # numpy is imported by the figures that need it (a run's report without them does not)
    import numpy as np

PASSED_COLOUR = "#2e7d32"
FAILED_COLOUR = "#c62828"
ERROR_COLOUR = "#6a1b9a"
STATUS_COLOURS = {"passed": PASSED_COLOUR, "failed": FAILED_COLOUR, "error": ERROR_COLOUR}
_SVG_START = re.compile(r"^.*?(?=<svg)", re.DOTALL)
_counter = iter(range(1, 1 << 62))


def _svg(fig: Any, label: str) -> str:
    """The figure as an `<svg>` element (text as text, ids made unique within the page)."""
    import matplotlib

    buffer = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": f"carlos{next(_counter)}"}):
        fig.savefig(buffer, format="svg", bbox_inches="tight")
    text = _SVG_START.sub("", buffer.getvalue(), count=1)
    return text.replace("<svg ", f'<svg role="img" aria-label="{html.escape(label)}" class="plot" ', 1)


def _figure(width: float, height: float) -> Any:
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=96, layout="constrained")


def _window(xs: np.ndarray, ys: np.ndarray, box: tuple[float, float, float, float]) -> np.ndarray:
    x0, x1, y0, y1 = box
    return (xs >= x0) & (xs <= x1) & (ys >= y0) & (ys <= y1)


def birds_eye(recording: Recording, road: RoadOutline | None, title: str) -> str:
    """Every entity's trajectory over the road outline (cropped to the trajectories), the start of each
    trajectory as a dot, the minimum-distance moment as a dashed line between the two boxes' centres and
    every collision as a red cross."""
    import numpy as np

    fig = _figure(9.0, 3.4)
    ax = fig.add_subplot()
    xs = np.concatenate([np.asarray(tr.x) for tr in recording.trajectories.values()] or [np.zeros(1)])
    ys = np.concatenate([np.asarray(tr.y) for tr in recording.trajectories.values()] or [np.zeros(1)])
    margin = 10.0
    box = (xs.min() - margin, xs.max() + margin, ys.min() - margin, ys.max() + margin)
    if road is not None:
        for lines, style in (
            (road.lanes, {"color": "#9e9e9e", "lw": 0.6, "ls": "--"}),
            (road.edges, {"color": "#424242", "lw": 1.0, "ls": "-"}),
        ):
            for lx, ly in lines:
                keep = _window(lx, ly, box)
                if keep.sum() >= 2:
                    ax.plot(np.where(keep, lx, np.nan), np.where(keep, ly, np.nan), zorder=1, **style)
    for name, track in recording.trajectories.items():
        is_ego = name == recording.ego
        (line,) = ax.plot(
            track.x, track.y, lw=2.2 if is_ego else 1.5, zorder=3, label=f"{name} (ego)" if is_ego else name
        )
        ax.plot(track.x[:1], track.y[:1], "o", color=line.get_color(), ms=5, zorder=4)
    closest = recording.closest
    if closest is not None:
        (ex, ey), (ox, oy) = closest.ego_xy, closest.other_xy
        ax.plot([ex, ox], [ey, oy], "k--", lw=1.0, zorder=5)
        ax.plot(
            [ex, ox],
            [ey, oy],
            "ko",
            ms=4,
            zorder=5,
            label=f"closest: {closest.distance:.2f} m to {closest.other} at t={closest.time:.2f} s",
        )
    for i, hit in enumerate(recording.collisions):
        ax.plot(
            *hit.ego_xy,
            "x",
            color=FAILED_COLOUR,
            ms=11,
            mew=2.5,
            zorder=6,
            label="collision" if i == 0 else None,
        )
    width, height = box[1] - box[0], box[3] - box[2]
    if max(width, height) <= 5 * min(width, height):
        ax.set_aspect("equal", adjustable="box")
    else:
        title += " (lateral scale exaggerated)" if width > height else " (longitudinal scale exaggerated)"
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="best")
    return _svg(fig, f"bird's-eye view: {title}")


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


def distributions(values: Mapping[str, Sequence[float]], columns: int = 4) -> str:
    """One histogram per metric (small multiples)."""
    import numpy as np

    names = list(values)
    rows = max(1, math.ceil(len(names) / columns))
    cell_w, cell_h = 864.0 / columns, 182.0
    out = _open_svg(864.0, cell_h * rows, "metric distributions")
    for i, name in enumerate(names):
        ox, oy = (i % columns) * cell_w, (i // columns) * cell_h
        px, py, pw, ph = ox + 34.0, oy + 24.0, cell_w - 46.0, cell_h - 50.0
        data = np.asarray(values[name], dtype=float)
        counts, edges = np.histogram(data, bins=min(20, max(5, len(data) // 2)))
        top = max(int(counts.max()), 1)
        span = float(edges[-1] - edges[0]) or 1.0
        out.append(_text(ox + cell_w / 2, oy + 14.0, name, size=9))
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
