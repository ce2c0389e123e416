"""Pure builders: a SimulationRun → its ConfigMap and Indexed Job (plain dicts, no I/O, no kopf).

One pod per slice of `runs_per_pod` indexes (simcore.shards; DESIGN.md, pod roles and shards): the
simulator core is the main container, running its slice one index after another; the bridge and the
recorder are native sidecars, i.e. init containers with `restartPolicy: Always` whose startup probes make
the kubelet start them in order, each ready before the next starts:

1. `bridge`: listens on 127.0.0.1:`BUS_PORT`; ready when the port accepts connections. Over DDS (the
   default) it logs the pod's ROS 2 graph; over the loopback transport it is the topic hub.
2. `recorder`: subscribes to every topic, then opens 127.0.0.1:`RECORDER_READY_PORT` (its startup probe)
   — so no message simcore publishes can be missed.
3. `simcore`: runs each index of its slice, publishes the topics and the verdict, waits until the recorder
   has uploaded the results, and exits with the worst of DESIGN.md's exit codes of its slice, which the
   Job's podFailurePolicy acts on.

Topics: `CARLOS_TRANSPORT` on every container, the operator's `pod_transport` (CARLOS_POD_TRANSPORT, Helm
value `podTransport`): `dds` (default) puts them on DDS as ROS 2 topics, so the system under test's
container (a ROS 2 node with rmw_cyclonedds_cpp, which the template selects with RMW_IMPLEMENTATION) talks
to simcore and the recorder directly; `loopback` keeps them on the bridge's TCP hub, which ROS 2 nodes
cannot reach. Every container of the pod gets the same ROS_DOMAIN_ID and a CYCLONEDDS_URI for 127.0.0.1
only, without multicast (`POD_DDS_CONFIG`): a pod has its own network namespace (no hostNetwork), so DDS
traffic stays inside the pod and pods on one node never see each other's topics.

Names are deterministic (`job_name`), every object carries an owner reference to the SimulationRun, so a
restarted operator adopts what exists and deleting the run deletes them (results in object storage stay).
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from carlos_operator.status import RUNS_ANNOTATION, RUNS_PER_POD_ANNOTATION
from simcore import kubeyaml, shards
from simcore.errors import BadInput, ExitCode
from simcore.plan import Plan
from simcore.spec import API_GROUP, API_VERSION, KIND, EnvVar, SimulationRun, Sweep
from simcore.transport.dds_config import loopback_config

SPEC_DIR = "/etc/carlos/spec"
SPEC_FILE = "simulationrun.yaml"
SCENARIO_DIR = "/etc/carlos/scenarios"
SCRATCH_DIR = "/scratch"
BUS_PORT = 7447
RECORDER_READY_PORT = 7448
QUEUE_LABEL = "kueue.x-k8s.io/queue-name"
RUN_LABEL = f"{API_GROUP}/run"
INDEX_FAILURES_ANNOTATION = "batch.kubernetes.io/job-index-failure-count"
#: a cluster run without `execution.parallelism` runs this many pods at a time
DEFAULT_PARALLELISM = 10
#: a per-pod backstop beyond `execution.timeoutSeconds` (simcore enforces the limit itself)
POD_DEADLINE_GRACE_S = 300
UID = 10001  # the images' non-root user (images/*/Dockerfile)
POD_TRANSPORTS = ("dds", "loopback")
#: the DDS domain of every pod (pods are isolated by their own loopback, not by the domain)
POD_DOMAIN_ID = 0
#: cyclonedds configuration of every container of a pod: 127.0.0.1 only, unicast discovery
POD_DDS_CONFIG = loopback_config()
#: the ROS 2 middleware of the system under test's container (a ros:jazzy image's default is Fast DDS)
SUT_RMW = "rmw_cyclonedds_cpp"


#: default requests/limits of the containers that do a run's work (Helm value runPods.resources)
RUN_RESOURCES = {
    "requests": {"cpu": "1", "memory": "1Gi", "ephemeral-storage": "1Gi"},
    "limits": {"memory": "4Gi", "ephemeral-storage": "12Gi"},
}
#: default requests/limits of the bridge and the recorder (Helm value runPods.sidecarResources)
SIDECAR_RESOURCES = {
    "requests": {"cpu": "100m", "memory": "128Mi", "ephemeral-storage": "100Mi"},
    "limits": {"memory": "512Mi", "ephemeral-storage": "1Gi"},
}
_RESOURCE_NAMES = ("cpu", "memory", "ephemeral-storage")


def _resources_setting(
    env: dict[str, str], name: str, default: dict[str, dict[str, str]]
) -> dict[str, dict[str, str]]:
    """A resources setting (JSON `{"requests": {...}, "limits": {...}}`), checked; absent: `default`."""
    text = env.get(name, "").strip()
    if not text:
        return copy.deepcopy(default)
    try:
        value = json.loads(text)
        out = {
            part: {str(k): str(v) for k, v in (value.get(part) or {}).items()}
            for part in ("requests", "limits")
        }
        for part in out.values():
            for key, quantity in part.items():
                if key not in _RESOURCE_NAMES:
                    raise ValueError(f"unknown resource {key!r} (use {', '.join(_RESOURCE_NAMES)})")
                _quantity(quantity)
    except (ValueError, TypeError, AttributeError) as exc:
        raise BadInput(
            f'{name}: {exc} (JSON: {{"requests": {{...}}, "limits": {{...}}}})', field=name
        ) from None
    return out


def _quantity(text: str) -> float:
    from kubernetes.utils.quantity import parse_quantity

    return float(parse_quantity(text))


def container_resources(
    defaults: dict[str, dict[str, str]], chosen: dict[str, dict[str, Any]] | None = None
) -> dict[str, dict[str, str]]:
    """Requests and limits: the run's own (spec.execution.resources) over the defaults, field by field. A
    request the run raises above a default limit it did not set raises that limit too (the API server
    refuses a request above its limit)."""
    chosen = chosen or {}
    requests = {
        **defaults.get("requests", {}),
        **{k: str(v) for k, v in (chosen.get("requests") or {}).items()},
    }
    limits = {**defaults.get("limits", {}), **{k: str(v) for k, v in (chosen.get("limits") or {}).items()}}
    for key, request in requests.items():
        if (
            key in limits
            and key not in (chosen.get("limits") or {})
            and _quantity(request) > _quantity(limits[key])
        ):
            limits[key] = request
    out = {"requests": requests}
    if limits:
        out["limits"] = limits
    return out


def _package_version() -> str:
    try:
        return version("carlos-sim")  # the distribution (simcore.DISTRIBUTION)
    except PackageNotFoundError:
        return "0.0.0"


@dataclass(frozen=True)
class OperatorSettings:
    """The operator's configuration (the Helm chart sets these environment variables on its Deployment)."""

    image_simcore: str
    image_bridge: str
    image_recorder: str
    image_pull_secrets: tuple[str, ...] = ()
    default_output_url: str | None = None
    default_s3_endpoint: str | None = None
    default_s3_secret: str | None = None
    job_ttl_seconds: int = 7 * 86_400
    pull_policies: dict[str, str] = field(default_factory=dict)  # role → imagePullPolicy
    extra_labels: dict[str, str] = field(default_factory=dict)
    pod_transport: str = "dds"  # CARLOS_TRANSPORT of the pods: dds | loopback
    #: namespaces whose runs may name Secrets (CARLOS_SECRET_NAMESPACES; Helm secretReferences.namespaces)
    secret_namespaces: frozenset[str] = frozenset()
    #: requests/limits of simcore and the system under test unless the run sets spec.execution.resources
    run_resources: dict[str, dict[str, str]] = field(default_factory=lambda: copy.deepcopy(RUN_RESOURCES))
    #: requests/limits of the bridge and the recorder
    sidecar_resources: dict[str, dict[str, str]] = field(
        default_factory=lambda: copy.deepcopy(SIDECAR_RESOURCES)
    )

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> OperatorSettings:
        env = dict(os.environ if env is None else env)
        tag = _package_version()

        def image(role: str) -> str:
            return env.get(f"CARLOS_IMAGE_{role.upper()}") or f"ghcr.io/carlos-sim/carlos-{role}:{tag}"

        secrets = tuple(s.strip() for s in env.get("CARLOS_IMAGE_PULL_SECRETS", "").split(",") if s.strip())
        ttl = env.get("CARLOS_JOB_TTL_SECONDS", "")
        policies = {
            role: env[f"CARLOS_IMAGE_{role.upper()}_PULL_POLICY"]
            for role in ("simcore", "bridge", "recorder")
            if env.get(f"CARLOS_IMAGE_{role.upper()}_PULL_POLICY") in ("Always", "IfNotPresent", "Never")
        }
        transport = env.get("CARLOS_POD_TRANSPORT", "").strip() or "dds"
        if transport not in POD_TRANSPORTS:
            raise BadInput(
                f"CARLOS_POD_TRANSPORT={transport!r} is not one of {', '.join(POD_TRANSPORTS)} "
                "(Helm value podTransport)",
                field="CARLOS_POD_TRANSPORT",
            )
        return cls(
            secret_namespaces=frozenset(
                n.strip() for n in env.get("CARLOS_SECRET_NAMESPACES", "").split(",") if n.strip()
            ),
            run_resources=_resources_setting(env, "CARLOS_RUN_RESOURCES", RUN_RESOURCES),
            sidecar_resources=_resources_setting(env, "CARLOS_SIDECAR_RESOURCES", SIDECAR_RESOURCES),
            pod_transport=transport,
            pull_policies=policies,
            image_simcore=image("simcore"),
            image_bridge=image("bridge"),
            image_recorder=image("recorder"),
            image_pull_secrets=secrets,
            default_output_url=env.get("CARLOS_DEFAULT_OUTPUT_URL") or None,
            default_s3_endpoint=env.get("CARLOS_DEFAULT_S3_ENDPOINT") or None,
            default_s3_secret=env.get("CARLOS_DEFAULT_S3_SECRET") or None,
            job_ttl_seconds=int(ttl) if ttl.isdigit() else 7 * 86_400,
        )


