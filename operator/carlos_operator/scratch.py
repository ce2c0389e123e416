"""The operator's local scratch space: the input files it reads for a run (a sweep's distribution, a search's
scenario) live in one folder per run, made on first use and removed when the run is deleted or the operator
stops, so a long-lived operator's disk does not grow with every run it has seen."""

from __future__ import annotations

import shutil
import tempfile
import threading
from pathlib import Path


class ScratchFolders:
    """Per-run folders under one temporary root (created lazily, so an operator that never needs one makes
    none)."""

    def __init__(self, prefix: str) -> None:
        self._prefix = prefix
        self._root: Path | None = None
        self._lock = threading.Lock()

    @property
    def root(self) -> Path | None:
        return self._root

    def folder(self, namespace: str, name: str) -> Path:
        """The run's folder, created if needed."""
        with self._lock:
            if self._root is None:
                self._root = Path(tempfile.mkdtemp(prefix=self._prefix))
            folder = self._root / namespace / name
        folder.mkdir(parents=True, exist_ok=True)
        return folder

    def forget(self, namespace: str, name: str) -> None:
        """Remove the run's folder (the run was deleted); a run of the same name later gets a fresh one."""
        with self._lock:
            root = self._root
        if root is not None:
            shutil.rmtree(root / namespace / name, ignore_errors=True)

    def close(self) -> None:
        """Remove every folder (the operator stops)."""
        with self._lock:
            root, self._root = self._root, None
        if root is not None:
            shutil.rmtree(root, ignore_errors=True)
