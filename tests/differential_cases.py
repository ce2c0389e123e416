"""The differential corpus (tests/differential_corpus): hand-written scenarios, one or more per esmini behaviour
CARLOS follows, each with esmini's trajectories stored beside it (INDEX.tsv: the end time, the RMSE limit, a
note where CARLOS still differs). `bench/differential_corpus.py` records the references and prints the table;
`tests/test_differential.py` checks every case without the esmini player."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

from simcore import conformance

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "differential_corpus"
CASES = CORPUS / "cases"
REFERENCE = CORPUS / "reference"
INDEX = CORPUS / "INDEX.tsv"
RMSE_LIMIT = 0.2  # m per entity
END_LIMIT = 0.05 + 1e-6  # s: one step
COLUMNS = (
    "path",
    "kind",
    "esmini_status",
    "esmini_end_s",
    "esmini_sim_s",
    "reference_csv",
    "rmse_limit",
    "note",
)


@dataclass
class Case:
    path: str  # relative to the corpus
    end: float
    rmse_limit: float
    note: str

    @property
    def file(self) -> Path:
        return CORPUS / self.path


def read_index() -> dict[str, Case]:
    if not INDEX.is_file():
        return {}
    with INDEX.open(newline="") as handle:
        rows = list(csv.DictReader(handle, delimiter="\t"))
    return {
        r["path"]: Case(r["path"], float(r["esmini_sim_s"]), float(r["rmse_limit"] or RMSE_LIMIT), r["note"])
        for r in rows
    }


def write_index(cases: dict[str, Case]) -> None:
    with INDEX.open("w", newline="") as handle:
        out = csv.writer(handle, delimiter="\t", lineterminator="\n")
        out.writerow(COLUMNS)
        for key in sorted(cases):
            c = cases[key]
            ref = f"reference/{conformance.reference_name(c.file)}"
            out.writerow(
                [c.path, "scenario", "ok", f"{c.end:.6f}", f"{c.end:.6f}", ref, f"{c.rmse_limit:g}", c.note]
            )


def check(case: Case, result: conformance.ScenarioResult) -> list[str]:
    """What keeps a case from agreeing (empty: it agrees)."""
    problems = []
    if result.status != "ended":
        problems.append(f"{result.status}: {result.message}")
    if result.end_error is None or result.end_error > END_LIMIT:
        problems.append(f"end {result.sim_seconds:.2f} s, esmini's {case.end:.2f} s")
    for entity in result.entities:
        if entity.scripted and (entity.rmse is None or entity.rmse > case.rmse_limit + 1e-9):
            problems.append(f"{entity.name} RMSE {entity.rmse} m > {case.rmse_limit:g} m")
    return problems


def run(include: list[str] | None = None) -> list[tuple[Case, conformance.ScenarioResult]]:
    cases = [c for c in read_index().values() if not include or any(c.file.match(g) for g in include)]
    results = conformance.run_files([c.file for c in cases], REFERENCE, cap_seconds=120.0)
    return list(zip(cases, results, strict=True))
