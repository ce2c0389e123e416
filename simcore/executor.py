"""The embedded default: run a SimulationRun's indexes on local worker processes.

Workers are spawned once and run index after index (a warm worker keeps its imports and network cache).
A worker that crashes (e.g. a segfault in a native library) breaks the pool: the pool is rebuilt, the
indexes that were in flight are retried (each counts an attempt, since which one crashed is unknown), and
an index that used up its attempts is reported as an error. Nothing already written is lost: every index's
files are final when written, `run.yaml` first and the run-level summary and `junit.xml` last.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import queue
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from simcore.errors import BadInput, ExitCode
from simcore.evaluation.report import junit_xml, run_summary
from simcore.plan import Plan
from simcore.runner import RunOutcome, error_outcome, run_index, summary_bytes
from simcore.spec import ScenarioRef, SimulationRun
from simcore.store import Store, open_store
from simcore.transport.bus import Bus

_progress_queue: Any = None


@dataclass
class Settings:
    """What a worker needs to run any index (picklable)."""

    run: SimulationRun
    base_dir: Path
    output_url: str
    endpoint: str | None
    region: str | None


def make_store(url: str, settings: Settings) -> Store:
    return open_store(url, endpoint=settings.endpoint, region=settings.region)


def _init_worker(progress: Any) -> None:
    global _progress_queue
    _progress_queue = progress


def _report(index: int, sim_time: float) -> None:
    if _progress_queue is not None:
        _progress_queue.put((index, sim_time))


def _work(settings: Settings, index: int, attempt: int, final_attempt: bool) -> RunOutcome:
    store = make_store(settings.output_url, settings)
    try:
        return run_index(
            settings.run,
            index,
            base_dir=settings.base_dir,
            store=store,
            store_factory=lambda url: make_store(url, settings),
            attempt=attempt,
            final_attempt=final_attempt,
            progress=_report,
        )
    except Exception as exc:  # object store failures: an infrastructure error of this index
        return error_outcome(settings.run, index, attempt, f"{type(exc).__name__}: {exc}")


@dataclass
class Events:
    """Callbacks for progress display (all optional)."""

    on_start: Callable[[int, int], None] = lambda total, skipped: None
    on_progress: Callable[[int, float], None] = lambda index, sim_time: None
    on_done: Callable[[RunOutcome], None] = lambda outcome: None
    on_retry: Callable[[int, int, str], None] = lambda index, attempt, reason: None


@dataclass
class RunReport:
    run_name: str
    output_url: str
    summary: dict[str, Any]
    outcomes: dict[int, dict[str, Any]] = field(default_factory=dict)
    skipped: int = 0
    wall_seconds: float = 0.0
    optional_scenarios: list[ScenarioRef] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        return int(self.summary["exitCode"])


def _dump_spec(run: SimulationRun) -> bytes:
    return yaml.safe_dump(
        run.model_dump(mode="json", by_alias=True, exclude_none=True), sort_keys=False
    ).encode()


def execute(
    run: SimulationRun,
    *,
    base_dir: Path,
    output_url: str | None = None,
    parallel: int | None = None,
    fresh: bool = False,
    indexes: list[int] | None = None,
    events: Events | None = None,
    bus: Bus | None = None,
    record: SimulationRun | None = None,
) -> RunReport:
    """Run every index (or `indexes`) of `run`; returns the run-level report. Resumes by default: an index
    whose summary.json is already in the output (from an interrupted invocation of the same spec) is kept.
    With `bus` (a live view), the runs go one after another in this process and publish on it. `record` is
    the spec kept as run.yaml and compared on resume (default `run`; a search runs derived runs of it)."""
    events = events or Events()
    spec = run.spec
    url = output_url or spec.output.url
    settings = Settings(
        run=run, base_dir=base_dir, output_url=url, endpoint=spec.output.endpoint, region=spec.output.region
    )
    store = make_store(url, settings)
    plan = Plan(spec)
    total = len(plan)
    wanted = list(range(total)) if indexes is None else indexes
    for index in wanted:
        if not 0 <= index < total:
            raise BadInput(f"index {index} is out of range 0..{total - 1}", field="--index")
    name = run.name
    spec_bytes = _dump_spec(record or run)
    previous: dict[int, dict[str, Any]] = {}
    if store.exists(f"{name}/run.yaml") and not fresh:
        if store.get_bytes(f"{name}/run.yaml") != spec_bytes:
            raise BadInput(
                f"results for run {name!r} already exist at {store.url_for(name)} with a different spec: "
                "change metadata.name, or pass --fresh to replace them",
                field="metadata.name",
            )
        for index in wanted:
            key = f"{name}/{index}/summary.json"
            if store.exists(key):
                previous[index] = json.loads(store.get_bytes(key))
    store.put_bytes(f"{name}/run.yaml", spec_bytes)
    todo = [i for i in wanted if i not in previous]
    events.on_start(len(wanted), len(previous))
    started = time.monotonic()
    outcomes: dict[int, dict[str, Any]] = dict(previous)
    workers = max(1, min(parallel or spec.execution.parallelism or os.cpu_count() or 1, max(len(todo), 1)))
    attempts = dict.fromkeys(todo, 0)
    max_attempts = spec.execution.retries + 1
    pending = list(todo)
    if bus is not None:
        _in_process(settings, store, pending, attempts, max_attempts, outcomes, events, bus)
    context = mp.get_context("spawn")
    progress: Any = context.Queue()
    while pending:
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=context, initializer=_init_worker, initargs=(progress,)
        ) as pool:
            in_flight: dict[Future[RunOutcome], int] = {}
            broken = False
            _submit(pool, settings, pending, in_flight, attempts, max_attempts, workers * 2)
            while in_flight:
                done, _ = wait(list(in_flight), timeout=0.2, return_when=FIRST_COMPLETED)
                _drain(progress, events)
                for future in done:
                    index = in_flight.pop(future)
                    try:
                        outcome = future.result()
                    except BrokenProcessPool:
                        broken = True
                        _crashed(index, attempts, max_attempts, pending, outcomes, settings, store, events)
                        continue
                    if outcome.exit_code == ExitCode.INFRASTRUCTURE and attempts[index] < max_attempts:
                        events.on_retry(index, attempts[index], str(outcome.summary.get("error")))
                        pending.append(index)
                        continue
                    outcomes[index] = outcome.summary
                    events.on_done(outcome)
                if broken:
                    for future, index in list(in_flight.items()):
                        in_flight.pop(future)
                        _crashed(index, attempts, max_attempts, pending, outcomes, settings, store, events)
                    break
                _submit(pool, settings, pending, in_flight, attempts, max_attempts, workers * 2)
    _drain(progress, events)
    summary = run_summary(name, [outcomes[i] for i in sorted(outcomes)], total=len(wanted))
    summary["outputUrl"] = store.url_for(name)
    store.put_bytes(f"{name}/junit.xml", junit_xml(name, [outcomes[i] for i in sorted(outcomes)]).encode())
    store.put_bytes(f"{name}/summary.json", summary_bytes(summary))
    return RunReport(
        run_name=name,
        output_url=store.url_for(name),
        summary=summary,
        outcomes=outcomes,
        skipped=len(previous),
        wall_seconds=time.monotonic() - started,
        optional_scenarios=[s for s in spec.scenarios if s.optional],
    )


def _in_process(
    settings: Settings,
    store: Store,
    pending: list[int],
    attempts: dict[int, int],
    max_attempts: int,
    outcomes: dict[int, dict[str, Any]],
    events: Events,
    bus: Bus,
) -> None:
    """Run the pending indexes here, one after another, publishing on `bus` (infrastructure errors retried)."""
    while pending:
        index = pending.pop(0)
        attempts[index] += 1
        outcome = run_index(
            settings.run,
            index,
            base_dir=settings.base_dir,
            store=store,
            store_factory=lambda url: make_store(url, settings),
            attempt=attempts[index],
            final_attempt=attempts[index] >= max_attempts,
            progress=events.on_progress,
            bus=bus,
        )
        if outcome.exit_code == ExitCode.INFRASTRUCTURE and attempts[index] < max_attempts:
            events.on_retry(index, attempts[index], str(outcome.summary.get("error")))
            pending.append(index)
            continue
        outcomes[index] = outcome.summary
        events.on_done(outcome)


def _submit(
    pool: ProcessPoolExecutor,
    settings: Settings,
    pending: list[int],
    in_flight: dict[Future[RunOutcome], int],
    attempts: dict[int, int],
    max_attempts: int,
    limit: int,
) -> None:
    """Keep up to `limit` indexes queued in the pool (a small queue keeps retries and progress prompt)."""
    while pending and len(in_flight) < limit:
        index = pending.pop(0)
        attempts[index] += 1
        final = attempts[index] >= max_attempts
        in_flight[pool.submit(_work, settings, index, attempts[index], final)] = index


def _drain(progress: Any, events: Events) -> None:
    while True:
        try:
            index, sim_time = progress.get_nowait()
        except queue.Empty:
            return
        except (OSError, ValueError):
            return
        events.on_progress(index, sim_time)


def _crashed(
    index: int,
    attempts: dict[int, int],
    max_attempts: int,
    pending: list[int],
    outcomes: dict[int, dict[str, Any]],
    settings: Settings,
    store: Store,
    events: Events,
) -> None:
    """An index whose worker process died: retry it, or record it as an error when out of attempts."""
    reason = "the worker process died (crash in the simulator)"
    if attempts[index] < max_attempts:
        events.on_retry(index, attempts[index], reason)
        pending.append(index)
        return
    outcome = error_outcome(settings.run, index, attempts[index], reason)
    summary = outcome.summary
    store.put_bytes(f"{settings.run.name}/{index}/summary.json", summary_bytes(summary))
    outcomes[index] = summary
    events.on_done(outcome)
