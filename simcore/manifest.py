"""Loading SimulationRun manifests: untrusted YAML → validated models, with one clear line per problem."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from simcore.errors import BadInput, shorten
from simcore.spec import SimulationRun

MAX_MANIFEST_BYTES = 4 * 1024 * 1024
# A manifest is a few hundred values a dozen levels deep; aliases (`*a`) count every time they are used, so
# an alias bomb stops here instead of in validation.
MAX_MANIFEST_DEPTH = 64
MAX_MANIFEST_VALUES = 1_000_000


def _location(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part.startswith(("function-", "tagged-union")):
            continue
        else:
            out += f".{part}" if out else str(part)
    return out


def format_validation_error(error: ValidationError) -> str:
    """pydantic's errors as `field.path: message` lines (camelCase paths, as the user wrote them)."""
    lines = []
    for item in error.errors(include_url=False):
        loc = _location(tuple(item["loc"]))
        message = str(item["msg"]).removeprefix("Value error, ")
        if item["type"] == "extra_forbidden":
            message = "unknown field (check the spelling; fields are camelCase: see `carlos docs`)"
        elif item["type"] == "missing":
            message = "required field is missing"
        elif item["type"] == "string_pattern_mismatch" and loc == "spec.output.url":
            given = shorten(str(item.get("input")))
            folder = f": a folder is file://{given}" if "://" not in given else ""
            message = f"{given!r} is not a results URL (file://PATH or s3://bucket/prefix){folder}"
        lines.append(f"{loc}: {message}" if loc else message)
    return "; ".join(lines)


def check_shape(data: Any, *, source: str) -> None:
    """Refuse a document nested deeper than MAX_MANIFEST_DEPTH or with more than MAX_MANIFEST_VALUES values
    (aliases counted each time), without recursion."""
    stack: list[tuple[Any, int]] = [(data, 1)]
    values = 0
    while stack:
        node, depth = stack.pop()
        values += 1
        if values > MAX_MANIFEST_VALUES:
            raise BadInput(f"more than {MAX_MANIFEST_VALUES} values (counting aliases)", file=source)
        if depth > MAX_MANIFEST_DEPTH:
            raise BadInput(f"nested more than {MAX_MANIFEST_DEPTH} levels deep", file=source)
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)


def _yaml_problem(exc: yaml.YAMLError, text: str) -> str:
    """`invalid YAML at line L, column C: problem` for any PyYAML error (a reader error has an offset)."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    if mark is not None:
        where = f" at line {mark.line + 1}, column {mark.column + 1}"
    elif isinstance(exc, yaml.reader.ReaderError):
        before = text[: exc.position]
        where = f" at line {before.count(chr(10)) + 1}, column {len(before) - before.rfind(chr(10))}"
    else:
        where = ""
    if isinstance(exc, yaml.reader.ReaderError):
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        problem = f"character #x{code:04x} is not allowed in YAML (control characters must be escaped)"
    else:
        problem = getattr(exc, "problem", None) or getattr(exc, "context", None) or str(exc).splitlines()[0]
    return f"invalid YAML{where}: {problem}"


def parse_manifest(data: Any, *, source: str) -> SimulationRun:
    """Validate an already-loaded manifest document."""
    if not isinstance(data, dict):
        raise BadInput(
            "the manifest must be a YAML mapping with apiVersion, kind, metadata and spec", file=source
        )
    try:
        run = SimulationRun.model_validate(data)
    except ValidationError as exc:
        raise BadInput(format_validation_error(exc), file=source) from None
    return run


@contextmanager
def _without_pydantic_plugins() -> Iterator[None]:
    """pydantic looks for plugins (the `pydantic` entry points of every installed distribution, 35-75 ms) when
    it builds its first validator. The spec models are CARLOS's own: a command line or pod process builds them
    without plugins (as typer does for its parameters); the variable is restored before anything else runs.
    Not for the operator, whose threads share the environment (it validates through parse_manifest)."""
    previous = os.environ.get("PYDANTIC_DISABLE_PLUGINS")
    os.environ["PYDANTIC_DISABLE_PLUGINS"] = "1"
    try:
        yield
    finally:
        if previous is None:
            del os.environ["PYDANTIC_DISABLE_PLUGINS"]
        else:
            os.environ["PYDANTIC_DISABLE_PLUGINS"] = previous


def load_manifest(path: str | Path) -> SimulationRun:
    """Read and validate a manifest file. A missing `metadata.name` is taken from the file name."""
    path = Path(path)
    source = str(path)
    if path.is_dir():
        raise BadInput(
            "is a directory: give a manifest file, e.g. examples/runs/automated-testing.yaml", file=source
        )
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise BadInput("file not found", file=source) from None
    except OSError as exc:
        raise BadInput(f"cannot read: {exc.strerror}", file=source) from None
    if size > MAX_MANIFEST_BYTES:
        raise BadInput(f"manifest is {size} bytes; at most {MAX_MANIFEST_BYTES} are allowed", file=source)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise BadInput("not UTF-8 text", file=source) from None
    try:
        documents = [doc for doc in yaml.safe_load_all(text) if doc is not None]
    except yaml.YAMLError as exc:
        raise BadInput(_yaml_problem(exc, text), file=source) from None
    except RecursionError:
        raise BadInput(f"nested more than {MAX_MANIFEST_DEPTH} levels deep", file=source) from None
    if len(documents) != 1:
        raise BadInput(f"expected exactly one YAML document, found {len(documents)}", file=source)
    data = documents[0]
    check_shape(data, source=source)
    if isinstance(data, dict):
        metadata = data.setdefault("metadata", {}) or {}
        if isinstance(metadata, dict) and not metadata.get("name") and not metadata.get("generateName"):
            metadata["name"] = _name_from_file(path)
            data["metadata"] = metadata
    with _without_pydantic_plugins():
        run = parse_manifest(data, source=source)
    if run.metadata.name is None and run.metadata.generate_name:
        # locally there is no API server to generate a name: take the prefix plus the file name
        name = f"{run.metadata.generate_name.rstrip('-')}-{_name_from_file(path)}"[:63].strip("-")
        run = run.model_copy(update={"metadata": run.metadata.model_copy(update={"name": name})})
    distribution = run.spec.sweep.distribution
    if distribution and not distribution.startswith("s3://") and not Path(distribution).is_absolute():
        # relative to the manifest, like the scenario files: the spec as applied names the file itself
        located = str((path.parent / distribution).resolve())
        sweep = run.spec.sweep.model_copy(update={"distribution": located})
        run = run.model_copy(update={"spec": run.spec.model_copy(update={"sweep": sweep})})
    return run


def _name_from_file(path: Path) -> str:
    stem = "".join(ch if ch.isalnum() else "-" for ch in path.stem.lower()).strip("-")
    return (stem or "run")[:63].strip("-")
