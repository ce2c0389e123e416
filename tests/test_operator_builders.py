"""Pure parts of the operator: ConfigMap/Job builders, settings and status aggregation."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from carlos_operator.builders import (
    BUS_PORT,
    QUEUE_LABEL,
    RECORDER_READY_PORT,
    ROUND_LABEL,
    SPEC_FILE,
    OperatorSettings,
    SearchRound,
    build_configmap,
    build_job,
    build_round_configmap,
    check_cluster_spec,
    job_name,
    resolve_output,
    round_job_name,
)
from carlos_operator.searching import round_of, round_step, search_status
from carlos_operator.status import (
    Tally,
    aggregate,
    count_intervals,
    format_intervals,
    iter_intervals,
    parse_intervals,
)

from simcore.errors import BadInput
from simcore.manifest import parse_manifest
from simcore.spec import SimulationRun
from tests.apiserver import Invalid, admit

SETTINGS = OperatorSettings.from_env(
    {
        "CARLOS_IMAGE_SIMCORE": "reg/simcore:1",
        "CARLOS_IMAGE_BRIDGE": "reg/bridge:1",
        "CARLOS_IMAGE_RECORDER": "reg/recorder:1",
        "CARLOS_IMAGE_PULL_SECRETS": "pull-a, pull-b",
        "CARLOS_DEFAULT_OUTPUT_URL": "s3://results/runs",
        "CARLOS_DEFAULT_S3_ENDPOINT": "http://minio:9000",
        "CARLOS_DEFAULT_S3_SECRET": "s3-creds",
        "CARLOS_IMAGE_BRIDGE_PULL_POLICY": "Always",
    }
)


def manifest(**spec: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "scenarios": [
            {"name": "a", "openscenario": "s3://bucket/a.xosc"},
            {"name": "b", "configMapRef": {"name": "scenarios", "key": "b.xosc"}},
        ],
        "sweep": {"matrix": {"speed": [10, 20, 30]}, "repetitions": 2},
        "execution": {"parallelism": 4, "retries": 2, "timeoutSeconds": 600, "runsPerPod": 1},
    }
    base.update(spec)
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": "sweep", "namespace": "sims", "uid": "uid-1"},
        "spec": base,
    }


def load(body: dict[str, Any]) -> SimulationRun:
    return parse_manifest(copy.deepcopy(body), source="test")


def test_settings_defaults_name_the_package_version() -> None:
    settings = OperatorSettings.from_env({})
    assert settings.image_simcore.startswith("ghcr.io/carlos-sim/carlos-simcore:")
    assert settings.image_bridge.startswith("ghcr.io/carlos-sim/carlos-bridge:")
    assert settings.image_pull_secrets == ()
    assert settings.default_output_url is None
    assert SETTINGS.image_pull_secrets == ("pull-a", "pull-b")


def test_configmap_holds_the_spec_not_the_permutations() -> None:
    body = manifest(sweep={"matrix": {"a": list(range(100)), "b": list(range(500))}})
    run = load(body)
    cm = build_configmap(run, body, SETTINGS)
    assert cm["metadata"]["name"] == job_name("sweep")
    assert cm["metadata"]["ownerReferences"][0]["uid"] == "uid-1"
    text = cm["data"]["simulationrun.yaml"]
    assert len(text) < 10_000  # 2 × 50,000 runs, still a small spec
    again = parse_manifest(yaml.safe_load(text), source="cm")
    assert again.spec == run.spec and again.name == "sweep"


def test_job_is_an_indexed_job_with_the_failure_policy() -> None:
    body = manifest()
    run = load(body)
    job = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))
    spec = job["spec"]
    assert job["metadata"]["name"] == job_name("sweep") and job["metadata"]["namespace"] == "sims"
    owner = job["metadata"]["ownerReferences"][0]
    assert owner["kind"] == "SimulationRun" and owner["controller"] is True
    assert spec["completionMode"] == "Indexed"
    assert spec["completions"] == 2 * 3 * 2 and spec["parallelism"] == 4
    assert spec["backoffLimitPerIndex"] == 2
    assert spec["suspend"] is False
    assert spec["ttlSecondsAfterFinished"] > 0 and spec["activeDeadlineSeconds"] > 600
    rules = spec["podFailurePolicy"]["rules"]
    by_action = {r["action"]: r for r in rules}
    assert by_action["FailJob"]["onExitCodes"]["values"] == [2]  # bad input: the same for every index
    assert by_action["FailIndex"]["onExitCodes"]["values"] == [1]
    assert by_action["Count"]["onExitCodes"]["values"] == [3]
    assert [r["action"] for r in rules][:2] == ["FailJob", "FailIndex"]
    assert "maxFailedIndexes" not in spec
    assert all(r["onExitCodes"]["containerName"] == "simcore" for r in rules if "onExitCodes" in r)
    pod = spec["template"]["spec"]
    assert pod["restartPolicy"] == "Never" and pod["automountServiceAccountToken"] is False
    assert pod["activeDeadlineSeconds"] == 600 + 300
    assert pod["securityContext"]["runAsNonRoot"] is True
    ids = {k: pod["securityContext"][k] for k in ("runAsUser", "runAsGroup", "fsGroup")}
    assert ids == {"runAsUser": 10001, "runAsGroup": 10001, "fsGroup": 10001}  # the images' user
    for absent in ("nodeSelector", "tolerations", "affinity", "priorityClassName", "serviceAccountName"):
        assert absent not in pod
    assert pod["securityContext"]["seccompProfile"] == {"type": "RuntimeDefault"}
    assert [c["name"] for c in pod["initContainers"]] == ["bridge", "recorder"]
    assert [c["name"] for c in pod["containers"]] == ["simcore"]
    assert pod["imagePullSecrets"] == [{"name": "pull-a"}, {"name": "pull-b"}]
    ports = {c["name"]: c["startupProbe"]["tcpSocket"]["port"] for c in pod["initContainers"]}
    assert ports == {"bridge": BUS_PORT, "recorder": RECORDER_READY_PORT}
    images = {c["name"]: c["image"] for c in [*pod["initContainers"], *pod["containers"]]}
    assert images == {"bridge": "reg/bridge:1", "recorder": "reg/recorder:1", "simcore": "reg/simcore:1"}
    policies = {c["name"]: c["imagePullPolicy"] for c in [*pod["initContainers"], *pod["containers"]]}
    assert policies == {"bridge": "Always", "recorder": "IfNotPresent", "simcore": "IfNotPresent"}
    volumes = {v["name"]: v for v in pod["volumes"]}
    assert volumes["spec"]["configMap"]["name"] == job_name("sweep")
    assert "emptyDir" in volumes["scratch"] and volumes["scenarios-0"]["configMap"]["name"] == "scenarios"
    for container in [*pod["initContainers"], *pod["containers"]]:
        assert container["args"] == ["pod", "--role", container["name"]]
        sc = container["securityContext"]
        assert sc["readOnlyRootFilesystem"] and not sc["allowPrivilegeEscalation"]
        assert sc["capabilities"] == {"drop": ["ALL"]} and sc["runAsNonRoot"]
        assert container["envFrom"] == [{"secretRef": {"name": "s3-creds"}}]
        env = {e["name"]: e for e in container["env"]}
        assert not any("SECRET" in name or "ACCESS_KEY" in name for name in env)
        assert env["CARLOS_OUTPUT_URL"]["value"] == "s3://results/runs"
        assert env["AWS_ENDPOINT_URL"]["value"] == "http://minio:9000"
        assert env["CARLOS_SPEC"]["value"] == "/etc/carlos/spec/simulationrun.yaml"
        assert "job-completion-index" in env["JOB_COMPLETION_INDEX"]["valueFrom"]["fieldRef"]["fieldPath"]
        mounts = {m["mountPath"] for m in container["volumeMounts"]}
        assert {"/etc/carlos/spec", "/scratch", "/tmp", "/etc/carlos/scenarios/scenarios"} <= mounts
    for sidecar in pod["initContainers"]:
        assert sidecar["restartPolicy"] == "Always"


def test_suspend_and_kueue() -> None:
    body = manifest(suspend=True)
    run = load(body)
    assert build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))["spec"]["suspend"] is True
    body = manifest(execution={"queueName": "team-a"})
    run = load(body)
    job = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))
    assert job["spec"]["suspend"] is True
    assert job["metadata"]["labels"][QUEUE_LABEL] == "team-a"
    assert QUEUE_LABEL not in job["spec"]["template"]["metadata"]["labels"]


def test_output_and_cluster_checks() -> None:
    run = load(manifest(output={"url": "s3://own/prefix", "credentialsSecretRef": {"name": "mine"}}))
    out = resolve_output(run, SETTINGS)
    assert (out.url, out.secret, out.endpoint) == ("s3://own/prefix", "mine", "http://minio:9000")
    with pytest.raises(BadInput, match=r"spec.output.url.*s3://"):
        resolve_output(load(manifest(output={"url": "file:///data"})), SETTINGS)
    with pytest.raises(BadInput, match="CARLOS_DEFAULT_OUTPUT_URL"):
        resolve_output(load(manifest()), OperatorSettings.from_env({}))
    with pytest.raises(BadInput, match=r"spec.scenarios\[0\].openscenario"):
        check_cluster_spec(load(manifest(scenarios=[{"name": "a", "openscenario": "rel/a.xosc"}])))
    with pytest.raises(BadInput, match="100,000"):
        check_cluster_spec(load(manifest(sweep={"matrix": {"a": list(range(1000)), "b": list(range(101))}})))
    check_cluster_spec(load(manifest()))
    check_cluster_spec(load(search_manifest()))  # a search runs on the cluster (in rounds)


def test_job_names_are_deterministic_and_short() -> None:
    long = "a" * 63
    assert job_name(long) == job_name(long) and len(job_name(long)) <= 48
    assert job_name(long) != job_name("a" * 62 + "b")
    assert job_name("run") == "carlos-run"


def test_intervals() -> None:
    assert parse_intervals("0-4,7,9-10") == [(0, 4), (7, 7), (9, 10)]
    assert count_intervals("0-4,7,9-10") == 8 and count_intervals(None) == 0
    assert list(iter_intervals("1,3-4")) == [1, 3, 4]
    assert format_intervals([0, 1, 2, 5, 7, 8]) == "0-2,5,7-8"


def summary(index: int, status: str, optional: bool = False) -> dict[str, Any]:
    return {
        "index": index,
        "scenario": "s",
        "status": status,
        "optional": optional,
        "error": "boom" if status == "error" else None,
        "criteria": [{"name": "minDistance >= 2", "passed": status != "failed", "optional": False}],
    }


def job(
    completed: str = "", failed: str = "", active: int = 0, finished: str | None = None
) -> dict[str, Any]:
    status: dict[str, Any] = {"completedIndexes": completed, "failedIndexes": failed, "active": active}
    status["startTime"] = "2026-01-01T00:00:00Z"
    if finished:
        status["conditions"] = [{"type": finished, "status": "True", "reason": "FailedIndexes"}]
    return {"spec": {"suspend": False}, "status": status}


def test_aggregate_phases_and_counts() -> None:
    tally = Tally(4)
    now = "2026-01-01T00:01:00Z"
    st = aggregate(total=4, job=None, tally=tally, results_url="s3://r/x", now=now)
    assert st["phase"] == "Pending" and st["progress"] == "0/4"
    st = aggregate(total=4, job=job(completed="0", active=2), tally=tally, results_url="s3://r/x", now=now)
    assert st["phase"] == "Running" and st["active"] == 2 and st["succeeded"] == 1
    tally.record(summary(0, "passed"))
    tally.record(summary(0, "passed"))  # idempotent
    tally.record(summary(1, "failed"))
    tally.record(summary(2, "passed"))
    finished = job(completed="0,2-3", failed="1", finished="Failed")
    st = aggregate(total=4, job=finished, tally=tally, results_url="s3://r/x", now=now, previous=st)
    assert st["phase"] == "Running"  # index 3's summary not read yet
    assert tally.unknown_among("0,2-3", 10) == [3]
    tally.record(summary(3, "error"))
    st = aggregate(total=4, job=finished, tally=tally, results_url="s3://r/x", now=now, previous=st)
    assert st["phase"] == "Failed"
    assert (st["passed"], st["testFailures"], st["errors"], st["succeeded"], st["failed"]) == (2, 1, 1, 3, 1)
    assert [f["index"] for f in st["failures"]] == [1, 3]
    assert st["failures"][0]["reason"] == "criteria failed: minDistance >= 2"
    conditions = {c["type"]: c for c in st["conditions"]}
    assert conditions["Complete"]["status"] == "True" and conditions["Failed"]["reason"] == "TestFailures"
    assert st["completionTime"] == now and st["startTime"] == "2026-01-01T00:00:00Z"


def test_optional_failures_succeed_and_suspended() -> None:
    tally = Tally(2)
    tally.record(summary(0, "passed"))
    tally.record(summary(1, "failed", optional=True))
    st = aggregate(total=2, job=job("0", "1", finished="Failed"), tally=tally, results_url="", now="t")
    assert st["phase"] == "Succeeded" and st["testFailures"] == 1
    suspended = {"spec": {"suspend": True}, "status": {}}
    assert aggregate(total=2, job=suspended, tally=Tally(2), results_url="", now="t")["phase"] == "Suspended"


def test_deadline_failure_reason() -> None:
    failed = {
        "spec": {},
        "status": {
            "completedIndexes": "0",
            "conditions": [
                {"type": "Failed", "status": "True", "reason": "DeadlineExceeded", "message": "m"}
            ],
        },
    }
    tally = Tally(3)
    tally.record(summary(0, "passed"))
    st = aggregate(total=3, job=failed, tally=tally, results_url="", now="t")
    assert st["phase"] == "Failed"
    assert {c["type"]: c for c in st["conditions"]}["Failed"]["reason"] == "DeadlineExceeded"


def test_aggregation_of_50000_indexes_is_incremental() -> None:
    total = 50_000
    tally = Tally(total)
    completed = "0-49999"
    pending = tally.unknown_among(completed, 1000)
    assert pending == list(range(1000))
    for i in range(total):
        tally.record(summary(i, "failed" if i % 1000 == 7 else "passed"))
    st = aggregate(total=total, job=job(completed, finished="Complete"), tally=tally, results_url="", now="t")
    assert st["testFailures"] == 50 and st["passed"] == total - 50 and len(st["failures"]) == 20
    assert tally.unknown_among(completed, 10) == []


def test_system_under_test_is_a_sidecar_on_the_cluster() -> None:
    body = manifest(
        systemUnderTest={
            "name": "planner",
            "image": "reg/planner:2",
            "command": ["planner"],
            "args": ["--fast"],
        }
    )
    run = load(body)
    check_cluster_spec(run)
    pod = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))["spec"]["template"]["spec"]
    assert [c["name"] for c in pod["initContainers"]] == ["bridge", "recorder", "planner"]
    sut = pod["initContainers"][2]
    assert sut["image"] == "reg/planner:2" and sut["command"] == ["planner"] and sut["args"] == ["--fast"]
    assert sut["restartPolicy"] == "Always" and sut["securityContext"]["readOnlyRootFilesystem"]
    assert "envFrom" not in sut
    assert {e["name"] for e in sut["env"]} >= {"JOB_COMPLETION_INDEX", "CARLOS_BUS_PORT", "CARLOS_SPEC"}
    with pytest.raises(BadInput, match=r"spec.systemUnderTest.image"):
        check_cluster_spec(load(manifest(systemUnderTest={"module": "pkg.mod:Node"})))
    with pytest.raises(BadInput, match=r"spec.systemUnderTest.name"):
        check_cluster_spec(load(manifest(systemUnderTest={"name": "bridge", "image": "x"})))


def test_system_under_test_env_values_and_secret_references() -> None:
    """The node's `env`: values as they are, `secretKeyRef` as a reference the kubelet resolves (the
    operator never reads the Secret); only the node's container gets them, after CARLOS' own variables."""
    body = manifest(
        systemUnderTest={
            "name": "detector",
            "image": "reg/detector:1",
            "env": [
                {"name": "MODEL", "value": "/models/pointpillars.onnx"},
                {"name": "LICENSE_KEY", "secretKeyRef": {"name": "detector-license", "key": "key"}},
            ],
        }
    )
    run = load(body)
    pod = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))["spec"]["template"]["spec"]
    containers = {c["name"]: c for c in [*pod["initContainers"], *pod["containers"]]}
    env = containers["detector"]["env"]
    assert env[-2:] == [
        {"name": "MODEL", "value": "/models/pointpillars.onnx"},
        {"name": "LICENSE_KEY", "valueFrom": {"secretKeyRef": {"name": "detector-license", "key": "key"}}},
    ]
    assert [e["name"] for e in env].index("CARLOS_SPEC") < len(env) - 2
    for name in ("simcore", "bridge", "recorder"):
        assert not {"MODEL", "LICENSE_KEY"} & {e["name"] for e in containers[name]["env"]}, name


def test_every_container_of_a_pod_shares_one_dds_domain_inside_the_pod() -> None:
    """DDS by default: every container (the roles and the system under test) gets CARLOS_TRANSPORT=dds, the
    same ROS_DOMAIN_ID and a CYCLONEDDS_URI for 127.0.0.1 without multicast, so the system under test's ROS 2
    node talks to simcore and the recorder and no DDS traffic leaves the pod (its own network namespace:
    no hostNetwork, no added capabilities). The system under test's container uses rmw_cyclonedds_cpp."""
    from carlos_operator.builders import POD_DDS_CONFIG

    body = manifest(systemUnderTest={"name": "planner", "image": "ros:jazzy", "command": ["ros2", "run"]})
    run = load(body)
    pod = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))["spec"]["template"]["spec"]
    containers = [*pod["initContainers"], *pod["containers"]]
    assert [c["name"] for c in containers] == ["bridge", "recorder", "planner", "simcore"]
    envs = {c["name"]: {e["name"]: e.get("value") for e in c["env"]} for c in containers}
    for name, env in envs.items():
        assert env["CARLOS_TRANSPORT"] == "dds", name
        assert env["ROS_DOMAIN_ID"] == "0", name
        assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST", name
        assert env["CYCLONEDDS_URI"] == POD_DDS_CONFIG, name
    assert envs["planner"]["RMW_IMPLEMENTATION"] == "rmw_cyclonedds_cpp"
    assert not any("RMW_IMPLEMENTATION" in env for name, env in envs.items() if name != "planner")
    assert '<NetworkInterface address="127.0.0.1"/>' in POD_DDS_CONFIG
    assert "<AllowMulticast>false</AllowMulticast>" in POD_DDS_CONFIG
    assert "hostNetwork" not in pod and "hostPID" not in pod
    for container in containers:
        assert container["securityContext"]["capabilities"] == {"drop": ["ALL"]}
        assert "add" not in container["securityContext"]["capabilities"]


