"""Flaky runs and determinism over the repeats of a point (`spec.execution.repeat`); pure functions but
`message_digest` and `recording_digests`, which read recordings. `carlos run` and the operator's
finalisation both flag runs through :func:`flag_repeats`.

A point (scenario, permutation, repetition) is run `repeat` times (repeats innermost in the index order).
It is *flaky* when its runs do not all have the same status. Runs of a point with the same seed
(`seedPolicy: same`) must record the same messages: same topics, log times and bytes, in order (the
recording's metadata, which names the index, aside); a point where they do not is *nondeterministic*.
"""

from __future__ import annotations

import hashlib
import io
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from simcore.store import Store


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


def recording_digests(store: Store, run: str) -> Callable[[int], str | None]:
    """`digest_of(index)` for :func:`flag_repeats`: the :func:`message_digest` of the run's
    `<index>/recording.mcap` in `store`, None when there is none or it cannot be read (not compared)."""

    def digest_of(index: int) -> str | None:
        key = f"{run}/{index}/recording.mcap"
        try:
            return message_digest(store.get_bytes(key)) if store.exists(key) else None
        except Exception:  # an unreadable recording is not compared (deterministic: None)
            return None

    return digest_of


class RepeatTally:
    """summary.json's `repeats`, built one point at a time (:func:`flag_repeats`): the counts, and the
    points with a flaky verdict or a determinism problem (only those are kept: bounded by what is wrong)."""

    def __init__(self, repeat: int) -> None:
        self.repeat = repeat
        self.points = self.flaky = self.checked = self.nondeterministic = 0
        self.listed: list[dict[str, Any]] = []

    def add(
        self, point: int, runs: Sequence[Mapping[str, Any]], digest_of: Callable[[int], str | None]
    ) -> bool:
        """Count one point's runs (index order); True when its verdict is flaky. `digest_of(index)` is asked
        only for runs that share their seed with another run of the point."""
        is_flaky = len({s["status"] for s in runs}) > 1
        seeds = [s.get("seed") for s in runs]
        groups: list[list[str]] = []  # the digests of the runs of each seed that more than one run has
        for seed in dict.fromkeys(seeds):
            if seeds.count(seed) > 1:
                found = [digest_of(int(s["index"])) for s in runs if s.get("seed") == seed]
                digests = [d for d in found if d is not None]
                if digests:
                    groups.append(digests)
        checked = any(len(g) > 1 for g in groups)
        deterministic = all(len(set(g)) == 1 for g in groups) if checked else None
        self.points += 1
        self.flaky += is_flaky
        self.nondeterministic += deterministic is False
        self.checked += deterministic is not None
        if is_flaky or deterministic is False:
            self.listed.append(
                {
                    "point": point,
                    "indexes": [int(s["index"]) for s in runs],
                    "statuses": [s["status"] for s in runs],
                    "seeds": seeds,
                    "flaky": is_flaky,
                    "deterministic": deterministic,
                }
            )
        return is_flaky

    def report(self) -> dict[str, Any]:
        return {
            "repeat": self.repeat,
            "points": self.points,
            "flaky": self.flaky,
            "determinismChecked": self.checked,
            "nondeterministic": self.nondeterministic,
            "flakyPoints": self.listed,
        }


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
    tally = RepeatTally(repeat)
    ordered = sorted(index_summaries, key=lambda s: int(s["index"]))
    for _ in flag_repeats(ordered, point_of, tally, digests.get):
        pass
    return tally.report()


def flag_repeats(
    index_summaries: Iterable[Mapping[str, Any]],
    point_of: Callable[[int], int],
    tally: RepeatTally,
    digest_of: Callable[[int], str | None],
) -> Iterator[dict[str, Any]]:
    """The summaries (in index order: a point's repeats are consecutive), each run of a flaky point with
    `flaky: true`, counted into `tally` as they pass; one point is held at a time (streams any run size).
    `digest_of(index)`: the recording's :func:`message_digest`, or None when it has none."""
    point: int | None = None
    runs: list[Mapping[str, Any]] = []

    def close() -> Iterator[dict[str, Any]]:
        assert point is not None
        flaky = tally.add(point, runs, digest_of)
        for s in runs:
            yield {**s, "flaky": True} if flaky else dict(s)

    for summary in index_summaries:
        p = point_of(int(summary["index"]))
        if runs and p != point:
            yield from close()
            runs = []
        point = p
        runs.append(summary)
    if runs:
        yield from close()


def flag_flaky(
    index_summaries: Iterable[dict[str, Any]], report: Mapping[str, Any]
) -> Iterator[dict[str, Any]]:
    """The summaries with `flaky: true` on every run of a flaky point of `report` (copies; pure)."""
    flagged = {i for p in report.get("flakyPoints", []) if p["flaky"] for i in p["indexes"]}
    return ({**s, "flaky": True} if int(s["index"]) in flagged else s for s in index_summaries)
