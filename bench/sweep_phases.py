"""Where a warm sweep worker's CPU goes, per run and per phase.

One process plays a `carlos run` pool worker (`simcore.executor._work`, as the pool calls it) over
BENCH_RUNS (default 150) indexes of bench/pipeline.py's sweep (examples/scenarios/cut-in.xosc, EgoSpeed ×
CutInGap × AdversarySpeed, SUMO drives Ego; recording off, BENCH_RECORDING=1 for on), after 3 warm-up
runs. Each phase is timed with `time.process_time` around the function that does it (a wrapper in this
process only; the exclusive time of each, nested phases subtracted): parsing the scenario, the road, SUMO's
start, step (libsumo and the placement of scripted vehicles) and close, the engine's set-up, the steps
(the engine, frames, metrics), publishing, the recording's metadata and close, criteria, the summary and
the object store. A wrapper costs ~0.3 µs per call, so per-step phases read slightly high.

CPU milliseconds per run (a shared machine's load changes wall times, less so CPU times; still, compare
figures measured in the same run: BENCH_BEFORE=DIR measures another checkout, interleaved, in rounds of
BENCH_ROUNDS (default 2), and the minimum of the rounds is shown). The last line is one JSON object.
Usage: .venv/bin/python bench/sweep_phases.py
"""

from __future__ import annotations

import collections
import functools
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RUNS = int(os.environ.get("BENCH_RUNS", "150"))
ROUNDS = int(os.environ.get("BENCH_ROUNDS", "2"))
RECORDING = os.environ.get("BENCH_RECORDING") == "1"
BEFORE = Path(os.environ["BENCH_BEFORE"]).resolve() if os.environ.get("BENCH_BEFORE") else None

#: (module, attribute path, phase): what is timed
PHASES = [
    ("simcore.scenario.xosc", "load_scenario", "parse scenario"),
    ("simcore.pipeline", "load_road", "road (OpenDRIVE)"),
    ("simcore.pipeline", "start_sumo", "SUMO start"),
    ("simcore.world.sumo", "SumoWorld.step", "SUMO step (libsumo + placing)"),
    ("simcore.world.sumo", "SumoWorld.close", "SUMO close"),
    ("simcore.scenario.engine", "ScenarioEngine.__init__", "engine set-up"),
    ("simcore.pipeline", "drive", "steps: engine, frames, metrics"),
    ("simcore.transport.world", "WorldPublisher.publish", "publish (+ record)"),
    ("simcore.pipeline", "_metadata", "recording metadata"),
    ("simcore.recorder", "McapRecorder.close", "recording close"),
    ("simcore.pipeline", "outcome", "outcome"),
    ("simcore.runner", "evaluate", "criteria"),
    ("simcore.runner", "index_summary", "summary"),
    ("simcore.runner", "summary_bytes", "summary JSON"),
    ("simcore.store", "FileStore.put_bytes", "object store"),
    ("simcore.executor", "_work", "rest of the worker"),
]


def _instrument(spent: collections.Counter[str]) -> None:
    import importlib

    stack: list[float] = []
    clock = time.process_time
    for module_name, attribute, phase in PHASES:
        owner: Any = importlib.import_module(module_name)
        *path, name = attribute.split(".")
        for part in path:
            owner = getattr(owner, part)
        function = getattr(owner, name)

        def timed(*args: Any, _f: Callable[..., Any] = function, _p: str = phase, **kwargs: Any) -> Any:
            started = clock()
            stack.append(0.0)
            try:
                return _f(*args, **kwargs)
            finally:
                total = clock() - started
                spent[_p] += total - stack.pop()
                if stack:
                    stack[-1] += total

        setattr(owner, name, functools.wraps(function)(timed))


def worker() -> None:
    """This process as a warm worker over RUNS indexes; prints the JSON of CPU ms per run per phase. Runs
    in the checkout measured (the current directory), whose bench/pipeline.py puts it first on sys.path."""
    sys.path.insert(0, str(Path.cwd() / "bench"))
    import pipeline as bench

    from simcore import executor
    from simcore.manifest import load_manifest

    assert Path(executor.__file__).is_relative_to(Path.cwd()), "simcore of another checkout"
    work = Path(tempfile.mkdtemp(prefix="carlos-phases-"))
    matrix = bench.sweep_matrix(1000)
    loaded = load_manifest(bench.manifest(work, "sweep", bench.EXAMPLE, matrix, recording=RECORDING))
    run = loaded[0] if isinstance(loaded, tuple) else loaded
    settings = executor.Settings(
        run=run, base_dir=work, output_url=(work / "results").as_uri(), endpoint=None, region=None
    )
    spent: collections.Counter[str] = collections.Counter()
    for index in (999, 998, 997):  # warm-up: imports, caches, the first collection
        executor._work(settings, index, 1, True)
    _instrument(spent)
    started = time.process_time()
    for i in range(RUNS):
        executor._work(settings, i * 7 % 1000, 1, True)
    total = time.process_time() - started
    figures = {phase: round(1000 * cpu / RUNS, 2) for phase, cpu in spent.items()}
    figures["total"] = round(1000 * total / RUNS, 2)
    print(json.dumps(figures))


def main() -> None:
    trees = {**({"before": BEFORE} if BEFORE is not None else {}), "after": ROOT}
    best: dict[str, dict[str, float]] = collections.defaultdict(dict)
    for _ in range(ROUNDS):
        for label, tree in trees.items():
            env = {**os.environ, "PYTHONPATH": f"{tree}{os.pathsep}{tree / 'operator'}"}
            done = subprocess.run(
                [sys.executable, str(Path(__file__).resolve()), "--worker"],
                cwd=tree,
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            for phase, value in json.loads(done.stdout.splitlines()[-1]).items():
                best[phase][label] = min(best[phase].get(label, float("inf")), value)
    labels = list(trees)
    print(f"{'CPU ms per run (min of rounds)':36}" + "".join(f"{label:>10}" for label in labels))
    order = sorted(best, key=lambda phase: (phase == "total", -best[phase].get(labels[0], 0.0)))
    for phase in order:
        print(f"{phase:36}" + "".join(f"{best[phase].get(label, 0.0):>10.2f}" for label in labels))
    print(json.dumps({"runs": RUNS, "recording": RECORDING, "phases": best}))


if __name__ == "__main__":
    if "--worker" in sys.argv:
        worker()
    else:
        main()
