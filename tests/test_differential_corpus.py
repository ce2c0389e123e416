"""The differential corpus (tests/differential_corpus): scenarios written for one feature each, run through
the run pipeline and compared with the esmini player's trajectories stored beside them (recorded by
`bench/differential_corpus.py record`): every entity's position RMSE over the whole run within 0.2 m (or the
tolerance a case not agreeing yet is held to, with its reason in INDEX.tsv) and the end time within one step.
No esmini needed; with it ($ESMINI), the stored references are checked against what it plays now."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tests.tooling import esmini_player

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import differential_corpus as corpus  # noqa: E402

CASES = corpus.scenarios([])
INDEX = corpus.read_index()


def test_every_case_has_a_reference() -> None:
    keys = {p.relative_to(corpus.CORPUS).as_posix() for p in CASES}
    assert keys and keys <= set(INDEX), sorted(keys - set(INDEX))
    for row in INDEX.values():
        assert (corpus.CORPUS / row["reference_csv"]).is_file()


@pytest.mark.parametrize("path", CASES, ids=[p.relative_to(corpus.CORPUS).as_posix() for p in CASES])
def test_case_agrees_with_the_stored_esmini_trajectories(path: Path) -> None:
    row = INDEX[path.relative_to(corpus.CORPUS).as_posix()]
    found = corpus.check(path)
    assert found["status"] == "ended", found.get("message")
    assert not found["missing"], f"entities esmini has and CARLOS does not: {found['missing']}"
    assert abs(float(found["end"]) - float(row["esmini_sim_s"])) <= corpus.END_LIMIT + 1e-6  # type: ignore[arg-type]
    limit = float(row.get("tolerance_m") or corpus.RMSE_LIMIT)
    rmse = found["rmse"]
    assert isinstance(rmse, dict) and rmse
    worst = {name: value for name, value in rmse.items() if value is None or value > limit}
    assert not worst, f"RMSE over {limit} m: {worst}"


def test_stored_references_are_what_esmini_plays() -> None:
    esmini = esmini_player()  # skips without it
    for path in CASES[:3]:
        now = corpus.check(path, esmini)
        stored = corpus.check(path)
        assert now["reference_end"] == pytest.approx(float(INDEX[stored["file"]]["esmini_sim_s"]), abs=1e-6)  # type: ignore[index]
        assert now["rmse"] == pytest.approx(stored["rmse"], abs=1e-3)
