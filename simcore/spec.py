"""The SimulationRun resource: the single source of truth for manifests, the CRD and the docs.

The same YAML is taken by `carlos run` and by `kubectl apply`, so the models follow Kubernetes API
conventions: camelCase fields, `spec`/`status`, defaults stated in every field's description, and unknown
fields rejected with their path.
"""

import re
from collections.abc import Callable
from typing import Annotated, Any, Literal, Self

from pydantic import (
    AfterValidator,
    AliasChoices,
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


def _new_list() -> list[Any]:
    """An empty list as a field's default. Not `default_factory=list`: pydantic inspects a factory's signature,
    and the signature of a builtin is parsed from its text (Python's tokenizer, ~10 ms of start-up)."""
    return []


def _new_dict() -> dict[Any, Any]:
    """An empty dict as a field's default (see _new_list)."""
    return {}


API_GROUP = "carlos.dev"
API_VERSION = "v1alpha1"
KIND = "SimulationRun"

_DNS_LABEL = re.compile(r"^[a-z0-9]([-a-z0-9]*[a-z0-9])?$")
_DNS_PREFIX = re.compile(r"^[a-z0-9][-a-z0-9]*$")
_PARAM_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class Model(BaseModel):
    """Base of every spec model: camelCase on the wire, unknown fields rejected, immutable."""

    model_config = ConfigDict(
        extra="forbid",
        alias_generator=to_camel,
        populate_by_name=True,
        frozen=True,
        validate_default=True,
        # validators and serializers are built on first use: a manifest's validation builds SimulationRun's
        # (nested models included) instead of every class's at import (~0.1 s of `carlos run`'s start-up)
        defer_build=True,
    )

    @model_validator(mode="before")
    @classmethod
    def _no_booleans_as_numbers(cls, data: Any) -> Any:
        """YAML's true/false are not numbers: `stepSeconds: true` is refused instead of becoming 1.0."""
        if isinstance(data, dict):
            for name, field in cls.model_fields.items():
                key = field.alias or name
                value = data.get(key, data.get(name))
                if isinstance(value, bool) and _is_number_type(field.annotation):
                    raise ValueError(f"{key}: {str(value).lower()} is a boolean, not a number")
        return data


# `v2x` as in the topics and metrics (`/carlos/<entity>/v2x/…`, `v2x.*`), not the camelCase generator's `v2X`,
# which manifests written against the earlier CRD use (still read)
_V2X_KEYS = AliasChoices("v2x", "v2X")


def _is_number_type(annotation: Any) -> bool:
    """float, int, or one of them or None."""
    if annotation in (float, int):
        return True
    arguments = getattr(annotation, "__args__", ())
    return bool(arguments) and all(a in (float, int, type(None)) for a in arguments)


def _dns_name(pattern: re.Pattern[str], limit: int, what: str) -> Callable[[str], str]:
    """A validator of a Kubernetes name (or name prefix) with its rule in the message."""

    def check(value: str) -> str:
        if len(value) > limit or not pattern.match(value):
            raise ValueError(
                f"{value[:80]!r} is not {what}: use at most {limit} lowercase letters, digits and '-', "
                + (
                    "starting and ending with a letter or digit"
                    if pattern is _DNS_LABEL
                    else "starting with a letter or digit"
                )
            )
        return value

    return check


_dns_label = _dns_name(_DNS_LABEL, 63, "a DNS-1123 label")
_dns_prefix = _dns_name(_DNS_PREFIX, 58, "a name prefix")


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

    model_config = ConfigDict(
        extra="ignore", alias_generator=to_camel, populate_by_name=True, frozen=True, defer_build=True
    )

    name: DnsLabel | None = Field(
        None, description="Name of the run; the results go under `<output>/<name>/`."
    )
    generate_name: Annotated[str, AfterValidator(_dns_prefix)] | None = Field(
        None, description="Prefix for a generated name (GitOps: a changed spec is a new run)."
    )
    namespace: str | None = Field(None, description="Namespace of the resource (cluster only).")
    labels: dict[str, str] = Field(default_factory=_new_dict, description="Labels.")
    annotations: dict[str, str] = Field(default_factory=_new_dict, description="Annotations.")


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
        default_factory=_new_dict,
        description="ParameterDeclaration overrides for this scenario only; they win over `spec.parameters`.",
    )
    optional: bool = Field(
        False,
        description=(
            "An optional scenario's failure does not fail the run: it is reported as skipped in JUnit. "
            "Default false."
        ),
    )
    criteria: list["Criterion"] = Field(  # defined below: resolved when the model is built
        default_factory=_new_list,
        description="Criteria for this scenario only, in addition to `evaluation.criteria`.",
    )

    @model_validator(mode="after")
    def _one_source(self) -> Self:
        if (self.openscenario is None) == (self.config_map_ref is None):
            raise ValueError("set exactly one of 'openscenario' and 'configMapRef'")
        return self


