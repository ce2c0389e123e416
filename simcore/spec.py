"""The SimulationRun resource: the single source of truth for manifests, the CRD and the docs.

The same YAML is taken by `carlos run` and by `kubectl apply`, so the models follow Kubernetes API
conventions: camelCase fields, `spec`/`status`, defaults stated in every field's description, and unknown
fields rejected with their path.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StrictBool,
    StrictFloat,
    StrictInt,
    StrictStr,
    field_validator,
    model_validator,
)
from pydantic.alias_generators import to_camel

API_GROUP = "carlos.dev"
API_VERSION = "v1alpha1"
KIND = "SimulationRun"

_DNS_LABEL = re.compile(r"^[a-z0-9]([-a-z0-9]*[a-z0-9])?$")
_PARAM_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class Model(BaseModel):
    """Base of every spec model: camelCase on the wire, unknown fields rejected, immutable."""

    model_config = ConfigDict(
        extra="forbid",
        alias_generator=to_camel,
        populate_by_name=True,
        frozen=True,
        validate_default=True,
    )


def _dns_label(value: str) -> str:
    if len(value) > 63 or not _DNS_LABEL.match(value):
        raise ValueError(
            f"{value!r} is not a DNS-1123 label: use at most 63 lowercase letters, digits and '-', "
            "starting and ending with a letter or digit"
        )
    return value


def _param_name(value: str) -> str:
    name = value[1:] if value.startswith("$") else value
    if not _PARAM_NAME.match(name):
        raise ValueError(f"{value!r} is not an OpenSCENARIO parameter name (letters, digits, '_')")
    return name


DnsLabel = Annotated[str, AfterValidator(_dns_label)]
ParameterName = Annotated[str, AfterValidator(_param_name)]
#: An OpenSCENARIO parameter value. YAML scalars keep their type; OpenSCENARIO converts as it declares.
ParameterValue = StrictBool | StrictInt | StrictFloat | StrictStr


class ObjectMeta(BaseModel):
    """Kubernetes object metadata. Only `name`/`generateName` matter to CARLOS; the API server's own
    fields (uid, resourceVersion, managedFields…) are accepted and ignored."""

    model_config = ConfigDict(extra="ignore", alias_generator=to_camel, populate_by_name=True, frozen=True)

    name: DnsLabel | None = Field(
        None, description="Name of the run; the results go under `<output>/<name>/`."
    )
    generate_name: str | None = Field(
        None, description="Prefix for a generated name (GitOps: a changed spec is a new run)."
    )
    namespace: str | None = Field(None, description="Namespace of the resource (cluster only).")
    labels: dict[str, str] = Field(default_factory=dict, description="Labels.")
    annotations: dict[str, str] = Field(default_factory=dict, description="Annotations.")


class ConfigMapKeyRef(Model):
    """A key of a ConfigMap in the run's namespace (cluster only)."""

    name: DnsLabel = Field(description="Name of the ConfigMap.")
    key: str = Field(description="Key holding the OpenSCENARIO file.", min_length=1, max_length=253)


class ScenarioRef(Model):
    """One OpenSCENARIO scenario of the run. Every scenario runs every parameter permutation of the sweep."""

    name: DnsLabel = Field(description="Name of the scenario in results and reports; unique within the run.")
    openscenario: str | None = Field(
        None,
        description=(
            "The OpenSCENARIO (.xosc) file: a path relative to the manifest, a `file://` URL or an "
            "`s3://bucket/key` URL. Exactly one of `openscenario` and `configMapRef` is set."
        ),
        min_length=1,
        max_length=4096,
    )
    config_map_ref: ConfigMapKeyRef | None = Field(
        None, description="The OpenSCENARIO file from a ConfigMap key (cluster only)."
    )
    parameters: dict[ParameterName, ParameterValue] = Field(
        default_factory=dict,
        description="ParameterDeclaration overrides for this scenario only; they win over `spec.parameters`.",
    )
    optional: bool = Field(
        False,
        description=(
            "An optional scenario's failure does not fail the run: it is reported as skipped in JUnit. "
            "Default false."
        ),
    )
    criteria: list[Criterion] = Field(
        default_factory=list,
        description="Criteria for this scenario only, in addition to `evaluation.criteria`.",
    )

    @model_validator(mode="after")
    def _one_source(self) -> ScenarioRef:
        if (self.openscenario is None) == (self.config_map_ref is None):
            raise ValueError("set exactly one of 'openscenario' and 'configMapRef'")
        return self


