"""The report's figures, drawn with matplotlib (object API, no pyplot state) and returned as inline SVG.

Each function takes plain data and returns the `<svg>` element's text; nothing here reads the store.
"""

from __future__ import annotations

import html
import io
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from simcore.report.trajectories import Recording, RoadOutline

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


def distributions(values: Mapping[str, Sequence[float]], columns: int = 4) -> str:
    """One histogram per metric (small multiples)."""
    names = list(values)
    rows = max(1, math.ceil(len(names) / columns))
    fig = _figure(9.0, 1.9 * rows)
    for i, name in enumerate(names):
        ax = fig.add_subplot(rows, columns, i + 1)
        data = np.asarray(values[name], dtype=float)
        ax.hist(data, bins=min(20, max(5, len(data) // 2)), color="#1565c0")
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
    return _svg(fig, "metric distributions")


def heat_map(
    x_name: str,
    y_name: str,
    points: Sequence[tuple[float, float, bool]],
) -> str:
    """Share of passed runs over two swept parameters: one cell per value pair (the runs of the other
    parameters pooled, `passed/runs` written in it), or a scatter when either parameter has many values."""
    from matplotlib.colors import LinearSegmentedColormap

    fig = _figure(6.0, 4.0)
    ax = fig.add_subplot()
    xs = sorted({p[0] for p in points})
    ys = sorted({p[1] for p in points})
    cmap = LinearSegmentedColormap.from_list("passfail", [FAILED_COLOUR, "#fdd835", PASSED_COLOUR])
    if len(xs) <= 12 and len(ys) <= 12:
        passed = np.zeros((len(ys), len(xs)))
        runs = np.zeros((len(ys), len(xs)))
        for x, y, ok in points:
            j, i = xs.index(x), ys.index(y)
            runs[i, j] += 1
            passed[i, j] += ok
        share = np.divide(passed, runs, out=np.full_like(passed, np.nan), where=runs > 0)
        image = ax.imshow(share, cmap=cmap, vmin=0, vmax=1, origin="lower", aspect="auto")
        for i in range(len(ys)):
            for j in range(len(xs)):
                if runs[i, j]:
                    ax.text(
                        j,
                        i,
                        f"{passed[i, j]:.0f}/{runs[i, j]:.0f}",
                        ha="center",
                        va="center",
                        fontsize=9,
                        color="black",
                    )
        ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
    else:
        image = ax.scatter(
            [p[0] for p in points],
            [p[1] for p in points],
            c=[1.0 if p[2] else 0.0 for p in points],
            cmap=cmap,
            vmin=0,
            vmax=1,
            s=18,
        )
    fig.colorbar(image, ax=ax, label="share passed")
    ax.set_xlabel(x_name)
    ax.set_ylabel(y_name)
    ax.set_title(f"pass/fail over {x_name} × {y_name}", fontsize=10)
    return _svg(fig, f"pass/fail heat map over {x_name} and {y_name}")
