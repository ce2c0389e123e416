"""The packages of the `carlos-sim` distribution and their data (every other field: pyproject.toml).

Here rather than in pyproject.toml because the repository's `examples/` folder ships as the data package
`simcore._examples` straight from the source tree, so that every way of installing (`pip install .`,
`pip install git+URL`, `make wheel`) carries the examples that `carlos examples DIR` writes out; pyproject's
`packages.find` cannot add a package mapped from another folder.

`operator/` must not be importable as `operator` (it would shadow the standard library): it has no
__init__.py and holds the package `carlos_operator` (operator/carlos_operator/). Every package under simcore/
and operator/carlos_operator/ is found (tests/test_wheel.py checks the built wheel against the source tree).
Folders of data only (simcore/transport/msg/*, examples/runs, …) are listed as packages too: setuptools
warns about every folder that is importable but not listed.
"""

from pathlib import Path

from setuptools import find_namespace_packages, setup

EXAMPLES = "simcore._examples"
CACHES = ["*__pycache__"]
# a source tree without examples/ (a container build that copies only the packages) installs without them:
# `carlos examples` then says so (exit 2)
examples = (
    [EXAMPLES, *(f"{EXAMPLES}.{name}" for name in find_namespace_packages("examples", exclude=CACHES))]
    if Path("examples").is_dir()
    else []
)
simcore = find_namespace_packages(".", include=["simcore", "simcore.*"], exclude=CACHES)
operator = find_namespace_packages(
    "operator", include=["carlos_operator", "carlos_operator.*"], exclude=CACHES
)

setup(
    packages=[*simcore, *operator, *examples],
    package_dir={
        "simcore": "simcore",
        "carlos_operator": "operator/carlos_operator",
        **({EXAMPLES: "examples"} if examples else {}),
    },
    package_data={
        "simcore": ["py.typed"],
        **{p: ["*.msg"] for p in simcore if p.startswith("simcore.transport.msg.")},
        "carlos_operator": ["py.typed"],
        **{name: ["*"] for name in examples},
    },
    exclude_package_data={name: ["*.pyc"] for name in examples},
)
