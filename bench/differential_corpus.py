"""The differential corpus (tests/differential_corpus): hand-written scenarios, one or more per feature or esmini
behaviour CARLOS follows, each with the esmini player's trajectories stored beside it, so that a regression
shows without esmini (tests/test_differential_corpus.py runs every case).

    .venv/bin/python bench/differential_corpus.py check [--esmini PATH] [FEATURE…]   # compare, print a table
    .venv/bin/python bench/differential_corpus.py record --esmini PATH [FEATURE…]    # (re)write the references

A FEATURE is a folder of the corpus (`route`, `controllers`, `cases`), or a glob of case paths (`cases/traj_*`).
`record` runs every scenario headless through esmini (0.05 s steps, seed 1) and writes
reference/FOLDER__NAME.csv.gz (time,name,x,y every 0.1 s; the first pass over the times a ghost restart
rewinds) and its row of INDEX.tsv (the exact end time; a case's RMSE limit and note are kept). `check` runs
each through the run pipeline (as `carlos conformance` does) and prints, per scenario, the end times, the
worst entity's position RMSE over the whole run (every entity esmini has, controller-driven ones too) and
whether it agrees: it ran to its own end, within one step (0.05 s) of esmini's end, with no entity of
esmini's missing and every entity within the case's `rmse_limit` (0.2 m, or the documented larger figure of
a behaviour still different, with a note). Against the stored references, or with --esmini against esmini
run now. Its last line is one JSON object; the exit code is 1 when a case does not agree. The user's path (a
fresh `carlos run` per file, recording on, the MCAP read back) is `bench/catalogues.py
tests/differential_corpus`.
"""

from __future__ import annotations

import argparse
import csv
import gzip
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore import conformance  # noqa: E402
from simcore.reference_player import find_esmini, run_esmini  # noqa: E402

CORPUS = ROOT / "tests" / "differential_corpus"
REFERENCE = CORPUS / "reference"
INDEX = CORPUS / "INDEX.tsv"
# the first four as the public corpora's INDEX.tsv has them (bench/catalogues.py runs this corpus too);
# esmini_sim_s and reference_csv as conformance.reference_end_times reads them; rmse_limit: the RMSE a case
# is held to (RMSE_LIMIT, or a larger figure where CARLOS still differs, the reason in note)
INDEX_FIELDS = (
    "path",
    "kind",
    "esmini_status",
    "esmini_end_s",
    "esmini_sim_s",
    "reference_csv",
    "rmse_limit",
    "note",
)
RMSE_LIMIT = 0.2  # m, every entity over the whole run
END_LIMIT = 0.05  # s, one step
NOT_CASES = ("roads", "reference", "catalogs")


def scenarios(features: list[str]) -> list[Path]:
    """The corpus' scenarios (of the folders or path globs `features`, else all), in a stable order."""
    every = sorted(
        p for d in CORPUS.iterdir() if d.is_dir() and d.name not in NOT_CASES for p in d.glob("*.xosc")
    )
    if not features:
        return every
    keys = [f.rstrip("/") for f in features]
    return [
        p
        for p in every
        if any(p.parent.name == k or p.relative_to(CORPUS).match(k) or p.match(k) for k in keys)
    ]


def read_index() -> dict[str, dict[str, str]]:
    """INDEX.tsv's rows by the case's path (relative to the corpus)."""
    if not INDEX.is_file():
        return {}
    with INDEX.open(newline="") as handle:
        return {row["path"]: row for row in csv.DictReader(handle, delimiter="\t")}


def write_index(index: dict[str, dict[str, str]]) -> None:
    with INDEX.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, INDEX_FIELDS, delimiter="\t", lineterminator="\n")
        writer.writeheader()
        for key in sorted(index):
            writer.writerow({k: index[key].get(k, "") for k in INDEX_FIELDS})


def limit_of(row: dict[str, str]) -> float:
    return float(row.get("rmse_limit") or RMSE_LIMIT)