class Sweep(Model):
    """The parameter space: every permutation of the matrix is one run of every scenario.

    Index order: scenarios in manifest order; within a scenario the permutations in mixed radix over the
    matrix keys in manifest order, last key fastest; repetitions innermost."""

    matrix: dict[ParameterName, Annotated[list[ParameterValue], Field(min_length=1, max_length=100_000)]] = (
        Field(
            default_factory=dict,
            description="Parameter name → the values it takes. Every permutation is run. Default: none (one run).",
        )
    )
    repetitions: int = Field(
        1,
        ge=1,
        le=100_000,
        description="Runs of each permutation with seeds `simulation.seed + k`, k = 0…repetitions-1. Default 1.",
    )

    @field_validator("matrix")
    @classmethod
    def _bounded(cls, matrix: dict[str, list[ParameterValue]]) -> dict[str, list[ParameterValue]]:
        total = 1
        for values in matrix.values():
            total *= len(values)
        if total > 10_000_000:
            raise ValueError(f"the matrix has {total} permutations; at most 10,000,000 are allowed")
        return matrix


class Simulation(Model):
    """Time stepping and randomness."""

    step_seconds: float = Field(
        0.05, gt=0, le=1.0, description="Fixed simulation step in seconds. Default 0.05."
    )
    max_seconds: float = Field(
        120.0,
        gt=0,
        le=86_400,
        description="Simulated time after which a run ends if the scenario's StopTrigger has not. Default 120.",
    )
    seed: int = Field(0, ge=0, le=2**31 - 1, description="Base random seed (SUMO, noise). Default 0.")
    ego: str | None = Field(
        None,
        description=(
            "The scenario entity the metrics are measured from. Default: the entity named `Ego`, `ego` or "
            "`hero`, else the first ScenarioObject."
        ),
    )


_CRITERION = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.]*)\s*(>=|<=|==|!=|>|<)\s*(\S+)\s*$")


def _criterion_from_string(value: Any) -> Any:
    if isinstance(value, str):
        match = _CRITERION.match(value)
        if not match:
            raise ValueError(
                f"{value!r} is not a criterion: write 'METRIC OP VALUE', e.g. 'minDistance >= 2.0' "
                "(OP is one of >=, >, <=, <, ==, !=)"
            )
        metric, op, raw = match.groups()
        number: float
        if raw.lower() in ("true", "false"):
            number = 1.0 if raw.lower() == "true" else 0.0
        else:
            try:
                number = float(raw)
            except ValueError as exc:
                raise ValueError(f"{value!r}: the value {raw!r} is not a number or true/false") from exc
        return {"name": value.strip(), "metric": metric, "operator": op, "value": number}
    return value


class CriterionModel(Model):
    """A pass/fail criterion on a run's metric. Also written as a string: `minDistance >= 2.0`."""

    name: str | None = Field(
        None, description="Name in reports. Default: the criterion as text.", max_length=200
    )
    metric: str = Field(
        description=(
            "Metric name: collision, minDistance, minTimeHeadway, minTimeToCollision, maxDeceleration, "
            "maxSpeed, stopTriggered, simSeconds (see README)."
        ),
        min_length=1,
        max_length=200,
    )
    operator: Literal[">=", ">", "<=", "<", "==", "!="] = Field(description="Comparison with `value`.")
    value: float = Field(description="Threshold; booleans are 1 (true) and 0 (false).")
    optional: bool = Field(
        False, description="An optional criterion's failure does not fail the run. Default false."
    )

    @property
    def label(self) -> str:
        return self.name or f"{self.metric} {self.operator} {self.value:g}"


