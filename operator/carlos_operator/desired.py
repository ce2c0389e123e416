"""What a run should have, decided (pure): (the run, its inputs, the settings) → the objects and the decision.

`decide` is the middle of the controller's three steps for a run that has no Job yet (controller.ensure):

1. reading.read_inputs reads every input once, in the order `decide` looks at them, into a `RunInputs` (the
   run's last status, its distribution file, which ConfigMaps it names are missing, whether its Secret
   lets the object store open, a search's scenario, the stored `run.yaml`, the existing ConfigMap and Job);
2. `decide` turns the run and those inputs into a `Decision`: `nothing` (the run is finished or was not
   accepted), `reject` (`Accepted=False`, a Warning event), `wait` (a prerequisite is missing: `Pending`
   with the `Prerequisites` condition, retried with backoff), `replace` (the ConfigMap or Job of an earlier
   run of the same name is deleted, then `wait`), `hold` (suspended with a Kueue `queueName`: no Job until
   resumed), `adopt` (what the run needs exists, or its status shows its Job started: never a second one),
   `create` (the ConfigMap and Job to create, `run.yaml` to store), `search` (`run.yaml` only: searching.py
   makes a ConfigMap and Job per round);
3. apply.apply does the writes the decision names; a 409 on create is the one answer it cannot know
   beforehand, and `claim` (pure, shared with a search's rounds) says what to do with the object found.

Nothing here talks to Kubernetes or the object store; `now` and `backoff` come in as arguments. The one file
read is a distribution's local copy (reading.py made it), which the sweep expands from to count its runs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from carlos_operator.builders import (
    DISTRIBUTION_FILE,
    OperatorSettings,
    Output,
    build_configmap,
    build_job,
    check_cluster_spec,
    job_name,
    manifest_yaml,
    resolve_output,
    round_job_name,
    scenario_configmaps,
    secret_references,
)
from carlos_operator.runstate import SearchProgress
from carlos_operator.status import TERMINAL_PHASES, condition
from simcore.errors import CarlosError
from simcore.manifest import parse_manifest
from simcore.plan import Plan
from simcore.spec import SimulationRun
from simcore.wording import plural

#: phases after which a run is never reconciled again
FINISHED_PHASES = (*TERMINAL_PHASES, "Unknown")
#: a distribution file the operator copies into a Job's ConfigMap (1 MiB at most, with the spec)
MAX_DISTRIBUTION_BYTES = 900 * 1024
#: a missing prerequisite is looked for again after 5 s, 10 s, 20 s … at most this often
MAX_BACKOFF_S = 300.0

Action = Literal["nothing", "reject", "wait", "replace", "hold", "adopt", "create", "search"]
Event = tuple[str, str, str]  # (type, reason, message)


class Rejected(Exception):
    """The run cannot be accepted: `reason` (CamelCase) and a message naming the field to fix."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason
        self.message = message


class Waiting(Rejected):
    """Something the run names does not exist yet (or is being deleted): retried with backoff."""


@dataclass(frozen=True)
class RunInputs:
    """What `decide` needs beyond the run itself, read once (reading.read_inputs). The reader reads in the
    order `decide` looks and stops at the first input that is missing or unusable, so a field after it keeps
    its default; nothing is read for a run whose status is final."""

    status: Mapping[str, Any] = field(default_factory=dict)  # the run's last known status
    waits: int = 0  # consecutive waits for a prerequisite so far (the backoff exponent)
    absent_configmaps: tuple[str, ...] = ()  # ConfigMaps the run names that do not exist
    credentials: Waiting | None = None  # the object store did not open: its Secret is missing or incomplete
    distribution: bytes | None = None  # a sweep's distribution file (from a ConfigMap key or s3://)
    distribution_error: str | None = None  # why that file cannot be used
    distribution_copy: str | None = None  # the operator's local copy of it (the sweep expands from it)
    search_known: bool = False  # a search's progress is kept from an earlier pass (its scenario was read)
    search: SearchProgress | None = None  # a search's scenario and space, read now
    search_error: str | None = None  # why a search's scenario cannot be used
    store: Any = None  # the opened object store (a handle for apply; `decide` never calls it)
    results_url: str | None = None  # where the run's results go
    stored_spec: bytes | None = None  # `<run>/run.yaml` already in the store (None: absent)
    configmap: Mapping[str, Any] | None = None  # the existing ConfigMap of the run's name, when known
    job: Mapping[str, Any] | None = None  # the existing Job of the run's name, when known (the Job watch's)