class Sweep(Model):
    """The parameter space: every permutation of the matrix is one run of every scenario.

    Index order: scenarios in manifest order; within a scenario the permutations in mixed radix over the
    matrix keys in manifest order, last key fastest; repetitions innermost."""

    matrix: dict[ParameterName, Annotated[list[ParameterValue], Field(min_length=1, max_length=100_000)]] = (
        Field(
            default_factory=_new_dict,
            description="Parameter name → the values it takes. Every permutation is run. Default: none (one run).",
        )
    )
    repetitions: int = Field(
        1,
        ge=1,
        le=100_000,
        description="Runs of each permutation with seeds `simulation.seed + k`, k = 0…repetitions-1. Default 1.",
    )
    distribution: str | None = Field(
        None,
        max_length=4096,
        description=(
            "An OpenSCENARIO ParameterValueDistribution file (.xosc; absolute, or relative to the manifest's "
            "folder, made absolute when the manifest is loaded): each of its permutations (deterministic sets and ranges, or stochastic draws from "
            "its randomSeed, else simulation.seed, and the permutation number) is crossed with the matrix, "
            "after its keys. Its ScenarioFile is not used: the scenarios are spec.scenarios. Default: none."
        ),
    )
    distribution_config_map_ref: ConfigMapKeyRef | None = Field(
        None,
        description=(
            "The distribution file (as `distribution`) from a ConfigMap key (cluster only; `carlos submit` "
            "packs a local distribution file there). Default: none."
        ),
    )

    indexes: list[Annotated[int, Field(ge=0)]] | None = Field(
        None,
        min_length=1,
        max_length=100_000,
        description=(
            "Run only these indexes of the sweep, in this order: index k of this run is index `indexes[k]` "
            "of the whole sweep (the same scenario, parameters and seed). `carlos rerun --failed` sets it "
            "for a run on a cluster. Default: every index."
        ),
    )

    @model_validator(mode="after")
    def _one_distribution(self) -> Self:
        if self.distribution is not None and self.distribution_config_map_ref is not None:
            raise ValueError("set at most one of 'distribution' and 'distributionConfigMapRef'")
        return self

    @field_validator("matrix")
    @classmethod
    def _bounded(cls, matrix: dict[str, list[ParameterValue]]) -> dict[str, list[ParameterValue]]:
        total = 1
        for values in matrix.values():
            total *= len(values)
        if total > 10_000_000:
            raise ValueError(f"the matrix has {total} permutations; at most 10,000,000 are allowed")
        return matrix


class SearchParameter(Model):
    """One dimension of a search: a continuous or integer range, or categorical values."""

    name: ParameterName = Field(description="The ParameterDeclaration searched over.")
    min: float | None = Field(
        None, description="Lowest value. Default: from the declaration's ValueConstraints/Range."
    )
    max: float | None = Field(
        None, description="Highest value. Default: from the declaration's ValueConstraints/Range."
    )
    integer: bool = Field(False, description="Whole numbers only (min and max included). Default false.")
    values: list[ParameterValue] | None = Field(
        None,
        description="Categorical: the values to choose from (instead of min/max). Default: none.",
        min_length=1,
        max_length=1000,
    )

    @model_validator(mode="after")
    def _range(self) -> Self:
        if self.values is not None and (self.min is not None or self.max is not None):
            raise ValueError(f"{self.name}: set either 'values' or 'min'/'max', not both")
        if self.min is not None and self.max is not None and not self.min < self.max:
            raise ValueError(
                f"{self.name}: the range [{self.min:g}, {self.max:g}] is empty: min must be below max"
            )
        if self.integer and self.values is not None:
            raise ValueError(f"{self.name}: 'integer' applies to a min/max range, not to 'values'")
        return self


class SearchObjective(Model):
    """What the search minimises or maximises."""

    metric: str = Field(
        "margin",
        description=(
            "A run metric (e.g. `minTimeToCollision`), or `margin`: the smallest margin of the run's required "
            "criteria (threshold distance, negative when violated). Default margin."
        ),
        min_length=1,
        max_length=200,
    )
    direction: Literal["minimize", "maximize"] = Field(
        "minimize", description="Minimise (find failures) or maximise the metric. Default minimize."
    )


class Search(Model):
    """An adaptive search over the scenario's parameters (falsification): runs in rounds of `batchSize`,
    each round's points chosen by an optuna sampler from the results so far. Instead of `sweep`."""

    parameters: list[SearchParameter] = Field(
        default_factory=_new_list,
        description=(
            "The dimensions. Default: every ParameterDeclaration of the scenario with a range "
            "(ValueConstraints or Range)."
        ),
        max_length=64,
    )
    objective: SearchObjective = Field(
        default_factory=SearchObjective, description="The objective. Default: minimise the criteria margin."
    )
    budget: int = Field(100, ge=1, le=10_000, description="Runs in total. Default 100.")
    batch_size: int = Field(16, ge=1, le=1000, description="Runs per round. Default 16.")
    strategy: Literal["random", "lhs", "tpe", "cmaes", "gp", "boundary"] = Field(
        "tpe",
        description=(
            "`random` (uniform), `lhs` (scrambled Sobol quasi-random), `tpe`, `cmaes`, `gp` (needs PyTorch), "
            "or `boundary` (TPE on the absolute criteria margin: samples the pass/fail boundary). Default tpe."
        ),
    )
    seed: int | None = Field(
        None, ge=0, le=2**31 - 1, description="Seed of the sampler. Default: simulation.seed."
    )

    @model_validator(mode="after")
    def _unique(self) -> Self:
        names = [p.name for p in self.parameters]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"parameters searched twice: {', '.join(twice)}")
        return self


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


_CRITERION = re.compile(
    r"^\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*(>=|<=|==|!=|>|<)\s*(\S+)(?:\s+within\s+(\S+?)\s*m)?\s*$"
)


def _criterion_from_string(value: Any) -> Any:
    if isinstance(value, str):
        match = _CRITERION.match(value)
        if not match:
            raise ValueError(
                f"{value!r} is not a criterion: write 'METRIC OP VALUE', e.g. 'minDistance >= 2.0' "
                "(OP is one of >=, >, <=, <, ==, !=)"
            )
        metric, op, raw, within = match.groups()
        if within is not None:
            # `detection.recall >= 0.9 within 50 m` is the metric over objects closer than 50 m,
            # `v2x.packetDeliveryRatio >= 0.9 within 300 m` the one over links shorter than 300 m
            if not metric.startswith(("detection.", "v2x.packetDeliveryRatio")):
                raise ValueError(
                    f"{value!r}: 'within N m' applies to detection.* and v2x.packetDeliveryRatio metrics only"
                )
            try:
                reach = float(within)
            except ValueError as exc:
                raise ValueError(f"{value!r}: {within!r} in 'within N m' is not a number") from exc
            if not 0 < reach <= 1000:
                raise ValueError(f"{value!r}: the distance in 'within N m' must be in (0, 1000]")
            metric = f"{metric}.0-{int(reach) if reach.is_integer() else reach:g}m"
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
            "maxSpeed, stopTriggered, simSeconds, detection.recall, v2x.packetDeliveryRatio, … (see README). As a "
            "string, `detection.recall >= 0.9 within 50 m` is the metric `detection.recall.0-50m` (objects "
            "closer than 50 m)."
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


