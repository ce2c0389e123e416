"""Local worker processes die with the process that started them and leave no scratch behind.

`kill -9` of `carlos run` gives its workers no chance to clean up: each worker asks the kernel for SIGKILL
when its parent dies (Linux prctl PR_SET_PDEATHSIG through ctypes; elsewhere a thread watching the parent's
pid), and once the workers are gone multiprocessing's resource tracker sees its pipe close and exits too.
Workers write their scratch folders under one folder per `carlos run` process (`carlos-run-<pid>-…` in the
temporary directory): the run removes it when it ends, and the next run (whatever it has left to do) removes
those of dead processes. A
process keeping SUMO between runs saves SUMO's start state in a folder named the same way with its own pid
(`carlos-run-<pid>-sumo-…`, simcore/world/sumo_warm.py), removed at its exit or, after a kill, by the next
run or the next such process.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

PR_SET_PDEATHSIG = 1
SCRATCH_PREFIX = "carlos-run-"
_SCRATCH_NAME = re.compile(rf"^{SCRATCH_PREFIX}(\d+)-")


def die_with_parent(parent_pid: int) -> None:
    """Make this process end when `parent_pid` (its parent) ends, however that ends."""
    if sys.platform.startswith("linux"):
        import ctypes  # here: only worker processes ask (ctypes is ~3 ms of every `carlos` start)

        # the process' own symbols, libc's among them (ctypes.util.find_library runs ldconfig: ~5 ms)
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
            if os.getppid() != parent_pid:  # the parent died before the request: nobody will signal
                os._exit(1)
            return
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True, name="parent-watch").start()


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(0.5)
    os._exit(1)


def _alive(pid: int) -> bool:
    """Whether process `pid` still runs: a zombie (ended, not yet reaped: a killed run's orphaned workers can
    stay so for a while when nothing reaps orphans, as in some containers) has ended."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:  # ended meanwhile; or no /proc (not Linux): the signal's answer stands
        return not Path("/proc").is_dir()
    return "\nState:\tZ" not in status


def remove_stale_scratch(temp_dir: Path | None = None) -> list[Path]:
    """Remove the scratch folders of `carlos run` processes that no longer exist; returns what was removed."""
    removed = []
    root = temp_dir or Path(tempfile.gettempdir())
    with contextlib.suppress(OSError):
        for entry in root.iterdir():
            match = _SCRATCH_NAME.match(entry.name)
            if (
                match
                and entry.is_dir()
                and int(match.group(1)) != os.getpid()
                and not _alive(int(match.group(1)))
            ):
                shutil.rmtree(entry, ignore_errors=True)
                removed.append(entry)
    return removed


def make_scratch_root(temp_dir: Path | None = None, label: str = "") -> Path:
    """A new scratch folder of this process (`carlos-run-<pid>-<label>…`: for its workers, or, labelled, for a
    purpose of its own); stale ones of dead processes are removed first."""
    remove_stale_scratch(temp_dir)
    return Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-{label}", dir=temp_dir))
