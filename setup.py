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

import os
import shutil
import sys
import sysconfig
from pathlib import Path

from setuptools import Extension, find_namespace_packages, setup
from setuptools.command.build_ext import build_ext

#: CARLOS_COMPILE: "0" pure Python, "1" compiled or fail, unset: compiled when possible (see COMPILED)
MODE = os.environ.get("CARLOS_COMPILE", "")

#: The modules of a run's step loop (the scenario engine, its actions, conditions and controllers, the road
#: network, the SUMO bridge, the world frame, the metrics, the loop itself), compiled to C extensions by
#: mypyc when a wheel is built (`pip install .`, tools/build-wheel, the images' wheel stage): the same
#: source as machine code, about 40% less CPU per run of a sweep (docs/benchmarks.md). An editable install
#: (`make install`) stays pure Python, so that an edited file takes effect at once. CARLOS_COMPILE=0 builds
#: a pure-Python wheel, CARLOS_COMPILE=1 fails the build when it cannot compile; unset, the build compiles
#: when a C compiler and Python's headers are there and says so when it falls back to pure Python. `carlos
#: --version` tells which.
COMPILED = [
    "simcore/evaluation/metrics.py",
    "simcore/stepping.py",
    *(
        f"simcore/scenario/{name}.py"
        for name in (
            "action_registry",
            "action_world",
            "actions",
            "conditions",
            "controller_actions",
            "core_actions",
            "drivers",
            "engine",
            "ghost",
            "global_actions",
            "measure",
            "motion",
            "paths",
            "positions",
            "runtime",
            "signals",
            "story",
            "storyboard",
            "sumo_bridge",
            "triggers",
            "world",
        )
    ),
    *(
        f"simcore/scenario/controllers/{name}.py"
        for name in ("alks_r157", "follow_route", "lane_router", "looming", "road_view", "sloppy")
    ),
    *(
        f"simcore/world/{name}.py"
        for name in ("native_calls", "opendrive", "road_geometry", "road_model", "state", "sumo", "sumo_lanes")
    ),
]

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


def _say(message: str) -> None:
    print(f"carlos-sim: {message}", file=sys.stderr)


def _cannot_compile() -> str | None:
    """Why the modules cannot be compiled here (None: they can)."""
    compiler = (sysconfig.get_config_var("CC") or "cc").split()[0]
    if shutil.which(compiler) is None:
        return f"no C compiler ({compiler})"
    headers = Path(sysconfig.get_paths()["include"]) / "Python.h"
    if not headers.is_file():
        return f"no Python headers ({headers}; Debian: python3-dev)"
    return None


def _extensions() -> list[Extension]:
    if MODE not in ("0", "1", ""):
        raise SystemExit(
            f"CARLOS_COMPILE={MODE!r}: 0 (pure Python), 1 (compiled) or unset (compiled when possible)"
        )
    # a build compiles (mypyc type-checks the sources first: not for pip's metadata steps); an editable install
    # never does
    building = any(command in sys.argv for command in ("bdist_wheel", "build", "build_ext", "install"))
    editable = any(command in sys.argv for command in ("editable_wheel", "develop"))
    if MODE == "0" or not building or editable:
        return []
    reason = _cannot_compile()
    if reason is not None:
        if MODE == "1":
            raise SystemExit(f"CARLOS_COMPILE=1 but {reason}")
        _say(
            f"{reason}: the wheel is pure Python, sweeps run slower (CARLOS_COMPILE=0: pure Python on purpose)"
        )
        return []
    try:
        from mypyc.build import mypycify
    except ImportError:  # a build without its isolated environment (--no-build-isolation) and no mypy
        if MODE == "1":
            raise
        _say("no mypyc (pip install mypy): the wheel is pure Python, sweeps run slower")
        return []

    # mypy's own settings, not pyproject's [tool.mypy] (its pydantic plugin is not in the build environment);
    # debug level 0: no build folder names in the binaries
    options = ["--config-file=", "--ignore-missing-imports"]
    # one library for all of them (calls between them stay native), inside the package, not at the top level
    return mypycify([*options, *COMPILED], opt_level="3", debug_level="0", group_name="simcore._compiled")


class OptionalBuildExt(build_ext):
    """Builds the compiled modules; unless CARLOS_COMPILE=1, a failed build leaves the wheel pure Python."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:
            if MODE == "1":
                raise
            for extension in self.extensions:  # nothing half built: a module's shim without its library
                Path(self.get_ext_fullpath(extension.name)).unlink(missing_ok=True)
            _say(f"compiling failed ({exc}): the wheel is pure Python")


setup(
    ext_modules=_extensions(),
    cmdclass={"build_ext": OptionalBuildExt},
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