class DetectionEvaluation(Model):
    """Scoring an object detector under test against a lidar's ground truth (metrics `detection.*`)."""

    sensor: str = Field(
        description=(
            "The lidar whose ground truth is the reference, as `ENTITY/SENSOR` (e.g. `Ego/lidar`): its "
            "`/carlos/<entity>/<sensor>/objects`, in the sensor frame."
        ),
        pattern=r"^[^/\s]+/[A-Za-z][A-Za-z0-9_]*$",
        max_length=200,
    )
    topic: str = Field(
        description=(
            "The detector's output topic (vision_msgs/Detection3DArray in the sensor frame, header stamp = "
            "the point cloud's stamp), e.g. `/carlos/sut/detections`."
        ),
        pattern=r"^/[A-Za-z0-9_/]+$",
        max_length=200,
    )
    iou: Literal["bev", "3d"] = Field(
        "bev", description="Overlap measure for matching: bird's-eye-view or 3D IoU. Default bev."
    )
    iou_threshold: float = Field(
        0.3, gt=0, le=1, description="A matched pair with at least this IoU is a true positive. Default 0.3."
    )
    min_points: int = Field(
        5,
        ge=0,
        le=100_000,
        description=(
            "Ground-truth objects with fewer lidar points are not required (a detection of one is neither "
            "a true nor a false positive). Default 5."
        ),
    )
    max_range: float = Field(
        100.0,
        gt=0,
        le=1000,
        description="Objects and detections farther than this (m, BEV) are ignored. Default 100.",
    )
    bands: list[Annotated[float, Field(ge=0)]] = Field(
        default_factory=lambda: [0.0, 30.0, 60.0],
        description=(
            "Distance band edges (m): metrics per band are named `detection.recall.0-30m`, … (the last band "
            "runs to `maxRange`). Default [0, 30, 60]."
        ),
        max_length=20,
    )

    @field_validator("bands")
    @classmethod
    def _increasing(cls, bands: list[float]) -> list[float]:
        if any(b >= a for a, b in zip(bands[1:], bands, strict=False)):
            raise ValueError("band edges must be strictly increasing")
        return bands


