"""The local executor survives a worker process dying mid-run: the pool is rebuilt, the runs that were in
flight are retried, nothing already written is lost."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True, check=False).stdout
    return [int(p) for p in out.split()]


def _run_killing_a_worker(
    manifest: Path, out: Path, ready: Callable[[], bool], *, settle: float, poll: float, within: float
) -> tuple[int, str, str]:
    """`carlos run` of `manifest` into `out` with 2 workers; one worker is killed with SIGKILL once `ready()`
    holds (and `settle` seconds more). (exit code, stdout, stderr)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "simcore.cli", "run", str(manifest), "-o", f"file://{out}", "-j", "2"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + within
        victim = None
        while time.monotonic() < deadline and victim is None:
            workers = [
                p for p in _children(process.pid) if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()
            ]
            if workers and ready():
                time.sleep(settle)
                victim = workers[0]
            time.sleep(poll)
        assert victim is not None, "no worker process appeared"
        os.kill(victim, signal.SIGKILL)
        stdout, stderr = process.communicate(timeout=300)
    finally:
        if process.poll() is None:
            process.kill()
    return process.returncode, stdout, stderr


def test_a_killed_worker_is_retried_and_the_sweep_completes(tmp_path: Path) -> None:
    scenario = ROOT / "examples" / "scenarios" / "curve-following.xosc"
    manifest = tmp_path / "m.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: crash}\n"
        f"spec:\n  scenarios: [{{name: c, openscenario: {scenario}}}]\n"
        "  sweep: {matrix: {LeadSpeed: [18.0, 19.0, 20.0, 21.0]}}\n"
        "  execution: {retries: 2}\n"
    )
    out = tmp_path / "out"
    # once a worker is simulating (the run's spec is stored, then 0.3 s), it is killed the hard way
    returncode, stdout, stderr = _run_killing_a_worker(
        manifest, out, (out / "crash" / "run.yaml").exists, settle=0.3, poll=0.05, within=60
    )
    assert returncode == 0, stderr
    assert "retrying" in stderr + stdout or "worker process died" in stderr + stdout
    summaries = [json.loads((out / "crash" / str(i) / "summary.json").read_text()) for i in range(4)]
    assert [s["status"] for s in summaries] == ["passed"] * 4
    assert max(s["attempts"] for s in summaries) >= 2  # at least one run was retried after the crash
    run_summary = json.loads((out / "crash" / "summary.json").read_text())
    assert run_summary["counts"]["total"] == 4 and run_summary["status"] == "passed"


def test_a_warm_worker_freezes_what_its_first_run_left_alive_once() -> None:
    """After a worker's first run its long-lived objects are frozen (never scanned by later collections);
    later runs do not freeze again. In a process of its own: freezing is for the life of the process."""
    code = """
import gc
from simcore.startup import settle_worker
kept = [[i] for i in range(1000)]
settle_worker()
first = gc.get_freeze_count()
more = [[i] for i in range(1000)]
settle_worker()
print(first >= 1000, gc.get_freeze_count() == first)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["True", "True"]


def test_a_worker_killed_mid_batch_costs_only_the_runs_it_had_started(tmp_path: Path) -> None:
    """Quick runs go to a worker in batches. A worker killed mid-batch (no retries) leaves the runs it finished
    as they are, ends the run it was running in an error, and gives the runs of its batches that had not
    started their attempt back: they run afterwards and pass. So at most one error per batch in flight (two
    per worker), however large the batches."""
    scenario = ROOT / "examples" / "scenarios" / "cut-in.xosc"
    manifest = tmp_path / "m.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: batches}\n"
        f"spec:\n  scenarios: [{{name: c, openscenario: {scenario}}}]\n"
        "  sweep: {repetitions: 120}\n"
        "  simulation: {stepSeconds: 0.1, maxSeconds: 0.5}\n"
        "  recording: {enabled: false}\n"
        "  execution: {retries: 0}\n"
    )
    out = tmp_path / "out"
    returncode, _, stderr = _run_killing_a_worker(
        manifest,
        out,
        lambda: len(list(out.glob("batches/*/summary.json"))) >= 20,
        settle=0.0,
        poll=0.005,
        within=120,
    )
    statuses = [
        json.loads((out / "batches" / str(i) / "summary.json").read_text())["status"] for i in range(120)
    ]
    errors = statuses.count("error")
    assert returncode == (3 if errors else 0), stderr
    assert errors <= 4, (errors, stderr)
    assert statuses.count("passed") == 120 - errors
