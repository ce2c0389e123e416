"""Apply a run's decision (desired.decide): the last of controller.ensure's three steps (read, decide, apply).

Thin: the status the decision names is published, its events posted, a waiting run re-queued after its
backoff, an earlier run's objects deleted (uid precondition), `run.yaml` stored, the ConfigMap and Job
created. A create answered 409 (the object appeared between the read and the create: a lost answer, another
pass) is the one thing decided here, by desired.claim on the object read then: adopted when it is the run's,
deleted and waited for when an earlier run's of the same name, refused otherwise. A search's rounds create
their ConfigMap and Job the same way (`create_owned`).
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any

from carlos_operator import metrics
from carlos_operator.desired import Decision, Rejected, RunInputs, Waiting, claim, rejection, waiting
from carlos_operator.kube import Conflict, now_rfc3339
from carlos_operator.runstate import RunState, slim_job
from carlos_operator.status import Tally

if TYPE_CHECKING:
    from carlos_operator.hosting import Host, Key

log = logging.getLogger("carlos.operator")


def apply(c: Host, key: Key, state: RunState, inputs: RunInputs, decision: Decision) -> bool:
    """Do what `decision` says for the run `state` holds; True when its objects are ensured and its status
    pass follows (False: nothing to do, rejected, waiting or held)."""
    if inputs.store is not None:
        state.store = inputs.store
    if decision.search is not None:
        state.search = decision.search
    if decision.run is not None and decision.total is not None:
        state.run, state.output = decision.run, decision.output
        if state.tally is None or state.tally.total != decision.total:
            state.tally = Tally(decision.total)
    action = decision.action
    if action == "nothing":
        return False
    if action == "reject":
        reject(c, state, decision)
        return False
    if action in ("wait", "replace"):
        for kind, name, uid in decision.delete:
            c.kube.delete(kind, key[0], name, uid)
        wait(c, key, state, decision)
        return False
    state.waits = 0
    state.held = action == "hold"
    if action == "hold":
        _announce(c, state, decision)
        return False
    assert state.run is not None and decision.total is not None
    if not decision.objects:  # its Job started before (adopted by the status pass), or a search's rounds
        if decision.spec is not None:
            state.store.put_bytes(f"{state.run.name}/run.yaml", decision.spec)
        state.ensured = True
        state.job_seen = state.job_seen or action == "adopt"
        return True
    job: dict[str, Any] | None = None
    created = False
    for wanted in decision.objects:
        if wanted.existing is not None:
            obj, made = dict(wanted.existing), False
        else:
            try:
                obj, made = create_owned(c, state, key[0], wanted.kind, wanted.body)
            except Waiting as exc:
                wait(c, key, state, _waiting(state, exc, c.backoff))
                return False
            except Rejected as exc:
                reject(c, state, rejection(state.last_status, exc.reason, exc.message, now_rfc3339()))
                return False
        if wanted.kind == "Job":
            job, created = obj, made
            if made:
                metrics.JOBS_CREATED.inc()
        if made and wanted.event is not None:
            c.kube.event(state.body, *wanted.event)
    assert job is not None
    with c._lock:
        c.jobs.setdefault((key[0], job["metadata"]["name"]), slim_job(job))
    if decision.spec is not None:  # after the Job, off its path: a pass that stops before stores it next time
        state.store.put_bytes(f"{state.run.name}/run.yaml", decision.spec)
    state.ensured = True
    state.job_seen = True
    if created:
        log.info("created Job %s/%s (%d runs)", key[0], job["metadata"]["name"], decision.total)
    else:
        log.info("adopted Job %s/%s", key[0], job["metadata"]["name"])
    return True


def create_owned(
    c: Host, state: RunState, namespace: str, kind: str, body: dict[str, Any]
) -> tuple[dict[str, Any], bool]:
    """Create `body`, a ConfigMap or Job of the run: (the object, True), or on 409 (the existing one, False)
    when it is the run's own. An earlier run's of the same name is deleted (uid precondition) and Waiting
    raised; something else's raises Rejected."""
    if kind == "Job":
        create, read = c.kube.create_job, c.kube.read_job
    else:
        create, read = c.kube.create_configmap, c.kube.read_configmap
    try:
        return create(namespace, body), True
    except Conflict:
        existing = read(namespace, body["metadata"]["name"])
    verdict = claim(existing, state.uid, state.body["metadata"]["name"], kind)
    if isinstance(verdict, Waiting):
        meta = existing["metadata"]
        c.kube.delete(kind, namespace, meta["name"], str(meta.get("uid")))
    if verdict is not None:
        raise verdict
    return existing, False


def reject(c: Host, state: RunState, decision: Decision) -> None:
    """Publish a rejection (desired.rejection): `Accepted=False`, a Warning event; the run is `Failed`."""
    assert decision.status is not None
    meta = state.body["metadata"]
    c._publish(state, dict(decision.status))
    for event in decision.events:
        c.kube.event(state.body, *event)
    metrics.set_phase(state.uid, "Failed")
    log.info("rejected %s/%s: %s", meta.get("namespace"), meta["name"], decision.message)


def wait(c: Host, key: Key, state: RunState, decision: Decision) -> None:
    """Publish a wait for a prerequisite (desired.waiting) and re-queue the run after its backoff."""
    assert decision.status is not None and decision.retry_after is not None
    c._publish(state, dict(decision.status))
    for event in decision.events:
        c.kube.event(state.body, *event)
    state.waits += 1
    metrics.ERRORS.labels(kind=decision.reason).inc()
    log.info("%s/%s waits %.0f s: %s", *key, decision.retry_after, decision.message)
    timer = threading.Timer(decision.retry_after, c.enqueue, args=(key,))
    timer.daemon = True
    timer.start()


def _announce(c: Host, state: RunState, decision: Decision) -> None:
    """Publish a held run's status and its events."""
    assert decision.status is not None
    c._publish(state, dict(decision.status))
    for event in decision.events:
        c.kube.event(state.body, *event)


def _waiting(state: RunState, exc: Waiting, backoff: float) -> Decision:
    return waiting(
        state.last_status, exc.reason, exc.message, now_rfc3339(), waits=state.waits, backoff=backoff
    )
