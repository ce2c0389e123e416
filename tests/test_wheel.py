"""The built wheel (tools/build-wheel): it holds every module and data file of the source tree, and an
installed copy (site-packages, not this checkout) works — the numba kernels compiled from it into a seed load
with no compilation, as the simcore image relies on. tools/wheel-check (CI) goes further: a clean virtualenv
with the wheel's dependencies, read-only, running `carlos run` and each pod role."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: source directory → its path in the wheel (operator/ is not a package: it holds carlos_operator)
PACKAGE_ROOTS = {
    ROOT / "simcore": "simcore",
    ROOT / "operator" / "carlos_operator": "carlos_operator",
    ROOT / "examples": "simcore/_examples",  # package data: `carlos examples DIR` writes it out
}
#: the distribution is carlos-sim (`carlos` on PyPI is another project); the command stays `carlos`
DIST_INFO = "carlos_sim-0.1.0.dist-info/"


def build_wheel(out: Path) -> Path:
    """A pure-Python wheel (CARLOS_COMPILE=0: what it holds besides the compiled modules is the same, and
    compiling them takes minutes; tools/wheel-check builds, checks and runs the compiled wheel)."""
    result = subprocess.run(
        [str(ROOT / "tools" / "build-wheel"), str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "PYTHON": sys.executable, "CARLOS_COMPILE": "0"},
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return Path(result.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_wheel(tmp_path_factory.mktemp("dist"))


def tracked() -> set[Path]:
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return {ROOT / name for name in listed.decode().split("\0") if name}


def source_files() -> dict[str, Path]:
    """Every file the wheel must hold, by its path inside the wheel: the files git tracks in the package
    folders (untracked scratch files, caches and bytecode stay out)."""
    files: dict[str, Path] = {}
    for path in sorted(tracked()):
        for directory, package in PACKAGE_ROOTS.items():
            if path.is_file() and path.is_relative_to(directory):
                files[f"{package}/{path.relative_to(directory).as_posix()}"] = path
    return files


def test_wheel_holds_every_module_and_data_file(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
        expected = source_files()
        missing = sorted(set(expected) - names)
        assert not missing, f"{wheel.name} lacks {missing}"
        packed = {n for n in names if not n.startswith(DIST_INFO)}
        assert packed == set(expected), (
            f"not tracked by git, yet in the wheel: {sorted(packed - set(expected))}"
        )
        for name, path in expected.items():
            assert archive.read(name) == path.read_bytes(), f"{name} differs from {path}"
        entry_points = archive.read(f"{DIST_INFO}entry_points.txt").decode()
    assert "carlos = simcore.cli:main" in entry_points
    # what the issue found missing, and the data files a run loads
    for required in ("simcore/sensors/kernels.py", "simcore/py.typed", "carlos_operator/py.typed"):
        assert required in names
    assert sum(n.endswith(".msg") for n in names) >= 18
    # nothing from outside the two packages (tests, examples, the operator/ folder as a package)
    tops = {n.split("/")[0] for n in names if not n.startswith(DIST_INFO)}
    assert tops == {"simcore", "carlos_operator"}


def _install(wheel: Path, target: Path) -> None:
    """Installs a wheel or a source folder (built pure Python: CARLOS_COMPILE=0, as in `build_wheel`)."""
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
        env={**os.environ, "CARLOS_COMPILE": "0"},
    )


KERNEL_MISSES = """
import simcore.sensors.kernels as kernels, sys
print(kernels.__file__)
kernels.warm()
print(sum(sum(getattr(kernels, n).stats.cache_misses.values()) for n in dir(kernels)
          if hasattr(getattr(kernels, n), "stats")))
