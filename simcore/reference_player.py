"""The esmini player as a reference for `carlos conformance --against esmini` (differential testing).

esmini (github esmini/esmini, MPL-2.0) is not part of CARLOS: it is found through `--esmini PATH` or the
`ESMINI` environment variable, run headless at the conformance step (0.05 s, seed 1) in a scratch directory,
and its `--csv_logger` output (a few lines of build information, a header naming a block of columns per
entity, one line per step) is read into the same tracks as the corpus' reference CSVs: entity name →
[(time, x, y)] every 0.1 s of simulated time, and the end time (the last logged step).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

ENV = "ESMINI"
WALL_TIMEOUT_S = 60.0
Tracks = dict[str, list[tuple[float, float, float]]]


@dataclass
class PlayerRun:
    """What the reference player made of one scenario: `ok` with tracks and end time, or a message."""

    ok: bool
    tracks: Tracks = field(default_factory=dict)
    end: float | None = None
    message: str = ""


def find_esmini(explicit: Path | None = None) -> Path | None:
    """The esmini binary: `explicit`, else $ESMINI, else `esmini` on PATH; None when there is none."""
    for candidate in (explicit, os.environ.get(ENV) or None, shutil.which("esmini")):
        if candidate and Path(candidate).is_file() and os.access(candidate, os.X_OK):
            return Path(candidate).resolve()  # esmini runs in a scratch directory: a relative path must not
    return None


def _on_period(t: float, period: float) -> bool:
    return abs(t / period - round(t / period)) < 1e-6


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_csv(text: str, period: float = 0.1) -> tuple[Tracks, float | None]:
    """esmini's --csv_logger text → (entity name → [(time, x, y)] at every `period` s, last time stamp)."""
    lines = text.splitlines()
    header_at = next((i for i, line in enumerate(lines) if line.startswith("Index [-]")), None)
    if header_at is None:
        raise ValueError("no header line (Index [-], TimeStamp [s], …) in the esmini CSV")
    header = [c.strip() for c in lines[header_at].split(",")]
    first = [i for i, c in enumerate(header) if c.startswith("#1 ")]
    if not first:
        raise ValueError("no entity columns (#1 …) in the esmini CSV header")
    start = first[0]
    names = [header[i][3:] for i in first]
    second = [i for i, c in enumerate(header) if c.startswith("#2 ")]
    width = (second[0] - start) if second else len(first) + 1  # blocks are separated by an empty column
    at_name = names.index("Entity_Name [-]")
    at_x = names.index("World_Position_X [m]")
    at_y = names.index("World_Position_Y [m]")
    tracks: Tracks = {}
    end: float | None = None
    for line in lines[header_at + 1 :]:
        cells = [c.strip() for c in line.split(",")]
        if len(cells) < 3:
            continue
        if _is_number(cells[2]):
            # no entity in the world: esmini writes only (index, time) pairs, all on one line
            end = float(cells[-2] if cells[-1] == "" else cells[-1])
            continue
        t = float(cells[1])
        end = t
        if not _on_period(t, period):
            continue
        for block in range(start, len(cells) - at_y, width):
            name = cells[block + at_name]
            if not name:
                continue
            track = tracks.setdefault(name, [])
            if track and round(t, 6) <= track[-1][0]:
                # a ghost restart: esmini's clock goes back by the head start while only the ghost moves;
                # the first pass over those times is the one the scenario's time line has
                continue
            track.append((round(t, 6), float(cells[block + at_x]), float(cells[block + at_y])))
    return tracks, end


def run_esmini(esmini: Path, scenario: Path, *, step: float = 0.05, seed: int = 1) -> PlayerRun:
    """Run `scenario` headless through `esmini` in a scratch directory and read its trajectories."""
    with tempfile.TemporaryDirectory(prefix="carlos-esmini-") as scratch:
        out = Path(scratch) / "out.csv"
        command = [
            str(esmini.resolve()),  # relative to the caller's directory, not to the scratch directory
            "--headless",
            "--fixed_timestep",
            f"{step:g}",
            "--osc",
            str(scenario.resolve()),
            "--disable_stdout",
            "--disable_log",
            "--csv_logger",
            str(out),
            "--seed",
            str(seed),
        ]
        try:
            done = subprocess.run(
                command, cwd=scratch, capture_output=True, text=True, timeout=WALL_TIMEOUT_S
            )
        except subprocess.TimeoutExpired:
            return PlayerRun(False, message=f"esmini did not end within {WALL_TIMEOUT_S:g} s wall")
        except OSError as exc:
            return PlayerRun(False, message=f"esmini could not start: {exc}")
        if done.returncode != 0 or not out.is_file():
            tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or [""]
            return PlayerRun(False, message=f"esmini failed (exit {done.returncode}) {tail[0][:160]}".strip())
        try:
            tracks, end = parse_csv(out.read_text(errors="replace"))
        except (ValueError, IndexError) as exc:
            return PlayerRun(False, message=f"unreadable esmini CSV: {exc}")
        if end is None:
            return PlayerRun(False, message="esmini logged no step")
        return PlayerRun(True, tracks, end)
