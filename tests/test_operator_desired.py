"""The controller's decision for a run without its objects (desired.decide), pure: plain dicts in, a Decision
out, no API server and no object store. One case per outcome: not accepted, waiting with backoff, an earlier
run's objects replaced, something else's refused, held for Kueue, adopted, created, finished, a search; and
the one answer only the writes can know (a 409 on create), decided by the same rule."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml
from carlos_operator.builders import DISTRIBUTION_FILE, SPEC_FILE, OperatorSettings, job_name, round_job_name
from carlos_operator.desired import (
    MAX_BACKOFF_S,
    MAX_DISTRIBUTION_BYTES,
    Decision,
    RunInputs,
    Waiting,
    claim,
    decide,
)

from tests.test_operator_controller import (  # _scratch_removed: its controllers' scratch folders go too
    FakeKube,
    FakeStore,
    _scratch_removed,  # noqa: F401
    controller,
    drain,
    run_body,
    search_body,
)

NOW = "2026-11-29T00:00:00Z"
SETTINGS = OperatorSettings.from_env({"CARLOS_SECRET_NAMESPACES": "default"})
DISTRIBUTION = b"""<OpenSCENARIO><ParameterValueDistribution><ScenarioFile filepath="s.xosc"/><Deterministic>
<DeterministicSingleParameterDistribution parameterName="Speed"><DistributionSet>
<Element value="20"/><Element value="25"/><Element value="30"/></DistributionSet>
</DeterministicSingleParameterDistribution></Deterministic></ParameterValueDistribution></OpenSCENARIO>
"""


class Untouchable:
    """An object store `decide` must never call (it is a handle for the writes)."""

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"decide called the store's {name}")


def inputs(**facts: Any) -> RunInputs:
    return RunInputs(**{"store": Untouchable(), "results_url": "s3://bucket/out/default/r", **facts})


def decision(body: dict[str, Any], settings: OperatorSettings = SETTINGS, **facts: Any) -> Decision:
    return decide(body, inputs(**facts), settings, now=NOW, backoff=5.0)


def owned(name: str, uid: str, run: str = "r", kind: str = "SimulationRun") -> dict[str, Any]:
    return {
        "metadata": {
            "name": name,
            "uid": f"object-of-{uid}",
            "ownerReferences": [{"kind": kind, "name": run, "uid": uid}],
        }
    }


def condition(d: Decision, kind: str) -> dict[str, Any]:
    assert d.status is not None
    return next(c for c in d.status["conditions"] if c["type"] == kind)


def test_a_new_run_gets_its_configmap_and_job_and_its_spec_stored() -> None:
    d = decision(run_body("r", "uid-1", 3))
    assert d.action == "create" and d.total == 3 and d.status is None and d.events == ()
    assert [(o.kind, o.body["metadata"]["name"], o.existing) for o in d.objects] == [
        ("ConfigMap", job_name("r"), None),
        ("Job", job_name("r"), None),
    ]
    configmap, job = (o.body for o in d.objects)
    assert job["spec"]["completions"] == 3 and job["metadata"]["ownerReferences"][0]["uid"] == "uid-1"
    assert yaml.safe_load(d.spec or b"")["metadata"]["name"] == "r"
    assert yaml.safe_load(configmap["data"][SPEC_FILE]) == yaml.safe_load(d.spec or b"")
    # the event is the Job's, posted only when the writes create it
    assert d.objects[0].event is None
    assert d.objects[1].event == ("Normal", "JobCreated", f"Job {job_name('r')} with 3 runs (parallelism 3)")
    # pure: the same inputs give the same decision
    assert decision(run_body("r", "uid-1", 3)) == d


def test_an_invalid_spec_is_rejected_with_the_field_to_fix() -> None:
    body = run_body("r", "uid-1", 3)
    body["spec"]["sweep"] = {"repetitions": 0}
    d = decision(body)
    assert (d.action, d.reason, d.objects, d.spec) == ("reject", "InvalidSpec", (), None)
    assert d.status is not None and d.status["phase"] == "Failed"
    accepted = condition(d, "Accepted")
    assert accepted["status"] == "False" and "repetitions" in accepted["message"]
    assert d.events == (("Warning", "InvalidSpec", d.message),)


@pytest.mark.parametrize(
    ("output", "reason"),
    [
        ({"url": "s3://bucket/out", "endpoint": "https://elsewhere.example"}, "CredentialsRequired"),
        ({"url": "s3://bucket/out", "credentialsSecretRef": {"name": "s3"}}, "SecretReferencesNotAllowed"),
        ({"url": "/tmp/out"}, "InvalidSpec"),
    ],
)
def test_what_the_cluster_does_not_allow_is_rejected(output: dict[str, Any], reason: str) -> None:
    body = run_body("r", "uid-1", 1)
    body["spec"]["output"] = output
    d = decision(body, OperatorSettings.from_env({}))  # no namespace may name Secrets
    assert (d.action, d.reason) == ("reject", reason)


def test_a_missing_secret_is_waited_for_with_backoff() -> None:
    missing = Waiting("SecretNotFound", "spec.output.credentialsSecretRef: Secret 's3' not found")
    d = decision(run_body("r", "uid-1", 3), credentials=missing)
    assert (d.action, d.reason, d.retry_after, d.objects, d.spec) == ("wait", "SecretNotFound", 5.0, (), None)
    assert d.status is not None and d.status["phase"] == "Pending"
    prerequisites = condition(d, "Prerequisites")
    assert prerequisites["status"] == "False" and prerequisites["message"] == missing.message
    assert d.events == (("Warning", "SecretNotFound", missing.message),)
    # the third wait in a row: 5 s · 2², one event per reason (the condition shows it already)
    again = decision(run_body("r", "uid-1", 3), credentials=missing, waits=2, status=d.status)
    assert again.retry_after == 20.0 and again.events == ()
    assert condition(again, "Prerequisites")["lastTransitionTime"] == NOW
    assert decision(run_body("r", "uid-1", 3), credentials=missing, waits=30).retry_after == MAX_BACKOFF_S


def test_a_missing_configmap_is_waited_for_naming_its_field() -> None:
    body = run_body("r", "uid-1", 1)
    body["spec"]["scenarios"] = [{"name": "s", "configMapRef": {"name": "scenarios", "key": "s.xosc"}}]
    d = decision(body, absent_configmaps=("scenarios",))
    assert (d.action, d.reason) == ("wait", "ConfigMapNotFound")
    assert "spec.scenarios[0].configMapRef" in d.message and "'scenarios'" in d.message
    body["spec"]["sweep"]["distributionConfigMapRef"] = {"name": "d-inputs", "key": "d.xosc"}
    d = decision(body, absent_configmaps=("d-inputs",))
    assert (d.action, d.reason) == ("wait", "ConfigMapNotFound")
    assert "spec.sweep.distributionConfigMapRef" in d.message


def test_a_missing_configmap_names_the_position_of_its_scenario_among_all_scenarios() -> None:
    body = run_body("r", "uid-1", 1)
    body["spec"]["scenarios"] = [
        {"name": "a", "openscenario": "s3://bucket/a.xosc"},
        {"name": "b", "configMapRef": {"name": "present", "key": "b.xosc"}},
        {"name": "c", "configMapRef": {"name": "absent", "key": "c.xosc"}},
    ]
    d = decision(body, absent_configmaps=("absent",))
    assert (d.action, d.reason) == ("wait", "ConfigMapNotFound")
    assert "spec.scenarios[2].configMapRef" in d.message and "'absent'" in d.message


def test_objects_of_this_run_are_adopted() -> None:
    name = job_name("r")
    d = decision(run_body("r", "uid-1", 3), configmap=owned(name, "uid-1"), job=owned(name, "uid-1"))
    assert d.action == "adopt" and [o.existing for o in d.objects] == [owned(name, "uid-1")] * 2
    # its Job exists, its ConfigMap is gone: the ConfigMap is created, the Job adopted
    d = decision(run_body("r", "uid-1", 3), job=owned(name, "uid-1"))
    assert d.action == "create"
    assert [(o.kind, o.existing is None) for o in d.objects] == [("ConfigMap", True), ("Job", False)]


def test_objects_of_an_earlier_run_of_the_same_name_are_deleted_then_waited_for() -> None:
    name = job_name("r")
    d = decision(run_body("r", "uid-2", 3), configmap=owned(name, "uid-1"), job=owned(name, "uid-1"))
    assert (d.action, d.reason, d.objects, d.spec) == ("replace", "PreviousRunCleanup", (), None)
    assert d.delete == (("ConfigMap", name, "object-of-uid-1"), ("Job", name, "object-of-uid-1"))
    assert d.retry_after == 5.0 and condition(d, "Prerequisites")["reason"] == "PreviousRunCleanup"
    d = decision(run_body("r", "uid-2", 3), job=owned(name, "uid-1"))
    assert d.delete == (("Job", name, "object-of-uid-1"),) and d.message.startswith(f"Job {name!r}")


def test_objects_of_something_else_are_never_taken_over() -> None:
    name = job_name("r")
    foreign = owned(name, "w", run="x", kind="Workflow")
    d = decision(run_body("r", "uid-1", 3), job=foreign, configmap=owned(name, "uid-0"))
    assert (d.action, d.reason, d.delete) == ("reject", "NameConflict", ())
    assert d.message.startswith(f"Job {name!r} exists and belongs to something else")


def test_claim_is_the_rule_for_an_object_found_by_a_409() -> None:
    assert claim(owned("o", "uid-1"), "uid-1", "r", "Job") is None
    earlier = claim(owned("o", "uid-0"), "uid-1", "r", "Job")
    assert isinstance(earlier, Waiting) and earlier.reason == "PreviousRunCleanup"
    foreign = claim(owned("o", "uid-0", run="other"), "uid-1", "r", "ConfigMap")
    assert foreign is not None and not isinstance(foreign, Waiting) and foreign.reason == "NameConflict"


def test_a_suspended_run_with_a_queue_is_held_without_a_job() -> None:
    body = run_body("r", "uid-1", 3)
    body["spec"]["suspend"] = True
    body["spec"]["execution"] = {"queueName": "team-a", "runsPerPod": 1}
    d = decision(body)
    assert (d.action, d.objects, d.spec) == ("hold", (), None)
    assert d.status is not None and (d.status["phase"], d.status["total"], d.status["jobName"]) == (
        "Suspended",
        3,
        job_name("r"),
    )
    assert condition(d, "Accepted")["reason"] == "Held"
    assert d.events == (("Normal", "Suspended", "held: the Job is created when resumed"),)
    assert decision(body, status=d.status).events == ()  # already shown
    body["spec"]["suspend"] = False  # resumed: the Job is created (suspended: Kueue admits it)
    d = decision(body)
    assert d.action == "create" and d.objects[1].body["spec"]["suspend"] is True


@pytest.mark.parametrize(
    "status",
    [
        {"phase": "Succeeded"},
        {"phase": "Failed"},
        {"phase": "Unknown"},
        {"phase": "Failed", "conditions": [{"type": "Accepted", "status": "False", "reason": "InvalidSpec"}]},
    ],
)
def test_a_finished_run_gets_nothing(status: dict[str, Any]) -> None:
    assert decision(run_body("r", "uid-1", 3), status=status) == Decision("nothing")


def test_a_run_whose_job_started_is_adopted_never_given_a_second_job() -> None:
    running = {"phase": "Running", "startTime": "2026-01-01T00:00:00Z"}
    d = decision(run_body("r", "uid-1", 3), status=running)
    assert (d.action, d.objects, d.spec, d.total) == ("adopt", (), None, 3)


def test_results_of_another_spec_under_the_name_are_not_overwritten() -> None:
    d = decision(run_body("r", "uid-1", 3), stored_spec=b"something else\n")
    assert (d.action, d.reason) == ("reject", "ResultsExist")
    assert "s3://bucket/out/default/r" in d.message
    same = decision(run_body("r", "uid-1", 3)).spec
    d = decision(run_body("r", "uid-1", 3), stored_spec=same)
    assert d.action == "create" and d.spec is None  # stored already: not written again
    # the same spec in another YAML layout (another version's writer): the same spec
    assert same is not None
    import yaml

    relaid = yaml.safe_dump(yaml.safe_load(same), width=20, default_flow_style=True).encode()
    assert relaid != same
    d = decision(run_body("r", "uid-1", 3), stored_spec=relaid)
    assert d.action == "create" and d.spec is None
    d = decision(run_body("r", "uid-1", 3), stored_spec=b"{unclosed: [")
    assert (d.action, d.reason) == ("reject", "ResultsExist")


def test_a_search_gets_its_spec_stored_and_no_configmap_or_job() -> None:
    from carlos_operator.runstate import SearchProgress

    progress = SearchProgress(scenario_name="cut-in.xosc", space=[])
    d = decision(search_body("s", "uid-1"), search=progress)
    assert (d.action, d.objects, d.total, d.search) == ("search", (), 6, progress)
    assert d.spec is not None and b"search:" in d.spec
    assert decision(search_body("s", "uid-1"), search_known=True).search is None  # read before: kept
    bad = decision(search_body("s", "uid-1"), search_error="spec.scenarios[0].openscenario: cannot read")
    assert (bad.action, bad.reason) == ("reject", "InvalidSpec")
    held = search_body("s", "uid-1")
    held["spec"]["suspend"] = True
    held["spec"]["execution"]["queueName"] = "team-a"
    d = decision(held, search=progress)
    assert d.action == "hold" and d.status is not None and d.status["jobName"] == round_job_name("s", 0)


def test_a_distribution_the_operator_read_is_counted_and_handed_to_the_pods(tmp_path: Path) -> None:
    body = run_body("d", "uid-1", 2)
    body["spec"]["sweep"]["distributionConfigMapRef"] = {"name": "d-inputs", "key": "speeds.xosc"}
    copy = tmp_path / DISTRIBUTION_FILE
    copy.write_bytes(DISTRIBUTION)
    d = decision(body, distribution=DISTRIBUTION, distribution_copy=str(copy))
    assert d.action == "create" and d.total == 6  # 3 speeds × 2 repetitions
    configmap, job = (o.body for o in d.objects)
    assert configmap["data"][DISTRIBUTION_FILE] == DISTRIBUTION.decode()
    assert job["spec"]["completions"] == 6
    # the results keep the spec as submitted
    assert yaml.safe_load(d.spec or b"")["spec"]["sweep"]["distributionConfigMapRef"]["name"] == "d-inputs"
    unreadable = decision(body, distribution_error="ConfigMap 'd-inputs' has no key 'speeds.xosc'")
    assert (unreadable.action, unreadable.reason) == ("reject", "InvalidSpec")
    large = decision(body, distribution=b"x" * (MAX_DISTRIBUTION_BYTES + 1))
    assert (large.action, large.reason) == ("reject", "InvalidSpec") and "split the sweep" in large.message


# --- the writes: what only a create can tell ----------------------------------------------------------------


class RacingKube(FakeKube):
    """The run's Job appears between the controller's read and its create (another pass, a lost answer):
    the create is answered 409."""

    def __init__(self, owner_uid: str) -> None:
        super().__init__()
        self.owner_uid = owner_uid

    def create_job(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        if body["metadata"]["name"] not in self.jobs:
            raced = json.loads(json.dumps(body))
            raced["metadata"]["uid"] = "raced"
            raced["metadata"]["ownerReferences"][0]["uid"] = self.owner_uid
            self.jobs[body["metadata"]["name"]] = raced
        return super().create_job(namespace, body)


def test_a_job_that_appears_before_the_create_is_adopted_when_it_is_the_runs() -> None:
    kube, store = RacingKube("uid-1"), FakeStore()
    c = controller(kube, store)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    assert kube.job_creates == 1 and kube.jobs[job_name("r")]["metadata"]["uid"] == "raced"
    assert c.runs[("default", "r")].ensured and ("Normal", "JobCreated") not in kube.events
    assert kube.status_patches[-1]["phase"] == "Pending"


def test_a_job_of_an_earlier_run_that_appears_before_the_create_is_deleted_and_waited_for() -> None:
    kube, store = RacingKube("uid-0"), FakeStore()
    c = controller(kube, store, backoff=600)
    c.observe_run("ADDED", run_body("r", "uid-1", 3))
    drain(c)
    assert kube.deleted == [("Job", job_name("r"), "raced")] and kube.jobs == {}
    assert not c.runs[("default", "r")].ensured
    waiting = next(x for x in kube.status_patches[-1]["conditions"] if x["type"] == "Prerequisites")
    assert waiting["reason"] == "PreviousRunCleanup"


def test_a_run_refused_by_the_policy_gets_nothing_read_for_it_not_even_its_distribution() -> None:
    """A run naming its own endpoint without its own credentials is refused before the operator reads its
    s3:// distribution: the operator's credentials never go to that endpoint."""
    kube, store = FakeKube(), FakeStore()
    store.put_bytes("inputs/speeds.xosc", DISTRIBUTION)
    body = run_body("d", "uid-1", 1)
    body["spec"]["output"] = {"url": "s3://bucket/out", "endpoint": "https://elsewhere.example"}
    body["spec"]["sweep"]["distribution"] = "s3://bucket/inputs/speeds.xosc"
    c = controller(kube, store)
    c.observe_run("ADDED", body)
    drain(c)
    assert kube.status_patches[-1]["conditions"][0]["reason"] == "CredentialsRequired"
    assert store.opened == 0 and store.gets == 0 and kube.jobs == {}


