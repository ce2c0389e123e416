"""A search (`spec.search`) on the cluster: one Indexed Job per round, the study in the object store.

The steps are simcore.search.driver's, as `carlos run` takes them locally: the operator loads the stored
state (`<run>/search/state.json`: the optuna journal and every evaluated point), asks the study for the
round's points, writes them into the round's ConfigMap (`points.xosc` beside a `simulationrun.yaml` that
runs them as a sweep) and creates the round's Job (`carlos-<run>-r<N>`, completions = the round's points,
CARLOS_INDEX_OFFSET = the round's first index: pod k runs the run's index start+k). When that Job has
finished every index it reads their summaries, tells the study, stores the state in one write, and creates
the next round's Job, until the budget is spent; then it writes `search.json`, `search/failing.xosc` and
the run-level `summary.json` and `junit.xml`.

Restarts: the state file is the truth. A round whose Job exists is adopted (deterministic name, never a
second Job); the study asks the same points again for the round in flight (the sampler is seeded by the
seed and the round); a round's Job that finished while the operator was down is read when it returns.

`round_step` and `search_status` are pure; `SearchRuns` does the I/O for the controller.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from carlos_operator.apply import create_owned
from carlos_operator.builders import (
    Output,
    SearchRound,
    build_job,
    build_round_configmap,
    round_job_name,
)
from carlos_operator.inputs import read_input
from carlos_operator.kube import NotFound, now_rfc3339
from carlos_operator.runstate import RunState, SearchProgress, slim_job
from carlos_operator.scratch import ScratchFolders
from carlos_operator.status import (
    ERROR,
    FAILED,
    PASSED,
    TERMINAL_PHASES,
    Tally,
    condition,
    count_intervals,
    iter_intervals,
    job_finished,
    runs_view,
    verdict_fields,
)
from simcore.search import driver
from simcore.search.export import distribution_xml
from simcore.spec import Search, SimulationRun
from simcore.wording import plural

if TYPE_CHECKING:
    from carlos_operator.hosting import Host

log = logging.getLogger("carlos.operator")

Step = Literal["finish", "create", "wait", "tell", "stopped"]


def round_of(search: Search, evaluated: int) -> SearchRound | None:
    """The round after `evaluated` points (None: the budget is spent)."""
    count = min(search.batch_size, search.budget - evaluated)
    if count <= 0:
        return None
    return SearchRound(number=evaluated // search.batch_size, start=evaluated, count=count)


def round_step(search: Search, evaluated: int, job: Mapping[str, Any] | None) -> Step:
    """What a search does next, from the points the study has and the current round's Job (or None):
    `finish` (the budget is spent), `create` (the round's Job), `wait` (it runs), `tell` (it finished every
    index: the study learns the results), `stopped` (it failed before every index finished: bad input,
    its deadline, maxFailedIndexes)."""
    current = round_of(search, evaluated)
    if current is None:
        return "finish"
    if job is None:
        return "create"
    finished = job_finished(job)
    if finished is None:
        return "wait"
    status = job.get("status") or {}
    done = count_intervals(status.get("completedIndexes")) + count_intervals(status.get("failedIndexes"))
    if finished == "Failed" and done < current.count:
        return "stopped"
    return "tell"


def _job_failure(job: Mapping[str, Any] | None) -> tuple[str, str]:
    for entry in ((job or {}).get("status") or {}).get("conditions") or []:
        if entry.get("type") == "Failed" and entry.get("status") == "True":
            return str(entry.get("reason") or "JobFailed"), str(entry.get("message") or "")
    return "JobFailed", ""


def search_status(
    *,
    search: Search,
    points: Sequence[Mapping[str, Any]],
    job: Mapping[str, Any] | None,
    tally: Tally,
    results_url: str,
    now: str,
    previous: Mapping[str, Any] | None = None,
    finished: bool = False,
    stopped: bool = False,
    search_url: str | None = None,
) -> dict[str, Any]:
    """The SimulationRun status of a search: `points` the study has, `job` the current round's Job (None
    between rounds or before the first), `tally` the verdicts read so far (points and the current round's
    finished indexes); `finished`: search.json and the run-level summary are written; `stopped`: the
    round's Job failed before every index finished."""
    previous = previous or {}
    before = {c.get("type"): c for c in previous.get("conditions") or []}
    current = round_of(search, len(points))
    job_status: Mapping[str, Any] = (job or {}).get("status") or {}
    job_spec: Mapping[str, Any] = (job or {}).get("spec") or {}
    round_done = count_intervals(job_status.get("completedIndexes"))
    round_failed = count_intervals(job_status.get("failedIndexes"))
    active = int(job_status.get("active") or 0) if current is not None else 0
    total_rounds = driver.rounds_total(search)
    rounds_done = len({p["round"] for p in points})
    done = len(points) + (round_done + round_failed if current is not None and job is not None else 0)
    if stopped:
        phase = "Failed"
    elif finished:
        phase = "Failed" if tally.required_failures else "Succeeded"
    elif job is None and not points:
        phase = "Pending"
    elif job is not None and job_spec.get("suspend") and active == 0 and not job_finished(job):
        phase = "Suspended"
    elif points or active or done or job_status.get("startTime"):
        phase = "Running"
    else:
        phase = "Pending"
    complete = phase in TERMINAL_PHASES
    conditions = [
        condition(before, "Accepted", True, "Valid", "the spec is valid; the search runs in rounds", now),
        condition(
            before,
            "Running",
            phase == "Running",
            "PodsActive" if active else ("RoundsInProgress" if phase == "Running" else phase),
            f"round {current.number + 1}/{total_rounds}: {active} pods active, {done}/{search.budget} runs "
            "finished"
            if current is not None
            else f"{done}/{search.budget} runs finished",
            now,
        ),
        condition(
            before,
            "Complete",
            complete,
            "AllRunsFinished" if finished else ("RoundFailed" if stopped else "InProgress"),
            f"{tally.counts[PASSED]} passed, {tally.counts[FAILED]} failed, {tally.counts[ERROR]} errors"
            if complete
            else f"{done}/{search.budget} runs finished",
            now,
        ),
    ]
    if phase == "Failed":
        if stopped:
            reason, message = _job_failure(job)
            message = f"round {current.number if current else '?'}'s Job failed: {reason} {message}".strip()
        elif tally.counts[ERROR] and not tally.counts[FAILED]:
            reason, message = "RunErrors", f"{plural(tally.counts[ERROR], 'run')} ended in an error"
        else:
            reason = "TestFailures"
            message = (
                f"the search found {plural(tally.counts[FAILED], 'run')} failing criteria, "
                f"{tally.counts[ERROR]} errors"
            )
        conditions.append(condition(before, "Failed", True, reason, message, now))
    else:
        conditions.append(condition(before, "Failed", False, "NoFailure", "", now))
    passed = sum(1 for p in points if p["status"] == "passed")
    sign = 1.0 if search.objective.direction == "minimize" else -1.0
    measured = [p for p in points if p.get("objective") is not None and math.isfinite(p["objective"])]
    best = min(measured, key=lambda p: sign * p["objective"]) if measured else None
    rounds: dict[str, Any] = {
        "rounds": f"{rounds_done}/{total_rounds}",
        "roundsDone": rounds_done,
        "roundsTotal": total_rounds,
        "evaluated": len(points),
        "failuresFound": sum(1 for p in points if p["status"] == "failed"),
    }
    # between rounds and once finished: null, so that the merge patch removes the field
    rounds["round"] = current.number if current is not None and job is not None and not complete else None
    if best is not None:
        rounds["bestObjective"] = float(best["objective"])
        rounds["bestIndex"] = int(best["index"])
    if search_url:
        rounds["searchURL"] = search_url
    status: dict[str, Any] = {
        "phase": phase,
        "progress": f"{done}/{search.budget}",
        "total": search.budget,
        "active": active,
        "succeeded": passed + (round_done if current is not None else 0),
        "failed": len(points) - passed + (round_failed if current is not None else 0),
        **verdict_fields(tally, results_url),
        "search": rounds,
        "conditions": conditions,
    }
    start = previous.get("startTime") or job_status.get("startTime")
    if start:
        status["startTime"] = start
    if complete:
        status["completionTime"] = previous.get("completionTime") or now
    return status


