"""`carlos get / watch / logs / results` on results in a file:// store (the cluster path is exercised in
tests/test_submit.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.test_cli import carlos


def _index(i: int, status: str) -> dict[str, object]:
    criteria = [
        {
            "name": "minDistance >= 2",
            "metric": "minDistance",
            "expected": ">= 2",
            "actual": 1.5,
            "passed": status == "passed",
            "optional": False,
            "message": "minDistance = 1.5: >= 2 does not hold",
        }
    ]
    return {
        "index": i,
        "scenario": "cut-in",
        "parameters": {"Speed": 10.0 + i},
        "seed": 1,
        "status": status,
        "optional": False,
        "metrics": {"minDistance": 1.5},
        "criteria": criteria,
        "error": None,
    }


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    run = tmp_path / "out" / "demo"
    (run / "0").mkdir(parents=True)
    (run / "1").mkdir()
    (run / "run.yaml").write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: demo}\nspec:\n"
        "  scenarios: [{name: cut-in, openscenario: s.xosc}]\n  sweep: {matrix: {Speed: [10.0, 11.0, 12.0]}}\n"
    )
    (run / "0" / "summary.json").write_text(json.dumps(_index(0, "passed")))
    (run / "1" / "summary.json").write_text(json.dumps(_index(1, "failed")))
    (run / "1" / "log.txt").write_text("carlos run demo index 1\nstatus: failed\n")
    return run


def test_get_of_a_running_run_counts_indexes_and_lists_failures(run_dir: Path) -> None:
    result = carlos("get", run_dir.as_uri())
    assert result.returncode == 0, result.stderr
    assert "demo: Running · 2 of 3 finished · 1 passed · 1 failed" in result.stdout
    assert (
        "failed cut-in[1] Speed=11: minDistance >= 2: minDistance = 1.5: >= 2 does not hold" in result.stdout
    )
    # the output URL holding one run is enough
    assert "demo: Running · 2 of 3 finished" in carlos("get", run_dir.parent.as_uri()).stdout


def test_watch_ends_with_the_run_and_its_exit_code(run_dir: Path) -> None:
    result = carlos("watch", run_dir.as_uri(), "--timeout", "0.5", "--interval", "0.2")
    assert result.returncode == 3 and result.stdout.count("demo: Running") == 1  # one line per change
    (run_dir / "summary.json").write_text(
        json.dumps({"run": "demo", "status": "failed", "exitCode": 1, "counts": {"total": 2}})
    )
    result = carlos("watch", run_dir.as_uri())
    assert result.returncode == 1 and "demo: Failed · 2 finished" in result.stdout


def test_logs_and_results(run_dir: Path, tmp_path: Path) -> None:
    assert carlos("logs", run_dir.as_uri(), "-i", "1").stdout == "carlos run demo index 1\nstatus: failed\n"
    missing = carlos("logs", run_dir.as_uri(), "-i", "0")
    assert missing.returncode == 2 and "no log of index 0" in missing.stderr
    listed = carlos("results", run_dir.as_uri()).stdout.split()
    assert (run_dir / "1" / "log.txt").as_uri() in listed and len(listed) == 4
    done = carlos("results", run_dir.as_uri(), "--download", tmp_path / "copy")
    assert done.returncode == 0
    assert (tmp_path / "copy" / "demo" / "1" / "summary.json").read_bytes() == (
        run_dir / "1" / "summary.json"
    ).read_bytes()
