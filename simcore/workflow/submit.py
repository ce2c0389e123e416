"""`carlos submit`: the manifest that runs locally, made runnable on a cluster.

A pod has no manifest directory, so every local scenario (a path relative to the manifest), the road
network and catalog files it names, and a local distribution file (`spec.sweep.distribution`) are packed
into one ConfigMap owned by the run (`<run>-inputs`, flat keys, the scenarios' relative paths rewritten to
those keys); each scenario becomes a `configMapRef`, the distribution a `distributionConfigMapRef` (the
operator reads it to expand the sweep and hands it to the pods beside the spec). `s3://` scenarios and absolute `file:///` paths (inside the image) stay.
A ConfigMap holds at most `CONFIGMAP_LIMIT` bytes; larger inputs are uploaded to the run's object store
(`<output>/<run>/inputs/`) and named by their `s3://` URL instead.

Objects are created the way that leaves no window without inputs: the SimulationRun suspended, then the
ConfigMap with an ownerReference to it (deleted with the run), then the run resumed unless the manifest
asked for `suspend: true`.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from simcore import kubeyaml
from simcore.errors import BadInput
from simcore.spec import SimulationRun

API_VERSION = "carlos.dev/v1alpha1"
GROUP, VERSION, PLURAL = "carlos.dev", "v1alpha1", "simulationruns"
#: Kubernetes refuses ConfigMaps over 1 MiB (data, keys and metadata): leave room for the metadata
CONFIGMAP_LIMIT = 1024 * 1024 - 16 * 1024
_KEY_CHARS = re.compile(r"[^-._a-zA-Z0-9]")


@dataclass
class Packed:
    """The objects to create: the SimulationRun and its inputs (key → text), and what goes to S3."""

    run: dict[str, Any]
    configmap_name: str
    files: dict[str, str] = field(default_factory=dict)
    uploads: dict[str, bytes] = field(default_factory=dict)  # object key below the output URL → bytes

    def configmap(self, owner_uid: str | None = None) -> dict[str, Any] | None:
        if not self.files:
            return None
        metadata: dict[str, Any] = {
            "name": self.configmap_name,
            "namespace": self.run["metadata"]["namespace"],
            "labels": {"carlos.dev/run": self.run["metadata"]["name"]},
        }
        if owner_uid is not None:
            metadata["ownerReferences"] = [
                {
                    "apiVersion": API_VERSION,
                    "kind": "SimulationRun",
                    "name": self.run["metadata"]["name"],
                    "uid": owner_uid,
                    "blockOwnerDeletion": True,
                }
            ]
        return {"apiVersion": "v1", "kind": "ConfigMap", "metadata": metadata, "data": dict(self.files)}

    def size(self) -> int:
        return sum(len(k) + len(v.encode()) for k, v in self.files.items())


def inputs_name(run_name: str) -> str:
    """`<run>-inputs`, shortened with a hash to stay a DNS label (pure)."""
    name = f"{run_name}-inputs"
    if len(name) <= 63:
        return name
    digest = hashlib.sha256(run_name.encode()).hexdigest()[:8]
    return f"{run_name[:46].rstrip('-')}-{digest}-inputs"


def _key(path: Path, taken: dict[str, Path]) -> str:
    """A ConfigMap key for `path`: its file name, made unique among the keys taken (pure but for `taken`)."""
    for existing, where in taken.items():
        if where == path:
            return existing
    base = _KEY_CHARS.sub("-", path.name) or "file"
    key, n = base, 2
    while key in taken:
        key, n = f"{n}-{base}", n + 1
    taken[key] = path
    return key


def _read_text(path: Path, file: str, where: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise BadInput(f"{path} not found", file=file, field=where) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"cannot read {path}: {exc}", file=file, field=where) from None


def _rewrite_attribute(text: str, tag: str, attribute: str, old: str, new: str) -> str:
    """`text` with `attribute="old"` of the first `<tag …>` element that has it replaced by `new`."""
    pattern = re.compile(rf"(<{tag}\b[^>]*\b{attribute}\s*=\s*)([\"']){re.escape(old)}\2", re.DOTALL)
    return pattern.sub(lambda m: f"{m.group(1)}{m.group(2)}{new}{m.group(2)}", text, count=1)


def _pack_scenario(
    path: Path, manifest: str, where: str, files: dict[str, str], taken: dict[str, Path]
) -> str:
    """Add the scenario, its road network and catalogs to `files` (paths rewritten to keys); its key."""
    from simcore.scenario.xosc_xml import read_xml

    text = _read_text(path, manifest, where)
    root = read_xml(path, what="OpenSCENARIO file")
    logic = root.find("RoadNetwork/LogicFile")
    relative = logic.get("filepath") if logic is not None else None
    if relative and not relative.startswith("$"):
        road = (path.parent / relative).resolve()
        road_key = _key(road, taken)
        files[road_key] = _read_text(road, str(path), "RoadNetwork/LogicFile")
        text = _rewrite_attribute(text, "LogicFile", "filepath", relative, road_key)
    for location in root.find("CatalogLocations") or []:
        directory = location.find("Directory")
        raw = directory.get("path") if directory is not None else None
        if not raw or raw.startswith("$"):
            continue
        folder = (path.parent / raw).resolve()
        for catalog in sorted(folder.glob("*.xosc")):
            files[_key(catalog, taken)] = _read_text(catalog, str(path), f"CatalogLocations/{location.tag}")
        text = _rewrite_attribute(text, "Directory", "path", raw, ".")
    key = _key(path, taken)
    files[key] = text
    return key


def pack(
    simulation_run: SimulationRun, manifest: Path, namespace: str, results_url: str | None = None
) -> Packed:
    """The SimulationRun object and its inputs for `namespace`, from a manifest loaded from `manifest`.

    Results go to `results_url` when given, else to the manifest's `output.url` when it is `s3://`, else to
    the operator's default output (a `file://` URL means nothing in a pod)."""
    base_dir = manifest.parent.resolve()
    sut = simulation_run.spec.system_under_test
    if sut is not None and not sut.image:
        raise BadInput(
            "a cluster runs the system under test as a container: set its image (module is for local runs)",
            file=str(manifest),
            field="spec.systemUnderTest.image",
        )
    if results_url is not None:
        if not results_url.startswith("s3://"):
            raise BadInput(
                f"{results_url!r}: on a cluster results go to s3://bucket/prefix", field="--results"
            )
        simulation_run = simulation_run.model_copy(
            update={
                "spec": simulation_run.spec.model_copy(
                    update={"output": simulation_run.spec.output.model_copy(update={"url": results_url})}
                )
            }
        )
    body = simulation_run.model_dump(mode="json", by_alias=True, exclude_none=True)
    body["apiVersion"], body["kind"] = API_VERSION, "SimulationRun"
    metadata = body.setdefault("metadata", {})
    metadata["namespace"] = namespace
    spec = body["spec"]
    if not str(spec.get("output", {}).get("url", "")).startswith("s3://"):
        spec.get("output", {}).pop("url", None)  # the operator's default output
    packed = Packed(run=body, configmap_name=inputs_name(simulation_run.name))
    taken: dict[str, Path] = {}
    for position, scenario in enumerate(simulation_run.spec.scenarios):
        source = scenario.openscenario
        if source is None or "://" in source:
            continue
        where = f"spec.scenarios[{position}].openscenario"
        key = _pack_scenario((base_dir / source).resolve(), str(manifest), where, packed.files, taken)
        ref = spec["scenarios"][position]
        ref.pop("openscenario")
        ref["configMapRef"] = {"name": packed.configmap_name, "key": key}
    distribution = simulation_run.spec.sweep.distribution
    if distribution is not None and "://" not in distribution:
        # made absolute when the manifest was loaded; the operator reads it from the ConfigMap
        path = (base_dir / distribution).resolve()
        key = _key(path, taken)
        packed.files[key] = _read_text(path, str(manifest), "spec.sweep.distribution")
        spec["sweep"].pop("distribution")
        spec["sweep"]["distributionConfigMapRef"] = {"name": packed.configmap_name, "key": key}
    if packed.size() > CONFIGMAP_LIMIT:
        _to_object_store(packed, simulation_run, str(manifest))
    return packed