@dataclass(frozen=True)
class Output:
    """Where a run's results go on the cluster, and how to reach the object store."""

    url: str  # the output URL (s3://bucket/prefix)
    endpoint: str | None
    region: str | None
    secret: str | None  # Secret with AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY

    @property
    def results_url(self) -> str:
        return self.url.rstrip("/")


def job_name(run_name: str) -> str:
    """The Job's (and ConfigMap's) name: `carlos-<run>`, shortened with a hash so that pod hostnames
    (`<job>-<index>-<suffix>`) stay within 63 characters."""
    name = f"carlos-{run_name}"
    if len(name) <= 48:
        return name
    digest = hashlib.sha256(run_name.encode()).hexdigest()[:8]
    return f"{name[:39].rstrip('-')}-{digest}"


def round_job_name(run_name: str, number: int) -> str:
    """The Job (and ConfigMap) of a search's round `number`: `carlos-<run>-r<number>`, at most 48
    characters as `job_name` (shortened with a hash of the run's name, the round number kept)."""
    suffix = f"-r{number}"
    name = f"carlos-{run_name}{suffix}"
    if len(name) <= 48:
        return name
    digest = hashlib.sha256(run_name.encode()).hexdigest()[:8]
    return f"{f'carlos-{run_name}'[: 39 - len(suffix)].rstrip('-')}-{digest}{suffix}"


