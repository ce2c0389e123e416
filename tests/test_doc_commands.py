"""Every command in the README's and the getting-started page's `sh` code blocks runs, on a fresh copy of the
repository (the files git tracks or would add), with the exit code the page gives: `# exit N` in the
command's comment, else 0. `.venv/bin/carlos` and `carlos` are this test's own installation. Commands that
need a cluster, or that CI runs itself, are listed in EXCLUDED with the reason; a command that is neither run
nor excluded fails the test, so a new command in those pages cannot go unchecked. Every SimulationRun in their
`yaml` blocks is validated from examples/runs/ (where their relative scenario paths point)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "docs" / "getting-started.md"]
VENV_BIN = Path(sys.executable).parent

#: command prefix → why it is not run here
EXCLUDED = {
    "make test": "runs the whole suite, this test included (CI runs it: .ci/run)",
    "make test-slow": "CI runs it (.ci/run)",
    "make lint": "CI runs it (.ci/run)",
    "make typecheck": "CI runs it (.ci/run)",
    "make docs": "CI runs it (.ci/run)",
    "make wheel-check": "CI runs it (.ci/run); it builds and installs the wheel in a clean virtualenv",
    "make wheel": "tests/test_wheel.py builds the wheel; tools/wheel-check installs it",
    "pip install": "installs into the current environment: tools/wheel-check does it in a clean virtualenv",
    "helm install": "needs a Kubernetes cluster (tests/test_helm.py renders the chart)",
    "kubectl": "needs a Kubernetes cluster",
    ".venv/bin/carlos submit": "needs a Kubernetes cluster (tests/test_submit.py against the emulator)",
    ".venv/bin/carlos watch automated-testing": "needs a Kubernetes cluster (a run name, not a results URL)",
}
SLOW = {"make demo"}


def commands(page: Path) -> list[tuple[str, int]]:
    """(command, expected exit code) of every `sh` block of a page, continuation lines joined."""
    out: list[tuple[str, int]] = []
    for block in re.findall(r"```sh\n(.*?)```", page.read_text(encoding="utf-8"), re.S):
        for line in block.replace("\\\n", " ").splitlines():
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            command, _, comment = line.partition(" # ")
            expected = re.search(r"\bexit (\d)\b", comment)
            out.append((" ".join(command.split()), int(expected.group(1)) if expected else 0))
    return out


def excluded(command: str) -> str | None:
    return next((why for prefix, why in EXCLUDED.items() if command.startswith(prefix)), None)


def fresh_copy(tmp: Path) -> Path:
    """The repository as a fresh clone of this working tree would have it (tracked and new files, not the
    ignored ones: no .venv, no results)."""
    listed = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, capture_output=True, check=True
    ).stdout.decode()
    copy = tmp / "carlos"
    for name in filter(None, listed.split("\0")):
        source = ROOT / name
        if source.is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, copy / name)
    return copy


def run(command: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    if command.startswith("make demo"):  # the installation is this test's: run the demo with it
        command = f"make -o install demo VENV={VENV_BIN.parent}"
    command = re.sub(r"(^|\s)\.venv/bin/", r"\1", command)
    env = {**os.environ, "PATH": f"{VENV_BIN}{os.pathsep}{os.environ['PATH']}"}
    return subprocess.run(command, shell=True, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


def test_every_command_is_run_or_excluded_with_a_reason() -> None:
    found = [c for page in PAGES for c, _ in commands(page)]
    assert "make demo" in found and "make test" in found  # the two set-up commands stay in the README
    for command in found:
        assert excluded(command) or command.startswith((".venv/bin/carlos", "carlos ", *SLOW)), (
            f"{command!r} is neither run by this test nor excluded with a reason"
        )


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_documented_commands_exit_as_documented(page: Path, tmp_path: Path) -> None:
    copy = fresh_copy(tmp_path)
    ran = 0
    for command, expected in commands(page):
        if excluded(command) or command in SLOW:
            continue
        result = run(command, copy)
        assert result.returncode == expected, (
            f"{page.name}: `{command}` exited {result.returncode}, documented {expected}\n{result.stderr[-2000:]}"
        )
        ran += 1
    assert ran >= 4


@pytest.mark.slow
def test_make_demo_runs_the_data_generation_example(tmp_path: Path) -> None:
    copy = fresh_copy(tmp_path)
    result = run("make demo", copy)
    assert result.returncode == 0, result.stderr[-3000:]
    assert (copy / "results" / "data-generation" / "summary.json").is_file()
    assert "12 runs" in result.stdout + result.stderr


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_documented_manifests_validate(page: Path, tmp_path: Path) -> None:
    copy = fresh_copy(tmp_path)
    manifests = []
    for i, manifest in enumerate(re.findall(r"```yaml\n(.*?)```", page.read_text(), re.S)):
        if "kind: SimulationRun" not in manifest:
            continue
        path = copy / "examples" / "runs" / f"documented-{i}.yaml"
        path.write_text(manifest)
        result = run(f"carlos validate {path.relative_to(copy)}", copy)
        assert result.returncode == 0, f"{page.name}, yaml block {i}: {result.stderr[-2000:]}"
        manifests.append(manifest)
    assert manifests, f"{page.name} shows no SimulationRun"