def record(files: list[Path], esmini: Path) -> int:
    """Write the reference trajectories and end times of `files` as esmini plays them; the number it did
    not run."""
    REFERENCE.mkdir(exist_ok=True)
    index = read_index()
    failed = 0
    for path in files:
        played = run_esmini(esmini, path, step=conformance.STEP_SECONDS)
        key = path.relative_to(CORPUS).as_posix()
        if not played.ok or played.end is None:
            print(f"{key}: esmini: {played.message}", file=sys.stderr)
            failed += 1
            continue
        name = conformance.reference_name(path)
        with gzip.open(REFERENCE / name, "wt", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(("time", "name", "x", "y"))
            for entity, track in played.tracks.items():
                for t, x, y in track:
                    writer.writerow((f"{t:.2f}", entity, f"{x:.4f}", f"{y:.4f}"))
        kept = index.get(key, {})
        index[key] = {
            "path": key,
            "kind": "scenario",
            "esmini_status": "ok",
            "esmini_end_s": f"{played.end:.6f}",
            "esmini_sim_s": f"{played.end:.6f}",
            "reference_csv": f"reference/{name}",
            "rmse_limit": kept.get("rmse_limit") or f"{RMSE_LIMIT:g}",
            "note": kept.get("note", ""),
        }
        print(f"{key}: {played.end:.2f} s, {len(played.tracks)} entities")
    write_index(index)
    return failed


def check(path: Path, esmini: Path | None = None) -> dict[str, object]:
    """One scenario against its reference: status, end times, every entity's RMSE (m), the entities esmini
    has and CARLOS does not, the case's limit and what keeps it from agreeing (`problems`, empty: agrees)."""
    key = path.relative_to(CORPUS).as_posix()
    row = read_index().get(key)
    if row is None:
        return {"file": key, "status": "no reference", "problems": ["no row in INDEX.tsv"]}
    result, trace = conformance.run_scenario(path, 120.0)
    if esmini is not None:
        played = run_esmini(esmini, path, step=conformance.STEP_SECONDS)
        tracks, end = played.tracks, played.end
    else:
        tracks, end = conformance.read_reference(CORPUS / row["reference_csv"]), float(row["esmini_sim_s"])
    rmse: dict[str, float | None] = {}
    for name, ours in trace.tracks.items():
        if name in tracks:
            rmse[name] = conformance.track_error(ours, tracks[name])[0]
    missing = sorted(set(tracks) - set(trace.tracks))
    limit = limit_of(row)
    problems: list[str] = []
    if result.status != "ended":
        problems.append(f"{result.status}: {result.message}")
    if end is None or abs(result.sim_seconds - end) > END_LIMIT + 1e-6:
        problems.append(f"end {result.sim_seconds:.2f} s, esmini's {end} s")
    if missing:
        problems.append(f"entities esmini has and CARLOS does not: {missing}")
    if not rmse:
        problems.append("no entity compared")
    problems.extend(
        f"{name} RMSE {value} m > {limit:g} m"
        for name, value in rmse.items()
        if value is None or value > limit + 1e-9
    )
    return {
        "file": key,
        "status": result.status,
        "message": result.message,
        "end": round(result.sim_seconds, 2),
        "reference_end": end,
        "rmse": rmse,
        "missing": missing,
        "limit": limit,
        "problems": problems,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("record", "check"))
    parser.add_argument(
        "features", nargs="*", help="folders of tests/differential_corpus or case path globs (default: all)"
    )
    parser.add_argument("--esmini", type=Path, default=None)
    args = parser.parse_intermixed_args()  # FEATUREs before or after --esmini
    files = scenarios(args.features)
    esmini = find_esmini(args.esmini)
    if args.command == "record":
        if esmini is None:
            print("no esmini player: --esmini PATH or $ESMINI", file=sys.stderr)
            sys.exit(3)
        sys.exit(1 if record(files, esmini) else 0)
    rows = [check(p, esmini if args.esmini else None) for p in files]
    print("| scenario | status | end s (CARLOS / esmini) | worst RMSE m | entity | limit m | agrees |")
    print("|---|---|---|---|---|---|---|")
    for row in rows:
        rmse = {k: v for k, v in row.get("rmse", {}).items() if v is not None}  # type: ignore[union-attr]
        worst = max(rmse.items(), key=lambda kv: kv[1], default=("", 0.0))
        problems = row["problems"]
        assert isinstance(problems, list)
        print(
            f"| {row['file']} | {row['status']} | {row.get('end')} / {row.get('reference_end')} | "
            f"{worst[1]:.3f} | {worst[0]} | {row.get('limit', RMSE_LIMIT):g} | "
            f"{'yes' if not problems else 'no: ' + '; '.join(problems)} |"
        )
    print(json.dumps(rows))
    sys.exit(1 if any(row["problems"] for row in rows) else 0)


if __name__ == "__main__":
    main()