class Evaluation(Model):
    """How a run's verdict is decided."""

    criteria: list[Criterion] = Field(
        default_factory=_new_list,
        description="Criteria every run must meet. Default: none (a run that completes without error passes).",
    )
    detection: DetectionEvaluation | None = Field(
        None,
        description=(
            "Score an object detector (`systemUnderTest`) against a lidar's ground truth: matching by IoU "
            "(Hungarian), metrics `detection.precision`, `detection.recall`, `detection.meanIou`, "
            "`detection.meanCenterError`, per distance band and class. Default: none."
        ),
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
    # None (not False) by default: a manifest that does not ask for OSI dumps as before (`carlos.spec` in the
    # recording keeps its bytes)
    osi: bool | None = Field(
        None,
        description=(
            "Also record ASAM OSI ground truth: channel `/carlos/osi/ground_truth`, protobuf `osi3.GroundTruth` "
            "(OSI 3.8.0), one message per step (needs `pip install 'carlos-sim[omega]'`). Default false."
        ),
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


#: a Kubernetes resource quantity: 2, "500m", "4Gi", "1.5"
_QUANTITY = r"^[0-9]+(\.[0-9]+)?(m|k|M|G|T|P|E|Ki|Mi|Gi|Ti|Pi|Ei)?$"
Quantity = StrictInt | Annotated[StrictStr, Field(pattern=_QUANTITY, max_length=32)]
_DNS_SUBDOMAIN = r"^[a-z0-9]([-a-z0-9]*[a-z0-9])?(\.[a-z0-9]([-a-z0-9]*[a-z0-9])?)*$"


class ResourceList(Model):
    """Amounts of compute resources, as in a Kubernetes container (`cpu: 2`, `memory: 4Gi`)."""

    cpu: Quantity | None = Field(None, description="CPU cores: 2, `500m` (millicores).")
    memory: Quantity | None = Field(None, description="Memory: `512Mi`, `4Gi`.")
    ephemeral_storage: Quantity | None = Field(
        None,
        alias="ephemeral-storage",
        description="Local scratch disk (the pod's /scratch and container logs): `10Gi`.",
    )


class Resources(Model):
    """Requests and limits of a run's working containers (cluster only)."""

    requests: ResourceList | None = Field(
        None, description="What the scheduler reserves (and Kueue and ResourceQuotas count)."
    )
    limits: ResourceList | None = Field(None, description="The most a container may use.")


class Toleration(Model):
    """A taint the run's pods tolerate, as in a Kubernetes pod."""

    key: str | None = Field(None, max_length=317, description="Taint key; empty with operator Exists: all.")
    operator: Literal["Exists", "Equal"] = Field("Equal", description="Exists or Equal. Default Equal.")
    value: str | None = Field(None, max_length=63, description="Taint value (operator Equal).")
    effect: Literal["NoSchedule", "PreferNoSchedule", "NoExecute"] | None = Field(
        None, description="Taint effect. Default: every effect."
    )
    toleration_seconds: int | None = Field(
        None, ge=0, description="NoExecute: how long the pod stays bound after the taint appears."
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
    repeat: int = Field(
        1,
        ge=1,
        le=100,
        description=(
            "Runs of every point (scenario, parameters, repetition) to find flaky runs: a point whose verdict "
            "differs between its runs is flagged flaky, and runs of a point with the same seed must record "
            "the same messages (determinism). Repeats are innermost in the index order. Default 1."
        ),
    )
    seed_policy: Literal["same", "vary"] = Field(
        "same",
        description=(
            "Seeds of a point's repeats: `same` (every repeat with the point's seed: checks determinism) or "
            "`vary` (repeat r with seed + r × sweep.repetitions, so that no two runs share a seed). "
            "Default same."
        ),
    )
    max_failed_indexes: int | None = Field(
        None,
        ge=0,
        le=100_000,
        description=(
            "Cluster: the Job fails as soon as more runs than this have failed (test failures, errors); the "
            "remaining runs are not started. Default: no limit (every run is tried)."
        ),
    )
    runs_per_pod: int | None = Field(
        None,
        ge=1,
        le=100_000,
        description=(
            "Cluster: runs one pod executes one after another (a contiguous slice of the indexes, the "
            "simulator kept warm across it; each index still has its own results). Default: chosen from "
            "the plan so that a pod works for minutes and a Job has at most 1,000 pods."
        ),
    )
    resources: Resources | None = Field(
        None,
        description=(
            "Cluster: requests and limits of the simcore container and of the system under test (the bridge "
            "and the recorder get the operator's sidecar defaults). Default: the operator's defaults (Helm "
            "value runPods.resources)."
        ),
    )
    node_selector: dict[str, Annotated[str, Field(max_length=63)]] | None = Field(
        None, description="Cluster: node labels the run's pods need."
    )
    tolerations: list[Toleration] | None = Field(None, description="Cluster: taints the run's pods tolerate.")
    affinity: dict[str, Any] | None = Field(
        None,
        description=(
            "Cluster: the pods' affinity (nodeAffinity, podAffinity, podAntiAffinity), as in a Kubernetes pod; "
            "checked by the API server when the Job is created."
        ),
    )
    priority_class_name: str | None = Field(
        None, max_length=253, pattern=_DNS_SUBDOMAIN, description="Cluster: PriorityClass of the run's pods."
    )
    service_account_name: str | None = Field(
        None,
        max_length=253,
        pattern=_DNS_SUBDOMAIN,
        description=(
            "Cluster: ServiceAccount of the run's pods (e.g. for cloud workload identity); its token is then "
            "mounted. Default: the namespace's default account, without a token."
        ),
    )


_SENSOR_NAME = r"^[A-Za-z][A-Za-z0-9_]*$"


class Mount(Model):
    """Where a sensor sits on its entity: a pose in `<entity>/base_link` (the reference point; x forward,
    y left, z up; for vehicles the rear axle on the ground)."""

    x: float = Field(0.0, ge=-100, le=100, description="Forward offset, m. Default 0.")
    y: float = Field(0.0, ge=-100, le=100, description="Left offset, m. Default 0.")
    z: float = Field(2.0, ge=-100, le=100, description="Height, m. Default 2.0.")
    roll: float = Field(0.0, ge=-180, le=180, description="Roll, degrees. Default 0.")
    pitch: float = Field(0.0, ge=-90, le=90, description="Pitch, degrees (positive: nose down). Default 0.")
    yaw: float = Field(0.0, ge=-180, le=180, description="Yaw, degrees (positive: to the left). Default 0.")


class _SensorBase(Model):
    name: str = Field(
        description=(
            "Sensor name, unique per entity; topics `/carlos/<entity>/<name>/…`, frame `<entity>/<name>`."
        ),
        pattern=_SENSOR_NAME,
        max_length=63,
    )
    entity: str | None = Field(
        None,
        description="The scenario entity carrying the sensor. Default: the ego (`simulation.ego`).",
        min_length=1,
        max_length=200,
    )
    mount: Mount = Field(default_factory=Mount, description="Mounting pose on the entity.")
    range_min: float = Field(
        0.5, ge=0, le=100, description="Returns closer than this (m) are dropped. Default 0.5."
    )
    range_max: float = Field(120.0, gt=0, le=2000, description="Maximum range, m. Default 120.")

    @model_validator(mode="after")
    def _ranges(self) -> Any:
        if self.range_min >= self.range_max:
            raise ValueError(f"rangeMin ({self.range_min}) must be below rangeMax ({self.range_max})")
        return self


class LidarSensor(_SensorBase):
    """A spinning lidar simulated by raycasting: one sweep per rotation, published as
    `sensor_msgs/PointCloud2` (x, y, z, intensity, time, object_id, ring, label) on
    `/carlos/<entity>/<name>/points`, with its ground truth (`…/objects`, `…/objects/info`)."""

    type: Literal["lidar"] = Field(description="`lidar`.")
    channels: int = Field(32, ge=1, le=256, description="Number of lasers (rings). Default 32.")
    vertical_angles: list[Annotated[float, Field(ge=-90, le=90)]] | None = Field(
        None,
        description=(
            "Elevation of every channel, degrees (one per channel). Default: `channels` angles spread "
            "uniformly over `verticalFov`."
        ),
        max_length=256,
    )
    vertical_fov: tuple[Annotated[float, Field(ge=-90, le=90)], Annotated[float, Field(ge=-90, le=90)]] = (
        Field(
            (-25.0, 15.0),
            description="Lowest and highest elevation, degrees, when `verticalAngles` is not set. Default [-25, 15].",
        )
    )
    horizontal_resolution: int = Field(
        1024, ge=1, le=16_384, description="Firings per channel per revolution (columns). Default 1024."
    )
    horizontal_fov: float = Field(
        360.0, gt=0, le=360, description="Horizontal field of view, degrees, centred on x. Default 360."
    )
    rotation_rate: float = Field(
        10.0, gt=0, le=100, description="Revolutions per second = point clouds per second (Hz). Default 10."
    )
    range_noise: float = Field(
        0.02, ge=0, le=10, description="Standard deviation of Gaussian range noise, m (seeded). Default 0.02."
    )
    dropout: float = Field(
        0.0, ge=0, le=1, description="Probability that a return is lost (seeded). Default 0."
    )
    motion_distortion: bool = Field(
        False,
        description=(
            "Fire every column from the pose the sensor had at its firing time within the sweep (the carrier "
            "moving with its current speed and yaw rate), points expressed in the frame at the sweep's end, "
            "`time` field = firing time relative to the stamp. Default false (the whole sweep at the stamp)."
        ),
    )
    ground_truth: bool = Field(
        True,
        description=(
            "Publish the ground-truth object list in the sensor frame (`…/objects`: box, class; "
            "`…/objects/info`: velocity, lidar points, occlusion ratio). Default true."
        ),
    )
    point_fields: list[Literal["x", "y", "z", "intensity", "time", "object_id", "ring", "label"]] | None = (
        Field(
            None,
            description=(
                "The PointCloud2 fields to publish and record, packed in this canonical order without padding "
                "(x, y, z required; e.g. `[x, y, z, intensity]`: 16 bytes a point, the common XYZI layout). "
                "Default: all eight (x, y, z, intensity, time, object_id, ring, label; 28 bytes a point)."
            ),
            max_length=8,
        )
    )

    @model_validator(mode="after")
    def _point_fields(self) -> Self:
        fields = self.point_fields
        if fields is not None:
            missing = [f for f in ("x", "y", "z") if f not in fields]
            if missing:
                raise ValueError(f"pointFields lacks {', '.join(missing)}: x, y and z are required")
            if len(set(fields)) != len(fields):
                raise ValueError("pointFields names a field twice")
        return self

    @model_validator(mode="after")
    def _angles(self) -> Self:
        if self.vertical_angles is not None and len(self.vertical_angles) != self.channels:
            raise ValueError(
                f"verticalAngles has {len(self.vertical_angles)} angles but channels is {self.channels}: "
                "give one angle per channel"
            )
        low, high = self.vertical_fov
        if low > high:
            raise ValueError(f"verticalFov [{low}, {high}]: the lowest angle comes first")
        return self


class CameraSensor(_SensorBase):
    """A pinhole depth and semantic camera simulated by raycasting: `sensor_msgs/Image` depth (32FC1, metres
    along the optical axis, NaN without a return) on `/carlos/<entity>/<name>/image`, the class of every
    pixel (mono8, class ids as the lidar labels) on `…/labels`, and `sensor_msgs/CameraInfo` on
    `…/camera_info`; frame `<entity>/<name>_optical` (z forward, x right, y down)."""

    type: Literal["camera"] = Field(description="`camera`.")
    width: int = Field(640, ge=1, le=8192, description="Image width, pixels. Default 640.")
    height: int = Field(480, ge=1, le=8192, description="Image height, pixels. Default 480.")
    horizontal_fov: float = Field(
        90.0, gt=1, lt=179, description="Horizontal field of view, degrees. Default 90."
    )
    rate: float = Field(10.0, gt=0, le=100, description="Images per second (Hz). Default 10.")


Sensor = Annotated[LidarSensor | CameraSensor, Field(discriminator="type")]


#: A number, or `$name`: the value of the scenario parameter `name` in each run (so a sweep can vary it).
NumberOrParameter = StrictFloat | StrictInt | Annotated[str, Field(pattern=r"^\$[A-Za-z_][A-Za-z0-9_]*$")]


class GeoOrigin(Model):
    """The WGS84 position of the map origin (the map frame is the local east/north plane there)."""

    latitude: float = Field(ge=-90, le=90, description="Latitude of the map origin, degrees.")
    longitude: float = Field(ge=-180, le=180, description="Longitude of the map origin, degrees.")
    altitude: float = Field(0.0, ge=-1000, le=10000, description="Altitude of z = 0, m. Default 0.")


class V2XChannel(Model):
    """The radio channel: log-distance path loss from a free-space reference, shadowing, fading, blocked
    line of sight, latency, jitter and a channel-busy limit. Numbers may be `$parameters`."""

    frequency_hz: float = Field(5.9e9, gt=1e6, le=1e11, description="Carrier frequency, Hz. Default 5.9e9.")
    tx_power_dbm: NumberOrParameter = Field(23.0, description="Transmit power, dBm. Default 23.")
    antenna_gain_db: float = Field(
        0.0, ge=-30, le=30, description="Antenna gain of each side (transmit and receive), dB. Default 0."
    )
    sensitivity_dbm: NumberOrParameter = Field(-90.0, description="Receiver sensitivity, dBm. Default -90.")
    path_loss_exponent: NumberOrParameter = Field(
        2.7, description="Path-loss exponent (2 free space, 2.7-3.5 urban). Default 2.7."
    )
    reference_distance: float = Field(
        1.0, gt=0, le=1000, description="Free-space reference distance d0, m. Default 1."
    )
    shadowing_sigma_db: NumberOrParameter = Field(
        4.0, description="Log-normal shadowing standard deviation, dB (0: none). Default 4."
    )
    fading_m: float | None = Field(
        None,
        gt=0,
        le=100,
        description="Nakagami-m fading of the received power (1: Rayleigh). Default: none.",
    )
    line_of_sight: bool = Field(
        True,
        description=(
            "Links whose straight line crosses an entity box or the road scene (surface, OpenDRIVE objects) "
            "lose `nlosLossDb`. Default true."
        ),
    )
    nlos_loss_db: NumberOrParameter = Field(
        20.0, description="Extra loss without line of sight, dB. Default 20."
    )
    latency_seconds: float = Field(0.002, ge=0, le=10, description="Delivery latency, s. Default 0.002.")
    jitter_seconds: float = Field(
        0.001, ge=0, le=10, description="Extra uniform random delay up to this, s. Default 0.001."
    )
    max_messages_per_second: float | None = Field(
        None,
        gt=0,
        le=1e6,
        description="Channel busy: a receiver takes at most this many messages per second (the strongest). Default: no limit.",
    )


class V2XStation(Model):
    """A scenario entity that takes part in V2X."""

    entity: str = Field(description="Scenario entity name.", min_length=1, max_length=256)
    cam: bool = Field(True, description="Send CAMs (ETSI EN 302 637-2 generation rules). Default true.")
    denm: bool = Field(
        True, description="Send DENMs on its hazards (hard braking, stationary). Default true."
    )
    cpm: bool = Field(
        False,
        description="Send CPMs of the objects it perceives (ground truth in line of sight). Default false.",
    )
    perception_range: float = Field(
        50.0, gt=0, le=1000, description="Range of its perception for CPMs, m. Default 50."
    )


class V2X(Model):
    """V2X: stations, message generation and the radio channel."""

    stations: list[V2XStation] | None = Field(
        None,
        description="Entities that take part. Default: every vehicle (CAM and DENM).",
        max_length=1000,
    )
    channel: V2XChannel = Field(default_factory=V2XChannel, description="The radio channel.")
    origin: GeoOrigin | None = Field(
        None,
        description=(
            "WGS84 position of the map origin. Default: the OpenDRIVE header's geoReference, else "
            "latitude 0, longitude 0."
        ),
    )
    hard_braking: float = Field(
        4.0, gt=0, le=20, description="Deceleration that raises a hard-braking DENM, m/s². Default 4."
    )
    ego_sensor_range: float = Field(
        50.0,
        gt=0,
        le=1000,
        description=(
            "Range of the ego's own sensors for the CPM coverage metric (objects in line of sight within it "
            "count as seen). Default 50."
        ),
    )


class RoadPose(Model):
    """A position on the OpenDRIVE road: road id, s along the reference line, t to the left of it."""

    road_id: str = Field(description="OpenDRIVE road id.", min_length=1, max_length=256)
    s: NumberOrParameter = Field(description="Distance along the road's reference line, m.")
    t: NumberOrParameter = Field(0.0, description="Lateral offset, m (positive: left). Default 0.")


class WorldPosition(Model):
    """A position in the map frame (ENU)."""

    x: NumberOrParameter = Field(description="East, m.")
    y: NumberOrParameter = Field(description="North, m.")
    z: NumberOrParameter = Field(0.0, description="Ground height, m. Default 0.")


class RsuV2X(Model):
    """The V2X station of a roadside unit."""

    cam: bool = Field(True, description="Send CAMs (every second). Default true.")
    cpm: bool = Field(True, description="Send CPMs of the objects it perceives. Default true.")
    perception_range: float = Field(
        80.0,
        gt=0,
        le=1000,
        description=(
            "Range of its perception for CPMs (ground truth in line of sight from its mast, or what "
            "`perceptionSensor` saw), m. Default 80."
        ),
    )
    perception_sensor: str | None = Field(
        None,
        pattern=_SENSOR_NAME,
        max_length=63,
        description=(
            "One of the unit's lidars (with ground truth): its CPMs then describe the objects with at least "
            "`perceptionMinPoints` points in that lidar's latest sweep (within `perceptionRange`). Default: "
            "ground truth in line of sight from the mast."
        ),
    )
    perception_min_points: int = Field(
        3, ge=1, le=100_000, description="Lidar points an object needs to be perceived. Default 3."
    )


class Infrastructure(Model):
    """A roadside unit: a fixed pose, optional sensors and an optional V2X station."""

    name: DnsLabel = Field(description="Name (topics `/carlos/infrastructure/<name>/…`).")
    position: WorldPosition | None = Field(None, description="Where it stands (map frame); or `road`.")
    road: RoadPose | None = Field(None, description="Where it stands on the road; or `position`.")
    height: NumberOrParameter = Field(
        6.0, description="Height of the mast (the V2X antenna) above ground, m. Default 6."
    )
    yaw: NumberOrParameter = Field(
        0.0, description="Orientation, degrees counter-clockwise from east. Default 0."
    )
    sensors: list[Sensor] = Field(
        default_factory=_new_list,
        description=(
            "Sensors on the unit (lidar, camera; fields as in `spec.sensors` without `entity`), `mount` "
            "relative to the unit's foot and yaw (e.g. `mount: {z: 6}` at the top of a 6 m mast): "
            "topics `/carlos/infrastructure/<name>/<sensor>/…`, frame `<name>/<sensor>` (a static "
            "transform from `map`). Default: none."
        ),
        max_length=16,
    )
    v2x: RsuV2X | None = Field(
        None, alias="v2x", validation_alias=_V2X_KEYS, description="Its V2X station. Default: none."
    )

    @model_validator(mode="after")
    def _one_pose(self) -> Self:
        if (self.position is None) == (self.road is None):
            raise ValueError(f"infrastructure {self.name!r}: give exactly one of position and road")
        names: set[str] = set()
        for sensor in self.sensors:
            if sensor.entity is not None:
                raise ValueError(
                    f"infrastructure {self.name!r}: sensor {sensor.name!r} stands on the unit; leave out entity"
                )
            if sensor.name in names:
                raise ValueError(f"infrastructure {self.name!r}: sensor name {sensor.name!r} is used twice")
            names.add(sensor.name)
        wanted = self.v2x.perception_sensor if self.v2x is not None else None
        if wanted is not None and not any(
            isinstance(s, LidarSensor) and s.name == wanted and s.ground_truth for s in self.sensors
        ):
            raise ValueError(
                f"infrastructure {self.name!r}: v2x.perceptionSensor {wanted!r} names no lidar with ground "
                "truth among its sensors"
            )
        return self


#: Environment variables CARLOS sets in a run pod's containers for their wiring (transport, discovery):
#: a system under test may not set them (any `CARLOS_…` name is reserved too).
RESERVED_ENV = frozenset(
    {"ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "CYCLONEDDS_URI", "RMW_IMPLEMENTATION"}
)


class SecretKeyRef(Model):
    """One key of a Secret in the run's namespace, by reference: the kubelet puts its value in the
    container; CARLOS never reads it."""

    name: DnsLabel = Field(description="Name of the Secret.")
    key: str = Field(
        description="Key in the Secret.", min_length=1, max_length=253, pattern=r"^[-._a-zA-Z0-9]+$"
    )


class EnvVar(Model):
    """An environment variable of the system under test: a `value`, or a `secretKeyRef` (cluster: the
    kubelet resolves it; local runs take the variable of the same name from the environment `carlos run`
    was started in)."""

    name: str = Field(
        description="Variable name (letters, digits, '_'; not CARLOS_* or the ROS 2/DDS wiring variables).",
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        max_length=256,
    )
    value: str | None = Field(None, description="The value.", max_length=32768)
    secret_key_ref: SecretKeyRef | None = Field(None, description="The value from a Secret's key.")

    @model_validator(mode="after")
    def _one_source(self) -> Self:
        if (self.value is None) == (self.secret_key_ref is None):
            raise ValueError(f"{self.name}: set exactly one of 'value' and 'secretKeyRef'")
        if self.name.startswith("CARLOS_") or self.name in RESERVED_ENV:
            raise ValueError(
                f"{self.name} is set by CARLOS to wire the run's pod (transport, ROS 2 discovery): "
                "choose another name"
            )
        return self


class SystemUnderTest(Model):
    """The software under test. It talks to the simulation through topics only.

    Locally (embedded executor) it is an in-process node: `module` names a class `module:Class`, constructed
    as `Class(bus, **parameters)` before the first frame (the bus has `advertise`/`subscribe`, messages
    are the ROS 2 types of `simcore.transport.messages.TYPESTORE`), and its `close()`, if it has one, is
    called after the last frame. On Kubernetes it is a container of the run's pod: `image` and `command`."""

    name: DnsLabel = Field("sut", description="Name in logs and pods. Default `sut`.")
    module: str | None = Field(
        None,
        description="In-process node as `package.module:Class` (local runs), e.g. `examples.detector:Detector`.",
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*:[A-Za-z_][A-Za-z0-9_]*$",
        max_length=300,
    )
    python_path: list[Annotated[str, Field(min_length=1, max_length=4096)]] = Field(
        default_factory=_new_list,
        description=(
            "Folders (relative to the manifest) put on the Python path before importing `module`. Default: "
            "none (the working directory is always searched)."
        ),
        max_length=20,
    )
    parameters: dict[Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")], Any] = Field(
        default_factory=_new_dict, description="Keyword arguments of the node (JSON values). Default: none."
    )
    image: str | None = Field(None, description="Container image (cluster).", min_length=1, max_length=1024)
    command: list[str] = Field(
        default_factory=_new_list, description="Container command (cluster). Default: the image's."
    )
    args: list[str] = Field(
        default_factory=_new_list, description="Container arguments (cluster). Default: none."
    )
    env: list[EnvVar] = Field(
        default_factory=_new_list,
        description=(
            "Environment of the node: its container's on a cluster; locally set in the run's process before "
            "the in-process node is constructed. Default: none."
        ),
        max_length=64,
    )

    @model_validator(mode="after")
    def _something_to_run(self) -> Self:
        if self.module is None and self.image is None:
            raise ValueError("set 'module' (in-process, local runs) or 'image' (cluster), or both")
        names = [e.name for e in self.env]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"env names must be unique: {', '.join(twice)} given more than once")
        return self


class Control(Model):
    """Closed loop: the system under test drives entities through `/carlos/<entity>/control`
    (ackermann_msgs/AckermannDriveStamped or geometry_msgs/Twist), moved by a kinematic bicycle model. The
    entities are those named here plus those whose scenario controller is external (ExternalController,
    InteractiveController, or the controller property `carlos.driver = external`) once it is activated."""

    entities: list[Annotated[str, Field(min_length=1, max_length=256)]] = Field(
        default_factory=_new_list,
        description="Scenario entities driven by the control input from the start. Default: none.",
        max_length=64,
    )
    mode: Literal["lockstep", "freeRunning"] = Field(
        "lockstep",
        description=(
            "`lockstep`: every step waits for each driven entity's command answering the frame just "
            "published (deterministic at any machine speed); `freeRunning`: the latest command holds, "
            "nothing waits. Default lockstep."
        ),
    )
    timeout_seconds: float = Field(
        10.0,
        gt=0,
        le=3600,
        description="Lockstep: wall seconds to wait for a step's command before the run fails. Default 10.",
    )
    startup_timeout_seconds: float = Field(
        60.0,
        gt=0,
        le=3600,
        description=(
            "Lockstep: wall seconds to wait before the first frame for the system under test to subscribe "
            "to the driven entities' odometry. Default 60."
        ),
    )


class SimulationRunSpec(Model):
    """What to simulate, how to sweep it, how to judge it and where the results go."""

    scenarios: list[ScenarioRef] = Field(
        description="The scenarios to run (at least one).", min_length=1, max_length=10_000
    )
    parameters: dict[ParameterName, ParameterValue] = Field(
        default_factory=_new_dict, description="ParameterDeclaration overrides for every scenario."
    )
    sweep: Sweep = Field(
        default_factory=Sweep, description="The parameter sweep. Default: one run per scenario."
    )
    search: Search | None = Field(
        None,
        description="Adaptive search over the scenario's parameters instead of a sweep. Default: none.",
    )
    simulation: Simulation = Field(default_factory=Simulation, description="Time stepping and seed.")
    sensors: list[Sensor] = Field(
        default_factory=_new_list,
        description=(
            "Sensors (lidar, camera) mounted on scenario entities, simulated by raycasting every frame they "
            "are due and published as ROS 2 messages. Default: none."
        ),
        max_length=64,
    )
    system_under_test: SystemUnderTest | None = Field(
        None,
        description="The software under test, talking to the simulation through topics only. Default: none.",
    )
    control: Control | None = Field(
        None,
        description=(
            "Closed loop (entities driven by the system under test's commands). Default: entities whose "
            "scenario controller is external follow commands free-running; none wait."
        ),
    )
    live: bool = Field(
        False,
        description=(
            "Serve the run live (Foxglove WebSocket on 127.0.0.1:8765), paced to real time, as "
            "`carlos run --live`. Local runs of one index only. Default false."
        ),
    )
    v2x: V2X | None = Field(
        None,
        alias="v2x",
        validation_alias=_V2X_KEYS,
        description=(
            "V2X: CAMs, CPMs and DENMs over a radio channel model, received per station on "
            "`/carlos/<entity>/v2x/{cam,cpm,denm}`, and the `v2x.*` metrics. Default: off."
        ),
    )
    infrastructure: list[Infrastructure] = Field(
        default_factory=_new_list,
        description="Roadside units (fixed poses, optional sensors and V2X station). Default: none.",
        max_length=100,
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
    def _unique_names(self) -> Self:
        seen: set[str] = set()
        for scenario in self.scenarios:
            if scenario.name in seen:
                raise ValueError(f"scenario name {scenario.name!r} is used twice; names must be unique")
            seen.add(scenario.name)
        sensors: set[tuple[str | None, str]] = set()
        for sensor in self.sensors:
            key = (sensor.entity, sensor.name)
            if key in sensors:
                raise ValueError(
                    f"sensor {sensor.name!r} is defined twice on the same entity; names must be unique"
                )
            sensors.add(key)
        if self.search is not None:
            if len(self.scenarios) != 1:
                raise ValueError("search: a search explores one scenario; list exactly one in spec.scenarios")
            if self.sweep != Sweep():
                raise ValueError("search: set either spec.search or spec.sweep, not both")
            needs_criteria = self.search.objective.metric == "margin" or self.search.strategy == "boundary"
            if needs_criteria and not [*self.evaluation.criteria, *self.scenarios[0].criteria]:
                raise ValueError(
                    "search.objective: the criteria margin needs criteria: add evaluation.criteria, or "
                    "set search.objective.metric to a run metric"
                )
        rsus: set[str] = set()
        for rsu in self.infrastructure:
            if rsu.name in rsus:
                raise ValueError(f"infrastructure name {rsu.name!r} is used twice; names must be unique")
            rsus.add(rsu.name)
            if rsu.v2x is not None and self.v2x is None:
                raise ValueError(
                    f"infrastructure {rsu.name!r} has a V2X station but V2X is off: add spec.v2x (e.g. `v2x: {{}}`)"
                )
        detection = self.evaluation.detection
        if detection is not None:
            entity, _, name = detection.sensor.partition("/")
            lidars = [
                s
                for s in self.sensors
                if isinstance(s, LidarSensor) and s.name == name and s.entity in (None, entity)
            ]
            if not lidars:
                raise ValueError(
                    f"evaluation.detection.sensor {detection.sensor!r} names no lidar of spec.sensors: add a lidar "
                    f"named {name!r} on {entity!r} (or on the ego)"
                )
            if not any(s.ground_truth for s in lidars):
                raise ValueError(
                    f"evaluation.detection.sensor {detection.sensor!r}: that lidar has groundTruth: false"
                )
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


class SearchStatus(Model):
    """Progress of a search (`spec.search`) on a cluster: one Indexed Job per round."""

    rounds: str | None = Field(
        None, description="Rounds whose results the study has / rounds in all, e.g. `2/4`."
    )
    rounds_done: int | None = Field(None, description="Rounds whose results the study has.")
    rounds_total: int | None = Field(None, description="Rounds in all: ceil(budget / batchSize).")
    round: int | None = Field(None, description="The round running now (0-based), while one runs.")
    evaluated: int | None = Field(None, description="Points whose results the study has.")
    best_objective: float | None = Field(
        None, description="The best objective value so far (the direction of spec.search.objective)."
    )
    best_index: int | None = Field(None, description="The index of the best point so far.")
    failures_found: int | None = Field(None, description="Evaluated points whose required criteria failed.")
    search_url: str | None = Field(
        None, alias="searchURL", description="Where search.json is, once the budget is spent."
    )


class SimulationRunStatus(Model):
    """Observed state, written by the operator (or by `carlos run` into the run-level summary)."""

    phase: Literal["Pending", "Running", "Succeeded", "Failed", "Suspended", "Unknown"] | None = Field(
        None,
        description=(
            "Run phase. Unknown: the run's Job is gone before every result was read (the run cannot finish; "
            "create it again under a new name)."
        ),
    )
    observed_generation: int | None = Field(
        None, description="The metadata.generation of the SimulationRun this status is about."
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
        default_factory=_new_list, description="The first failing indexes (at most 20) with their reason."
    )
    search: SearchStatus | None = Field(None, description="A search's rounds (spec.search).")
    conditions: list[Condition] = Field(default_factory=_new_list, description="Status conditions.")


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
