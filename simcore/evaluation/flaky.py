"""Flaky runs and determinism over the repeats of a point (`spec.execution.repeat`); pure functions but
`message_digest`, which reads a recording's bytes.

A point (scenario, permutation, repetition) is run `repeat` times (repeats innermost in the index order).
It is *flaky* when its runs do not all have the same status. Runs of a point with the same seed
(`seedPolicy: same`) must record the same messages: same topics, log times and bytes, in order (the
recording's metadata, which names the index, aside); a point where they do not is *nondeterministic*.
"""

from __future__ import annotations

import hashlib
import io
from collections.abc import Callable, Mapping, Sequence
from typing import Any


def message_digest(data: bytes) -> str:
    """SHA-256 over every message of an MCAP recording (topic, log time, bytes, in order): equal for two
    recordings of the same simulation whatever their metadata."""
    from mcap.reader import make_reader

    digest = hashlib.sha256()
    reader = make_reader(io.BytesIO(data))
    for _schema, channel, message in reader.iter_messages(log_time_order=False):
        digest.update(channel.topic.encode())
        digest.update(message.log_time.to_bytes(8, "little"))
        digest.update(len(message.data).to_bytes(8, "little"))
        digest.update(message.data)
    return digest.hexdigest()


def repeat_report(
    index_summaries: Sequence[Mapping[str, Any]],
    point_of: Callable[[int], int],
    repeat: int,
    digests: Mapping[int, str],
) -> dict[str, Any]:
    """summary.json's `repeats`: `repeat`, the counts of `flaky` and `nondeterministic` points and, for
    each point with a flaky verdict or a determinism problem, its indexes, statuses, seeds and whether it
    is `flaky` and `deterministic` (None: not checked, fewer than two recordings with one seed). Points in
    index order (pure)."""
    points: dict[int, list[Mapping[str, Any]]] = {}
    for summary in sorted(index_summaries, key=lambda s: int(s["index"])):
        points.setdefault(point_of(int(summary["index"])), []).append(summary)
    listed = []
    flaky = nondeterministic = checked = 0
    for point, runs in points.items():
        is_flaky = len({s["status"] for s in runs}) > 1
        by_seed: dict[Any, set[str]] = {}
        for s in runs:
            if int(s["index"]) in digests:
                by_seed.setdefault(s.get("seed"), set()).add(digests[int(s["index"])])
        compared = [d for d in by_seed.values() if d]
        has_pairs = any(
            sum(1 for s in runs if s.get("seed") == seed and int(s["index"]) in digests) > 1
            for seed in by_seed
        )
        deterministic = all(len(d) == 1 for d in compared) if has_pairs else None
        flaky += is_flaky
        nondeterministic += deterministic is False
        checked += deterministic is not None
        if is_flaky or deterministic is False:
            listed.append(
                {
                    "point": point,
                    "indexes": [int(s["index"]) for s in runs],
                    "statuses": [s["status"] for s in runs],
                    "seeds": [s.get("seed") for s in runs],
                    "flaky": is_flaky,
                    "deterministic": deterministic,
                }
            )
    return {
        "repeat": repeat,
        "points": len(points),
        "flaky": flaky,
        "determinismChecked": checked,
        "nondeterministic": nondeterministic,
        "flakyPoints": listed,
    }


def flag_flaky(index_summaries: Sequence[dict[str, Any]], report: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The summaries with `flaky: true` on every run of a flaky point (copies; pure)."""
    flagged = {i for p in report.get("flakyPoints", []) if p["flaky"] for i in p["indexes"]}
    return [{**s, "flaky": True} if int(s["index"]) in flagged else s for s in index_summaries]
