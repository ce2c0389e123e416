"""The differential corpus (tests/differential_corpus): scenarios written for one feature each, with the esmini
player's trajectories stored beside them, so that they are checked without esmini (tests/test_differential_corpus.py).

    .venv/bin/python bench/differential_corpus.py record --esmini PATH [FEATURE…]   # (re)write the references
    .venv/bin/python bench/differential_corpus.py check [--esmini PATH] [FEATURE…]  # compare, print a table

`record` runs every scenario under tests/differential_corpus/FEATURE/ headless through esmini (0.05 s steps,
seed 1) and writes reference/FEATURE__NAME.csv.gz (time,name,x,y every 0.1 s) and INDEX.tsv (the exact end
time). `check` runs each through the run pipeline (as `carlos conformance` does) and prints, per scenario, the
worst entity's position RMSE over time (every entity, controller-driven ones too) and the end-time error,
against the stored references (or, with --esmini, against esmini run now). Its last line is one JSON object.
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
# tolerance_m: the RMSE a case is held to when CARLOS does not agree with esmini yet (empty: RMSE_LIMIT); note:
# why it does not
# kind and esmini_status as the corpora's INDEX.tsv has them: bench/catalogues.py runs this corpus too (`carlos
# run` in a fresh process, recording on, the trajectories read back from the MCAP)
INDEX_FIELDS = ("path", "kind", "esmini_status", "reference_csv", "esmini_sim_s", "tolerance_m", "note")
RMSE_LIMIT = 0.2  # m, every entity over the whole run
END_LIMIT = 0.05  # s, one step


def scenarios(features: list[str]) -> list[Path]:
    """The corpus' scenarios (of `features`, else all), in a stable order."""
    folders = [CORPUS / f for f in features] if features else [p for p in CORPUS.iterdir() if p.is_dir()]
    return sorted(
        p for d in folders if d.name not in ("roads", "reference", "catalogs") for p in d.glob("*.xosc")
    )


def read_index() -> dict[str, dict[str, str]]:
    if not INDEX.is_file():
        return {}
    with INDEX.open(newline="") as handle:
        return {row["path"]: row for row in csv.DictReader(handle, delimiter="\t")}


def record(files: list[Path], esmini: Path) -> int:
    """Write the reference trajectories and end times of `files` as esmini plays them."""
    REFERENCE.mkdir(exist_ok=True)
    index = read_index()
    failed = 0
    for path in files:
        played = run_esmini(esmini, path)
        key = path.relative_to(CORPUS).as_posix()
        if not played.ok or played.end is None:
            print(f"{key}: esmini: {played.message}")
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
            "reference_csv": f"reference/{name}",
            "esmini_sim_s": f"{played.end:.2f}",
            "tolerance_m": kept.get("tolerance_m", ""),
            "note": kept.get("note", ""),
        }
        print(f"{key}: {played.end:.2f} s, {len(played.tracks)} entities")
    with INDEX.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, INDEX_FIELDS, delimiter="\t", lineterminator="\n")
        writer.writeheader()
        for key in sorted(index):
            writer.writerow(index[key])
    return failed


def check(path: Path, esmini: Path | None = None) -> dict[str, object]:
    """One scenario against its reference: status, end times, and every entity's RMSE (m)."""
    result, trace = conformance.run_scenario(path, 120.0)
    if esmini is not None:
        played = run_esmini(esmini, path)
        tracks, end = played.tracks, played.end
    else:
        row = read_index().get(path.relative_to(CORPUS).as_posix())
        if row is None:
            return {"file": path.name, "status": "no reference"}
        tracks, end = conformance.read_reference(CORPUS / row["reference_csv"]), float(row["esmini_sim_s"])
    rmse: dict[str, float | None] = {}
    for name, ours in trace.tracks.items():
        if name in tracks:
            rmse[name] = conformance.track_error(ours, tracks[name])[0]
    missing = sorted(set(tracks) - set(trace.tracks))
    return {
        "file": path.relative_to(CORPUS).as_posix(),
        "status": result.status,
        "message": result.message,
        "end": round(result.sim_seconds, 2),
        "reference_end": end,
        "rmse": rmse,
        "missing": missing,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("record", "check"))
    parser.add_argument("features", nargs="*", help="folders of tests/differential_corpus (default: all)")
    parser.add_argument("--esmini", type=Path, default=None)
    args = parser.parse_args()
    files = scenarios(args.features)
    esmini = find_esmini(args.esmini)
    if args.command == "record":
        if esmini is None:
            print("no esmini player: --esmini PATH or $ESMINI")
            sys.exit(3)
        sys.exit(1 if record(files, esmini) else 0)
    rows = [check(p, esmini if args.esmini else None) for p in files]
    print("| scenario | status | end s (CARLOS / esmini) | worst RMSE m | entity |")
    print("|---|---|---|---|---|")
    for row in rows:
        rmse = {k: v for k, v in row.get("rmse", {}).items() if v is not None}  # type: ignore[union-attr]
        worst = max(rmse.items(), key=lambda kv: kv[1], default=("", 0.0))
        print(
            f"| {row['file']} | {row['status']} | {row.get('end')} / {row.get('reference_end')} | {worst[1]:.3f} | {worst[0]} |"
        )
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
