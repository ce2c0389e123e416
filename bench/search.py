"""Adaptive search versus a grid sweep and uniform random sampling: failures found per 100 runs.

The space: the cut-in (examples/scenarios/cut-in.xosc) over CutInGap [0.5, 20] m, AdversaryDeceleration
[1, 9] m/s² and EgoSpeed [20, 30] m/s, Adversary overtaking at 35 m/s, changing lanes in 1.5 s and braking to
5 m/s; a run fails on a collision or a time to collision under 1 s (`collision == 0`,
`minTimeToCollision >= 1.0`). Ego is SUMO's car-following model.

- ground truth: a dense grid (BENCH_DENSE values per axis, default 8: 512 runs) gives the failure share;
- grid: the sweep a user would write with the same budget (BENCH_BUDGET, default 125: 5 values per axis);
- random: `spec.search` strategy random, same budget;
- tpe: `spec.search` strategy tpe, same budget, rounds of 16 (the first one uniform);
- overhead: a tpe search of two rounds of 64: seconds in the optimiser (loading the study, 64 asks, 64
  tells) as a share of the round's simulation seconds (the round's wall time without the optimiser).

All runs go through `carlos run`'s pipeline (local executor, warm workers, 2 by default: BENCH_WORKERS).
Prints a table and, as its last line, one JSON object with `failuresVsGrid` and `failuresVsRandom` (the
tpe search's failures per 100 runs over the grid's and random's; a baseline that found none counts as one
failure, so the ratio is then a lower bound). No assertions: machines are noisy.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore.executor import execute  # noqa: E402
from simcore.manifest import parse_manifest  # noqa: E402
from simcore.search.driver import SearchReport, run_search  # noqa: E402

SCENARIO = ROOT / "examples" / "scenarios" / "cut-in.xosc"
AXES = {"CutInGap": (0.5, 20.0), "AdversaryDeceleration": (1.0, 9.0), "EgoSpeed": (20.0, 30.0)}
FIXED = {"AdversarySpeed": 35.0, "LaneChangeTime": 1.5, "AdversaryEndSpeed": 5.0, "StopDelay": 2.0}
DENSE = int(os.environ.get("BENCH_DENSE", "8"))
BUDGET = int(os.environ.get("BENCH_BUDGET", "125"))
WORKERS = int(os.environ.get("BENCH_WORKERS", "2"))
BATCH = int(os.environ.get("BENCH_BATCH", "64"))


def _run(name: str, extra: dict[str, Any]) -> Any:
    return parse_manifest(
        {
            "apiVersion": "carlos.dev/v1alpha1",
            "kind": "SimulationRun",
            "metadata": {"name": name},
            "spec": {
                "scenarios": [{"name": "cut-in", "openscenario": str(SCENARIO), "parameters": FIXED}],
                "evaluation": {"criteria": ["collision == 0", "minTimeToCollision >= 1.0"]},
                "simulation": {"maxSeconds": 40},
                "recording": {"enabled": False},
                **extra,
            },
        },
        source=name,
    )


def _grid(name: str, per_axis: int, out: str) -> tuple[int, int, float]:
    matrix = {
        axis: [low + (high - low) * k / (per_axis - 1) for k in range(per_axis)]
        for axis, (low, high) in AXES.items()
    }
    started = time.monotonic()
    report = execute(
        _run(name, {"sweep": {"matrix": matrix}}), base_dir=ROOT, output_url=out, parallel=WORKERS
    )
    counts = report.summary["counts"]
    return counts["total"], counts["failed"], time.monotonic() - started


def _search(name: str, strategy: str, budget: int, batch: int, out: str) -> tuple[SearchReport, float]:
    space = [{"name": axis, "min": low, "max": high} for axis, (low, high) in AXES.items()]
    search = {"parameters": space, "strategy": strategy, "budget": budget, "batchSize": batch, "seed": 1}
    started = time.monotonic()
    report = run_search(
        _run(name, {"search": search}),
        base_dir=ROOT,
        scenario_file=SCENARIO,
        output_url=out,
        parallel=WORKERS,
    )
    return report, time.monotonic() - started


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="carlos-bench-search-") as scratch:
        out = f"file://{scratch}"
        per_axis = max(2, round(BUDGET ** (1 / len(AXES))))
        dense_runs, dense_failed, dense_s = _grid("dense", DENSE, out)
        grid_runs, grid_failed, grid_s = _grid("grid", per_axis, out)
        random_report, random_s = _search("random", "random", BUDGET, 25, out)
        tpe_report, tpe_s = _search("tpe", "tpe", BUDGET, 16, out)
        batch_report, _ = _search("overhead", "tpe", 2 * BATCH, BATCH, out)
    rows = [
        ("dense grid (truth)", dense_runs, dense_failed, dense_s),
        (f"grid {per_axis}^{len(AXES)}", grid_runs, grid_failed, grid_s),
        ("random", random_report.document["runs"], random_report.document["failures"], random_s),
        ("tpe (rounds of 16)", tpe_report.document["runs"], tpe_report.document["failures"], tpe_s),
    ]
    print(f"{'method':<22}{'runs':>6}{'failures':>10}{'per 100 runs':>14}{'wall s':>9}")
    for name, runs, failed, seconds in rows:
        print(f"{name:<22}{runs:>6}{failed:>10}{100 * failed / runs:>14.1f}{seconds:>9.1f}")
    share = dense_failed / dense_runs
    estimate = tpe_report.document["failureShare"]
    print(
        f"failure share of the space: {100 * share:.1f} % (dense grid); tpe's estimate from its first round: "
        f"{100 * estimate['estimate']:.1f} % (95 %: {100 * estimate['low95']:.1f}–{100 * estimate['high95']:.1f})"
    )
    overheads = [opt / max(total - opt, 1e-9) for opt, total in batch_report.timings]
    for number, ((opt, total), share_round) in enumerate(zip(batch_report.timings, overheads, strict=True)):
        print(
            f"batch {BATCH} round {number}: optimiser {opt:.2f} s, simulation {total - opt:.1f} s ({100 * share_round:.1f} %)"
        )
    per100 = {name: 100 * failed / runs for name, runs, failed, _ in rows}
    tpe = per100["tpe (rounds of 16)"]
    result = {
        "failureShare": round(share, 4),
        "failuresPer100": {name: round(v, 1) for name, v in per100.items()},
        "failuresVsGrid": round(tpe / max(per100[rows[1][0]], 100 / grid_runs), 2),
        "failuresVsRandom": round(tpe / max(per100["random"], 100 / BUDGET), 2),
        f"optimizerOverheadBatch{BATCH}": round(max(overheads), 4),
        "budget": BUDGET,
        "gridLowerBound": grid_failed == 0,
        "randomLowerBound": random_report.document["failures"] == 0,
        "date": time.strftime("%Y-%m-%d"),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