@dataclass(frozen=True)
class Wanted:
    """An object the run needs: `body` to create, or `existing` (the run's own, adopted); `event` is posted
    when this process creates it."""

    kind: str  # ConfigMap | Job
    body: dict[str, Any]
    existing: Mapping[str, Any] | None = None
    event: Event | None = None


@dataclass(frozen=True)
class Decision:
    """What to do for a run (see the module's docstring for the actions). `status` is published and `events`
    posted as they are; `retry_after` (seconds) re-queues a waiting run; `delete` names (kind, name, uid) of
    an earlier run's objects; `spec` is `run.yaml` to store (absent from the store); `objects` the ConfigMap
    and Job (created or adopted, in order); `run` is the run as the operator runs it (a distribution read
    from its local copy), `total` its runs."""

    action: Action
    reason: str = ""
    message: str = ""
    status: Mapping[str, Any] | None = None
    events: tuple[Event, ...] = ()
    retry_after: float | None = None
    delete: tuple[tuple[str, str, str], ...] = ()
    spec: bytes | None = None
    objects: tuple[Wanted, ...] = ()
    run: SimulationRun | None = None
    output: Output | None = None
    total: int | None = None
    search: SearchProgress | None = None  # a search's progress, new (its scenario was read now)


# --- the parts of a decision (each pure; `decide` composes them, apply.py and the reader use some) ---------


def condition_status(status: Mapping[str, Any], kind: str) -> str | None:
    """The `status` ("True", "False", "Unknown") of the condition `kind`, None when there is none."""
    for entry in status.get("conditions") or []:
        if entry.get("type") == kind:
            return str(entry.get("status"))
    return None


def finished(status: Mapping[str, Any]) -> bool:
    """Nothing is read or written for the run again: not accepted, or its phase is final."""
    return condition_status(status, "Accepted") == "False" or status.get("phase") in FINISHED_PHASES


def started(status: Mapping[str, Any]) -> bool:
    """The run's status shows its Job started: that Job is adopted if it is still there, never created again."""
    return bool(status.get("startTime")) or status.get("phase") == "Running"


def held(body: Mapping[str, Any], run: SimulationRun) -> bool:
    """Suspended with a Kueue queueName: Kueue would admit (unsuspend) a queued Job, so none exists until the
    run is resumed (`spec.suspend` is read from the latest body: the one field that may change)."""
    return bool((body.get("spec") or {}).get("suspend")) and bool(run.spec.execution.queue_name)


def namespace_of(body: Mapping[str, Any]) -> str:
    return str((body.get("metadata") or {}).get("namespace") or "default")


def parse(body: Mapping[str, Any], settings: OperatorSettings) -> tuple[SimulationRun, Output]:
    """The run as submitted and its output; Rejected (InvalidSpec) naming the field to fix."""
    import json

    meta = body["metadata"]
    namespace = namespace_of(body)
    document = {k: body[k] for k in ("apiVersion", "kind", "metadata", "spec") if k in body}
    try:
        run = parse_manifest(json.loads(json.dumps(document)), source=f"{namespace}/{meta['name']}")
        return run, resolve_output(run, settings, namespace=namespace)
    except CarlosError as exc:
        raise Rejected("InvalidSpec", str(exc)) from None


def reads_distribution(run: SimulationRun) -> bool:
    """The run's distribution is one the pods cannot read as a path (a ConfigMap key, s3://): the operator
    reads it and copies it into the Job's ConfigMap."""
    sweep = run.spec.sweep
    return sweep.distribution_config_map_ref is not None or (sweep.distribution or "").startswith("s3://")