@dataclass(frozen=True)
class SearchRound:
    """One round of a search on the cluster: its Job runs the run's indexes start…start+count-1."""

    number: int
    start: int
    count: int


POINTS_FILE = "points.xosc"
ROUND_LABEL = f"{API_GROUP}/search-round"


def round_manifest(run: SimulationRun) -> SimulationRun:
    """What a round's pods run: the run as a sweep over the round's points (`points.xosc` beside the spec
    in the round's ConfigMap; a relative distribution is read beside the manifest)."""
    spec = run.spec.model_copy(update={"search": None, "sweep": Sweep(distribution=POINTS_FILE)})
    return run.model_copy(update={"spec": spec})


def build_round_configmap(
    run: SimulationRun,
    body: dict[str, Any],
    settings: OperatorSettings,
    search_round: SearchRound,
    points_xml: bytes,
) -> dict[str, Any]:
    """A round's ConfigMap: the round's sweep (`simulationrun.yaml`) and its points (`points.xosc`)."""
    cm = build_configmap(round_manifest(run), body, settings)
    cm["metadata"]["name"] = round_job_name(run.name, search_round.number)
    cm["metadata"]["labels"][ROUND_LABEL] = str(search_round.number)
    cm["data"][POINTS_FILE] = points_xml.decode()
    return cm


