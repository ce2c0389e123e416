"""Every command in the `sh` code blocks of the README, the getting-started page and every tutorial runs, in
the order of the page, on a fresh copy of the repository (the files git tracks or would add), with the exit
code the page gives: `# exit N` in the command's comment, else 0. `.venv/bin/carlos`, `.venv/bin/python` and
`carlos` are this test's own installation. As a reader's shell would: `export` sets variables for the commands
after it, a command ending in `&` runs in the background (it must end, with its exit code, by the end of its
block). A `yaml` block whose first line is `# save as PATH` is written to PATH when the page reaches it (the
page's later commands run it). Commands that need a cluster, or that CI runs itself, are listed in EXCLUDED
with the reason; a command that is neither run nor excluded fails the test, so a new command in those pages
cannot go unchecked. Every other SimulationRun in their `yaml` blocks is validated from examples/runs/ (where
their relative scenario paths point)."""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [
    ROOT / "README.md",
    ROOT / "docs" / "getting-started.md",
    *sorted((ROOT / "docs" / "tutorials").glob("*.md")),
    ROOT / "docs" / "ci.md",  # "Comparing builds, flaky runs, the report" in the tutorials' section
]
VENV_BIN = Path(sys.executable).parent
SAVE_AS = re.compile(r"#\s*save as\s+(\S+)")

#: command prefix → why it is not run here
EXCLUDED = {
    "make test": "runs the whole suite, this test included (CI runs it: .ci/run)",
    "make test-slow": "CI runs it (.ci/run)",
    "make lint": "CI runs it (.ci/run)",
    "make typecheck": "CI runs it (.ci/run)",
    "make docs": "CI runs it (.ci/run)",
    "make wheel-check": "CI runs it (.ci/run); it builds and installs the wheel in a clean virtualenv",
    "make wheel": "tests/test_wheel.py builds the wheel; tools/wheel-check installs it",
    "pip install": "installs into the current environment: tests/test_wheel.py installs the source folder, "
    "tools/wheel-check the wheel, each in a folder of its own",
    "helm install": "needs a Kubernetes cluster (tests/test_helm.py renders the chart)",
    "kubectl": "needs a Kubernetes cluster",
    ".venv/bin/carlos submit": "needs a Kubernetes cluster (tests/test_submit.py against the emulator)",
    ".venv/bin/carlos watch automated-testing": "needs a Kubernetes cluster (a run name, not a results URL)",
}
SLOW = {"make demo"}
#: a live view serves on 127.0.0.1:8765 (the documented default): one at a time across test processes
LIVE_LOCK = Path(tempfile.gettempdir()) / "carlos-doc-commands-live.lock"


@dataclass(frozen=True)
class Command:
    text: str
    expected: int
    block: int  # the page's code block it is in (a background command must end within its block)


@dataclass(frozen=True)
class SavedFile:
    path: str
    content: str
    block: int


def steps(page: Path) -> list[Command | SavedFile]:
    """In the page's order: every command of its `sh` blocks (continuation lines joined) with its expected
    exit code, and every `yaml` block to be saved (`# save as PATH`)."""
    out: list[Command | SavedFile] = []
    text = page.read_text(encoding="utf-8")
    for block, (kind, body) in enumerate(re.findall(r"```(sh|yaml)\n(.*?)```", text, re.S)):
        if kind == "yaml":
            first = body.splitlines()[0] if body.strip() else ""
            saved = SAVE_AS.fullmatch(first.strip())
            if saved:
                out.append(SavedFile(saved.group(1), body, block))
            continue
        for line in body.replace("\\\n", " ").splitlines():
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            command, _, comment = line.partition(" # ")
            expected = re.search(r"\bexit (\d)\b", comment)
            out.append(Command(" ".join(command.split()), int(expected.group(1)) if expected else 0, block))
    return out


def commands(page: Path) -> list[tuple[str, int]]:
    return [(s.text, s.expected) for s in steps(page) if isinstance(s, Command)]


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


def shell_command(command: str) -> str:
    if command.startswith("make demo"):  # the installation is this test's: run the demo with it
        return f"make -o install demo VENV={VENV_BIN.parent}"
    return re.sub(r"(^|\s)\.venv/bin/", r"\1", command)


