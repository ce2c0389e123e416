"""`carlos` — the command line (`main`; the commands are simcore.cli_app's typer app, also as `simcore.cli.app`).

This module stays small: the worker processes `carlos run` spawns start by importing the program's main module
(this one, or the `carlos` script importing `main` from it), and a worker needs none of the command line's
imports (typer, rich: some 50 ms before its first run).
"""

import gc
import sys
from typing import Any

from simcore.errors import CarlosError

_gc_paused = False


def pause_gc() -> None:
    """Start-up (imports, the CLI, the spec's validators, the scenario) allocates some 10^5 objects that live as
    long as the process and hardly any garbage; the cyclic collector would go through them again and again
    (40-60 ms of `carlos run`). `carlos` pauses it from the start until resume_gc()."""
    global _gc_paused
    if gc.isenabled():
        gc.disable()
        _gc_paused = True


def resume_gc() -> None:
    """Collect again, once start-up is over, with what start-up allocated frozen (gc.freeze: never scanned
    again). Only after pause_gc(): a process that did not pause the collector (tests calling the app, a
    program importing simcore) is left as it is."""
    global _gc_paused
    if _gc_paused:
        _gc_paused = False
        gc.freeze()
        gc.enable()


def main() -> None:
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


if __name__ == "__main__":  # `python -m simcore.cli`: run the module proper (where resume_gc looks)
    from simcore import cli

    cli.main()
