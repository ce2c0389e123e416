"""`carlos examples DIR`: writes the examples (manifests, scenarios, maps, nodes) into DIR/examples/, keeps
unchanged files, refuses to overwrite changed ones (exit 2) unless --force, and what it wrote runs from DIR
as the documentation says. (tools/wheel-check does the same from an installed wheel.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def carlos(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "simcore.cli", *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def source_files() -> dict[str, bytes]:
    return {
        p.relative_to(ROOT / "examples").as_posix(): p.read_bytes()
        for p in (ROOT / "examples").rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"
    }


def written_files(target: Path) -> dict[str, bytes]:
    return {p.relative_to(target).as_posix(): p.read_bytes() for p in target.rglob("*") if p.is_file()}


def test_examples_are_written_kept_and_refused_when_changed(tmp_path: Path) -> None:
    first = carlos("examples", "work", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    target = tmp_path / "work" / "examples"
    expected = source_files()
    assert written_files(target) == expected
    assert f"{len(expected)} files written, 0 unchanged" in first.stdout

    again = carlos("examples", "work", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert f"0 files written, {len(expected)} unchanged" in again.stdout

    manifest = target / "runs" / "prototyping.yaml"
    manifest.write_text(manifest.read_text() + "# my change\n")
    refused = carlos("examples", "work", cwd=tmp_path)
    assert refused.returncode == 2
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and "runs/prototyping.yaml" in lines[0] and "--force" in lines[0], refused.stderr
    assert manifest.read_text().endswith("# my change\n")  # nothing written

    forced = carlos("examples", "work", "--force", cwd=tmp_path)
    assert forced.returncode == 0, forced.stderr
    assert manifest.read_bytes() == expected["runs/prototyping.yaml"]


def test_a_file_where_the_examples_folder_belongs_is_bad_input(tmp_path: Path) -> None:
    (tmp_path / "examples").write_text("not a folder")
    result = carlos("examples", ".", cwd=tmp_path)
    assert result.returncode == 2
    assert "is not a folder" in result.stderr and "Traceback" not in result.stderr


def test_the_written_examples_run_from_the_folder_the_docs_name(tmp_path: Path) -> None:
    assert carlos("examples", ".", cwd=tmp_path).returncode == 0
    result = carlos("run", "examples/runs/prototyping.yaml", "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "results" / "prototyping" / "summary.json").read_text())
    assert summary["exitCode"] == 0
    assert (tmp_path / "results" / "prototyping" / "0" / "recording.mcap").stat().st_size > 0


def test_an_installation_without_the_examples_is_one_line_and_exit_2(tmp_path: Path, monkeypatch) -> None:
    """Exit 3 is a retryable infrastructure error: a missing data file is not one."""
    from simcore import examples as module
    from tests.inprocess import carlos_in_process

    monkeypatch.setattr(module.resources, "files", lambda _package: tmp_path / "site" / "simcore")
    monkeypatch.setattr(module, "__file__", str(tmp_path / "site" / "simcore" / "examples.py"))
    outcome = carlos_in_process("examples", tmp_path / "work")
    assert outcome.exception is None
    assert outcome.exit_code == 2
    lines = outcome.stderr.strip().splitlines()
    assert len(lines) == 1 and "has no examples" in lines[0] and "pip install" in lines[0], outcome.stderr