def test_the_pod_transport_is_an_operator_setting() -> None:
    loopback = OperatorSettings.from_env({"CARLOS_POD_TRANSPORT": "loopback"})
    assert OperatorSettings.from_env({}).pod_transport == "dds"
    body = manifest()
    run = load(body)
    pod = build_job(run, body, loopback, resolve_output(run, SETTINGS))["spec"]["template"]["spec"]
    env = {e["name"]: e.get("value") for e in pod["containers"][0]["env"]}
    assert env["CARLOS_TRANSPORT"] == "loopback"
    with pytest.raises(BadInput, match=r"CARLOS_POD_TRANSPORT='zmq' is not one of dds, loopback"):
        OperatorSettings.from_env({"CARLOS_POD_TRANSPORT": "zmq"})


EXAMPLE_RUNS = sorted(
    p
    for folder in ("examples/runs", "examples/gitops/runs", "examples/gitops/ci")
    for p in (Path(__file__).resolve().parent.parent / folder).glob("*.yaml")
    if p.name != "kustomization.yaml"
)


@pytest.mark.parametrize("path", EXAMPLE_RUNS, ids=[f"{p.parent.name}/{p.name}" for p in EXAMPLE_RUNS])
def test_every_object_built_for_an_example_is_accepted_by_the_strict_stand_in(path: Path) -> None:
    """What the operator creates for each example manifest passes the API server's checks (tests/apiserver.py:
    strict OpenAPI schemas of the oldest supported Kubernetes version)."""
    for body in yaml.safe_load_all(path.read_text()):
        if not body or body.get("kind") != "SimulationRun":
            continue
        body["metadata"].setdefault("name", f"{body['metadata'].get('generateName', 'run-')}abcde")
        body["metadata"].update(namespace="sims", uid="0b5c7a4e-1d2f-4a8b-9c3d-2e1f0a9b8c7d")
        admit(body)
        output = body["spec"].setdefault("output", {})
        if not str(output.get("url", "s3://")).startswith("s3://"):
            output["url"] = "s3://results/runs"  # a local example's file:// output, as on a cluster
        run = load(body)
        objects = [
            build_configmap(run, body, SETTINGS),
            build_job(run, body, SETTINGS, resolve_output(run, SETTINGS)),
        ]
        search = run.spec.search
        if search is not None:  # on a cluster a search's pods are its rounds'
            from simcore.search.export import distribution_xml

            last = SearchRound(number=3, start=3 * search.batch_size, count=search.batch_size)
            points = distribution_xml(Path("s.xosc"), [{"a": 1.5}] * last.count, "round 3")
            objects += [
                build_round_configmap(run, body, SETTINGS, last, points),
                build_job(run, body, SETTINGS, resolve_output(run, SETTINGS), search_round=last),
            ]
        for obj in objects:
            try:
                admit(obj)
            except Invalid as exc:
                pytest.fail(f"{path.name}: {exc}")


