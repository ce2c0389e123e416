"""The embedded default: run a SimulationRun's indexes on local worker processes.

A single index runs in this process (no worker pool to start). Otherwise workers are spawned once and run
index after index (a warm worker keeps its imports and network cache).
A worker that crashes (e.g. a segfault in a native library) breaks the pool: the pool is rebuilt, the
indexes that were in flight are retried (each counts an attempt, since which one crashed is unknown), and
an index that used up its attempts is reported as an error. Nothing already written is lost: every index's
files are final when written, `run.yaml` first and the run-level summary and `junit.xml` last; the store is
flushed to disk (`Store.sync`) after `run.yaml` and after the run-level summary. An index whose summary
cannot be read (a power cut before the flush) counts as not run.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from simcore.errors import BadInput, ExitCode
from simcore.evaluation.report import in_manifest_order, junit_xml, run_summary
from simcore.lifetime import die_with_parent, make_scratch_root, remove_stale_scratch
from simcore.plan import Plan
from simcore.runner import RunOutcome, error_outcome, run_index, summary_bytes
from simcore.spec import ScenarioRef, SimulationRun
from simcore.startup import settle_worker
from simcore.store import Store, StoreError, open_store
from simcore.transport.bus import Bus

if TYPE_CHECKING:
    from concurrent.futures import Future, ProcessPoolExecutor

#: wall seconds between two looks at the workers' progress queue
DRAIN_INTERVAL_S = 0.2
#: quick indexes go to a worker in batches (one message each way, not one per index): a batch holds about
#: BATCH_TARGET_S of runs (by the mean wall time of the indexes done so far), at most BATCH_MAX indexes, and at
#: most a share of what is left so that the workers end together; one index until the first is done
BATCH_TARGET_S = 0.1
BATCH_MAX = 16
_progress_queue: Any = None
_worker_settings: Any = None  # Settings of this pool worker (_init_worker)


@dataclass
class Settings:
    """What a worker needs to run any index (picklable)."""

    run: SimulationRun
    base_dir: Path
    output_url: str
    endpoint: str | None
    region: str | None
    scratch_root: Path | None = None  # the workers' scratch folders go here (simcore.lifetime)


def make_store(url: str, settings: Settings) -> Store:
    return open_store(url, endpoint=settings.endpoint, region=settings.region)


def _init_worker(progress: Any, parent_pid: int, settings: Settings) -> None:
    global _progress_queue, _worker_settings
    die_with_parent(parent_pid)
    _progress_queue = progress
    _worker_settings = settings  # sent once per worker, not with every index


def _work_in_pool(index: int, attempt: int, final_attempt: bool) -> RunOutcome:
    assert _worker_settings is not None, "a pool worker starts with _init_worker"
    try:
        return _work(_worker_settings, index, attempt, final_attempt)
    finally:
        settle_worker()


def _work_batch(batch: list[tuple[int, int, bool]]) -> tuple[list[RunOutcome], StoreError | None]:
    """(index, attempt, final attempt) one after another in this worker: their outcomes, and the StoreError
    that stopped the batch (the indexes after it are not run)."""
    outcomes = []
    for index, attempt, final_attempt in batch:
        try:
            outcomes.append(_work_in_pool(index, attempt, final_attempt))
        except StoreError as exc:
            return outcomes, exc
    return outcomes, None


def _report(index: int, sim_time: float) -> None:
    if _progress_queue is not None:
        _progress_queue.put((index, sim_time))


def _work(settings: Settings, index: int, attempt: int, final_attempt: bool) -> RunOutcome:
    """One index in a worker. The object store failing beyond its retries (StoreError) is not this index's
    fault: it reaches the executor, which stops the run (exit code 3) keeping every finished index."""
    try:
        store = make_store(settings.output_url, settings)
        return run_index(
            settings.run,
            index,
            base_dir=settings.base_dir,
            store=store,
            store_factory=lambda url: make_store(url, settings),
            attempt=attempt,
            final_attempt=final_attempt,
            progress=_report,
            scratch_root=settings.scratch_root,
        )
    except StoreError:
        raise
    except Exception as exc:  # anything else: an infrastructure error of this index
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
    report_url: str | None = None
    report_error: str | None = None

    @property
    def exit_code(self) -> int:
        return int(self.summary["exitCode"])


@dataclass
class _Sweep:
    """The state of one invocation's sweep, shared by the ways of running its indexes."""

    settings: Settings
    store: Store
    pending: list[int]  # indexes still to run (retries are appended)
    attempts: dict[int, int]
    max_attempts: int
    outcomes: dict[int, dict[str, Any]]  # final summaries by index
    events: Events
    run_seconds: float = 0.0  # the wall seconds of the runs done here so far, and how many (batch sizes)
    runs_done: int = 0

    def batch_size(self, workers: int) -> int:
        if not self.runs_done:
            return 1
        by_time = int(BATCH_TARGET_S * self.runs_done / max(self.run_seconds, 1e-9))
        return max(1, min(BATCH_MAX, by_time, len(self.pending) // (2 * workers)))


def kept_on_resume(summary: dict[str, Any]) -> bool:
    """Whether a finished index's summary stands when the same run is invoked again: a pass or a test failure
    does (rerunning cannot change it); an error (a crash, an outage, attempts used up) is run again."""
    return summary.get("status") in ("passed", "failed")


def _written_summary(store: Store, key: str) -> dict[str, Any] | None:
    """An index's summary in the store; None when there is none or it cannot be read (cut short by a power
    cut before the store was flushed): such an index runs again."""
    if not store.exists(key):
        return None
    try:
        summary = json.loads(store.get_bytes(key))
    except ValueError:  # not JSON (UnicodeDecodeError is a ValueError too)
        return None
    return summary if isinstance(summary, dict) else None


def _other_results(store: Store, plan: Plan, name: str, wanted: set[int]) -> dict[int, dict[str, Any]]:
    """The summaries already written for the run's indexes outside `wanted` (parameters in the manifest's
    order), by index: what a partial run (--index) keeps in the run-level results."""
    found: dict[int, dict[str, Any]] = {}
    prefix = f"{name}/"
    for key in store.list(prefix):
        parts = key[len(prefix) :].split("/")
        if len(parts) != 2 or parts[1] != "summary.json" or not parts[0].isdigit():
            continue
        index = int(parts[0])
        if index in wanted or index >= len(plan):
            continue
        summary = _written_summary(store, key)
        if summary is not None and summary.get("index") == index:
            found[index] = in_manifest_order(summary, list(plan[index].parameters))
    return found


def _exit_code_of(summary: dict[str, Any]) -> ExitCode:
    return ExitCode.PASSED if summary.get("status") == "passed" else ExitCode.FAILED


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
    whose summary.json is already in the output (from an interrupted invocation of the same spec) is kept
    when it passed or failed; one that ended in an error runs again.
    With `bus` (a live view), the runs go one after another in this process and publish on it. `record` is
    the spec kept as run.yaml and compared on resume (default `run`; a search runs derived runs of it)."""
    events = events or Events()
    spec = run.spec
    url = output_url or spec.output.url
    settings = Settings(
        run=run, base_dir=base_dir, output_url=url, endpoint=spec.output.endpoint, region=spec.output.region
    )
    try:
        store = make_store(url, settings)
    except ValueError as exc:  # an unsupported scheme or an empty path
        hint = f" (a folder: file://{url})" if "://" not in url else ""
        raise BadInput(f"{exc}{hint}", field="--output" if output_url else "spec.output.url") from None
    plan = Plan(spec)
    total = len(plan)
    wanted = list(range(total)) if indexes is None else list(dict.fromkeys(indexes))
    for index in wanted:
        if not 0 <= index < total:
            raise BadInput(f"index {index} is out of range 0..{total - 1}", field="--index")
    name = run.name
    spec_bytes = _dump_spec(record or run)
    previous: dict[int, dict[str, Any]] = {}
    written_spec = store.get_bytes(f"{name}/run.yaml") if store.exists(f"{name}/run.yaml") else None
    if written_spec is not None and not fresh:
        if written_spec != spec_bytes:
            raise BadInput(
                f"results for run {name!r} already exist at {store.url_for(name)} with a different spec: "
                "change metadata.name, or pass --fresh to replace them",
                field="metadata.name",
            )
        for index in wanted:
            kept = _written_summary(store, f"{name}/{index}/summary.json")
            if kept is not None and kept_on_resume(kept):
                previous[index] = in_manifest_order(kept, list(plan[index].parameters))
    # a partial run (--index, also with --fresh) merges into the results of the same spec: the indexes it
    # does not run keep theirs
    merging = indexes is not None and written_spec == spec_bytes
    others = _other_results(store, plan, name, set(wanted)) if merging else {}
    store.put_bytes(f"{name}/run.yaml", spec_bytes)
    store.sync()
    todo = [i for i in wanted if i not in previous]
    events.on_start(len(wanted), len(previous))
    started = time.monotonic()
    outcomes: dict[int, dict[str, Any]] = dict(previous)
    workers = max(1, min(parallel or spec.execution.parallelism or os.cpu_count() or 1, max(len(todo), 1)))
    attempts = dict.fromkeys(todo, 0)
    max_attempts = spec.execution.retries + 1
    pending = list(todo)
    sweep = _Sweep(settings, store, pending, attempts, max_attempts, outcomes, events)
    # the scratch of killed runs goes now, also when nothing is left to run (a run killed after its last index)
    # or the one left runs here
    remove_stale_scratch()
    if bus is not None or len(pending) == 1:
        # a live view's bus, or a single run: here, without paying for a worker process and its imports
        _in_process(sweep, bus)
    if pending:
        settings.scratch_root = make_scratch_root()
        try:
            _in_pool(sweep, workers)
        finally:
            shutil.rmtree(settings.scratch_root, ignore_errors=True)
    # this invocation's verdict (its exit code, what it prints) is over the indexes it selected; what it
    # writes covers every index of the run that has a result
    merged = {**others, **outcomes}
    results = [merged[i] for i in sorted(merged)]
    repeats = None
    if plan.repeat > 1:
        from simcore.evaluation.flaky import RepeatTally, flag_repeats, recording_digests

        tally = RepeatTally(plan.repeat)
        results = list(flag_repeats(results, plan.point_of, tally, recording_digests(store, name)))
        repeats = tally.report()
    selected = [s for s in results if int(s["index"]) in outcomes]
    summary = run_summary(name, selected, total=len(wanted), expected=set(wanted))
    summary["outputUrl"] = store.url_for(name)
    written = summary
    if others:
        covered = set(merged) | set(wanted)  # a selected index without a result counts as missing
        written = run_summary(name, results, total=len(covered), expected=covered)
        written["outputUrl"] = summary["outputUrl"]
    if repeats is not None:
        summary["repeats"] = written["repeats"] = repeats
    store.put_bytes(f"{name}/junit.xml", junit_xml(name, results).encode())
    store.put_bytes(f"{name}/summary.json", summary_bytes(written))
    store.sync()
    report_url, report_error = _html_report(store, run, written, results)
    return RunReport(
        run_name=name,
        output_url=store.url_for(name),
        summary=summary,
        outcomes=outcomes,
        skipped=len(previous),
        wall_seconds=time.monotonic() - started,
        optional_scenarios=[s for s in spec.scenarios if s.optional],
        report_url=report_url,
        report_error=report_error,
    )


def _in_pool(sweep: _Sweep, workers: int) -> None:
    """Run the pending indexes on worker processes (a crashed pool is rebuilt, its indexes retried). The
    object store failing beyond its retries in a worker stops the run: no new index starts, the ones in
    flight end, and the StoreError is raised (exit code 3; finished indexes stay in the store)."""
    import multiprocessing as mp  # here, not at the top: a run in this process does without them
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    context = mp.get_context("spawn")
    progress: Any = context.Queue()
    outage: StoreError | None = None
    while sweep.pending and outage is None:
        with ProcessPoolExecutor(
            max_workers=workers,
            mp_context=context,
            initializer=_init_worker,
            initargs=(progress, os.getpid(), sweep.settings),
        ) as pool:
            in_flight: dict[Future[tuple[list[RunOutcome], StoreError | None]], list[int]] = {}
            broken = False
            _submit(pool, sweep, in_flight, workers)
            next_drain = 0.0
            while in_flight:
                done, _ = wait(list(in_flight), timeout=DRAIN_INTERVAL_S, return_when=FIRST_COMPLETED)
                if not done or time.monotonic() >= next_drain:
                    # progress reports come at most every stepping.PROGRESS_INTERVAL_S per run: polling the
                    # queue (a selector each time) after every finished index of a quick sweep would cost more
                    _drain(progress, sweep.events)
                    next_drain = time.monotonic() + DRAIN_INTERVAL_S
                for future in done:
                    batch = in_flight.pop(future)
                    try:
                        outcomes, error = future.result()
                    except BrokenProcessPool:
                        broken = True
                        _crashed_batch(sweep, batch)
                        continue
                    for outcome in outcomes:
                        _finished(sweep, outcome)
                    if error is not None:
                        outage = outage or error
                        sweep.pending.clear()
                if broken:
                    for future, batch in list(in_flight.items()):
                        in_flight.pop(future)
                        _crashed_batch(sweep, batch)
                    break
                _submit(pool, sweep, in_flight, workers)
    _drain(progress, sweep.events)
    if outage is not None:
        raise outage


def _html_report(
    store: Store, run: SimulationRun, summary: dict[str, Any], index_summaries: list[dict[str, Any]]
) -> tuple[str | None, str | None]:
    """(URL of report.html, None), or (None, why it could not be written): the results are complete
    without it, so a failure here never changes the run's outcome."""
    from simcore.report.html import write_after_run

    try:
        return write_after_run(store, run, summary, index_summaries), None
    except Exception as exc:  # a plot of unusual data, a store hiccup: the report is an extra
        return None, f"{type(exc).__name__}: {exc}"


def _in_process(sweep: _Sweep, bus: Bus | None) -> None:
    """Run the pending indexes here, one after another, publishing on `bus` (default: a bus of each run's
    own; infrastructure errors retried). A run closes a given bus when it ends (its subscribers see the end;
    another process' transport is torn down), so an attempt cannot be repeated on it: there every attempt is
    final, and an infrastructure error is reported with its own cause instead of the closed bus' error."""
    while sweep.pending:
        index = sweep.pending.pop(0)
        sweep.attempts[index] += 1
        final = bus is not None or sweep.attempts[index] >= sweep.max_attempts
        outcome = run_index(
            sweep.settings.run,
            index,
            base_dir=sweep.settings.base_dir,
            store=sweep.store,
            store_factory=lambda url: make_store(url, sweep.settings),
            attempt=sweep.attempts[index],
            final_attempt=final,
            progress=sweep.events.on_progress,
            bus=bus,
        )
        if outcome.exit_code == ExitCode.INFRASTRUCTURE and not final:
            sweep.events.on_retry(index, sweep.attempts[index], str(outcome.summary.get("error")))
            sweep.pending.append(index)
            continue
        sweep.outcomes[index] = outcome.summary
        sweep.events.on_done(outcome)


def _finished(sweep: _Sweep, outcome: RunOutcome) -> None:
    """An index a worker ran: retried after an infrastructure error while it has attempts left, else done."""
    index = outcome.index
    wall = float(outcome.summary.get("wallSeconds") or 0.0)
    if wall > 0.0:  # an index that ended before it ran (an error) says nothing of how long runs take
        sweep.run_seconds += wall
        sweep.runs_done += 1
    if outcome.exit_code == ExitCode.INFRASTRUCTURE and sweep.attempts[index] < sweep.max_attempts:
        sweep.events.on_retry(index, sweep.attempts[index], str(outcome.summary.get("error")))
        sweep.pending.append(index)
        return
    sweep.outcomes[index] = outcome.summary
    sweep.events.on_done(outcome)


def _submit(
    pool: ProcessPoolExecutor,
    sweep: _Sweep,
    in_flight: dict[Future[tuple[list[RunOutcome], StoreError | None]], list[int]],
    workers: int,
) -> None:
    """Keep two batches per worker queued in the pool (a small queue keeps retries and progress prompt)."""
    while sweep.pending and len(in_flight) < 2 * workers:
        batch = sweep.pending[: sweep.batch_size(workers)]
        del sweep.pending[: len(batch)]
        work = []
        for index in batch:
            sweep.attempts[index] += 1
            work.append((index, sweep.attempts[index], sweep.attempts[index] >= sweep.max_attempts))
        in_flight[pool.submit(_work_batch, work)] = batch


def _drain(progress: Any, events: Events) -> None:
    while True:
        try:
            index, sim_time = progress.get_nowait()
        except queue.Empty:
            return
        except (OSError, ValueError):
            return
        events.on_progress(index, sim_time)


def _crashed_batch(sweep: _Sweep, batch: list[int]) -> None:
    """A batch whose worker process died (or was ended with the pool): its indexes run in order, so those
    with this attempt's summary written were done (`_crashed` keeps them), the first without one was
    running or waiting, and the ones after it never started: they get their attempt back and run again."""
    for position, index in enumerate(batch):
        if not _crashed(sweep, index):
            later = batch[position + 1 :]
            for unstarted in later:
                sweep.attempts[unstarted] -= 1
            sweep.pending[:0] = later
            return


def _crashed(sweep: _Sweep, index: int) -> bool:
    """An index whose worker process died: retry it, or record it as an error when out of attempts. True when
    the worker had finished it (its summary kept)."""
    written = _written_summary(sweep.store, f"{sweep.settings.run.name}/{index}/summary.json")
    if written is not None and kept_on_resume(written) and written.get("attempts") == sweep.attempts[index]:
        # the worker finished this attempt (its summary is written last) and died before reporting it
        written = in_manifest_order(written, list(Plan(sweep.settings.run.spec)[index].parameters))
        sweep.outcomes[index] = written
        sweep.events.on_done(RunOutcome(index=index, summary=written, exit_code=_exit_code_of(written)))
        return True
    reason = "the worker process died (crash in the simulator)"
    if sweep.attempts[index] < sweep.max_attempts:
        sweep.events.on_retry(index, sweep.attempts[index], reason)
        sweep.pending.append(index)
        return False
    outcome = error_outcome(sweep.settings.run, index, sweep.attempts[index], reason)
    summary = outcome.summary
    sweep.store.put_bytes(f"{sweep.settings.run.name}/{index}/summary.json", summary_bytes(summary))
    sweep.outcomes[index] = summary
    sweep.events.on_done(outcome)
    return False
