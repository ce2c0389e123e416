"""`carlos examples DIR`: the example manifests, scenarios, maps and nodes, written from the installed package.

Every installed copy carries the repository's `examples/` folder as the package data `simcore/_examples`
(setup.py maps it, for `pip install .`, `pip install git+URL` and `make wheel` alike); an editable install
reads `examples/` beside the `simcore` package. Either way the files
are written to `DIR/examples/`, the layout of the repository, so every command of the documentation
(`carlos run examples/runs/perception.yaml`, `python -m examples.controller`) works from DIR.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

from simcore import DISTRIBUTION
from simcore.errors import BadInput

PACKAGED = "_examples"  # inside the simcore package, in the wheel
SKIPPED_PARTS = frozenset({"__pycache__"})
SKIPPED_SUFFIXES = (".pyc",)


def source() -> Traversable:
    """Where the examples of this installation are: the wheel's copy, else a checkout's `examples/`."""
    packaged = resources.files("simcore") / PACKAGED
    if packaged.is_dir():
        return packaged
    checkout = Path(__file__).resolve().parents[1] / "examples"
    if checkout.is_dir():
        return checkout
    raise BadInput(
        f"this installation of {DISTRIBUTION} has no examples ({packaged} is missing): reinstall it "
        f"(pip install --force-reinstall {DISTRIBUTION}), or copy examples/ from the source repository"
    )


def example_files(root: Traversable) -> list[tuple[str, bytes]]:
    """Every example file as (path relative to the examples folder, content), sorted by path."""
    found: list[tuple[str, bytes]] = []

    def walk(node: Traversable, prefix: str) -> None:
        for child in node.iterdir():
            if child.name in SKIPPED_PARTS or child.name.endswith(SKIPPED_SUFFIXES):
                continue
            path = f"{prefix}{child.name}"
            if child.is_dir():
                walk(child, f"{path}/")
            else:
                found.append((path, child.read_bytes()))

    walk(root, "")
    return sorted(found)


@dataclass(frozen=True)
class Plan:
    """What writing the examples into a folder would do: new files, files kept as they are (same content)
    and files that exist with other content (refused unless forced)."""

    write: list[tuple[str, bytes]]
    unchanged: list[str]
    conflicts: list[str]


def plan(files: list[tuple[str, bytes]], target: Path) -> Plan:
    write: list[tuple[str, bytes]] = []
    unchanged: list[str] = []
    conflicts: list[str] = []
    for name, content in files:
        path = target / name
        if path.is_file() and path.read_bytes() == content:
            unchanged.append(name)
            continue
        if path.exists():
            conflicts.append(name)
        write.append((name, content))
    return Plan(write, unchanged, conflicts)


def _write_atomic(path: Path, content: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(content)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def write_examples(directory: Path, *, force: bool = False) -> Plan:
    """Write the examples into `directory/examples/`. A file that exists with other content is bad input
    (exit 2) unless `force`; nothing is written then."""
    target = directory / "examples"
    if target.exists() and not target.is_dir():
        raise BadInput("exists and is not a folder: choose another DIR", file=str(target))
    result = plan(example_files(source()), target)
    if result.conflicts and not force:
        shown = ", ".join(result.conflicts[:3]) + (" …" if len(result.conflicts) > 3 else "")
        raise BadInput(
            f"{len(result.conflicts)} example file(s) exist with other content ({shown}): "
            "keep your changes by choosing another DIR, or overwrite them with --force",
            file=str(target),
        )
    for name, content in result.write:
        if (target / name).is_dir():
            raise BadInput(
                "is a folder where an example file belongs: choose another DIR", file=str(target / name)
            )
        _write_atomic(target / name, content)
    return result
