"""`carlos submit / watch / get / results / logs / rerun` against the real cluster, as the walk-through
(docs/kubernetes/walkthrough.md) runs them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.e2e.conftest import RUNS_NS, Cluster

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(1200)]


def test_submit_watch_results_logs_rerun(cluster: Cluster, tmp_path: Path) -> None:
    manifest = "examples/runs/automated-testing-failing.yaml"
    submitted = cluster.carlos("submit", manifest, "-n", RUNS_NS)
    assert submitted.returncode == 0, submitted.stderr
    assert "simulationrun.carlos.dev/automated-testing-failing created" in submitted.stdout

    watched = cluster.carlos("watch", "automated-testing-failing", "-n", RUNS_NS, "--timeout", "900")
    assert watched.returncode == 1, (
        watched.stdout + watched.stderr
    )  # as `carlos run`: a required criterion failed
    assert "Failed" in watched.stdout

    got = cluster.carlos("get", "automated-testing-failing", "-n", RUNS_NS)
    assert got.returncode == 0, got.stderr
    assert "automated-testing-failing" in got.stdout

    results = cluster.carlos(
        "results", "automated-testing-failing", "-n", RUNS_NS, "--download", str(tmp_path)
    )
    assert results.returncode == 0, results.stderr
    download = tmp_path / "automated-testing-failing"  # DIR/<run>/
    summary = json.loads((download / "summary.json").read_text())
    assert summary["exitCode"] == 1 and summary["counts"]["total"] == 4
    assert (download / "junit.xml").exists() and (download / "0" / "recording.mcap").exists()
    failed = sorted(
        i
        for i in range(4)
        if json.loads((download / str(i) / "summary.json").read_text())["status"] != "passed"
    )
    assert failed

    logs = cluster.carlos("logs", "automated-testing-failing", "-n", RUNS_NS, "-i", str(failed[0]))
    assert logs.returncode == 0, logs.stderr
    assert logs.stdout.strip()

    rerun = cluster.carlos("rerun", "automated-testing-failing", "-n", RUNS_NS, "--failed")
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr
    status = cluster.wait_phase("automated-testing-failing-rerun")
    assert status["total"] == len(failed)
    assert status["phase"] == "Failed"  # the same failures, now alone