def test_every_container_has_requests_and_limits_with_defaults() -> None:
    body = manifest()
    pod = build_job(load(body), body, SETTINGS, resolve_output(load(body), SETTINGS))["spec"]["template"][
        "spec"
    ]
    for container in [*pod["initContainers"], *pod["containers"]]:
        resources = container["resources"]
        assert set(resources["requests"]) == {"cpu", "memory", "ephemeral-storage"}, container["name"]
        assert {"memory", "ephemeral-storage"} <= set(resources["limits"]), container["name"]
    (simcore,) = pod["containers"]
    assert simcore["resources"]["requests"]["memory"] == "1Gi"


def test_execution_resources_and_scheduling_reach_the_pod() -> None:
    execution = {
        "retries": 1,
        "maxFailedIndexes": 5,
        "resources": {
            "requests": {"cpu": 2, "memory": "8Gi", "ephemeral-storage": "20Gi"},
            "limits": {"cpu": "4"},
        },
        "nodeSelector": {"node.kubernetes.io/instance-type": "c6i.4xlarge"},
        "tolerations": [{"key": "sim", "operator": "Exists", "effect": "NoSchedule"}],
        "affinity": {
            "nodeAffinity": {
                "requiredDuringSchedulingIgnoredDuringExecution": {
                    "nodeSelectorTerms": [
                        {"matchExpressions": [{"key": "zone", "operator": "In", "values": ["a"]}]}
                    ]
                }
            }
        },
        "priorityClassName": "batch-low",
        "serviceAccountName": "sim-runner",
    }
    body = manifest(
        execution=execution,
        systemUnderTest={"name": "detector", "image": "reg/detector:1"},
    )
    run = load(body)
    job = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))
    admit(job)  # the API server takes it: a request above the default limit raised that limit
    assert job["spec"]["maxFailedIndexes"] == 5
    pod = job["spec"]["template"]["spec"]
    (simcore,) = pod["containers"]
    assert simcore["resources"]["requests"] == {"cpu": "2", "memory": "8Gi", "ephemeral-storage": "20Gi"}
    assert simcore["resources"]["limits"] == {"cpu": "4", "memory": "8Gi", "ephemeral-storage": "20Gi"}
    sut = next(c for c in pod["initContainers"] if c["name"] == "detector")
    assert sut["resources"] == simcore["resources"]
    bridge = next(c for c in pod["initContainers"] if c["name"] == "bridge")
    assert bridge["resources"]["requests"]["cpu"] == "100m"  # the sidecar defaults
    assert pod["nodeSelector"] == execution["nodeSelector"]
    assert pod["tolerations"] == execution["tolerations"]
    assert pod["affinity"] == execution["affinity"]
    assert pod["priorityClassName"] == "batch-low"
    assert pod["serviceAccountName"] == "sim-runner" and pod["automountServiceAccountToken"] is True