def owner_reference(body: dict[str, Any]) -> dict[str, Any]:
    meta = body["metadata"]
    return {
        "apiVersion": f"{API_GROUP}/{API_VERSION}",
        "kind": KIND,
        "name": meta["name"],
        "uid": meta["uid"],
        "controller": True,
        "blockOwnerDeletion": True,
    }


def resolve_output(run: SimulationRun, settings: OperatorSettings, *, namespace: str | None = None) -> Output:
    """The output of a cluster run: `spec.output.url` when set, else the operator's default; only s3://
    (pods are ephemeral). With `namespace` (the operator always gives it) results go under
    `<url>/<namespace>/<run>/`, so same-named runs of two namespaces never share keys. Raises BadInput with
    the field to fix."""
    out = run.spec.output
    url = out.url if "url" in out.model_fields_set else settings.default_output_url
    if url is None:
        raise BadInput(
            "no output on the cluster: set spec.output.url to s3://bucket/prefix (or install the operator "
            "with a default output, CARLOS_DEFAULT_OUTPUT_URL)",
            field="spec.output.url",
        )
    if not url.startswith("s3://"):
        raise BadInput(
            f"{url!r}: on a cluster results go to object storage: use s3://bucket/prefix",
            field="spec.output.url",
        )
    secret = out.credentials_secret_ref.name if out.credentials_secret_ref else settings.default_s3_secret
    if namespace:
        url = f"{url.rstrip('/')}/{namespace}"
    return Output(
        url=url, endpoint=out.endpoint or settings.default_s3_endpoint, region=out.region, secret=secret
    )


#: Kubernetes' limit on completions of an Indexed Job with backoffLimitPerIndex
MAX_COMPLETIONS = 100_000


def secret_references(run: SimulationRun) -> list[str]:
    """The fields of a run that name a Secret of its namespace."""
    fields = []
    if run.spec.output.credentials_secret_ref is not None:
        fields.append("spec.output.credentialsSecretRef")
    sut = run.spec.system_under_test
    for position, var in enumerate(sut.env if sut is not None else []):
        if var.secret_key_ref is not None:
            fields.append(f"spec.systemUnderTest.env[{position}].secretKeyRef")
    return fields


def check_cluster_spec(run: SimulationRun) -> None:
    """What a cluster run needs beyond the models: at most `MAX_COMPLETIONS` runs, and scenarios a pod can
    reach (s3://, a ConfigMap, or an absolute file:// path inside the image)."""
    sut = run.spec.system_under_test
    if sut is not None and not sut.image:
        raise BadInput(
            "a cluster runs the system under test as a container: set its image (module is for local runs)",
            field="spec.systemUnderTest.image",
        )
    if sut is not None and sut.name in ("simcore", "bridge", "recorder"):
        raise BadInput(
            f"{sut.name!r} is the name of a CARLOS container: choose another name",
            field="spec.systemUnderTest.name",
        )
    search = run.spec.search
    if search is not None and search.batch_size > MAX_COMPLETIONS:
        raise BadInput(  # never: the spec allows at most 1000 (kept beside the sweep's check)
            f"batchSize {search.batch_size}: a round's Job has at most {MAX_COMPLETIONS:,} runs",
            field="spec.search.batchSize",
        )
    total = len(Plan(run.spec))
    if total > MAX_COMPLETIONS:
        raise BadInput(
            f"{total} runs: a cluster run has at most {MAX_COMPLETIONS:,} (Kubernetes' limit for an Indexed "
            "Job); split the sweep into several SimulationRuns",
            field="spec.sweep",
        )
    for position, scenario in enumerate(run.spec.scenarios):
        source = scenario.openscenario
        if source is None or source.startswith("s3://"):
            continue
        if source.startswith("file:///"):
            continue
        raise BadInput(
            f"{source!r}: a pod has no manifest directory; give the scenario as s3://bucket/key, as a "
            "configMapRef, or as an absolute file:/// path inside the simcore image",
            field=f"spec.scenarios[{position}].openscenario",
        )


