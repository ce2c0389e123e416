"""Two folders of run results must hold the same results: the same files, recordings byte for byte, and
summaries, verdicts, logs and manifests the same except for what differs between any two runs (wall-clock
times, the output folder's own name). Not `carlos compare` (simcore/compare.py): that one judges a candidate
build against a baseline within tolerances; this one asks for the same bytes. tools/wheel-check runs two
examples with the installed (compiled) wheel and with the checkout's source and compares them with this. `report.html` is left out: it shows wall
times and the folder in its text.

Usage: python tools/same_results.py FOLDER_A FOLDER_B   (exit 1 with the differences; 0 and a count when the same)
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

#: summary keys that differ between any two runs of the same thing
RUN_SPECIFIC = {"wallSeconds", "outputUrl"}
#: JUnit's wall times
WALL_TIMES = re.compile(rb'\btime="[^"]*"')


def _drop(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop(v) for k, v in value.items() if k not in RUN_SPECIFIC}
    if isinstance(value, list):
        return [_drop(v) for v in value]
    return value


def files(root: Path) -> set[Path]:
    """The files compared under `root`, relative to it."""
    return {p.relative_to(root) for p in root.rglob("*") if p.is_file() and p.name != "report.html"}


def differences(a: Path, b: Path) -> list[str]:
    files_a, files_b = files(a), files(b)
    out = [f"only in {a}: {p}" for p in sorted(files_a - files_b)]
    out += [f"only in {b}: {p}" for p in sorted(files_b - files_a)]
    for rel in sorted(files_a & files_b):
        x, y = (a / rel).read_bytes(), (b / rel).read_bytes()
        if x == y:
            continue
        if rel.suffix == ".json":
            if _drop(json.loads(x)) == _drop(json.loads(y)):
                continue
        elif rel.suffix in (".xml", ".txt", ".yaml"):
            x = WALL_TIMES.sub(b"", x.replace(str(a).encode(), b"<root>"))
            y = WALL_TIMES.sub(b"", y.replace(str(b).encode(), b"<root>"))
            if x == y:
                continue
        out.append(f"differs: {rel}")
    return out


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    a, b = (Path(arg) for arg in argv)
    found = differences(a, b)
    if found:
        print("\n".join(found[:50]), file=sys.stderr)
        return 1
    count = len(files(a))
    if count == 0:
        print(f"no results in {a}", file=sys.stderr)
        return 1
    print(f"the same results: {count} files")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