def _to_object_store(packed: Packed, simulation_run: SimulationRun, manifest: str) -> None:
    """Inputs over the ConfigMap limit: every file to `<output>/<run>/inputs/<key>`, scenarios by URL."""
    url = str(packed.run["spec"].get("output", {}).get("url", ""))
    if not url.startswith("s3://"):
        raise BadInput(
            f"the scenarios and roads are {packed.size():,} bytes, over a ConfigMap's {CONFIGMAP_LIMIT:,}: set "
            "spec.output.url (or --results) to s3://bucket/prefix so that they are uploaded there",
            file=manifest,
            field="spec.output.url",
        )
    prefix = f"{simulation_run.name}/inputs"
    packed.uploads = {f"{prefix}/{key}": text.encode() for key, text in packed.files.items()}
    for ref in packed.run["spec"]["scenarios"]:
        cm = ref.get("configMapRef")
        if cm is not None and cm["name"] == packed.configmap_name:
            ref.pop("configMapRef")
            ref["openscenario"] = f"{url.rstrip('/')}/{prefix}/{cm['key']}"
    sweep = packed.run["spec"].get("sweep") or {}
    cm = sweep.get("distributionConfigMapRef")
    if cm is not None and cm["name"] == packed.configmap_name:
        sweep.pop("distributionConfigMapRef")
        sweep["distribution"] = f"{url.rstrip('/')}/{prefix}/{cm['key']}"
    packed.files = {}