def test_a_search_rounds_objects_are_claimed_by_the_same_rule() -> None:
    """A round's Job of the run's name that is something else's refuses the run (NameConflict), as a plain
    run's; one of an earlier run of the same name is deleted and waited for, then the round starts."""
    from tests.test_operator_controller import search_kube

    name = round_job_name("s", 0)
    kube, store = search_kube(), FakeStore()
    kube.jobs[name] = owned(name, "w", run="x", kind="Workflow")
    c = controller(kube, store)
    c.observe_run("ADDED", search_body("s", "uid-1"))
    drain(c)
    rejected = kube.status_patches[-1]
    assert rejected["phase"] == "Failed" and rejected["conditions"][0]["reason"] == "NameConflict"
    assert kube.jobs[name]["metadata"]["ownerReferences"][0]["kind"] == "Workflow"
    kube, store = search_kube(), FakeStore()
    kube.jobs[name] = owned(name, "uid-0", run="s")
    c = controller(kube, store, backoff=600)
    c.observe_run("ADDED", search_body("s", "uid-1"))
    drain(c)
    assert kube.deleted == [("Job", name, "object-of-uid-0")]
    reason = next(x for x in kube.status_patches[-1]["conditions"] if x["type"] == "Prerequisites")["reason"]
    assert reason == "PreviousRunCleanup"
    c.enqueue(("default", "s"))
    drain(c)
    assert kube.jobs[name]["metadata"]["ownerReferences"][0]["uid"] == "uid-1"
