"""The run-level search.json (pure): points, best, failing ones, failure-region share, rounds."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from simcore.search.space import Dimension
from simcore.spec import Search

#: z of a two-sided 95 % interval
_Z = 1.959964


def wilson(successes: int, samples: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of a proportion."""
    if samples == 0:
        return 0.0, 1.0
    p = successes / samples
    denominator = 1 + _Z**2 / samples
    centre = (p + _Z**2 / (2 * samples)) / denominator
    half = _Z * math.sqrt(p * (1 - p) / samples + _Z**2 / (4 * samples**2)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def search_document(
    run_name: str, search: Search, seed: int, space: Sequence[Dimension], points: Sequence[dict[str, Any]]
) -> dict[str, Any]:
    """`points`: {index, round, parameters, status, objective, explore} in index order. The failure share
    is estimated from the exploration points (uniform over the space: every point of random and lhs, the
    first round of the adaptive strategies)."""
    sign = 1.0 if search.objective.direction == "minimize" else -1.0
    measured = [p for p in points if p["objective"] is not None]
    best = min(measured, key=lambda p: sign * p["objective"]) if measured else None
    failing = [p for p in points if p["status"] == "failed"]
    explore = [p for p in points if p["explore"]]
    explore_failed = sum(1 for p in explore if p["status"] == "failed")
    low, high = wilson(explore_failed, len(explore))
    rounds: list[dict[str, Any]] = []
    for number in sorted({p["round"] for p in points}):
        these = [p for p in points if p["round"] == number]
        values = [sign * p["objective"] for p in these if p["objective"] is not None]
        rounds.append(
            {
                "round": number,
                "runs": len(these),
                "failures": sum(1 for p in these if p["status"] == "failed"),
                "bestObjective": sign * min(values) if values else None,
            }
        )
    return {
        "run": run_name,
        "strategy": search.strategy,
        "objective": {"metric": search.objective.metric, "direction": search.objective.direction},
        "seed": seed,
        "budget": search.budget,
        "batchSize": search.batch_size,
        "space": [
            {"name": d.name, "values": list(d.choices)}
            if d.choices is not None
            else {"name": d.name, "min": d.low, "max": d.high, "integer": d.integer}
            for d in space
        ],
        "runs": len(points),
        "failures": len(failing),
        "errors": sum(1 for p in points if p["status"] == "error"),
        "verdict": "failed" if failing else "passed",
        "best": best,
        "failing": [p["index"] for p in failing],
        "failureShare": {
            "estimate": explore_failed / len(explore) if explore else None,
            "low95": low,
            "high95": high,
            "samples": len(explore),
        },
        "rounds": rounds,
        "points": list(points),
    }
