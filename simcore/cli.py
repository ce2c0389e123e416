"""`carlos` — the command line (`main`; the commands are simcore.cli_app's typer app, also as `simcore.cli.app`,
imported when first asked for: simcore.cli_app does not import this module, so there is no import circle).

This module stays small: the worker processes `carlos run` spawns start by importing the program's main module
(this one, or the `carlos` script importing `main` from it), and a worker needs none of the command line's
imports (typer, rich: some 50 ms before its first run).
"""

import os
import sys
from typing import Any

from simcore.errors import CarlosError
from simcore.startup import pause_gc, resume_gc

__all__ = ["main", "pause_gc", "resume_gc"]


#: one BLAS thread per process unless the environment says otherwise: CARLOS runs in parallel as processes
#: (`--parallel` workers, pods), each busy on its own core, so OpenBLAS's pool of threads (numpy's) would only
#: compete with the other processes for the cores (its threads spin when they start and after each product)
SINGLE_THREADED_BLAS = {"OPENBLAS_NUM_THREADS": "1"}


def main() -> None:
    for name, value in SINGLE_THREADED_BLAS.items():  # before anything imports numpy; workers inherit it
        os.environ.setdefault(name, value)
    pause_gc()
    from simcore.cli_app import _line, app, console

    try:
        app()
    except CarlosError as exc:  # a last guard: never a traceback for our own errors
        console.print(_line("error:", "bold red", exc), highlight=False, soft_wrap=True)
        sys.exit(int(exc.exit_code))


def __getattr__(name: str) -> Any:
    """`simcore.cli.app` and the rest of simcore.cli_app, imported when first asked for."""
    if name.startswith("__"):
        raise AttributeError(name)
    import simcore.cli_app

    return getattr(simcore.cli_app, name)


if __name__ == "__main__":  # `python -m simcore.cli`
    main()