def base_env() -> dict[str, str]:
    return {**os.environ, "PATH": f"{VENV_BIN}{os.pathsep}{os.environ['PATH']}"}


def run(command: str, cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        shell_command(command),
        shell=True,
        cwd=cwd,
        env=env or base_env(),
        capture_output=True,
        text=True,
        timeout=900,
    )


@contextlib.contextmanager
def live_view(command: str) -> Iterator[None]:
    if "--live" not in command.split():
        yield
        return
    with LIVE_LOCK.open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def test_every_command_is_run_or_excluded_with_a_reason() -> None:
    found = [c for page in PAGES for c, _ in commands(page)]
    assert "make demo" in found and "make test" in found  # the two set-up commands stay in the README
    runnable = (".venv/bin/carlos", ".venv/bin/python", "carlos ", "export ", *SLOW)
    for command in found:
        assert excluded(command) or command.startswith(runnable), (
            f"{command!r} is neither run by this test nor excluded with a reason"
        )
    # every tutorial is here
    assert {p.name for p in PAGES} >= {p.name for p in (ROOT / "docs" / "tutorials").glob("*.md")}


def test_the_readme_keeps_exactly_two_set_up_commands() -> None:
    readme = ROOT / "README.md"
    setup = [c for c, _ in commands(readme) if c.startswith("make ") and c in ("make demo", "make test")]
    assert setup == ["make demo", "make test"]


#: pages whose commands take minutes on two busy cores: CI runs them as the slow step (make test-slow)
SLOW_PAGES = {"data-driven.md", "v2x.md"}


@pytest.mark.parametrize(
    "page",
    [pytest.param(p, marks=pytest.mark.slow) if p.name in SLOW_PAGES else p for p in PAGES],
    ids=lambda p: p.name,
)
def test_documented_commands_exit_as_documented(page: Path, tmp_path: Path) -> None:
    copy = fresh_copy(tmp_path)
    env = base_env()
    background: list[tuple[Command, subprocess.Popen[str]]] = []
    ran = 0

    def finish_background() -> None:
        for command, process in background:
            try:
                out, err = process.communicate(timeout=300)
            except subprocess.TimeoutExpired:
                process.kill()
                out, err = process.communicate()
                pytest.fail(
                    f"{page.name}: `{command.text} &` still ran at the end of its block\n{err[-2000:]}"
                )
            assert process.returncode == command.expected, (
                f"{page.name}: `{command.text} &` exited {process.returncode}, documented {command.expected}\n"
                f"{out[-1000:]}{err[-2000:]}"
            )
        background.clear()

    block = -1
    for step in steps(page):
        if step.block != block:
            finish_background()
            block = step.block
        if isinstance(step, SavedFile):
            target = copy / step.path
            assert copy in target.resolve().parents, step.path
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(step.content)
            continue
        if excluded(step.text) or step.text in SLOW:
            continue
        if step.text.startswith("export "):
            for assignment in shlex.split(step.text)[1:]:
                name, _, value = assignment.partition("=")
                env[name] = value
            continue
        if step.text.endswith("&"):
            process = subprocess.Popen(
                shell_command(step.text[:-1].strip()),
                shell=True,
                cwd=copy,
                env=dict(env),
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            background.append((step, process))
            continue
        with live_view(step.text):
            result = run(step.text, copy, dict(env))
        assert result.returncode == step.expected, (
            f"{page.name}: `{step.text}` exited {result.returncode}, documented {step.expected}\n"
            f"{result.stdout[-1500:]}\n{result.stderr[-2000:]}"
        )
        ran += 1
    finish_background()
    assert ran >= 1


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
    for i, manifest in enumerate(re.findall(r"```yaml\n(.*?)```", page.read_text(), re.S)):
        if "kind: SimulationRun" not in manifest:
            continue
        saved = SAVE_AS.fullmatch(manifest.splitlines()[0].strip())
        path = copy / (saved.group(1) if saved else f"examples/runs/documented-{i}.yaml")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(manifest)
        result = run(f"carlos validate {path.relative_to(copy)}", copy)
        assert result.returncode == 0, f"{page.name}, yaml block {i}: {result.stderr[-2000:]}"
