"""The differential corpus (tests/differential_corpus): hand-written scenarios, one or more per esmini
behaviour CARLOS follows (issue 33's table), each with esmini's trajectories stored beside it, so that a
regression shows without the esmini player (`tests/test_differential.py` runs them).

    .venv/bin/python bench/differential_corpus.py                  # CARLOS against the stored references
    .venv/bin/python bench/differential_corpus.py --record --esmini PATH [-k GLOB…]   # esmini's anew

A case agrees when it runs to its own end, its end time is within one step (0.05 s) of esmini's and every
compared entity's position RMSE is within its limit (`rmse_limit` in INDEX.tsv: 0.2 m, or the documented
larger figure of a behaviour that is still different). `--record` runs esmini (headless, 0.05 s steps,
seed 1) on every case and writes `reference/cases__<name>.csv.gz` (time, name, x, y every 0.1 s; the first
pass over times a ghost restart rewinds) and the end time into INDEX.tsv. The user's path (a fresh
`carlos run` per file, recording on, the MCAP read back) is `bench/catalogues.py tests/differential_corpus`.
"""

from __future__ import annotations

import argparse
import csv
import gzip
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore import conformance  # noqa: E402
from simcore.reference_player import find_esmini, run_esmini  # noqa: E402
from tests.differential_cases import (  # noqa: E402
    CASES,
    CORPUS,
    REFERENCE,
    RMSE_LIMIT,
    Case,
    check,
    read_index,
    run,
    write_index,
)


def record(esmini: Path, include: list[str] | None) -> None:
    cases = read_index()
    REFERENCE.mkdir(exist_ok=True)
    for file in sorted(CASES.glob("*.xosc")):
        if include and not any(file.match(g) for g in include):
            continue
        played = run_esmini(esmini, file, step=conformance.STEP_SECONDS)
        if not played.ok or played.end is None:
            print(f"{file.name}: esmini did not run it: {played.message}", file=sys.stderr)
            continue
        with gzip.open(REFERENCE / conformance.reference_name(file), "wt", newline="") as handle:
            out = csv.writer(handle, lineterminator="\n")
            out.writerow(("time", "name", "x", "y"))
            for name, track in played.tracks.items():
                for t, x, y in track:
                    out.writerow((f"{t:.2f}", name, f"{x:.4f}", f"{y:.4f}"))
        key = str(file.relative_to(CORPUS))
        old = cases.get(key)
        cases[key] = Case(key, played.end, old.rmse_limit if old else RMSE_LIMIT, old.note if old else "")
        print(f"{file.name}: {played.end:.2f} s, {len(played.tracks)} entities")
    write_index(cases)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", action="store_true", help="run esmini and store its trajectories")
    parser.add_argument("--esmini", type=Path, default=None)
    parser.add_argument("-k", dest="include", action="append", default=None, help="case file glob")
    args = parser.parse_args()
    if args.record:
        esmini = find_esmini(args.esmini)
        if esmini is None:
            print("no esmini binary (--esmini, $ESMINI or PATH)", file=sys.stderr)
            sys.exit(3)
        record(esmini, args.include)
        return
    failed = 0
    print("| case | end s (CARLOS / esmini) | worst entity | RMSE m | limit m | agrees |")
    print("|---|---|---|---|---|---|")
    for case, result in run(args.include):
        problems = check(case, result)
        failed += bool(problems)
        print(
            f"| {Path(case.path).stem} | {result.sim_seconds:.2f} / {case.end:.2f} | {result.worst_entity or ''} | "
            f"{result.max_rmse if result.max_rmse is not None else float('nan'):.3f} | {case.rmse_limit:g} | "
            f"{'yes' if not problems else 'no: ' + '; '.join(problems)} |"
        )
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