"""


@pytest.mark.slow
def test_numba_seed_compiled_from_the_installed_package_loads_without_compiling(
    wheel: Path, tmp_path: Path
) -> None:
    """What images/simcore does: install the wheel, compile the kernels from site-packages into a seed
    (read-only in the image); a pod copies it into its empty NUMBA_CACHE_DIR and compiles nothing. A seed
    compiled from the source tree (what the image once did, from /src) is keyed by the other path: it
    would not be used."""
    site = tmp_path / "site"
    _install(wheel, site)
    env = {
        **{k: v for k, v in os.environ.items() if k != "CARLOS_NUMBA_CACHE_SEED"},
        "PYTHONPATH": str(site),
        "NUMBA_CPU_NAME": "generic",
    }

    def misses(cache: Path, seed: Path | None = None, source: Path = site) -> int:
        run_env = {**env, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(source)}
        if seed is not None:
            run_env["CARLOS_NUMBA_CACHE_SEED"] = str(seed)
        result = subprocess.run(
            [sys.executable, "-c", KERNEL_MISSES],
            env=run_env,
            cwd=tmp_path,  # not the checkout: `import simcore` must find the installed copy
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert result.returncode == 0, result.stderr[-3000:]
        module, count = result.stdout.split()[-2:]
        assert module.startswith(str(source)), module  # the copy meant, not whatever is on the path
        return int(count)

    assert misses(tmp_path / "seed") > 0  # compiled into the seed
    (tmp_path / "seed").chmod(0o555)
    assert misses(tmp_path / "pod", seed=tmp_path / "seed") == 0
    assert any((tmp_path / "pod").rglob("*.nbi"))

    assert misses(tmp_path / "src-seed", source=ROOT) > 0
    (tmp_path / "src-seed").chmod(0o555)
    assert misses(tmp_path / "pod2", seed=tmp_path / "src-seed") > 0


@pytest.mark.slow
def test_every_module_imports_from_the_installed_wheel(wheel: Path, tmp_path: Path) -> None:
    """Installed (not this checkout), every module of both packages imports and the message definitions
    load: nothing relies on a file the wheel lacks."""
    site = tmp_path / "site"
    _install(wheel, site)
    code = """
import importlib, pkgutil, simcore, carlos_operator
from simcore.transport.messages import TYPESTORE
for package in (simcore, carlos_operator):
    for module in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        importlib.import_module(module.name)
assert "vision_msgs/msg/Detection3DArray" in TYPESTORE.types
print(simcore.__file__, carlos_operator.__file__)
"""
    result = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, "PYTHONPATH": str(site)},
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert all(path.startswith(str(site)) for path in result.stdout.split()), result.stdout


def test_pip_install_of_the_source_folder_carries_the_examples(tmp_path: Path) -> None:
    """`pip install <source folder>` (and so `pip install git+URL`), not only `make wheel`, installs the
    examples: `carlos examples .` writes them in another folder, and an example runs from there."""
    source = tmp_path / "source"
    for path in tracked():
        if path.is_file():
            (source / path.relative_to(ROOT)).parent.mkdir(parents=True, exist_ok=True)
            (source / path.relative_to(ROOT)).write_bytes(path.read_bytes())
    site = tmp_path / "site"
    _install(source, site)
    assert (site / "simcore" / "_examples" / "runs" / "prototyping.yaml").is_file()
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site)}

    def carlos(*args: str) -> subprocess.CompletedProcess[str]:
        command = [sys.executable, "-m", "simcore.cli", *args]
        return subprocess.run(command, cwd=work, env=env, capture_output=True, text=True, timeout=600)

    version = carlos("--version")
    assert version.stdout.strip() == "carlos 0.1.0 (carlos-sim, pure Python)", version.stdout + version.stderr
    written = carlos("examples", ".")
    assert written.returncode == 0, written.stderr
    assert (work / "examples" / "runs" / "prototyping.yaml").read_bytes() == (
        ROOT / "examples" / "runs" / "prototyping.yaml"
    ).read_bytes()
    ran = carlos("run", "examples/runs/prototyping.yaml", "--quiet")
    assert ran.returncode == 0, ran.stderr[-3000:]
    assert (work / "results" / "prototyping" / "0" / "summary.json").is_file()