def objects_yaml(packed: Packed) -> str:
    """`-o yaml`: the ConfigMap (its ownerReference to the run is set when it is created) and the run."""
    docs = [d for d in (packed.configmap(), packed.run) if d is not None]
    return "---\n".join(kubeyaml.dump(d, sort_keys=False) for d in docs)


def current_namespace() -> str:
    """The namespace of the kubeconfig's current context (as kubectl reads it), else `default`."""
    from kubernetes import config

    try:
        _, context = config.list_kube_config_contexts()
    except Exception:  # no kubeconfig (in-cluster, or none at all)
        return "default"
    return str((context or {}).get("context", {}).get("namespace") or "default")


def kube_clients() -> tuple[Any, Any]:
    """(CustomObjectsApi, CoreV1Api) configured as kubectl is: KUBECONFIG (several files merged) or
    ~/.kube/config and its current context, else the pod's service account."""
    from kubernetes import client, config

    try:
        config.load_kube_config()
    except Exception:
        try:
            config.load_incluster_config()
        except Exception as exc:
            raise BadInput(f"no Kubernetes configuration: {exc}", field="KUBECONFIG") from None
    return client.CustomObjectsApi(), client.CoreV1Api()


def create(packed: Packed) -> str:
    """Create the run (suspended), its ConfigMap owned by it, upload oversized inputs, resume the run.
    Returns the run's uid. Kubernetes errors become one-line CarlosErrors."""
    from kubernetes.client.exceptions import ApiException

    from simcore.errors import SimulationError

    namespace, name = packed.run["metadata"]["namespace"], packed.run["metadata"]["name"]
    custom, core = kube_clients()
    wanted_suspend = bool(packed.run["spec"].get("suspend", False))
    body = {**packed.run, "spec": {**packed.run["spec"], "suspend": True}}
    if packed.uploads:
        from simcore.store import StoreError, open_store

        out = packed.run["spec"]["output"]
        try:
            store = open_store(out["url"], endpoint=out.get("endpoint"), region=out.get("region"))
            for key, data in packed.uploads.items():
                store.put_bytes(key, data)
        except StoreError as exc:
            raise SimulationError(f"uploading the inputs: {exc}") from None
    try:
        created: Any = custom.create_namespaced_custom_object(GROUP, VERSION, namespace, PLURAL, body)
        uid = str(created["metadata"]["uid"])
        configmap: Any = packed.configmap(owner_uid=uid)  # the client takes plain dicts too
        if configmap is not None:
            core.create_namespaced_config_map(namespace, configmap)
        if not wanted_suspend:
            custom.patch_namespaced_custom_object(
                GROUP, VERSION, namespace, PLURAL, name, {"spec": {"suspend": False}}
            )
    except ApiException as exc:
        reason = exc.reason or ""
        if exc.status == 409:
            raise BadInput(
                f"SimulationRun {name!r} already exists in namespace {namespace!r}: change metadata.name",
                field="metadata.name",
            ) from None
        if exc.status in (400, 403, 404, 422):
            raise BadInput(f"the cluster refused {name!r}: {exc.status} {reason}", field="MANIFEST") from None
        raise SimulationError(f"Kubernetes API: {exc.status} {reason}") from None
    except Exception as exc:  # urllib3's connection errors: the API server is unreachable
        raise SimulationError(f"Kubernetes API unreachable: {type(exc).__name__}: {exc}") from None
    return uid
