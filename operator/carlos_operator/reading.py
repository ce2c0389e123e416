"""Read every input of a run once, for controller.ensure: the first of its three steps (read, decide, apply).

`read_inputs` reads in the order desired.decide looks at the inputs and stops at the first one that is
missing or unusable (what comes after it would not be looked at): the run's distribution file (its
ConfigMap, then the file; its local copy is written here), the ConfigMaps its scenarios name, its object
store (opening it reads the Secret the run names, where its namespace may name Secrets), a search's scenario,
then, for a run whose Job is still to be made, the stored `run.yaml` and the Job of its name as the operator's
Job watch holds it (no request: a Job or ConfigMap of the run's name that is not known there is met by the
create's 409, which apply.create_owned settles by the same rule, desired.claim).
The cluster's policy (desired.refusal) is asked before anything is read: a run it refuses gets no distribution,
Secret or store read for it, so the operator's credentials never reach a store the run chose. Nothing is read
for a run whose status is final or whose spec is invalid, and no store opened for one that cannot run on a
cluster (desired.unfit).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from carlos_operator.builders import DISTRIBUTION_FILE, Output, job_name, scenario_configmaps
from carlos_operator.desired import (
    MAX_DISTRIBUTION_BYTES,
    Rejected,
    RunInputs,
    Waiting,
    finished,
    held,
    namespace_of,
    parse,
    reads_distribution,
    refusal,
    started,
    unfit,
    with_copy,
)
from carlos_operator.inputs import read_input
from carlos_operator.kube import NotFound
from carlos_operator.runstate import RunState, SearchProgress
from simcore.errors import CarlosError
from simcore.spec import SimulationRun

if TYPE_CHECKING:
    from carlos_operator.hosting import Host

#: reads a search's scenario into its progress: (run, output, namespace) → SearchProgress, or CarlosError
PrepareSearch = Callable[[SimulationRun, Output, str], SearchProgress]


def read_inputs(c: Host, state: RunState, *, prepare_search: PrepareSearch) -> RunInputs:
    """The inputs of the run `state` holds (see the module's docstring for what is read, in which order)."""
    status = state.last_status
    found: dict[str, Any] = {"status": status, "waits": state.waits, "search_known": state.search is not None}
    if finished(status):
        return RunInputs(**found)
    body = state.body
    try:
        run, output = parse(body, c.settings)
    except Rejected:
        return RunInputs(**found)
    namespace = namespace_of(body)
    if refusal(run, namespace, c.settings) is not None:
        return RunInputs(**found)
    if reads_distribution(run):
        found.update(_distribution(c, run, namespace, output))
        if "distribution" not in found:
            return RunInputs(**found)
        if found.get("distribution_copy"):
            run = with_copy(run, found["distribution_copy"])
    if unfit(run) is not None:
        return RunInputs(**found)
    for name in scenario_configmaps(run):
        if _get(c.kube.read_configmap, namespace, name) is None:
            return RunInputs(**found, absent_configmaps=(name,))
    # the operator reads a Secret only where allowed; elsewhere its own credentials reach its default store
    allowed = namespace in c.settings.secret_namespaces
    try:
        store = c.store_factory(
            c.kube, namespace, output if allowed else dataclasses.replace(output, secret=None)
        )
    except Waiting as exc:
        return RunInputs(**found, credentials=exc)
    found.update(store=store, results_url=store.url_for(run.name))
    if run.spec.search is not None and state.search is None:
        try:
            found["search"] = prepare_search(run, output, namespace)
        except Waiting as exc:
            return RunInputs(**found, credentials=exc)
        except CarlosError as exc:
            return RunInputs(**found, search_error=str(exc))
    if started(status) or held(body, run):
        return RunInputs(**found)
    run_yaml = f"{run.name}/run.yaml"
    if store.exists(run_yaml):
        found["stored_spec"] = bytes(store.get_bytes(run_yaml))
    if run.spec.search is None:  # a search's ConfigMaps and Jobs are its rounds' (searching.py)
        with c._lock:
            found["job"] = c.jobs.get((namespace, job_name(run.name)))
    return RunInputs(**found)


def _get(read: Callable[[str, str], dict[str, Any]], namespace: str, name: str) -> dict[str, Any] | None:
    try:
        return read(namespace, name)
    except NotFound:
        return None


def _distribution(c: Host, run: SimulationRun, namespace: str, output: Output) -> dict[str, Any]:
    """A distribution the pods cannot read as a path (a ConfigMap key, s3://): its bytes and the operator's
    local copy (`distribution`, `distribution_copy`), or why it cannot be had (no `distribution` then)."""
    sweep = run.spec.sweep
    ref = sweep.distribution_config_map_ref
    configmap = None
    if ref is not None:
        configmap = _get(c.kube.read_configmap, namespace, ref.name)
        if configmap is None:
            return {"absent_configmaps": (ref.name,)}
    try:
        _, data = read_input(
            c,
            namespace,
            output,
            ref=ref,
            source=sweep.distribution,
            field="spec.sweep.distribution",
            ref_field="spec.sweep.distributionConfigMapRef",
            why="to expand the sweep",
            configmap=configmap,
        )
        data.decode("utf-8")
    except UnicodeDecodeError:
        return {"distribution_error": "spec.sweep.distribution: the file is not UTF-8 text"}
    except Waiting as exc:  # an s3:// object, read with the run's credentials
        return {"credentials": exc}
    except CarlosError as exc:
        return {"distribution_error": str(exc)}
    found: dict[str, Any] = {"distribution": data}
    if len(data) <= MAX_DISTRIBUTION_BYTES:  # a larger one is refused (desired.decide): no copy is kept
        local = c.scratch.folder(namespace, run.name) / DISTRIBUTION_FILE
        local.write_bytes(data)
        found["distribution_copy"] = str(local)
    return found