Criterion = Annotated[CriterionModel, BeforeValidator(_criterion_from_string)]


class Evaluation(Model):
    """How a run's verdict is decided."""

    criteria: list[Criterion] = Field(
        default_factory=list,
        description="Criteria every run must meet. Default: none (a run that completes without error passes).",
    )


class Recording(Model):
    """What goes into each run's MCAP file."""

    enabled: bool = Field(True, description="Write `recording.mcap` for each run. Default true.")
    topics: list[str] = Field(
        default_factory=lambda: ["*"],
        description="Topic patterns to record (shell-style globs, e.g. `/carlos/*`). Default: every topic.",
    )
    compression: Literal["zstd", "lz4", "none"] = Field(
        "zstd", description="MCAP chunk compression. Default zstd."
    )


class SecretRef(Model):
    """A Secret in the run's namespace (by reference only: its values are never read into the spec)."""

    name: DnsLabel = Field(description="Name of the Secret (keys AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY).")


class Output(Model):
    """Where results go (object-store layout `<url>/<run-name>/<index>/…`)."""

    url: str = Field(
        "file://./results",
        description=(
            "`file://PATH` (relative to the working directory) or `s3://bucket/prefix`. Default "
            "`file://./results`."
        ),
        pattern=r"^(file|s3)://.+",
        max_length=2048,
    )
    endpoint: str | None = Field(
        None,
        description="S3 endpoint URL (MinIO, Ceph, SeaweedFS). Default: AWS_ENDPOINT_URL from the environment, else AWS.",
        pattern=r"^https?://.+",
    )
    region: str | None = Field(None, description="S3 region. Default: from the environment.")
    credentials_secret_ref: SecretRef | None = Field(
        None,
        description=(
            "Secret with the S3 credentials, mounted into the pods as environment (cluster). Locally the "
            "credentials come from the environment (AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY)."
        ),
    )


class Execution(Model):
    """How the runs are executed."""

    parallelism: int | None = Field(
        None, ge=1, le=10_000, description="Runs at the same time. Default: the number of cores (locally)."
    )
    retries: int = Field(
        1,
        ge=0,
        le=10,
        description=(
            "Retries of a run that failed for infrastructure reasons (exit code 3). Test failures (exit 1) "
            "and bad input (exit 2) are never retried. Default 1."
        ),
    )
    timeout_seconds: int = Field(
        3600,
        ge=1,
        le=7 * 86_400,
        description="Wall-clock limit of one run; a run past it is an error. Default 3600.",
    )
    queue_name: DnsLabel | None = Field(
        None,
        description=(
            "Kueue LocalQueue to submit the run's Job to (cluster only): the Job is created suspended with "
            "the label `kueue.x-k8s.io/queue-name` and Kueue admits it. Default: none (no Kueue)."
        ),
    )