class SearchRuns:
    """The search side of the controller: the scenario, the rounds, their Jobs and the status."""

    def __init__(self, controller: Host) -> None:
        self.c = controller
        self._scratch = ScratchFolders("carlos-operator-search-")

    def forget(self, key: tuple[str, str]) -> None:
        """The run was deleted: its scenario copy goes."""
        self._scratch.forget(*key)

    def close(self) -> None:
        self._scratch.close()

    # --- acceptance ------------------------------------------------------------------------------------

    def prepare(self, run: SimulationRun, output: Output, namespace: str) -> SearchProgress:
        """The search space from the scenario (read from its ConfigMap, s3:// or a file the operator can
        read): bad input raises BadInput naming the field."""
        ref = run.spec.scenarios[0]
        name, text = read_input(
            self.c,
            namespace,
            output,
            ref=ref.config_map_ref,
            source=ref.openscenario,
            field="spec.scenarios[0].openscenario",
            ref_field="spec.scenarios[0].configMapRef",
            why="to choose a search's points",
        )
        path = self._scratch.folder(namespace, run.name) / name
        path.write_bytes(text)
        return SearchProgress(scenario_name=name, space=driver.search_space(run, path))

    # --- reconciliation --------------------------------------------------------------------------------

    def update(self, key: tuple[str, str], state: RunState) -> None:
        run, tally, progress = state.run, state.tally, state.search
        assert run is not None and tally is not None and progress is not None and run.spec.search is not None
        search = run.spec.search
        namespace = key[0]
        if not progress.loaded:
            self._load(state, progress)
        job: dict[str, Any] | None = None
        for _ in range(driver.rounds_total(search) + 1):  # a round that finished starts the next at once
            current = round_of(search, len(progress.points))
            job = self._round_job(state, current) if current is not None else None
            step = round_step(search, len(progress.points), job)
            if step == "create":
                assert current is not None
                if self._gone(state, current):
                    return
                if state.held:
                    break
                job = self._create(state, namespace, current, progress)
                break
            if step == "tell":
                assert current is not None and job is not None
                self._tell(state, current, progress)
                continue
            if step == "stopped":
                progress.stopped = True
            if step in ("wait", "stopped"):
                assert current is not None and job is not None
                self._suspend(key, state, job)
                self._read_finished(state, current, job)
            break
        finished = round_of(search, len(progress.points)) is None
        search_url = None
        if finished or progress.stopped:  # stopped: the points told so far, and the round's summaries
            search_url = self._finish(state, progress)
        status = search_status(
            search=search,
            points=progress.points,
            job=None if finished else job,
            tally=tally,
            results_url=state.store.url_for(run.name),
            now=now_rfc3339(),
            previous=state.last_status,
            finished=finished,
            stopped=progress.stopped,
            search_url=search_url,
        )
        current = round_of(search, len(progress.points))
        if current is not None:
            status["jobName"] = round_job_name(run.name, current.number)
        elif state.last_status.get("jobName"):
            status["jobName"] = state.last_status["jobName"]
        if job is not None and status["phase"] not in TERMINAL_PHASES:
            self.c._check_pods(state, job, status)
        before = state.last_status.get("phase")
        rounds_before = (state.last_status.get("search") or {}).get("roundsDone")
        self.c._publish(state, status)
        if status["phase"] != before:
            self.c._transition(state, before, status)
        elif status["search"]["roundsDone"] != rounds_before and rounds_before is not None:
            self.c.kube.event(
                state.body,
                "Normal",
                "RoundFinished",
                f"round {status['search']['roundsDone']}/{status['search']['roundsTotal']}: "
                f"{status['search']['failuresFound']} failing so far, best objective "
                f"{status['search'].get('bestObjective', 'n/a')}",
            )
        from carlos_operator import metrics

        metrics.set_phase(state.uid, status["phase"])

    def _load(self, state: RunState, progress: SearchProgress) -> None:
        """The stored state (after a restart: the rounds told before it) and the verdicts of its points."""
        assert state.run is not None and state.tally is not None
        progress.log, progress.points = driver.load_state(state.run, state.store)
        for point in progress.points:
            if point["status"] == "passed":
                state.tally.record({"index": point["index"], "status": "passed"})
            else:  # the reason is in its summary (few: only the failing ones are read)
                summary = self.c._maybe(state, int(point["index"]))
                state.tally.record(summary or {"index": point["index"], "status": point["status"]})
        progress.loaded = True

    def _round_job(self, state: RunState, current: SearchRound) -> dict[str, Any] | None:
        meta = state.body["metadata"]
        namespace = meta.get("namespace") or "default"
        assert state.run is not None
        name = round_job_name(state.run.name, current.number)
        with self.c._lock:
            job = self.c.jobs.get((namespace, name))
        if job is None:
            try:
                job = self.c.kube.read_job(namespace, name)
            except NotFound:
                return None
        owners = job.get("metadata", {}).get("ownerReferences") or []
        return runs_view(job) if any(o.get("uid") == state.uid for o in owners) else None

    def _gone(self, state: RunState, current: SearchRound) -> bool:
        """The round's Job was created (by this process, or before a restart: the status names it) and is
        gone before the study had its results: the run is Unknown, never a second Job of the round."""
        assert state.run is not None and state.search is not None
        name = round_job_name(state.run.name, current.number)
        created = current.number in state.search.created or (
            state.last_status.get("jobName") == name
            and (state.last_status.get("search") or {}).get("round") == current.number
        )
        if not created:
            return False
        state.job_seen = True
        self.c._job_gone(state, name=name)
        return True

    def _ask(self, state: RunState, current: SearchRound, progress: SearchProgress) -> driver.Round:
        assert state.run is not None
        if progress.round is None or progress.round.start != current.start:
            asked = driver.ask_round(state.run, progress.space, progress.log, progress.points)
            assert asked is not None and len(asked.asked) == current.count
            progress.round = asked
        return progress.round

    def _create(
        self, state: RunState, namespace: str, current: SearchRound, progress: SearchProgress
    ) -> dict[str, Any]:
        from carlos_operator import metrics

        assert state.run is not None and state.output is not None
        run = state.run
        asked = self._ask(state, current, progress)
        points = distribution_xml(
            Path(progress.scenario_name), asked.asked, f"search {run.name}: round {current.number}"
        )
        cm = build_round_configmap(run, state.body, self.c.settings, current, points)
        create_owned(self.c, state, namespace, "ConfigMap", cm)
        job = build_job(
            run,
            state.body,
            self.c.settings,
            state.output,
            search_round=current,
            measured=progress.wall_seconds[-1000:],
        )
        job, created = create_owned(self.c, state, namespace, "Job", job)
        with self.c._lock:
            self.c.jobs.setdefault((namespace, job["metadata"]["name"]), slim_job(job))
        progress.created.add(current.number)
        state.job_seen = True
        if created:
            metrics.JOBS_CREATED.inc()
            self.c.kube.event(
                state.body,
                "Normal",
                "JobCreated",
                f"round {current.number + 1}/{driver.rounds_total(driver.search_of(run))}: Job "
                f"{job['metadata']['name']} with runs {current.start}-{current.start + current.count - 1}",
            )
            log.info("created Job %s/%s (round %d)", namespace, job["metadata"]["name"], current.number)
        return slim_job(job)

    def _suspend(self, key: tuple[str, str], state: RunState, job: dict[str, Any]) -> None:
        """spec.suspend reaches the current round's Job (a queued Job's suspend is Kueue's)."""
        assert state.run is not None
        suspend = bool(state.body.get("spec", {}).get("suspend"))
        if (
            not state.run.spec.execution.queue_name
            and bool(job.get("spec", {}).get("suspend")) != suspend
            and not job_finished(job)
        ):
            job.update(self.c.kube.patch_job(key[0], job["metadata"]["name"], {"spec": {"suspend": suspend}}))

    def _read_finished(self, state: RunState, current: SearchRound, job: Mapping[str, Any]) -> None:
        """Count the round's finished indexes as they come (the status shows them before the round ends)."""
        assert state.tally is not None
        job_status = job.get("status") or {}
        todo = [
            current.start + i
            for text in (job_status.get("completedIndexes"), job_status.get("failedIndexes"))
            for i in iter_intervals(text)
            if i < current.count and not state.tally.known(current.start + i)
        ]
        for summary in self.c._fetch.map(lambda i: self.c._maybe(state, i), todo[: self.c.batch]):
            if summary is not None:  # one without a summary is counted when the round is told
                state.tally.record(summary)

    def _tell(self, state: RunState, current: SearchRound, progress: SearchProgress) -> None:
        """Every index of the round finished: the study learns them and the state is stored."""
        assert state.run is not None and state.tally is not None
        asked = self._ask(state, current, progress)
        indexes = range(current.start, current.start + current.count)
        summaries = [
            summary
            if summary is not None
            else self._missing(state, index, asked.asked[index - current.start])
            for index, summary in zip(
                indexes, self.c._fetch.map(lambda i: self.c._maybe(state, i), indexes), strict=True
            )
        ]
        points = list(progress.points)
        driver.tell_round(state.run, asked, summaries, points)
        driver.save_state(state.run, state.store, asked.log, points)
        progress.log, progress.points, progress.round = asked.log, points, None
        for summary in summaries:
            state.tally.record(summary)
            if summary.get("status") != "error" and summary.get("wallSeconds"):
                progress.wall_seconds.append(float(summary["wallSeconds"]))
        del progress.wall_seconds[:-1000]
        log.info(
            "search %s: round %d told (%d points, optimiser %.2f s)",
            state.run.name,
            current.number,
            len(points),
            asked.optimizer_seconds,
        )

    def _missing(self, state: RunState, index: int, parameters: Mapping[str, Any]) -> dict[str, Any]:
        """An index of a finished round without a summary (its pod ended without writing one): an error
        with the round's parameters, written where its summary belongs (as the local executor does)."""
        from simcore.evaluation.report import index_summary
        from simcore.runner import summary_bytes
        from simcore.scenario.parameters import format_value

        assert state.run is not None
        ref = state.run.spec.scenarios[0]
        summary = index_summary(
            index=index,
            scenario=ref.name,
            parameters={
                **state.run.spec.parameters,
                **ref.parameters,
                **{k: format_value(v) for k, v in parameters.items()},
            },
            seed=state.run.spec.simulation.seed,
            optional=ref.optional,
            sim_seconds=0.0,
            wall_seconds=0.0,
            metrics={},
            results=[],
            error="the pod ended without writing its summary (see its logs)",
            end_reason="error",
        )
        state.store.put_bytes(f"{state.run.name}/{index}/summary.json", summary_bytes(summary))
        return summary

    def _finish(self, state: RunState, progress: SearchProgress) -> str:
        """search.json, failing.xosc, then the run-level summary.json and junit.xml (once)."""
        assert state.run is not None and state.tally is not None
        if not state.tally.finalized:
            driver.finish(
                state.run, state.store, progress.space, progress.points, Path(progress.scenario_name)
            )
            self.c._finalize(state, None)
            state.tally.finalized = True
        return str(state.store.url_for(f"{state.run.name}/search.json"))
