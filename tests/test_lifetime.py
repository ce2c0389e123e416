"""Scratch folders of ended `carlos run` processes are removed; those of running ones are kept."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from simcore.lifetime import SCRATCH_PREFIX, remove_stale_scratch


def _zombie() -> subprocess.Popen[bytes]:
    """A child process that has ended and is not reaped yet."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if "\nState:\tZ" in Path(f"/proc/{child.pid}/status").read_text():
            return child
        time.sleep(0.01)
    raise AssertionError("the child did not end")


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc (Linux)")
def test_the_scratch_of_an_ended_process_goes_even_before_it_is_reaped(tmp_path: Path) -> None:
    """A killed run's orphaned workers stay zombies while nothing reaps them (as in some containers): their
    folders are removed all the same; a running process' folder and this process' own are kept."""
    zombie = _zombie()
    running = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        ended = tmp_path / f"{SCRATCH_PREFIX}{zombie.pid}-sumo-a"
        alive = tmp_path / f"{SCRATCH_PREFIX}{running.pid}-b"
        own = tmp_path / f"{SCRATCH_PREFIX}{os.getpid()}-c"
        other = tmp_path / "carlos-7-none"  # not a run's scratch folder
        for folder in (ended, alive, own, other):
            folder.mkdir()
            (folder / "file").write_text("x")
        assert remove_stale_scratch(tmp_path) == [ended]
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in (alive, own, other))
    finally:
        running.kill()
        running.wait()
        zombie.wait()


def test_a_run_with_nothing_left_to_do_removes_the_scratch_of_killed_runs(tmp_path: Path) -> None:
    """`carlos run` removes what killed runs left in the temporary directory also when it has no index left
    to run (a run killed after its last index, then resumed) and when it runs its one index in-process."""
    scenario = Path(__file__).resolve().parents[1] / "examples" / "scenarios" / "curve-following.xosc"
    manifest = tmp_path / "m.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: once}\n"
        f"spec:\n  scenarios: [{{name: c, openscenario: {scenario}}}]\n  simulation: {{maxSeconds: 1}}\n"
    )
    temp = tmp_path / "tmp"
    temp.mkdir()
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    env = {**os.environ, "TMPDIR": str(temp)}
    command = [
        sys.executable,
        "-m",
        "simcore.cli",
        "run",
        str(manifest),
        "-o",
        f"file://{tmp_path / 'out'}",
        "-q",
    ]
    for attempt in ("runs its index here", "has nothing left to run"):
        left = temp / f"{SCRATCH_PREFIX}{ended.pid}-x"
        left.mkdir()
        result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr
        assert list(temp.iterdir()) == [], attempt