def test_operator_resource_defaults_come_from_the_environment() -> None:
    settings = OperatorSettings.from_env(
        {"CARLOS_RUN_RESOURCES": '{"requests": {"cpu": "3", "memory": "2Gi"}, "limits": {"memory": "2Gi"}}'}
    )
    assert settings.run_resources == {"requests": {"cpu": "3", "memory": "2Gi"}, "limits": {"memory": "2Gi"}}
    with pytest.raises(BadInput, match="CARLOS_SIDECAR_RESOURCES"):
        OperatorSettings.from_env({"CARLOS_SIDECAR_RESOURCES": '{"requests": {"gpu": "1"}}'})
    with pytest.raises(BadInput, match="CARLOS_RUN_RESOURCES"):
        OperatorSettings.from_env({"CARLOS_RUN_RESOURCES": '{"requests": {"cpu": "lots"}}'})


def test_same_named_runs_of_two_namespaces_never_share_object_keys() -> None:
    run = load(manifest())
    urls = {ns: resolve_output(run, SETTINGS, namespace=ns).url for ns in ("team-a", "team-b")}
    assert urls == {"team-a": "s3://results/runs/team-a", "team-b": "s3://results/runs/team-b"}
    body = manifest()
    job = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS, namespace="sims"))
    env = {e["name"]: e.get("value") for e in job["spec"]["template"]["spec"]["containers"][0]["env"]}
    assert env["CARLOS_OUTPUT_URL"] == "s3://results/runs/sims"  # pods write <url>/<namespace>/<run>/<index>/


