"""The reconciler: level-based, idempotent, one work queue for every SimulationRun the operator sees.

kopf delivers the watch events (handlers.py); this module does the work on a pool of threads:

- `ensure` (a run without its objects yet), in three steps, as the operators we learn from shape it:
  reading.read_inputs reads every input once (its distribution file, the ConfigMaps and Secret it names, a
  search's scenario, the stored `run.yaml`, the existing ConfigMap and Job) into a `RunInputs`;
  desired.decide (pure) turns the run and its inputs into a `Decision`: not accepted (`Accepted=False`
  with the field to fix and a Warning event, nothing created), waiting with backoff for what the run names
  but may not exist yet (its Secret, its ConfigMaps: External Secrets, sealed-secrets; the `Prerequisites`
  condition), replacing an earlier run's objects of the same name (deleted and created again before the
  garbage collector got to them), held (`spec.suspend` with a Kueue `queueName`: the Job is created when
  resumed, Kueue owns a queued Job's `suspend`), or the ConfigMap and Indexed Job to create or adopt under
  deterministic names with owner references (a restarted operator never creates a second Job; a run whose
  status shows it started never gets a second one); apply.apply does the writes (a 409 on create is
  adopted or refused there, by the same pure rule).
- A run whose recorded status is terminal is finished: nothing is read or written for it again, after a
  restart too (the run-level summary is written before the terminal status). A Job that disappears before
  the run finished (deleted, or expired) leaves the run `Unknown`, never back to `Pending`.
- `reconcile`: read the per-index summaries the Job reports finished and not yet counted (at most
  `batch` per pass, in parallel), aggregate the status (status.py), patch it when it changed, post events
  on transitions, and when every index is final write the run-level `summary.json` and `junit.xml`.

While a run's pods are active, its pods are read by label (at most `POD_SAMPLE`, every `pod_check`
seconds): a container waiting for a reason that does not pass by itself (ImagePullBackOff,
CreateContainerConfigError…) is shown as the `PodsStuck` condition and a Warning event.

A search (`spec.search`) gets no ConfigMap and Job here: searching.py creates one of each per round and
tells the study each round's results (the stored state is the truth after a restart).

Runs are re-queued when their Job changes (watch events) and every `resync` seconds while not finished.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from carlos_operator import metrics
from carlos_operator.apply import apply, reject, wait
from carlos_operator.builders import OperatorSettings, Output, job_name
from carlos_operator.desired import (
    FINISHED_PHASES,
    MAX_BACKOFF_S,
    MAX_DISTRIBUTION_BYTES,
    Rejected,
    Waiting,
    condition_status,
    decide,
    namespace_of,
    rejection,
    waiting,
)
from carlos_operator.kube import Kube, NotFound, now_rfc3339
from carlos_operator.reading import read_inputs
from carlos_operator.runstate import RunState, slim_job
from carlos_operator.scratch import ScratchFolders
from carlos_operator.searching import SearchRuns
from carlos_operator.status import (
    TERMINAL_PHASES,
    aggregate,
    condition,
    job_finished,
    runs_view,
)
from simcore.errors import BadInput, CarlosError
from simcore.evaluation.flaky import RepeatTally, flag_flaky, flag_repeats, recording_digests
from simcore.evaluation.report import run_summary, write_junit_xml
from simcore.plan import Plan
from simcore.spec import SimulationRun

log = logging.getLogger("carlos.operator")

Key = tuple[str, str]  # (namespace, name)


#: container waiting reasons that do not pass by themselves (a pod in them never starts)
STUCK_REASONS = frozenset(
    {
        "ImagePullBackOff",
        "ErrImagePull",
        "InvalidImageName",
        "CreateContainerConfigError",
        "CreateContainerError",
        "RunContainerError",
    }
)
#: pods read per check (bounded: a run may have thousands)
POD_SAMPLE = 20
#: index summaries a run's report.html shows at most (failed and errored first): bounds the operator's
#: memory and the report's reads for the largest runs (its counts are summary.json's, of every index)
REPORT_INDEXES = 1000
#: bird's-eye plots (recordings read) of a run's report.html
REPORT_WORST = 6
#: tries of writing report.html before the run finishes without it
REPORT_ATTEMPTS = 3


def _store_for(kube: Kube, namespace: str, output: Output) -> Any:
    """The object store of a run's output, with the credentials of its Secret (or the operator's own)."""
    bucket, _, prefix = output.url.removeprefix("s3://").partition("/")
    creds: dict[str, str] = {}
    if output.secret:
        try:
            creds = kube.read_secret_data(namespace, output.secret)
        except NotFound:
            raise Waiting(
                "SecretNotFound",
                f"spec.output.credentialsSecretRef: Secret {output.secret!r} not found in namespace "
                f"{namespace!r}; the run starts when it exists",
            ) from None
        if not creds.get("AWS_ACCESS_KEY_ID") or not creds.get("AWS_SECRET_ACCESS_KEY"):
            raise Waiting(
                "SecretIncomplete",
                f"spec.output.credentialsSecretRef: Secret {output.secret!r} needs the keys AWS_ACCESS_KEY_ID "
                "and AWS_SECRET_ACCESS_KEY",
            )
    else:  # the operator's own credentials (its environment)
        creds = {k: v for k, v in os.environ.items() if k.startswith("AWS_")}
    endpoint = output.endpoint or creds.get("AWS_ENDPOINT_URL") or os.environ.get("AWS_ENDPOINT_URL") or None
    region = output.region or creds.get("AWS_REGION") or os.environ.get("AWS_REGION") or "us-east-1"
    return _s3_store(bucket, prefix, endpoint, region, creds)


def warm_up(kube: Kube, settings: OperatorSettings) -> None:
    """Make at start what the first passes of a burst of new runs would otherwise all wait for at once: the
    object-store client of the default output (boto3's import, its service model) when it needs no Secret.
    Best effort: a run opens its store as always."""
    if not (settings.default_output_url or "").startswith("s3://") or settings.default_s3_secret:
        return
    output = Output(
        url=str(settings.default_output_url), endpoint=settings.default_s3_endpoint, region=None, secret=None
    )
    try:
        _store_for(kube, "", output)
    except Exception as exc:  # the first run opens it again and says what is wrong
        log.debug("warming the default object store's client failed: %s", exc)


_clients: dict[tuple[str | None, ...], Any] = {}
_clients_lock = threading.Lock()


def _s3_store(bucket: str, prefix: str, endpoint: str | None, region: str, creds: dict[str, str]) -> Any:
    """An S3Store on a shared client per (credentials, endpoint, region): a boto3 client costs ~10 MB and
    ~0.2 s to build, and 1,000 runs usually share one Secret. S3Store itself takes credentials from the
    process environment, where a run's Secret must not go (other runs use other Secrets), so the client is
    built here and handed to it."""
    import boto3
    from boto3.s3.transfer import TransferConfig
    from botocore.config import Config

    from simcore.store import S3Store

    access_key = creds.get("AWS_ACCESS_KEY_ID")
    secret_key = creds.get("AWS_SECRET_ACCESS_KEY")
    token = creds.get("AWS_SESSION_TOKEN") or None
    key = (access_key, secret_key, token, endpoint, region)
    with _clients_lock:
        client = _clients.get(key)
        if client is None:
            session = boto3.session.Session(
                aws_access_key_id=access_key,
                aws_secret_access_key=secret_key,
                aws_session_token=token,
                region_name=region,
            )
            config = Config(
                retries={"mode": "standard", "max_attempts": 5},
                connect_timeout=10.0,
                read_timeout=60.0,
                s3={"addressing_style": "path"} if endpoint else {},
                max_pool_connections=32,
            )
            client = _clients[key] = session.client("s3", endpoint_url=endpoint, config=config)
    store = S3Store.__new__(S3Store)
    store.bucket = bucket
    store.prefix = prefix.strip("/")
    store.endpoint = endpoint
    store.region = region
    store._secrets = tuple(s for s in (secret_key, token) if s)
    store._client = client
    store._transfer = TransferConfig(max_concurrency=4)
    return store


class Controller:
    def __init__(
        self,
        kube: Kube,
        settings: OperatorSettings,
        *,
        workers: int = 4,
        resync: float = 10.0,
        batch: int = 500,
        pod_check: float = 30.0,
        backoff: float = 5.0,
        store_factory: Callable[[Kube, str, Output], Any] = _store_for,
    ) -> None:
        self.kube = kube
        self.settings = settings
        self.resync = resync
        self.batch = batch
        self.pod_check = pod_check
        self.backoff = backoff
        self.store_factory = store_factory
        self.scratch = ScratchFolders("carlos-operator-inputs-")
        self.runs: dict[Key, RunState] = {}
        self.jobs: dict[Key, dict[str, Any]] = {}  # (namespace, job name) → Job
        self._lock = threading.Lock()
        self._queue: list[Key] = []
        self._queued: set[Key] = set()
        self._busy: set[Key] = set()
        self._wake = threading.Condition(self._lock)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._fetch = ThreadPoolExecutor(max_workers=16, thread_name_prefix="carlos-s3")
        self.workers = workers
        self.searches = SearchRuns(self)

    # --- events (from kopf's watch streams) ------------------------------------------------------------

    def observe_run(self, event_type: str, body: dict[str, Any]) -> None:
        meta = body.get("metadata", {})
        body = slim_run(body)
        meta = body["metadata"] = {
            k: meta[k]
            for k in ("name", "namespace", "uid", "generateName", "labels", "generation")
            if k in meta
        }
        key = (meta.get("namespace") or "", meta.get("name") or "")
        with self._lock:
            if event_type == "DELETED":
                self.runs.pop(key, None)
                self.scratch.forget(*key)
                self.searches.forget(key)
                return
            state = self.runs.get(key)
            generation = meta.get("generation")
            known = int(generation) if generation is not None else None
            if state is None or state.uid != meta.get("uid"):
                state = self.runs[key] = RunState(body=body, uid=str(meta.get("uid")))
            elif event_type == "MODIFIED" and known is not None and state.generation == known:
                # the spec is as seen: a change of the status (the operator's own patches) or of metadata,
                # nothing to reconcile (every status patch would cost a pass otherwise)
                state.body = body
                return
            else:
                state.body = body
            state.generation = known
        self.enqueue(key)

    def observe_job(self, event_type: str, body: dict[str, Any]) -> None:
        meta = body.get("metadata", {})
        namespace = meta.get("namespace") or ""
        with self._lock:
            if event_type == "DELETED":
                self.jobs.pop((namespace, meta.get("name")), None)
            else:
                self.jobs[(namespace, meta.get("name"))] = slim_job(body)
        for owner in meta.get("ownerReferences") or []:
            if owner.get("kind") == "SimulationRun":
                self.enqueue((namespace, owner.get("name")))

    # --- queue ----------------------------------------------------------------------------------------

    def enqueue(self, key: Key) -> None:
        with self._wake:
            if key not in self._queued:
                self._queued.add(key)
                self._queue.append(key)
                self._wake.notify()

    def start(self) -> None:
        for i in range(self.workers):
            thread = threading.Thread(target=self._work, name=f"carlos-reconcile-{i}", daemon=True)
            thread.start()
            self._threads.append(thread)
        thread = threading.Thread(target=self._resync_loop, name="carlos-resync", daemon=True)
        thread.start()
        self._threads.append(thread)

    def stop(self) -> None:
        self._stop.set()
        with self._wake:
            self._wake.notify_all()
        for thread in self._threads:
            thread.join(timeout=10)
        self._fetch.shutdown(wait=False, cancel_futures=True)
        self.kube.close()
        self.scratch.close()
        self.searches.close()

    def _resync_loop(self) -> None:
        while not self._stop.wait(self.resync):
            with self._lock:
                keys = [k for k, s in self.runs.items() if s.last_status.get("phase") not in FINISHED_PHASES]
            for key in keys:
                self.enqueue(key)

    def _next(self) -> Key | None:
        with self._wake:
            while not self._stop.is_set():
                for position, key in enumerate(self._queue):
                    if key not in self._busy:
                        del self._queue[position]
                        self._queued.discard(key)
                        self._busy.add(key)
                        return key
                self._wake.wait(1.0)
        return None

    def _work(self) -> None:
        while True:
            key = self._next()
            if key is None:
                return
            started = time.perf_counter()
            try:
                self.reconcile(key)
            except Exception as exc:
                metrics.ERRORS.labels(kind=type(exc).__name__).inc()
                log.exception("reconciling %s/%s failed; retrying", *key)
                retry = threading.Timer(5.0, self.enqueue, args=(key,))
                retry.daemon = True  # never keeps a stopping operator alive
                retry.start()
            finally:
                metrics.RECONCILE_SECONDS.observe(time.perf_counter() - started)
                with self._wake:
                    self._busy.discard(key)
                    self._wake.notify()

    # --- reconciliation -------------------------------------------------------------------------------

    def reconcile(self, key: Key) -> None:
        with self._lock:
            state = self.runs.get(key)
        if state is None:
            return
        body = state.body
        status = dict(body.get("status") or {})
        if not state.last_status and status:
            state.last_status = status
        if condition_status(status, "Accepted") == "False":
            return  # rejected: nothing to do until a new run (the spec is immutable)
        if state.last_status.get("phase") in FINISHED_PHASES:
            # finished: the verdict and the run-level summary are recorded; nothing is read again
            self._observe_generation(state)
            return
        if not state.ensured:
            if not self.ensure(key, state):
                return  # rejected, waiting for a prerequisite, or held
            if state.search is None:
                # its Job is made: the status pass waits its turn in the queue, so that the runs queued
                # behind this one get their Jobs first (a burst of new runs is not slowed by status writes)
                self.enqueue(key)
                return
        if state.search is not None:
            now = now_rfc3339()
            try:
                self.searches.update(key, state)
            except Waiting as exc:  # a round's objects of an earlier run of the same name are being deleted
                wait(
                    self,
                    key,
                    state,
                    waiting(
                        state.last_status,
                        exc.reason,
                        exc.message,
                        now,
                        waits=state.waits,
                        backoff=self.backoff,
                    ),
                )
            except Rejected as exc:  # a round's object of the run's name is something else's
                reject(self, state, rejection(state.last_status, exc.reason, exc.message, now))
            except CarlosError as exc:  # the stored study does not fit the run (another spec, optuna)
                reject(self, state, rejection(state.last_status, "SearchStateMismatch", str(exc), now))
            return
        self._update_status(key, state)

    def ensure(self, key: Key, state: RunState) -> bool:
        """Read every input of a run without its objects once (reading.py), decide what it should have
        (desired.decide, pure), apply the decision (apply.py): True when its objects are there (created or
        adopted) and its status pass follows; False when it is rejected, waits for a prerequisite or is
        held."""
        inputs = read_inputs(self, state, prepare_search=self.searches.prepare)
        decision = decide(state.body, inputs, self.settings, now=now_rfc3339(), backoff=self.backoff)
        return apply(self, key, state, inputs, decision)

    def _observe_generation(self, state: RunState) -> None:
        """A finished run whose spec.suspend changed: only observedGeneration moves."""
        if state.generation is not None and state.last_status.get("observedGeneration") != state.generation:
            meta = state.body["metadata"]
            self.kube.patch_run_status(
                meta.get("namespace"), meta["name"], {"observedGeneration": state.generation}
            )
            state.last_status = {**state.last_status, "observedGeneration": state.generation}

    def _publish(self, state: RunState, status: dict[str, Any]) -> None:
        """Patch the run's status (with observedGeneration) when it changed."""
        if state.generation is not None:
            status["observedGeneration"] = state.generation
        if _comparable(status) != _comparable(state.last_status):
            meta = state.body["metadata"]
            self.kube.patch_run_status(meta.get("namespace"), meta["name"], status)
            state.last_status = status

    def _job(self, state: RunState) -> dict[str, Any] | None:
        assert state.run is not None
        meta = state.body["metadata"]
        namespace = meta.get("namespace") or "default"
        name = job_name(state.run.name)
        with self._lock:
            job = self.jobs.get((namespace, name))
        if job is None:
            try:
                job = self.kube.read_job(namespace, name)
            except NotFound:
                return None
        owners = job.get("metadata", {}).get("ownerReferences") or []
        return runs_view(job) if any(o.get("uid") == state.uid for o in owners) else None

    def _update_status(self, key: Key, state: RunState) -> None:
        assert state.run is not None and state.tally is not None and state.output is not None
        run, tally = state.run, state.tally
        job = self._job(state)
        if job is not None:
            state.job_seen = True
        # spec.suspend is the one field that may change after creation: read it from the latest body.
        # A queued (Kueue) Job's suspend is Kueue's: the run holds it before creation instead (_hold).
        suspend = bool(state.body.get("spec", {}).get("suspend"))
        if (
            job is not None
            and not run.spec.execution.queue_name
            and bool(job.get("spec", {}).get("suspend")) != suspend
            and not job_finished(job)
        ):
            job = self.kube.patch_job(key[0], job["metadata"]["name"], {"spec": {"suspend": suspend}})
        job_status = (job or {}).get("status") or {}
        more = False
        for intervals in (job_status.get("completedIndexes"), job_status.get("failedIndexes")):
            todo = tally.unknown_among(intervals, self.batch)
            more = more or len(todo) >= self.batch
            for summary in self._fetch.map(lambda i: self._summary(state, i), todo):
                tally.record(summary)
        if more:
            self.enqueue(key)  # more finished indexes to read: the next batch right after this pass
        previous = state.last_status
        if job is None and state.job_seen:
            self._job_gone(state)
            return
        reported = sum(int(previous.get(k) or 0) for k in ("passed", "testFailures", "errors"))
        if more and tally.known_count < reported:
            return  # catching up after a restart: never publish counts lower than the ones already shown
        status = aggregate(
            total=tally.total,
            job=job,
            tally=tally,
            results_url=state.store.url_for(run.name),
            now=now_rfc3339(),
            previous=previous,
        )
        status["jobName"] = job_name(run.name)
        if job is not None and status["phase"] not in TERMINAL_PHASES:
            self._check_pods(state, job, status)
        if status["phase"] in TERMINAL_PHASES and not tally.finalized:
            self._finalize(state, job)
            tally.finalized = True
        before = previous.get("phase")
        self._publish(state, status)
        if status["phase"] != before:
            self._transition(state, before, status)
        metrics.set_phase(state.uid, status["phase"])

    def _job_gone(self, state: RunState, name: str | None = None) -> None:
        """The run's Job (`name`: a search's round) disappeared before the run finished: the results read
        so far stay, the run is `Unknown` (never `Pending` again, never a second Job)."""
        assert state.run is not None and state.tally is not None
        tally = state.tally
        previous = state.last_status
        name = name or job_name(state.run.name)
        message = (
            f"the Job {name} is gone with {tally.known_count} of {tally.total} results read; the run cannot "
            "finish: create it again under a new name"
        )
        conditions = {c.get("type"): c for c in previous.get("conditions") or []}
        status = {
            **{k: v for k, v in previous.items() if k not in ("conditions", "active")},
            "phase": "Unknown",
            "active": 0,
            "jobName": name,
            "passed": tally.counts[1],
            "testFailures": tally.counts[2],
            "errors": tally.counts[3],
            "total": tally.total,
            "conditions": [
                *(c for c in conditions.values() if c.get("type") not in ("Running", "Complete")),
                condition(conditions, "Running", False, "JobGone", message, now_rfc3339()),
                {
                    "type": "Complete",
                    "status": "Unknown",
                    "reason": "JobGone",
                    "message": message,
                    "lastTransitionTime": now_rfc3339(),
                },
            ],
        }
        self._publish(state, status)
        if previous.get("phase") != "Unknown":
            self.kube.event(state.body, "Warning", "JobGone", message)
        metrics.set_phase(state.uid, "Unknown")

    def _check_pods(self, state: RunState, job: dict[str, Any], status: dict[str, Any]) -> None:
        """Pods of an active Job that cannot start (image, config): the `PodsStuck` condition and an event.
        Read by label, at most POD_SAMPLE pods, at most every `pod_check` seconds."""
        if int(status.get("active") or 0) > 0 and time.monotonic() - state.pods_checked >= self.pod_check:
            state.pods_checked = time.monotonic()
            meta = job["metadata"]
            try:
                pods = self.kube.list_pods(
                    meta.get("namespace") or "default", f"job-name={meta['name']}", POD_SAMPLE
                )
            except Exception as exc:  # best effort: the run's status does not depend on it
                log.warning("reading the pods of %s failed: %s", meta["name"], exc)
                pods = None
            if pods is not None:
                state.stuck = stuck_reason(pods)
                if state.stuck is not None:
                    before = condition_status(state.last_status, "PodsStuck")
                    if before != "True":
                        self.kube.event(state.body, "Warning", *state.stuck)
        previous = {c.get("type"): c for c in state.last_status.get("conditions") or []}
        reason, message = state.stuck or ("PodsStarting", "")
        status["conditions"].append(
            condition(previous, "PodsStuck", state.stuck is not None, reason, message, now_rfc3339())
        )

    def _transition(self, state: RunState, before: str | None, status: dict[str, Any]) -> None:
        phase = status["phase"]
        counts = f"{status['passed']} passed, {status['testFailures']} failed, {status['errors']} errors"
        if phase == "Running":
            self.kube.event(state.body, "Normal", "Running", f"runs started ({status['progress']})")
        elif phase == "Suspended":
            self.kube.event(state.body, "Normal", "Suspended", "the Job is suspended")
        elif phase == "Succeeded":
            self.kube.event(state.body, "Normal", "Succeeded", f"{counts}; results: {status['resultsURL']}")
        elif phase == "Failed":
            self.kube.event(state.body, "Warning", "Failed", f"{counts}; results: {status['resultsURL']}")

    def _summary(self, state: RunState, index: int) -> dict[str, Any]:
        from simcore.store import NotFoundError

        assert state.run is not None
        try:
            return dict(json.loads(state.store.get_bytes(f"{state.run.name}/{index}/summary.json")))
        except NotFoundError:
            return _missing_summary(
                state.run, index, "the pod ended without writing its summary (see its logs)"
            )

    def _finalize(self, state: RunState, job: dict[str, Any] | None) -> None:
        """Write the run-level summary.json and junit.xml (streamed: never all summaries in memory)."""
        assert state.run is not None and state.tally is not None
        run, tally = state.run, state.tally

        def summaries() -> Iterator[dict[str, Any]]:
            chunk = 256
            for start in range(0, tally.total, chunk):
                indexes = range(start, min(start + chunk, tally.total))
                for index, summary in zip(
                    indexes, self._fetch.map(lambda i: self._maybe(state, i), indexes), strict=True
                ):
                    if summary is not None:
                        yield summary
                    elif tally.known(index):
                        yield _missing_summary(run, index, "the pod ended without writing its summary")

        from simcore.report.html import ReportSample

        sample = ReportSample(REPORT_INDEXES)
        # execution.repeat (not for searches): the runs of a flaky point are flagged, as by `carlos run`
        repeated = run.spec.search is None and run.spec.execution.repeat > 1
        repeats = RepeatTally(run.spec.execution.repeat) if repeated else None

        def sampled() -> Iterator[dict[str, Any]]:
            flagged = summaries()
            if repeats is not None:
                digests = recording_digests(state.store, run.name)
                flagged = flag_repeats(flagged, Plan(run.spec).point_of, repeats, digests)
            for summary in flagged:
                sample.add(summary)
                yield summary

        summary = run_summary(run.name, sampled(), total=tally.total)
        summary["outputUrl"] = state.store.url_for(run.name)
        junit_summaries = summaries()
        if repeats is not None:
            summary["repeats"] = repeats.report()
            junit_summaries = flag_flaky(junit_summaries, summary["repeats"])
        # spooled to a file in the run's scratch folder and uploaded from there: 50,000 test cases never
        # held in memory at once
        spool = self.scratch.folder(namespace_of(state.body), run.name) / "junit.xml"
        try:
            with spool.open("wb") as out:
                write_junit_xml(run.name, junit_summaries, out)
            state.store.put_file(f"{run.name}/junit.xml", spool)
        finally:
            spool.unlink(missing_ok=True)
        state.store.put_bytes(
            f"{run.name}/summary.json", (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode()
        )
        self._report(state, summary, sample)

    def _report(self, state: RunState, summary: dict[str, Any], sample: Any) -> None:
        """`report.html` beside summary.json, best effort: a failure is logged, the verdict stands."""
        from simcore.report.html import write_after_run

        assert state.run is not None
        for attempt in range(REPORT_ATTEMPTS):  # a passing store or API error is tried again
            try:
                write_after_run(
                    state.store,
                    state.run,
                    summary,
                    sample.summaries(),
                    omitted=sample.omitted,
                    worst=REPORT_WORST,
                )
                return
            except Exception as exc:  # the report never changes the run's outcome (as `carlos run`)
                log.warning(
                    "%s: writing report.html failed (attempt %d/%d): %s: %s",
                    state.run.name,
                    attempt + 1,
                    REPORT_ATTEMPTS,
                    type(exc).__name__,
                    exc,
                )
        metrics.ERRORS.labels(kind="ReportFailed").inc()

    def _maybe(self, state: RunState, index: int) -> dict[str, Any] | None:
        from simcore.store import NotFoundError

        assert state.run is not None
        try:
            return dict(json.loads(state.store.get_bytes(f"{state.run.name}/{index}/summary.json")))
        except NotFoundError:
            return None


def stuck_reason(pods: list[dict[str, Any]]) -> tuple[str, str] | None:
    """(reason, message) of the first container of `pods` waiting for a reason in STUCK_REASONS."""
    for pod in pods:
        status = pod.get("status") or {}
        for container in [
            *(status.get("initContainerStatuses") or []),
            *(status.get("containerStatuses") or []),
        ]:
            waiting = (container.get("state") or {}).get("waiting") or {}
            if waiting.get("reason") in STUCK_REASONS:
                name = (pod.get("metadata") or {}).get("name")
                detail = str(waiting.get("message") or "")[:300]
                return str(
                    waiting["reason"]
                ), f"pod {name} container {container.get('name')}: {detail}".rstrip(": ")
    return None


def _missing_summary(run: SimulationRun, index: int, reason: str) -> dict[str, Any]:
    from simcore.runner import error_outcome

    return error_outcome(run, index, 1, reason).summary


def slim_run(body: dict[str, Any]) -> dict[str, Any]:
    """A SimulationRun as the controller keeps it between events (the status is not kept: last_status)."""
    return {k: body[k] for k in ("apiVersion", "kind", "metadata", "spec") if k in body} | {
        "status": body.get("status") or {}
    }


def _comparable(status: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in status.items() if k != "conditions"} | {
        "conditions": [
            (c.get("type"), c.get("status"), c.get("reason"), c.get("message"))
            for c in status.get("conditions") or []
        ]
    }


__all__ = ["MAX_BACKOFF_S", "MAX_DISTRIBUTION_BYTES", "BadInput", "Controller", "Rejected", "Waiting"]