def manifest_yaml(run: SimulationRun) -> str:
    """The spec as applied (apiVersion, kind, name, spec): what every pod reads. Never the permutations.
    Compared with a stored `run.yaml` by its data, not its bytes (desired.same_spec)."""
    document = {
        "apiVersion": f"{API_GROUP}/{API_VERSION}",
        "kind": KIND,
        "metadata": {"name": run.name},
        "spec": run.spec.model_dump(mode="json", by_alias=True, exclude_none=True),
    }
    return kubeyaml.dump_fast(document, sort_keys=False)


def _labels(run: SimulationRun, settings: OperatorSettings) -> dict[str, str]:
    return {
        "app.kubernetes.io/name": "carlos",
        "app.kubernetes.io/component": "simulation",
        "app.kubernetes.io/managed-by": "carlos-operator",
        RUN_LABEL: run.name,
        **settings.extra_labels,
    }


#: the run's distribution file beside its spec in the Job's ConfigMap (the pods read it there)
DISTRIBUTION_FILE = "distribution.xosc"


def pod_manifest(run: SimulationRun) -> SimulationRun:
    """The run as its pods read it: a distribution (a ConfigMap key, s3://) becomes `DISTRIBUTION_FILE`
    beside the spec, which the operator copies into the Job's ConfigMap (pure)."""
    sweep = run.spec.sweep
    if sweep.distribution_config_map_ref is None and not (sweep.distribution or "").startswith("s3://"):
        return run
    moved = sweep.model_copy(update={"distribution": DISTRIBUTION_FILE, "distribution_config_map_ref": None})
    return run.model_copy(update={"spec": run.spec.model_copy(update={"sweep": moved})})


def build_configmap(
    run: SimulationRun,
    body: dict[str, Any],
    settings: OperatorSettings,
    distribution: str | None = None,
    *,
    spec_yaml: str | None = None,
) -> dict[str, Any]:
    """The Job's ConfigMap: the spec as the pods read it, and the distribution file the operator read.
    `spec_yaml`: `manifest_yaml(run)` when the caller has it already (used when there is no distribution)."""
    if distribution is not None:
        spec_text = manifest_yaml(pod_manifest(run))
    else:
        spec_text = spec_yaml if spec_yaml is not None else manifest_yaml(run)
    data = {SPEC_FILE: spec_text}
    if distribution is not None:
        data[DISTRIBUTION_FILE] = distribution
    return {
        "apiVersion": "v1",
        "kind": "ConfigMap",
        "metadata": {
            "name": job_name(run.name),
            "namespace": body["metadata"].get("namespace"),
            "labels": _labels(run, settings),
            "ownerReferences": [owner_reference(body)],
        },
        "data": data,
    }


_RESTRICTED_CONTAINER = {
    "allowPrivilegeEscalation": False,
    "readOnlyRootFilesystem": True,
    "runAsNonRoot": True,
    "capabilities": {"drop": ["ALL"]},
    "seccompProfile": {"type": "RuntimeDefault"},
}