def with_copy(run: SimulationRun, path: str) -> SimulationRun:
    """The run whose sweep expands from the operator's copy of its distribution at `path`."""
    sweep = run.spec.sweep
    moved = sweep.model_copy(update={"distribution": path, "distribution_config_map_ref": None})
    return run.model_copy(update={"spec": run.spec.model_copy(update={"sweep": moved})})


def refusal(run: SimulationRun, namespace: str, settings: OperatorSettings) -> Rejected | None:
    """Why the cluster's policy refuses the run, or None: a run that names its own object store names its
    own credentials, and Secrets only where its namespace may. Asked before anything is read for the run
    (its distribution, its Secret, its store): the operator's credentials never go to a store the run
    chose."""
    chosen = run.spec.output.endpoint
    if chosen and not run.spec.output.credentials_secret_ref and chosen != settings.default_s3_endpoint:
        return Rejected(
            "CredentialsRequired",
            f"spec.output.endpoint {chosen!r}: a run that names its own object store must name its "
            "credentials too (spec.output.credentialsSecretRef); the operator's own are only for its "
            "default store",
        )
    named = secret_references(run)
    if named and namespace not in settings.secret_namespaces:
        return Rejected(
            "SecretReferencesNotAllowed",
            f"{named[0]}: runs in namespace {namespace!r} may not name Secrets (the operator's "
            "administrator allows it per namespace: Helm value secretReferences.namespaces)",
        )
    return None


def unfit(run: SimulationRun) -> Rejected | None:
    """Why the run (its distribution read) cannot run on a cluster (builders.check_cluster_spec), or None."""
    try:
        check_cluster_spec(run)
    except CarlosError as exc:
        return Rejected("InvalidSpec", str(exc))
    return None


def owner(obj: Mapping[str, Any], uid: str, run_name: str) -> Literal["ours", "earlier", "foreign"]:
    """Whose an object of the run's deterministic name is: this run's (by uid), an earlier run's of the same
    name (deleted and created again before the garbage collector came), or something else's."""
    owners = (obj.get("metadata") or {}).get("ownerReferences") or []
    if any(o.get("uid") == uid for o in owners):
        return "ours"
    if any(o.get("kind") == "SimulationRun" and o.get("name") == run_name for o in owners):
        return "earlier"
    return "foreign"


def claim(obj: Mapping[str, Any], uid: str, run_name: str, kind: str) -> Rejected | None:
    """What to do with `obj`, an existing `kind` (ConfigMap, Job) of the run's name: None (adopt it: the
    run's own), Waiting (PreviousRunCleanup: an earlier run's, deleted by the caller, uid precondition) or
    Rejected (NameConflict: something else's, never taken over)."""
    name = (obj.get("metadata") or {}).get("name")
    whose = owner(obj, uid, run_name)
    if whose == "ours":
        return None
    if whose == "earlier":
        return Waiting(
            "PreviousRunCleanup",
            f"{kind} {name!r} of an earlier run named {run_name!r} is being deleted; retrying",
        )
    return Rejected(
        "NameConflict",
        f"{kind} {name!r} exists and belongs to something else: delete it or rename the run",
    )


def rejection(previous: Mapping[str, Any], reason: str, message: str, now: str) -> Decision:
    """Not accepted: `Failed` with `Accepted=False` (the reason and the field to fix) and a Warning event."""
    status = {
        "phase": "Failed",
        "conditions": [
            {
                "type": "Accepted",
                "status": "False",
                "reason": reason,
                "message": message,
                "lastTransitionTime": now,
            }
        ],
    }
    return Decision("reject", reason, message, status, (("Warning", reason, message),))


