"""The cyclic garbage collector's pause during `carlos`'s start-up (pause_gc from simcore.cli.main, resume_gc
from the command once under way). A module of its own, so the command line's entry point (simcore.cli) and its
commands (simcore.cli_app) both use it without importing each other."""

import gc

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


_worker_settled = False


def settle_worker() -> None:
    """Called by a warm worker (a `carlos run` pool worker, the simcore pod) after each run: after the first,
    what it left alive (imports, the parsed scenario and road, the type store: some 10^5 objects that live as
    long as the process) is frozen once (gc.collect, then gc.freeze), so that the collections of later runs
    go through what those runs allocate only. Later calls do nothing."""
    global _worker_settled
    if not _worker_settled:
        _worker_settled = True
        gc.collect()
        gc.freeze()