def search_manifest(**search: Any) -> dict[str, Any]:
    body = manifest(
        search={
            "parameters": [{"name": "speed", "min": 5, "max": 30}],
            "objective": {"metric": "minDistance"},
            "budget": 10,
            "batchSize": 4,
            **search,
        },
        sweep={},
        scenarios=manifest()["spec"]["scenarios"][1:],
    )
    body["metadata"]["name"] = "falsify"
    return body


def test_round_names_are_deterministic_short_and_distinct() -> None:
    assert round_job_name("run", 0) == "carlos-run-r0" and round_job_name("run", 12) == "carlos-run-r12"
    long = "a" * 63
    names = {round_job_name(long, n) for n in range(1000)}
    assert len(names) == 1000 and all(len(n) <= 48 for n in names)
    assert round_job_name(long, 7).endswith("-r7") and round_job_name(long, 7) == round_job_name(long, 7)
    assert round_job_name(long, 7) != round_job_name("a" * 62 + "b", 7)
    assert job_name("run") not in {round_job_name("run", n) for n in range(3)}


def test_a_search_round_is_a_configmap_with_its_points_and_an_indexed_job_offset_to_its_indexes(
    tmp_path: Path,
) -> None:
    from simcore.manifest import load_manifest
    from simcore.plan import Plan
    from simcore.pod import PodEnv
    from simcore.search.export import distribution_xml

    body = search_manifest()
    run = load(body)
    current = SearchRound(number=2, start=8, count=2)  # the last round of 10 in rounds of 4
    points = [{"speed": 7.5}, {"speed": 22.25}]
    xml = distribution_xml(Path("b.xosc"), points, "round 2")
    cm = build_round_configmap(run, body, SETTINGS, current, xml)
    job = build_job(
        run, body, SETTINGS, resolve_output(run, SETTINGS, namespace="sims"), search_round=current
    )
    for obj in (cm, job):
        admit(obj)  # the strict stand-in of the API server
        assert obj["metadata"]["name"] == round_job_name("falsify", 2)
        assert obj["metadata"]["ownerReferences"][0]["uid"] == "uid-1"
        assert obj["metadata"]["labels"][ROUND_LABEL] == "2"
    spec = job["spec"]
    assert (spec["completionMode"], spec["completions"], spec["parallelism"]) == ("Indexed", 2, 2)
    pod = spec["template"]["spec"]
    assert {"name": "spec", "configMap": {"name": round_job_name("falsify", 2)}} in pod["volumes"]
    for container in [*pod["initContainers"], *pod["containers"]]:
        env = {e["name"]: e.get("value") for e in container["env"]}
        assert env["CARLOS_INDEX_OFFSET"] == "8", container["name"]
    # what a pod mounts runs the round's points as a sweep, pod k as the run's index 8 + k
    folder = tmp_path / "spec"
    folder.mkdir()
    for key, text in cm["data"].items():
        (folder / key).write_text(text)
    mounted = load_manifest(folder / SPEC_FILE)
    assert mounted.spec.search is None and mounted.name == "falsify"
    plan = Plan(mounted.spec)
    assert len(plan) == 2 and [float(plan[k].parameters["speed"]) for k in range(2)] == [7.5, 22.25]
    env = PodEnv.from_env(
        {
            "CARLOS_SPEC": str(folder / SPEC_FILE),
            "CARLOS_OUTPUT_URL": "s3://b/o",
            "JOB_COMPLETION_INDEX": "1",
            "CARLOS_INDEX_OFFSET": "8",
        }
    )
    assert (env.index, env.position) == (9, 1)


