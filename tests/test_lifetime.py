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
