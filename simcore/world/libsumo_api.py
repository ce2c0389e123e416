"""libsumo's API (its SWIG module: `simulation`, `vehicle`, `vehicletype`, `route`, `edge`, `lane`,
`TraCIException`) without what the `libsumo` package imports around it.

`import libsumo` also imports traci, and through it sumolib, numpy, pyproj and lxml, and looks up pyarrow's
version: ~0.25 CPU s of a worker's first run (or of a single `carlos run` with a SUMO-driven entity) that a
run never uses. So the package's compiled module and its SWIG wrapper are loaded as the package would load
them, under the same names (`libsumo._libsumo`, `libsumo.libsumo`), without running the package's
`__init__`: a later `import libsumo` (a user's module, a test) runs it and finds both loaded, so the package
and this API share one module and one set of classes (a `TraCIException` raised is the class both name).
What the package's `__init__` adds that a run uses is repeated here: `SUMO_HOME` (and PROJ's data) set from
the `sumo_data` or `eclipse-sumo` wheel when unset. Its other additions (traci's step listeners around
`simulationStep`, `start` with tracing) CARLOS never uses: start, step and close are
`simulation.start`, `simulation.step` and `simulation.close`.

Anything unexpected (another libsumo layout) falls back to `import libsumo`.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import types
from importlib.machinery import EXTENSION_SUFFIXES
from pathlib import Path
from typing import Any


def load() -> Any:
    """The libsumo API: the `libsumo` package when it is imported already (or cannot be loaded apart), else
    its SWIG module, loaded once per process."""
    package = sys.modules.get("libsumo")
    if package is not None:
        return package
    loaded = sys.modules.get("libsumo.libsumo")
    if loaded is not None:
        return loaded
    try:
        return _load_apart()
    except Exception:
        # another layout of the package: load it the usual way (`_module` left nothing half-made)
        import libsumo

        return libsumo


def compiled() -> Any:
    """libsumo's compiled module (`libsumo._libsumo`: the functions the SWIG classes forward to), once `load`
    loaded it."""
    return sys.modules["libsumo._libsumo"]


def _load_apart() -> Any:
    spec = importlib.util.find_spec("libsumo")  # finds the package without importing it
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("no libsumo package")
    folder = Path(next(iter(spec.submodule_search_locations)))
    wrapper_file = folder / "libsumo.py"
    compiled_file = next(
        (
            folder / f"_libsumo{suffix}"
            for suffix in EXTENSION_SUFFIXES
            if (folder / f"_libsumo{suffix}").is_file()
        ),
        None,
    )
    if compiled_file is None or not wrapper_file.is_file():
        raise ImportError(f"libsumo's modules are not in {folder}")
    _set_sumo_home()
    compiled = sys.modules.get("libsumo._libsumo")
    if compiled is None:
        compiled = _module("libsumo._libsumo", compiled_file)
    # The wrapper imports its compiled module relatively (`from . import _libsumo`), which would import the
    # package: for that moment, a bare package holding the compiled module stands in for it.
    stand_in = types.ModuleType("libsumo")
    stand_in.__path__ = [str(folder)]
    stand_in._libsumo = compiled  # type: ignore[attr-defined]
    sys.modules["libsumo"] = stand_in
    try:
        wrapper = _module("libsumo.libsumo", wrapper_file)  # (the package's own import of it finds it)
    finally:
        if sys.modules.get("libsumo") is stand_in:
            del sys.modules["libsumo"]
    return wrapper


def _module(name: str, path: Path) -> Any:
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def _set_sumo_home() -> None:
    """`SUMO_HOME` (and PROJ's data folder) as `libsumo/__init__.py` sets them when they are not set: from the
    `sumo_data` wheel, else from the `eclipse-sumo` wheel."""
    try:
        import sumo_data

        home = sumo_data.__path__[0]
        if not os.environ.get("SUMO_HOME"):
            os.environ["SUMO_HOME"] = home
        if not os.environ.get("PROJ_LIB") and not os.environ.get("PROJ_DATA"):
            os.environ["PROJ_LIB"] = os.environ["PROJ_DATA"] = os.path.join(home, "data", "proj")
    except ImportError:
        try:
            import sumo

            if hasattr(sumo, "SUMO_HOME") and not os.environ.get("SUMO_HOME"):
                os.environ["SUMO_HOME"] = sumo.SUMO_HOME
        except ImportError:
            pass
