"""Plain-text lines for the terminal: what failed after a run, and progress for logs (no TTY)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from simcore.evaluation.criteria import format_number
from simcore.evaluation.report import testcase_name
from simcore.wording import plural

#: significant digits of the numbers a person reads (parameters of a search's points)
READ_DIGITS = 4


def failure_lines(index_summaries: Sequence[Mapping[str, Any]], limit: int = 20) -> list[str]:
    """One line per failed required criterion or error of the failed and errored indexes (optional
    scenarios marked), at most `limit` lines and a last line saying how many more (pure)."""
    lines: list[str] = []
    for s in sorted(index_summaries, key=lambda s: int(s["index"])):
        if s["status"] == "passed":
            continue
        tag = " (optional)" if s.get("optional") else ""
        if s["status"] == "error":
            lines.append(f"error  {testcase_name(s, READ_DIGITS)}{tag}: {s.get('error')}")
            continue
        for c in s.get("criteria", []):
            if c["passed"] or (c.get("optional") and not s.get("optional")):
                continue
            actual = "absent" if c.get("actual") is None else format_number(float(c["actual"]))
            detail = c.get("message") or f"{c['metric']} = {actual}, expected {c['expected']}"
            lines.append(f"failed {testcase_name(s, READ_DIGITS)}{tag}: {c['name']}: {detail}")
    if len(lines) > limit:
        lines = [*lines[:limit], f"… and {len(lines) - limit} more (see summary.json or report.html)"]
    return lines


def eta_seconds(done: int, total: int, elapsed: float) -> float | None:
    """Seconds left at the average pace so far; None before the first completion (pure)."""
    if done <= 0 or total <= done:
        return None if done <= 0 else 0.0
    return elapsed / done * (total - done)


def duration(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes, secs = divmod(round(seconds), 60)
    if minutes < 60:
        return f"{minutes} min {secs:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


class ProgressLines:
    """Progress as plain lines (for CI logs): one when the run starts, then one per completed index at
    most every `interval` seconds, and always the last one. `emit` writes a line."""

    def __init__(
        self,
        name: str,
        emit: Callable[[str], None],
        *,
        interval: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.name = name
        self.emit = emit
        self.interval = interval
        self.clock = clock
        self.started = clock()
        self.last = -float("inf")
        self.total = 0
        self.skipped = 0
        self.done = 0
        self.counts = {"passed": 0, "failed": 0, "error": 0}

    def start(self, total: int, skipped: int) -> None:
        self.total, self.skipped, self.started = total, skipped, self.clock()
        resumed = f" ({skipped} already complete)" if skipped else ""
        self.emit(f"{self.name}: {plural(total, 'run')}{resumed}")

    def index_done(self, status: str) -> None:
        self.done += 1
        self.counts[status if status in self.counts else "error"] += 1
        now = self.clock()
        finished = self.skipped + self.done >= self.total
        if not finished and now - self.last < self.interval:
            return
        self.last = now
        elapsed = now - self.started
        eta = eta_seconds(self.done, self.total - self.skipped, elapsed)
        c = self.counts
        self.emit(
            f"{self.name}: {self.skipped + self.done}/{self.total} done · passed {c['passed']} failed "
            f"{c['failed']} errors {c['error']} · {duration(elapsed)} elapsed"
            + ("" if eta is None or finished else f" · ETA {duration(eta)}")
        )