def waiting(
    previous: Mapping[str, Any],
    reason: str,
    message: str,
    now: str,
    *,
    waits: int,
    backoff: float,
    delete: tuple[tuple[str, str, str], ...] = (),
) -> Decision:
    """A prerequisite is missing: `Pending` with the `Prerequisites` condition, a Warning event when its
    reason changes, looked for again after `backoff`·2^`waits` seconds (at most MAX_BACKOFF_S)."""
    conditions = previous.get("conditions") or []
    before = {c.get("type"): c for c in conditions}
    status = {
        **{k: v for k, v in previous.items() if k != "conditions"},
        "phase": "Pending",
        "conditions": [
            *(c for c in conditions if c.get("type") != "Prerequisites"),
            condition(before, "Prerequisites", False, reason, message, now),
        ],
    }
    prior = before.get("Prerequisites")
    events = (("Warning", reason, message),) if prior is None or prior.get("reason") != reason else ()
    return Decision(
        "replace" if delete else "wait",
        reason,
        message,
        status,
        events,
        retry_after=min(backoff * 2**waits, MAX_BACKOFF_S),
        delete=delete,
    )


def _holding(previous: Mapping[str, Any], run: SimulationRun, total: int, now: str) -> dict[str, Any]:
    before = {c.get("type"): c for c in previous.get("conditions") or []}
    return {
        "phase": "Suspended",
        "total": total,
        "jobName": round_job_name(run.name, 0) if run.spec.search is not None else job_name(run.name),
        "conditions": [
            condition(
                before,
                "Accepted",
                True,
                "Held",
                "spec.suspend: the Job is submitted to its Kueue queue when the run is resumed",
                now,
            )
        ],
    }


# --- the decision ------------------------------------------------------------------------------------------


def same_spec(stored: bytes, spec: bytes) -> bool:
    """Whether a stored `run.yaml` holds the spec `spec` (YAML): the same bytes, or the same data written
    otherwise (another version's YAML layout); unreadable is another spec."""
    if stored == spec:
        return True
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    try:
        return bool(yaml.load(stored, Loader=loader) == yaml.load(spec, Loader=loader))
    except yaml.YAMLError:
        return False


def decide(
    run: Mapping[str, Any],
    inputs: RunInputs,
    settings: OperatorSettings,
    *,
    now: str,
    backoff: float = 5.0,
) -> Decision:
    """The decision for the SimulationRun `run` (the object as the API serves it: metadata, spec) from its
    `inputs`, with the operator's `settings`; `now` stamps new conditions, `backoff` is the first wait."""
    status = inputs.status
    if finished(status):
        return Decision("nothing")
    try:
        return _decide(run, inputs, settings, now=now, backoff=backoff)
    except Waiting as exc:
        return waiting(status, exc.reason, exc.message, now, waits=inputs.waits, backoff=backoff)
    except Rejected as exc:
        return rejection(status, exc.reason, exc.message, now)


