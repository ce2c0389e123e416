"""Differential testing against the esmini player: generated scenarios of every feature type
(tests/differential_scenarios.py), each run by CARLOS and by esmini (`carlos conformance --against esmini`),
agreement per type.

A scenario agrees when it ran to its own end in both, the end times are within 0.1 s and every scripted
entity's position RMSE over the common time span is within 0.5 m (as `carlos conformance`). Scenarios esmini
itself cannot run are counted apart ("no reference"). Prints the table (Markdown) and, as its last line, one
JSON object with the figures. Needs the esmini binary ($ESMINI or --esmini); exits 3 without it.

Usage: .venv/bin/python bench/differential.py [--per-type N] [--seed S] [--jobs J] [--keep DIR] [-k TYPE…]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore import conformance  # noqa: E402
from simcore.reference_player import find_esmini  # noqa: E402
from tests.differential_scenarios import GENERATORS, generate  # noqa: E402


def table(rows: dict[str, list[conformance.ScenarioResult]]) -> tuple[str, dict[str, dict[str, float]]]:
    lines = [
        "| feature type | scenarios | agreed | agreement | no reference | errors | worst RMSE m | worst end Δ s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    figures: dict[str, dict[str, float]] = {}
    for name in sorted(rows):
        results = rows[name]
        compared = [r for r in results if r.reference is not None]
        agreed = sum(r.agreed for r in compared)
        errors = sum(r.status in ("error", "bad_input") for r in results)
        rmse = max((r.max_rmse or 0.0 for r in compared), default=0.0)
        end = max((r.end_error or 0.0 for r in compared), default=0.0)
        rate = agreed / len(compared) if compared else 0.0
        figures[name] = {"scenarios": len(results), "compared": len(compared), "agreed": agreed, "rate": rate}
        lines.append(
            f"| {name} | {len(results)} | {agreed} | {100 * rate:.0f}% | {len(results) - len(compared)} | "
            f"{errors} | {rmse:.2f} | {end:.2f} |"
        )
    return "\n".join(lines), figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-type", type=int, default=12)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", "-j", type=int, default=2)
    parser.add_argument("--esmini", type=Path, default=None)
    parser.add_argument("--keep", type=Path, default=None, help="write the scenarios here (kept)")
    parser.add_argument("--verbose", "-v", action="store_true", help="one line per disagreeing scenario")
    parser.add_argument("-k", dest="types", action="append", help="only feature types starting with this")
    args = parser.parse_args()
    esmini = find_esmini(args.esmini)
    if esmini is None:
        print("no esmini binary: give --esmini PATH or set ESMINI=/path/to/esmini", file=sys.stderr)
        sys.exit(3)
    types = [t for t in GENERATORS if not args.types or any(t.startswith(p) for p in args.types)]
    with tempfile.TemporaryDirectory(prefix="carlos-differential-") as scratch:
        directory = args.keep or Path(scratch)
        files = generate(directory, args.per_type, args.seed, types)
        started = time.perf_counter()
        results = conformance.run_files(list(files), jobs=args.jobs, esmini=esmini, cap_seconds=60.0)
        wall = time.perf_counter() - started
    rows: dict[str, list[conformance.ScenarioResult]] = defaultdict(list)
    for result in results:
        rows[files[Path(result.file)]].append(result)
        if args.verbose and not result.agreed:
            print(
                f"  {Path(result.file).name}: {result.status} end {result.sim_seconds:.2f}/{result.reference_end}"
                f" rmse {result.max_rmse} ({result.worst_entity}) {result.message or result.reference_message}"[
                    :300
                ]
            )
    text, figures = table(rows)
    compared = sum(f["compared"] for f in figures.values())
    agreed = sum(f["agreed"] for f in figures.values())
    print(text)
    print(
        f"\n{len(results)} scenarios of {len(figures)} feature types; esmini ran {compared}; agreed {agreed} "
        f"({100 * agreed / max(compared, 1):.1f}%); {wall:.1f} s wall"
    )
    summary = {
        "scenarios": len(results),
        "types": len(figures),
        "compared": compared,
        "agreed": agreed,
        "rate": round(agreed / max(compared, 1), 4),
        "wall_s": round(wall, 1),
        "per_type": {k: round(v["rate"], 3) for k, v in figures.items()},
    }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