def test_round_steps_and_search_status() -> None:
    from simcore.spec import Search

    search = Search.model_validate({"budget": 10, "batchSize": 4})
    assert round_of(search, 0) == SearchRound(0, 0, 4) and round_of(search, 8) == SearchRound(2, 8, 2)
    assert round_of(search, 10) is None
    running = {"status": {"active": 2, "completedIndexes": "0-1"}}
    complete = {
        "status": {
            "completedIndexes": "0,2-3",
            "failedIndexes": "1",
            "conditions": [{"type": "Failed", "status": "True", "reason": "FailedIndexes"}],
        }
    }
    aborted = {
        "status": {
            "completedIndexes": "0",
            "conditions": [
                {"type": "Failed", "status": "True", "reason": "PodFailurePolicy", "message": "exit code 2"}
            ],
        }
    }
    assert round_step(search, 4, None) == "create"
    assert round_step(search, 4, running) == "wait"
    assert round_step(search, 4, complete) == "tell"  # a failing index is a finding, not the end
    assert round_step(search, 4, aborted) == "stopped"
    assert round_step(search, 10, complete) == "finish"
    points = [
        {"index": i, "round": i // 4, "status": "failed" if i == 2 else "passed", "objective": 5.0 - i}
        for i in range(4)
    ]
    tally = Tally(10)
    for p in points:
        tally.record({"index": p["index"], "status": p["status"]})
    st = search_status(
        search=search, points=points, job=running, tally=tally, results_url="s3://b/r", now="T"
    )
    assert st["phase"] == "Running" and (st["progress"], st["total"], st["active"]) == ("6/10", 10, 2)
    assert st["search"] == {
        "rounds": "1/3",
        "roundsDone": 1,
        "roundsTotal": 3,
        "round": 1,
        "evaluated": 4,
        "failuresFound": 1,
        "bestObjective": 2.0,
        "bestIndex": 3,
    }
    stopped = search_status(
        search=search, points=points, job=aborted, tally=tally, results_url="s3://b/r", now="T", stopped=True
    )
    failed = {c["type"]: c for c in stopped["conditions"]}["Failed"]
    assert stopped["phase"] == "Failed" and failed["reason"] == "PodFailurePolicy"
    every = [
        *points,
        *({"index": i, "round": i // 4, "status": "passed", "objective": 9.0} for i in range(4, 10)),
    ]
    done = search_status(
        search=search,
        points=every,
        job=None,
        tally=tally,
        results_url="s3://b/r",
        now="T",
        finished=True,
        search_url="s3://b/r/search.json",
    )
    assert done["phase"] == "Failed"  # a required criterion failed at index 2: as `carlos run` exits 1
    assert done["search"]["rounds"] == "3/3" and done["search"]["round"] is None
    assert done["search"]["searchURL"] == "s3://b/r/search.json" and done["completionTime"] == "T"


# --- shards: slices of runs per pod ----------------------------------------------------------------------


def test_a_large_sweep_gets_a_slice_per_pod_by_default_and_runs_per_pod_when_asked() -> None:
    from carlos_operator.status import RUNS_ANNOTATION, RUNS_PER_POD_ANNOTATION

    body = manifest(sweep={"matrix": {"a": list(range(210)), "b": list(range(125))}, "repetitions": 1})
    del body["spec"]["execution"]["runsPerPod"]
    run = load(body)
    job = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))
    runs = 2 * 210 * 125  # 52,500
    per_pod = int(job["metadata"]["annotations"][RUNS_PER_POD_ANNOTATION])
    assert job["metadata"]["annotations"][RUNS_ANNOTATION] == str(runs)
    assert job["spec"]["completions"] == -(-runs // per_pod) <= 1_050
    env = {e["name"]: e.get("value") for e in job["spec"]["template"]["spec"]["containers"][0]["env"]}
    assert env["CARLOS_RUNS_PER_POD"] == str(per_pod)
    # a pod's deadline covers its whole slice
    assert job["spec"]["template"]["spec"]["activeDeadlineSeconds"] == 600 * per_pod + 300
    body["spec"]["execution"]["runsPerPod"] = 7
    run = load(body)
    job = build_job(run, body, SETTINGS, resolve_output(run, SETTINGS))
    assert job["spec"]["completions"] == -(-runs // 7)


def test_default_slices_follow_the_cost_of_a_run() -> None:
    from simcore import shards

    quick = shards.default_runs_per_pod(52_500, shards.estimate_run_seconds(20.0, 0))
    lidar = shards.default_runs_per_pod(52_500, shards.estimate_run_seconds(20.0, 2))
    assert shards.pods_for(52_500, quick) <= 1_050 and shards.pods_for(52_500, lidar) <= 1_050
    assert shards.default_runs_per_pod(200, shards.estimate_run_seconds(120.0, 2)) < 200  # long: more pods
    assert shards.default_runs_per_pod(200, shards.estimate_run_seconds(10.0, 0)) == 200  # short: one pod
    # a search round: the measured wall seconds of earlier rounds decide, not the plan's estimate
    assert shards.default_runs_per_pod(100, shards.estimate_run_seconds(10.0, 0, [30.0, 30.0])) == 10
    assert shards.default_runs_per_pod(3, 1.0) == 3 and shards.default_runs_per_pod(0, 1.0) == 1


def test_slices_cover_every_run_once_in_index_order() -> None:
    from simcore import shards

    for runs, per_pod in ((10, 3), (9, 3), (1, 5), (52_500, 500)):
        covered = [
            p for k in range(shards.pods_for(runs, per_pod)) for p in shards.slice_of(k, per_pod, runs)
        ]
        assert covered == list(range(runs))
        assert all(
            shards.pod_of(p, per_pod) == k for k in range(3) for p in shards.slice_of(k, per_pod, runs)
        )


def test_finished_pods_count_as_the_runs_of_their_slices() -> None:
    from carlos_operator.status import RUNS_ANNOTATION, RUNS_PER_POD_ANNOTATION, runs_view

    job = {
        "metadata": {"annotations": {RUNS_PER_POD_ANNOTATION: "3", RUNS_ANNOTATION: "10"}},
        "status": {"completedIndexes": "0,2-3", "failedIndexes": "1", "active": 1},
    }
    view = runs_view(job)
    assert view is not None
    assert view["status"]["completedIndexes"] == "0-2,6-9"  # pod 3 holds run 9 only
    assert view["status"]["failedIndexes"] == "3-5"
    assert view["status"]["active"] == 1  # pods
    assert job["status"]["completedIndexes"] == "0,2-3"  # the Job itself is left alone
    one = {"metadata": {}, "status": {"completedIndexes": "0-4"}}
    assert runs_view(one) == one and runs_view(None) is None


def test_operator_modules_import_no_circle() -> None:
    """controller ↔ inputs ↔ searching once formed a circle; module-level imports (with TYPE_CHECKING ones)
    of carlos_operator form none."""
    import ast

    package = Path(__file__).resolve().parent.parent / "operator/carlos_operator"
    graph: dict[str, set[str]] = {}
    for path in package.glob("*.py"):
        edges = graph.setdefault(path.stem, set())
        for node in ast.parse(path.read_text()).body:
            for sub in ast.walk(node) if isinstance(node, ast.If) else [node]:
                if isinstance(sub, ast.ImportFrom) and (sub.module or "").startswith("carlos_operator"):
                    mod = sub.module or ""
                    edges.update(
                        {a.name for a in sub.names} if mod == "carlos_operator" else {mod.rpartition(".")[2]}
                    )
    seen: dict[str, int] = {}

    def visit(name: str, stack: list[str]) -> None:
        if seen.get(name) == 2:
            return
        assert seen.get(name) != 1, f"import circle: {' → '.join([*stack, name])}"
        seen[name] = 1
        for target in sorted(graph.get(name, ())):
            visit(target, [*stack, name])
        seen[name] = 2

    for name in sorted(graph):
        visit(name, [])
