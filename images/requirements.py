"""Print the package's runtime requirements (pyproject.toml [project].dependencies), one per line, leaving out
the named distributions. The slim images install only what their role imports:

    python images/requirements.py --without eclipse-sumo libsumo sumolib open3d-cpu > requirements.txt

An unknown name is an error (exit 2), so a renamed dependency cannot slip into a slim image unnoticed.
"""

from __future__ import annotations

import argparse
import re
import sys
import tomllib
from pathlib import Path


def distribution(requirement: str) -> str:
    """The normalised distribution name of a PEP 508 requirement."""
    match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement)
    if not match:
        raise ValueError(f"not a requirement: {requirement!r}")
    return re.sub(r"[-_.]+", "-", match.group(1)).lower()


def requirements(pyproject: Path, without: list[str]) -> list[str]:
    dependencies: list[str] = tomllib.loads(pyproject.read_text())["project"]["dependencies"]
    names = {distribution(d) for d in dependencies}
    dropped = {distribution(w) for w in without}
    unknown = sorted(dropped - names)
    if unknown:
        raise KeyError(f"not a dependency in {pyproject}: {', '.join(unknown)}")
    return [d for d in dependencies if distribution(d) not in dropped]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--pyproject", type=Path, default=Path(__file__).resolve().parents[1] / "pyproject.toml"
    )
    parser.add_argument("--without", nargs="*", default=[], help="distributions to leave out")
    args = parser.parse_args(argv)
    try:
        lines = requirements(args.pyproject, args.without)
    except KeyError as exc:
        print(f"error: {exc.args[0]}", file=sys.stderr)
        return 2
    sys.stdout.write("".join(f"{line}\n" for line in lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