def _env(run: SimulationRun, output: Output, settings: OperatorSettings) -> list[dict[str, Any]]:
    env: list[dict[str, Any]] = [
        {
            "name": "JOB_COMPLETION_INDEX",
            "valueFrom": {
                "fieldRef": {"fieldPath": "metadata.annotations['batch.kubernetes.io/job-completion-index']"}
            },
        },
        {
            "name": "CARLOS_INDEX_FAILURES",
            "valueFrom": {"fieldRef": {"fieldPath": f"metadata.annotations['{INDEX_FAILURES_ANNOTATION}']"}},
        },
        {"name": "CARLOS_SPEC", "value": f"{SPEC_DIR}/{SPEC_FILE}"},
        {"name": "CARLOS_OUTPUT_URL", "value": output.url},
        {"name": "CARLOS_SCENARIO_DIR", "value": SCENARIO_DIR},
        {"name": "CARLOS_SCRATCH", "value": SCRATCH_DIR},
        {"name": "CARLOS_BUS_PORT", "value": str(BUS_PORT)},
        {"name": "CARLOS_RECORDER_READY_PORT", "value": str(RECORDER_READY_PORT)},
        {"name": "CARLOS_TRANSPORT", "value": settings.pod_transport},
        {"name": "ROS_DOMAIN_ID", "value": str(POD_DOMAIN_ID)},
        {"name": "ROS_AUTOMATIC_DISCOVERY_RANGE", "value": "LOCALHOST"},
        {"name": "CYCLONEDDS_URI", "value": POD_DDS_CONFIG},
        {"name": "HOME", "value": SCRATCH_DIR},
        {"name": "TMPDIR", "value": "/tmp"},
        # numba's compiled-kernel cache (the lidar's kernels): the root filesystem is read-only, /tmp is not
        {"name": "NUMBA_CACHE_DIR", "value": "/tmp/numba-cache"},
    ]
    if output.endpoint:
        env.append({"name": "AWS_ENDPOINT_URL", "value": output.endpoint})
    if output.region:
        env.append({"name": "AWS_REGION", "value": output.region})
    return env


def _container(
    role: str, settings: OperatorSettings, run: SimulationRun, output: Output, mounts: list[dict[str, Any]]
) -> dict[str, Any]:
    container: dict[str, Any] = {
        "name": role,
        "image": getattr(settings, f"image_{role}", ""),
        "imagePullPolicy": settings.pull_policies.get(role, "IfNotPresent"),
        "args": ["pod", "--role", role],
        "env": _env(run, output, settings),
        "volumeMounts": mounts,
        "securityContext": dict(_RESTRICTED_CONTAINER),
        "terminationMessagePolicy": "FallbackToLogsOnError",
    }
    if output.secret:
        container["envFrom"] = [{"secretRef": {"name": output.secret}}]
    return container


def _sidecar(container: dict[str, Any], port: int) -> dict[str, Any]:
    return {
        **container,
        "restartPolicy": "Always",
        "ports": [{"name": "bus" if port == BUS_PORT else "ready", "containerPort": port, "protocol": "TCP"}],
        "startupProbe": {
            "tcpSocket": {"port": port},
            "periodSeconds": 1,
            "failureThreshold": 120,
            "timeoutSeconds": 1,
        },
    }


def scenario_configmaps(run: SimulationRun) -> list[str]:
    """Names of the ConfigMaps the scenarios come from, in first-use order."""
    names: dict[str, None] = {}
    for scenario in run.spec.scenarios:
        if scenario.config_map_ref is not None:
            names[scenario.config_map_ref.name] = None
    return list(names)


def _env_var(var: EnvVar) -> dict[str, Any]:
    """A container env entry from a systemUnderTest.env item: a value, or a Secret key reference."""
    if var.secret_key_ref is None:
        return {"name": var.name, "value": var.value}
    return {"name": var.name, "valueFrom": {"secretKeyRef": var.secret_key_ref.model_dump()}}