class SimulationRunSpec(Model):
    """What to simulate, how to sweep it, how to judge it and where the results go."""

    scenarios: list[ScenarioRef] = Field(
        description="The scenarios to run (at least one).", min_length=1, max_length=10_000
    )
    parameters: dict[ParameterName, ParameterValue] = Field(
        default_factory=dict, description="ParameterDeclaration overrides for every scenario."
    )
    sweep: Sweep = Field(
        default_factory=Sweep, description="The parameter sweep. Default: one run per scenario."
    )
    simulation: Simulation = Field(default_factory=Simulation, description="Time stepping and seed.")
    sensors: list[dict[str, Any]] = Field(
        default_factory=list,
        description="Sensors (lidar, camera). Reserved for the sensors feature: a non-empty list is rejected today.",
        max_length=0,
    )
    evaluation: Evaluation = Field(default_factory=Evaluation, description="Verdict criteria.")
    recording: Recording = Field(default_factory=Recording, description="MCAP recording.")
    output: Output = Field(default_factory=Output, description="Where results go.")
    execution: Execution = Field(default_factory=Execution, description="Parallelism, retries, timeouts.")
    suspend: bool = Field(
        False,
        description=(
            "Cluster only: create the run's Job suspended (no pod starts); set to false to start it. The "
            "only field of `spec` that may change after creation. Default false."
        ),
    )

    @model_validator(mode="after")
    def _unique_names(self) -> SimulationRunSpec:
        seen: set[str] = set()
        for scenario in self.scenarios:
            if scenario.name in seen:
                raise ValueError(f"scenario name {scenario.name!r} is used twice; names must be unique")
            seen.add(scenario.name)
        return self


class Condition(Model):
    """A status condition, as in Kubernetes' Job and Kueue APIs."""

    type: str = Field(description="Condition type: Accepted, Running, Complete, Failed.")
    status: Literal["True", "False", "Unknown"] = Field(description="Condition status.")
    reason: str = Field("", description="One-word CamelCase reason.")
    message: str = Field("", description="Human-readable message.")
    last_transition_time: str | None = Field(None, description="When the condition last changed (RFC 3339).")


class IndexFailure(Model):
    """One failing index of a run and why."""

    index: int = Field(description="The run index.")
    scenario: str | None = Field(None, description="The scenario of the index.")
    status: str | None = Field(None, description="`failed` (a test failure) or `error`.")
    reason: str = Field("", description="The failing criteria or the error message.")


class SimulationRunStatus(Model):
    """Observed state, written by the operator (or by `carlos run` into the run-level summary)."""

    phase: Literal["Pending", "Running", "Succeeded", "Failed", "Suspended"] | None = Field(
        None, description="Run phase."
    )
    progress: str | None = Field(None, description="Finished runs / total, e.g. `12/50`.")
    total: int | None = Field(None, description="Number of runs (scenarios × permutations).")
    active: int | None = Field(None, description="Runs whose pods are running now.")
    succeeded: int | None = Field(
        None, description="Runs that ended with exit code 0 (every required criterion passed)."
    )
    failed: int | None = Field(
        None, description="Runs that ended unsuccessfully (test failure, bad input or error, after retries)."
    )
    passed: int | None = Field(None, description="Runs whose summary says passed.")
    test_failures: int | None = Field(None, description="Runs whose required criteria failed.")
    errors: int | None = Field(None, description="Runs that ended in an error.")
    start_time: str | None = Field(None, description="When the run's Job started (RFC 3339).")
    completion_time: str | None = Field(None, description="When the run finished (RFC 3339).")
    results_url: str | None = Field(
        None, alias="resultsURL", description="Where the results are: `<output>/<run>/`."
    )
    job_name: str | None = Field(None, description="Name of the run's Job.")
    failures: list[IndexFailure] = Field(
        default_factory=list, description="The first failing indexes (at most 20) with their reason."
    )
    conditions: list[Condition] = Field(default_factory=list, description="Status conditions.")


class SimulationRun(Model):
    """A batch of simulation runs: scenarios × parameter permutations, recorded and judged."""

    api_version: Literal["carlos.dev/v1alpha1"] = Field(description="carlos.dev/v1alpha1")
    kind: Literal["SimulationRun"] = Field(description="SimulationRun")
    metadata: ObjectMeta = Field(default_factory=ObjectMeta, description="Standard object metadata.")
    spec: SimulationRunSpec = Field(description="What to run.")
    status: SimulationRunStatus | None = Field(None, description="Observed state (written by CARLOS).")

    @property
    def name(self) -> str:
        if not self.metadata.name:
            raise ValueError("metadata.name is not set")
        return self.metadata.name


ScenarioRef.model_rebuild()