def _decide(
    body: Mapping[str, Any], inputs: RunInputs, settings: OperatorSettings, *, now: str, backoff: float
) -> Decision:
    namespace = namespace_of(body)
    submitted, output = parse(body, settings)
    run = submitted
    refused = refusal(run, namespace, settings)
    if refused is not None:
        raise refused
    if reads_distribution(run):
        ref = run.spec.sweep.distribution_config_map_ref
        if ref is not None and ref.name in inputs.absent_configmaps:
            raise Waiting(
                "ConfigMapNotFound",
                f"spec.sweep.distributionConfigMapRef: ConfigMap {ref.name!r} not found in namespace "
                f"{namespace!r}; the run starts when it exists",
            )
        if inputs.credentials is not None:  # its s3:// object is read with the run's credentials
            raise Waiting(inputs.credentials.reason, inputs.credentials.message)
        if inputs.distribution_error is not None:
            raise Rejected("InvalidSpec", inputs.distribution_error)
        size = len(inputs.distribution or b"")
        if size > MAX_DISTRIBUTION_BYTES:
            raise Rejected(
                "InvalidSpec",
                f"spec.sweep.distribution: the file is {size:,} bytes; the pods read it from the Job's "
                f"ConfigMap, which holds at most {MAX_DISTRIBUTION_BYTES:,}: split the sweep",
            )
        run = with_copy(run, inputs.distribution_copy or DISTRIBUTION_FILE)
    refused = unfit(run)
    if refused is not None:
        raise refused
    total = run.spec.search.budget if run.spec.search is not None else len(Plan(run.spec))
    for name in scenario_configmaps(run):
        if name in inputs.absent_configmaps:
            position = next(
                i
                for i, scenario in enumerate(run.spec.scenarios)
                if scenario.config_map_ref is not None and scenario.config_map_ref.name == name
            )
            raise Waiting(
                "ConfigMapNotFound",
                f"spec.scenarios[{position}].configMapRef: ConfigMap {name!r} not found in namespace "
                f"{namespace!r}; the run starts when it exists",
            )
    if inputs.credentials is not None:
        raise Waiting(inputs.credentials.reason, inputs.credentials.message)
    search = None
    if run.spec.search is not None and not inputs.search_known:
        if inputs.search_error is not None:
            raise Rejected("InvalidSpec", inputs.search_error)
        search = inputs.search
    accepted: dict[str, Any] = {"run": run, "output": output, "total": total, "search": search}
    status = inputs.status
    if started(status):  # its Job ran: adopt it if it is still there, never create another
        return Decision("adopt", **accepted)
    if held(body, run):
        before = status.get("phase")
        events = (
            ()
            if before == "Suspended"
            else (("Normal", "Suspended", "held: the Job is created when resumed"),)
        )
        return Decision("hold", status=_holding(status, run, total, now), events=events, **accepted)
    spec = manifest_yaml(submitted).encode()
    if inputs.stored_spec is not None and not same_spec(inputs.stored_spec, spec):
        raise Rejected(
            "ResultsExist",
            f"results for run {run.name!r} already exist at {inputs.results_url} with a different spec: "
            "choose another metadata.name (or metadata.generateName)",
        )
    to_store = spec if inputs.stored_spec is None else None
    if run.spec.search is not None:  # a search creates one ConfigMap and Job per round (searching.py)
        return Decision("search", spec=to_store, **accepted)
    distribution = (
        inputs.distribution.decode()
        if reads_distribution(submitted) and inputs.distribution is not None
        else None
    )
    configmap = build_configmap(submitted, dict(body), settings, distribution, spec_yaml=spec.decode())
    job = build_job(run, dict(body), settings, output)
    uid = str(body["metadata"].get("uid"))
    objects: list[Wanted] = []
    earlier: list[tuple[str, str, str]] = []
    for kind, wanted, existing in (("ConfigMap", configmap, inputs.configmap), ("Job", job, inputs.job)):
        if existing is None:
            event = None
            if kind == "Job":
                message = (
                    f"Job {job['metadata']['name']} with {plural(total, 'run')} "
                    f"(parallelism {job['spec']['parallelism']})"
                )
                event = ("Normal", "JobCreated", message)
            objects.append(Wanted(kind, wanted, None, event))
            continue
        verdict = claim(existing, uid, run.name, kind)
        if verdict is None:
            objects.append(Wanted(kind, wanted, existing))
        elif isinstance(verdict, Waiting):
            earlier.append((kind, str(existing["metadata"]["name"]), str(existing["metadata"].get("uid"))))
        else:
            raise verdict
    if earlier:
        kinds = " and ".join(kind for kind, _, _ in earlier)
        verb = "is" if len(earlier) == 1 else "are"
        message = (
            f"{kinds} {earlier[0][1]!r} of an earlier run named {run.name!r} {verb} being deleted; retrying"
        )
        return waiting(
            inputs.status,
            "PreviousRunCleanup",
            message,
            now,
            waits=inputs.waits,
            backoff=backoff,
            delete=tuple(earlier),
        )
    action: Action = "create" if any(o.existing is None for o in objects) else "adopt"
    return Decision(action, spec=to_store, objects=tuple(objects), **accepted)
