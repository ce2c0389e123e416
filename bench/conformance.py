"""Scenario execution speed over the esmini corpus: simulated seconds per wall second in a warm worker.

Every scenario of the corpus that loads is run headless (0.05 s steps, no SUMO unless an entity is SUMO-driven,
no recording) in this process, after one warm-up pass over the corpus (imports, parsed roads cached by the OS,
libsumo loaded). Per scenario: simulated seconds, wall seconds of the run (load + steps), ×RT. Totals against
esmini's own figures from the corpus INDEX.tsv (`esmini_sim_s`, `esmini_cli_wall_s`, measured on this machine
class with a fresh process per scenario), on the same scenarios.

Prints a table and, as its last line, one JSON object with the figures. No assertions: machines are noisy.
Usage: .venv/bin/python bench/conformance.py [CORPUS_DIR] (default $CARLOS_ESMINI_CORPUS)
"""

from __future__ import annotations

import csv
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore import conformance  # noqa: E402

CAP = float(os.environ.get("BENCH_CAP", "1250"))


def main() -> None:
    given = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("CARLOS_ESMINI_CORPUS", "")
    if not given or not Path(given).is_dir():
        print(
            "usage: bench/conformance.py CORPUS_DIR (or set CARLOS_ESMINI_CORPUS): the esmini corpus directory",
            file=sys.stderr,
        )
        sys.exit(2)
    corpus = Path(given)
    resources = corpus / "resources"
    files = [f for f in conformance.scenario_files(resources) if conformance.file_kind(f) == "scenario"]
    esmini: dict[str, tuple[float, float]] = {}
    index = corpus / "INDEX.tsv"
    if index.is_file():
        with index.open(newline="") as handle:
            for row in csv.DictReader(handle, delimiter="\t"):
                try:
                    esmini[row["path"]] = (float(row["esmini_sim_s"]), float(row["esmini_cli_wall_s"]))
                except (KeyError, ValueError):
                    continue
    # warm-up: one pass (imports, caches)
    for f in files:
        conformance.run_scenario(f, min(CAP, 5.0))
    rows = []
    for f in files:
        started = time.perf_counter()
        result, _ = conformance.run_scenario(f, CAP)
        wall = time.perf_counter() - started
        if not result.loaded:
            continue
        key = str(f.relative_to(corpus))
        rows.append((key, result.sim_seconds, wall, esmini.get(key)))
    print(f"{'scenario':58} {'sim s':>8} {'wall s':>8} {'×RT':>8} {'esmini ×RT':>11}")
    for key, sim, wall, ref in rows:
        esm = f"{ref[0] / ref[1]:.0f}" if ref and ref[1] > 0 else ""
        print(f"{key[-58:]:58} {sim:8.2f} {wall:8.3f} {sim / wall:8.0f} {esm:>11}")
    sim_total = sum(r[1] for r in rows)
    wall_total = sum(r[2] for r in rows)
    both = [r for r in rows if r[3] is not None and r[3][1] > 0]
    esm_sim = sum(r[3][0] for r in both if r[3] is not None)
    esm_wall = sum(r[3][1] for r in both if r[3] is not None)
    ours_same = sum(r[2] for r in both)
    ours_same_sim = sum(r[1] for r in both)
    figures = {
        "scenarios": len(rows),
        "sim_seconds": round(sim_total, 2),
        "wall_seconds": round(wall_total, 3),
        "x_realtime": round(sim_total / wall_total, 1) if wall_total else None,
        "median_wall_per_scenario_s": round(statistics.median(r[2] for r in rows), 4) if rows else None,
        "esmini_x_realtime_same_scenarios": round(esm_sim / esm_wall, 1) if esm_wall else None,
        "carlos_x_realtime_same_scenarios": round(ours_same_sim / ours_same, 1) if ours_same else None,
    }
    print(
        f"total: {sim_total:.0f} simulated s in {wall_total:.1f} s wall = {figures['x_realtime']}× real time "
        f"(esmini on these scenarios: {figures['esmini_x_realtime_same_scenarios']}×, fresh process each)"
    )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