def runs_per_pod(run: SimulationRun, runs: int, measured: Sequence[float] = ()) -> int:
    """The Job's slice size: `execution.runsPerPod`, else `simcore.shards.default_runs_per_pod` from the
    plan's estimate (or `measured` wall seconds of earlier runs, a search's earlier rounds)."""
    spec = run.spec
    if spec.execution.runs_per_pod is not None:
        return min(spec.execution.runs_per_pod, max(runs, 1))
    sensors = len(spec.sensors) + sum(len(rsu.sensors) for rsu in spec.infrastructure)
    cost = shards.estimate_run_seconds(spec.simulation.max_seconds, sensors, measured)
    return shards.default_runs_per_pod(runs, cost)


def build_job(
    run: SimulationRun,
    body: dict[str, Any],
    settings: OperatorSettings,
    output: Output,
    search_round: SearchRound | None = None,
    measured: Sequence[float] = (),
) -> dict[str, Any]:
    """The run's Indexed Job: one completion per slice of `runs_per_pod` indexes (simcore.shards),
    Kubernetes doing retries and parallelism. A search's round (`search_round`) gets its own Job over the
    round's ConfigMap, its pods' indexes offset by the round's start (CARLOS_INDEX_OFFSET)."""
    spec = run.spec
    if search_round is None:
        runs = len(Plan(spec))
        name = job_name(run.name)
    else:
        runs = search_round.count
        name = round_job_name(run.name, search_round.number)
    per_pod = runs_per_pod(run, runs, measured)
    total = shards.pods_for(runs, per_pod)
    parallelism = min(spec.execution.parallelism or DEFAULT_PARALLELISM, total)
    attempts = spec.execution.retries + 1
    pod_deadline = spec.execution.timeout_seconds * per_pod + POD_DEADLINE_GRACE_S
    waves = math.ceil(total / parallelism)
    labels = _labels(run, settings)
    if search_round is not None:
        labels[ROUND_LABEL] = str(search_round.number)
    job_labels = dict(labels)
    if spec.execution.queue_name:
        job_labels[QUEUE_LABEL] = spec.execution.queue_name
    mounts: list[dict[str, Any]] = [
        {"name": "spec", "mountPath": SPEC_DIR, "readOnly": True},
        {"name": "scratch", "mountPath": SCRATCH_DIR},
        {"name": "tmp", "mountPath": "/tmp"},
    ]
    volumes: list[dict[str, Any]] = [
        {"name": "spec", "configMap": {"name": name}},
        {"name": "scratch", "emptyDir": {"sizeLimit": "10Gi"}},
        {"name": "tmp", "emptyDir": {"medium": "Memory", "sizeLimit": "256Mi"}},
    ]
    for position, cm in enumerate(scenario_configmaps(run)):
        volumes.append({"name": f"scenarios-{position}", "configMap": {"name": cm}})
        mounts.append(
            {"name": f"scenarios-{position}", "mountPath": f"{SCENARIO_DIR}/{cm}", "readOnly": True}
        )
    execution = spec.execution
    chosen = (
        execution.resources.model_dump(mode="json", by_alias=True, exclude_none=True)
        if execution.resources
        else None
    )
    work_resources = container_resources(settings.run_resources, chosen)
    sidecar_resources = container_resources(settings.sidecar_resources)
    simcore = _container("simcore", settings, run, output, mounts)
    simcore["resources"] = work_resources
    bridge = _sidecar(_container("bridge", settings, run, output, mounts), BUS_PORT)
    bridge["resources"] = sidecar_resources
    recorder = _sidecar(_container("recorder", settings, run, output, mounts), RECORDER_READY_PORT)
    recorder["resources"] = copy.deepcopy(sidecar_resources)
    for container in (simcore, bridge, recorder):
        container["env"].append({"name": "CARLOS_RUNS_PER_POD", "value": str(per_pod)})
        if search_round is not None:
            container["env"].append({"name": "CARLOS_INDEX_OFFSET", "value": str(search_round.start)})
    sidecars = [bridge, recorder]
    sut = spec.system_under_test
    if sut is not None and sut.image:
        # the system under test: a native sidecar too, started after the recorder, stopped after simcore
        node = {
            **_container(sut.name, settings, run, output, mounts),
            "image": sut.image,
            "imagePullPolicy": "IfNotPresent",
            "restartPolicy": "Always",
            "resources": copy.deepcopy(work_resources),
        }
        node.pop("args")
        node.pop("envFrom", None)  # the object-store credentials are CARLOS' business, not the node's
        if sut.command:
            node["command"] = list(sut.command)
        if sut.args:
            node["args"] = list(sut.args)
        node["env"] = [
            *node["env"],
            {"name": "CARLOS_ROLE", "value": "system-under-test"},
            {"name": "RMW_IMPLEMENTATION", "value": SUT_RMW},
            *(_env_var(var) for var in sut.env),
        ]
        sidecars.append(node)
    pod_spec: dict[str, Any] = {
        "restartPolicy": "Never",
        "automountServiceAccountToken": False,
        "enableServiceLinks": False,
        "activeDeadlineSeconds": pod_deadline,
        "terminationGracePeriodSeconds": 60,
        "securityContext": {
            "runAsNonRoot": True,
            "runAsUser": UID,
            "runAsGroup": UID,
            "fsGroup": UID,
            "seccompProfile": {"type": "RuntimeDefault"},
        },
        "initContainers": sidecars,
        "containers": [simcore],
        "volumes": volumes,
    }
    if settings.image_pull_secrets:
        pod_spec["imagePullSecrets"] = [{"name": s} for s in settings.image_pull_secrets]
    if execution.node_selector:
        pod_spec["nodeSelector"] = dict(execution.node_selector)
    if execution.tolerations:
        pod_spec["tolerations"] = [
            t.model_dump(mode="json", by_alias=True, exclude_none=True) for t in execution.tolerations
        ]
    if execution.affinity:
        pod_spec["affinity"] = copy.deepcopy(execution.affinity)
    if execution.priority_class_name:
        pod_spec["priorityClassName"] = execution.priority_class_name
    if execution.service_account_name:
        pod_spec["serviceAccountName"] = execution.service_account_name
        pod_spec["automountServiceAccountToken"] = True  # workload identity reads the account's token
    exit_codes = {"containerName": "simcore", "operator": "In"}
    return {
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": {
            "name": name,
            "namespace": body["metadata"].get("namespace"),
            "labels": job_labels,
            "annotations": {RUNS_PER_POD_ANNOTATION: str(per_pod), RUNS_ANNOTATION: str(runs)},
            "ownerReferences": [owner_reference(body)],
        },
        "spec": {
            "completionMode": "Indexed",
            "completions": total,
            "parallelism": parallelism,
            "backoffLimitPerIndex": spec.execution.retries,
            **(
                {"maxFailedIndexes": execution.max_failed_indexes}
                if execution.max_failed_indexes is not None
                else {}
            ),
            "podFailurePolicy": {
                "rules": [
                    # bad input is the same for every index: the whole Job fails at once
                    {
                        "action": "FailJob",
                        "onExitCodes": {**exit_codes, "values": [int(ExitCode.BAD_INPUT)]},
                    },
                    # ran and a required criterion failed: the index fails, never retried
                    {
                        "action": "FailIndex",
                        "onExitCodes": {**exit_codes, "values": [int(ExitCode.FAILED)]},
                    },
                    # infrastructure error: counts towards backoffLimitPerIndex (execution.retries)
                    {
                        "action": "Count",
                        "onExitCodes": {**exit_codes, "values": [int(ExitCode.INFRASTRUCTURE)]},
                    },
                    # evicted or preempted: not the run's fault, retried without counting
                    {
                        "action": "Ignore",
                        "onPodConditions": [{"type": "DisruptionTarget", "status": "True"}],
                    },
                ]
            },
            "activeDeadlineSeconds": pod_deadline * waves * attempts + 600,
            "ttlSecondsAfterFinished": settings.job_ttl_seconds,
            "suspend": bool(spec.suspend or spec.execution.queue_name),
            "template": {
                "metadata": {"labels": labels},
                "spec": pod_spec,
            },
        },
    }
