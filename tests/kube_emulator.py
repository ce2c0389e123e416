"""A Kubernetes API for the operator tests: kmock's KubernetesEmulator with its known gaps filled, run on
a background event loop, plus a Job controller + kubelet that runs each index's pod as local processes.

Gaps of kmock 0.8 filled here (test side only):
- objects get `uid`, `creationTimestamp`, `generation` and a `resourceVersion` that grows with every
  change (kopf's and the kubernetes client's consistency checks need them); create answers 201;
- the resources are registered for discovery (kind, namespaced, status subresource);
- kmock misparses the cluster-scoped Namespace paths (`/api/v1/namespaces[/NAME]` as a namespace
  prefix): `parse_path` is wrapped so they address the `namespaces` resource (kopf lists and watches
  Namespaces when it serves named namespaces, and serves only those that exist).
No garbage collector: owner references are asserted, not acted on.

Stricter than kmock: every create and patch is validated as an API server would before it is stored
(tests/apiserver.py): built-in kinds against the Kubernetes OpenAPI schemas (strict), SimulationRuns against
the shipped CRD (crds/simulationrun.yaml: its structural schema and its CEL rules, `oldSelf` on update); a
refused request answers 422 Invalid with the field errors, and `CarlosEmulator.refused` keeps them.
"""

from __future__ import annotations

import asyncio
import base64
import collections
import datetime as dt
import itertools
import os
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiohttp.web
import kmock
from kmock._internal import enums, k8s, parsing, rendering

from tests.apiserver import Invalid, merge_patch, shipped_crd, validate_builtin
from tests.kubelet import Kubelet

RESOURCES = {
    "carlos.dev/v1alpha1/simulationruns": kmock.ResourceInfo(
        kind="SimulationRun",
        namespaced=True,
        singular="simulationrun",
        subresources={"status"},
        verbs={"get", "list", "watch", "create", "patch", "update", "delete"},
    ),
    "batch/v1/jobs": kmock.ResourceInfo(
        kind="Job",
        namespaced=True,
        singular="job",
        subresources={"status"},
        verbs={"get", "list", "watch", "create", "patch", "delete"},
    ),
    "v1/configmaps": kmock.ResourceInfo(
        kind="ConfigMap", namespaced=True, singular="configmap", verbs={"get", "create", "delete"}
    ),
    "v1/pods": kmock.ResourceInfo(kind="Pod", namespaced=True, singular="pod", verbs={"list", "create"}),
    "v1/secrets": kmock.ResourceInfo(
        kind="Secret", namespaced=True, singular="secret", verbs={"get", "create"}
    ),
    "v1/events": kmock.ResourceInfo(kind="Event", namespaced=True, singular="event", verbs={"create"}),
    "v1/namespaces": kmock.ResourceInfo(
        kind="Namespace", namespaced=False, singular="namespace", verbs={"get", "list"}
    ),
}


_parse_path = parsing.parse_path


def _parse_path_with_namespaces(path: str) -> parsing.ParsedPath:
    parts = path.strip("/").split("/")
    if parts[:3] == ["api", "v1", "namespaces"] and len(parts) <= 4:
        return parsing.ParsedPath("", "v1", "namespaces", None, parts[3] if len(parts) == 4 else None, None)
    return _parse_path(path)


parsing.parse_path = _parse_path_with_namespaces  # rendering calls parsing.parse_path at request time


def matches(selector: str | None, labels: dict[str, str] | None) -> bool:
    """A label selector as the API server reads it: `key`, `!key`, `key=value`, `key!=value`, comma-joined."""
    labels = labels or {}
    for term in (selector or "").split(","):
        term = term.strip()
        if not term:
            continue
        if "!=" in term:
            key, value = term.split("!=", 1)
            if labels.get(key.strip()) == value.strip():
                return False
        elif "=" in term:
            key, value = term.replace("==", "=").split("=", 1)
            if labels.get(key.strip()) != value.strip():
                return False
        elif term.startswith("!"):
            if term[1:] in labels:
                return False
        elif term not in labels:
            return False
    return True


def _now() -> str:
    return dt.datetime.now(tz=dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


class CarlosEmulator(kmock.KubernetesEmulator):
    """KubernetesEmulator + uid, creationTimestamp, generation, growing resourceVersion, 201 on create,
    and a bounded request history: kmock matches every request against its whole request log (O(history)
    per request: ~80 ms per GET after 300 requests), which these tests and the benchmark never read."""

    HISTORY = 2

    _versions = itertools.count(1)

    def __attrs_post_init__(self) -> None:
        super().__attrs_post_init__()
        self.refused: list[str] = []  # the problems of every request refused as invalid
        self.validate = True
        self.calls: collections.Counter[tuple[str, str]] = collections.Counter()  # (action, plural) → count
        self.selectors: list[tuple[str, str]] = []  # (plural, labelSelector) of every list and watch
        # injected failures: (action, plural, subresource or "", HTTP status, labelSelector the request must
        # carry or "" for any), each answered once, in order
        self.faults: list[tuple[str, str, str, int, str]] = []
        self.injected: list[tuple[str, str, str, int, str]] = []  # the faults answered so far

    async def _serve_list(self, request: rendering.Request) -> Any:
        """kmock's list, then the label selector applied (the API server selects, kmock does not)."""
        result = await super()._serve_list(request)
        selector = request.params.get("labelSelector")
        if selector and isinstance(result, dict):
            result["items"] = [i for i in result["items"] if matches(selector, i["metadata"].get("labels"))]
        limit = request.params.get("limit")
        if limit and isinstance(result, dict) and str(limit).isdigit():
            result["items"] = result["items"][: int(limit)]
        return result

    async def _serve_watch(self, request: rendering.Request) -> Any:
        assert request.resource is not None
        status = self._fault(request)
        if status is not None:  # as the API server ends a watch whose resourceVersion is too old: 200 + ERROR
            yield {
                "type": "ERROR",
                "object": {
                    "kind": "Status",
                    "apiVersion": "v1",
                    "status": "Failure",
                    "code": status,
                    "reason": "Expired" if status == 410 else "InternalError",
                    "message": "injected fault",
                },
            }
            return
        selector = request.params.get("labelSelector")
        async for event in super()._serve_watch(request):
            if (
                not selector
                or not isinstance(event, dict)
                or matches(selector, event.get("object", {}).get("metadata", {}).get("labels"))
            ):
                yield event

    def _check(self, request: rendering.Request) -> None:
        """Validate the object a create or patch would store; raise 422 as the API server does."""
        assert request.resource is not None
        res = request.resource
        group_version = f"{res.group}/{res.version}" if res.group else str(res.version)
        kind = RESOURCES.get(f"{group_version}/{res.plural}")
        old: dict[str, Any] | None = None
        if request.action == enums.action.CREATE:
            new = dict(request.data)
        else:
            key = (request.resource, request.namespace, request.name)
            if key not in self._objects or self._objects[key].deleted:
                return  # kmock answers 404
            old = dict(self._objects[key].raw)
            new = merge_patch(old, request.data)
            if request.subresource == "status":
                new["spec"] = old.get("spec")  # the status subresource never changes spec
            elif "status" in (kind.subresources if kind else set()):
                new["status"] = old.get("status")  # nor the main resource the status
                new = {k: v for k, v in new.items() if v is not None}
        if kind is not None:
            new.setdefault("kind", kind.kind)
            new.setdefault("apiVersion", group_version)
        try:
            if new.get("kind") == "SimulationRun":
                shipped_crd().validate(new, old)
            else:
                validate_builtin(new)
        except Invalid as exc:
            self.refused.append(str(exc))
            raise k8s.KubernetesError(status=422, reason="Invalid", message=str(exc)) from None

    def _fault(self, request: rendering.Request) -> int | None:
        """The status of the first injected fault this request matches (removed: each is answered once)."""
        assert request.resource is not None
        action = str(request.action.value if request.action else request.method)
        call = (action, request.resource.plural or "", request.subresource or "")
        selector = request.params.get("labelSelector", "")
        for position, fault in enumerate(self.faults):
            if fault[:3] == call and fault[4] in ("", selector):
                del self.faults[position]
                self.injected.append(fault)
                return fault[3]
        return None

    async def _handle(self, request: rendering.Request) -> aiohttp.web.StreamResponse:
        if len(self._requests) > 2 * self.HISTORY:
            del self._requests[: -self.HISTORY]
        if request.resource is not None:
            action = str(request.action.value if request.action else request.method)
            self.calls[(action, request.resource.plural or "")] += 1
            watch = request.action == enums.action.WATCH  # a watch's fault is an ERROR event (_serve_watch)
            status = None if watch else self._fault(request)
            if status is not None:
                reasons = {409: "Conflict", 410: "Expired", 429: "TooManyRequests", 500: "InternalError"}
                error = k8s.KubernetesError(
                    status=status, reason=reasons.get(status, "ServiceUnavailable"), message="injected fault"
                )
                return await self._render_error(error)
            if request.action in (enums.action.LIST, enums.action.WATCH):
                self.selectors.append(
                    (request.resource.plural or "", request.params.get("labelSelector", ""))
                )
        if request.resource is not None and isinstance(request.data, dict):
            if request.action == enums.action.CREATE:
                meta = request.data.setdefault("metadata", {})
                if not meta.get("name") and meta.get("generateName"):
                    meta["name"] = meta["generateName"] + uuid.uuid4().hex[:5]
                meta.setdefault("namespace", request.namespace)
                meta["uid"] = str(uuid.uuid4())
                meta["creationTimestamp"] = _now()
                meta["generation"] = 1
                meta["resourceVersion"] = str(next(self._versions))
            elif request.action == enums.action.UPDATE:
                meta = request.data.setdefault("metadata", {})
                meta["resourceVersion"] = str(next(self._versions))
                key = (request.resource, request.namespace, request.name)
                if request.subresource is None and "spec" in request.data and key in self._objects:
                    old = dict(self._objects[key].raw)  # ObjectsArray has no .get
                    if merge_patch(old.get("spec"), request.data["spec"]) != old.get("spec"):
                        generation = int(old.get("metadata", {}).get("generation") or 1)
                        meta["generation"] = generation + 1  # a spec change, as the API server counts
            if self.validate and request.action in (enums.action.CREATE, enums.action.UPDATE):
                try:
                    self._check(request)
                except k8s.KubernetesError as exc:
                    return await self._render_error(exc)
        response = await super()._handle(request)
        if request.action == enums.action.CREATE and response.status == 200 and not response.prepared:
            response.set_status(201)
        return response


def write_kubeconfig(path: Path, url: str) -> Path:
    path.write_text(
        f"""apiVersion: v1
kind: Config
clusters: [{{name: emulator, cluster: {{server: "{url}"}}}}]
users: [{{name: tester, user: {{token: test-token}}}}]
contexts: [{{name: emulator, context: {{cluster: emulator, user: tester, namespace: default}}}}]
current-context: emulator
"""
    )
    return path


class Cluster:
    """The emulator (and, on demand, the operator) on a background event loop."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name="emulator-loop", daemon=True)
        self._thread.start()
        self.emulator: CarlosEmulator | None = None
        self._server: Any = None
        self._operator: Any = None
        self.url = ""

    def _run(self, coro: Any, timeout: float = 60) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def start(self) -> str:
        async def start() -> str:
            self.emulator = CarlosEmulator()
            await self.emulator.__aenter__()
            for key, info in RESOURCES.items():
                self.emulator.resources[key] = info
            self._server = kmock.Server(self.emulator)
            await self._server.__aenter__()
            return str(self.emulator.url).rstrip("/")

        self.url = self._run(start())
        return self.url

    def start_operator(self, namespaces: list[str] | None = None) -> None:
        """kopf on its own thread and event loop (it waits for every task of its loop when stopping):
        cluster-wide, or serving `namespaces` (as `carlos operator --namespace NS`)."""
        import carlos_operator.handlers  # registers the handlers
        import kopf

        carlos_operator.handlers.WATCH_NAMESPACES[:] = list(namespaces or [])

        stop = threading.Event()

        def run() -> None:
            settings = kopf.OperatorSettings()
            settings.queueing.idle_timeout = 0.5  # per-object workers exit soon: a quick shutdown
            settings.queueing.exit_timeout = 0.5
            asyncio.run(
                kopf.operator(
                    clusterwide=not namespaces,
                    namespaces=namespaces or (),
                    standalone=True,
                    stop_flag=stop,
                    settings=settings,
                )
            )

        thread = threading.Thread(target=run, name="operator", daemon=True)
        thread.start()
        self._operator = (thread, stop)

    def stop_operator(self) -> None:
        if self._operator is None:
            return
        thread, stop = self._operator
        stop.set()
        thread.join(30)
        self._operator = None

    def objects(self, plural: str) -> list[dict[str, Any]]:
        assert self.emulator is not None
        out = []
        # a copy of the underlying dict is atomic under the GIL; iterating the view races the loop thread
        stored = dict(self.emulator.objects._objects)
        for (resource, _ns, _name), obj in stored.items():
            if resource.plural == plural and not obj.deleted:
                out.append(dict(obj.raw))
        return out

    def close(self) -> None:
        self.stop_operator()

        async def stop() -> None:
            if self._server is not None:
                await self._server.__aexit__(None, None, None)
            if self.emulator is not None:
                await self.emulator.__aexit__(None, None, None)

        try:
            self._run(stop())
        finally:
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(10)


@contextmanager
def cluster(tmp_path: Path) -> Iterator[Cluster]:
    c = Cluster()
    try:
        c.start()
        yield c
    finally:
        c.close()


@dataclass
class JobRunner:
    """The Job controller and kubelet: runs the indexes of each Job in the cluster as local pods (test
    kubelet), honouring parallelism, podFailurePolicy and backoffLimitPerIndex, and writes the Job status
    (completedIndexes, failedIndexes, active, conditions) as Kubernetes does."""

    kube: Any  # carlos_operator.kube.Kube
    workdir: Path
    extra_env: dict[str, str] = field(default_factory=dict)
    crash_first_attempt: set[int] = field(default_factory=set)  # indexes whose first simcore is killed
    #: completion index → a condition polled while its first simcore runs: SIGKILL once it holds
    #: (e.g. mid-slice, after the slice's first runs wrote their summaries)
    crash_first_attempt_when: dict[int, Callable[[], bool]] = field(default_factory=dict)
    attempts: dict[tuple[str, int], int] = field(default_factory=dict)
    _seen: set[str] = field(default_factory=set)
    _stop: threading.Event = field(default_factory=threading.Event)
    _threads: list[threading.Thread] = field(default_factory=list)
    errors: list[BaseException] = field(default_factory=list)

    def start(self) -> JobRunner:
        thread = threading.Thread(target=self._watch, name="job-runner", daemon=True)
        thread.start()
        self._threads.append(thread)
        return self

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(60)

    def _watch(self) -> None:
        while not self._stop.is_set():
            try:
                jobs = self.kube.batch.list_job_for_all_namespaces(_preload_content=False)
                import json

                for job in json.loads(jobs.data).get("items", []):
                    uid = job["metadata"]["uid"]
                    if uid in self._seen or job["spec"].get("suspend"):
                        continue
                    self._seen.add(uid)
                    thread = threading.Thread(target=self._run_job, args=(job,), daemon=True)
                    thread.start()
                    self._threads.append(thread)
            except Exception as exc:  # surfaced by the tests
                self.errors.append(exc)
            self._stop.wait(0.2)

    def _patch_status(self, job: dict[str, Any], status: dict[str, Any]) -> None:
        meta = job["metadata"]
        self.kube.batch.patch_namespaced_job_status(
            meta["name"], meta["namespace"], {"status": status}, _preload_content=False
        )

    def _run_job(self, job: dict[str, Any]) -> None:
        try:
            self._run_job_inner(job)
        except BaseException as exc:
            self.errors.append(exc)

    def _run_job_inner(self, job: dict[str, Any]) -> None:
        from carlos_operator.status import format_intervals

        meta, spec = job["metadata"], job["spec"]
        namespace = meta["namespace"]
        pod = spec["template"]["spec"]
        configmaps = {}
        for volume in pod.get("volumes", []):
            if "configMap" in volume:
                name = volume["configMap"]["name"]
                configmaps[name] = self.kube.read_configmap(namespace, name).get("data", {})
        secrets = {}
        for container in [*pod.get("initContainers", []), *pod["containers"]]:
            for source in container.get("envFrom", []):
                name = source["secretRef"]["name"]
                data = self.kube.read_secret_data(namespace, name)
                secrets[name] = {k: base64.b64encode(v.encode()).decode() for k, v in data.items()}
        rules = spec.get("podFailurePolicy", {}).get("rules", [])
        limit = int(spec.get("backoffLimitPerIndex", 0))
        max_failed = spec.get("maxFailedIndexes")
        job_failure: list[str] = []  # the reason the whole Job failed (FailJob, maxFailedIndexes)
        lock = threading.Lock()
        completed: list[int] = []
        failed: list[int] = []
        active = [0]
        counts = {"succeeded": 0, "failed": 0}
        started = _now()

        def publish() -> None:
            with lock:
                status = {
                    "startTime": started,
                    "active": active[0],
                    "completedIndexes": format_intervals(sorted(completed)),
                    "failedIndexes": format_intervals(sorted(failed)),
                    "succeeded": counts["succeeded"],
                    "failed": counts["failed"],
                }
            self._patch_status(job, status)

        def run_index(index: int) -> None:
            failures = 0
            while not job_failure:  # a failed Job starts no more pods
                key = (meta["uid"], index)
                self.attempts[key] = self.attempts.get(key, 0) + 1

                def on_start(name: str, proc: Any, key: tuple[str, int] = key) -> None:
                    if name == "simcore" and index in self.crash_first_attempt and self.attempts[key] == 1:
                        time.sleep(0.5)
                        proc.kill()
                    when = self.crash_first_attempt_when.get(index)
                    if name == "simcore" and when is not None and self.attempts[key] == 1:

                        def kill_when() -> None:
                            while proc.poll() is None:
                                if when():
                                    proc.kill()
                                    return
                                time.sleep(0.02)

                        threading.Thread(target=kill_when, daemon=True).start()

                kubelet = Kubelet(
                    configmaps=configmaps,
                    secrets=secrets,
                    workdir=self.workdir,
                    extra_env=self.extra_env,
                    on_start=on_start,
                )
                with lock:
                    active[0] += 1
                publish()
                result = kubelet.run_pod(pod, index=index, failures=failures)
                code = result.exit_codes["simcore"]
                exit_code = 128 + 9 if code < 0 else code
                with lock:
                    active[0] -= 1
                    if exit_code == 0:
                        counts["succeeded"] += 1
                        completed.append(index)
                        break
                    counts["failed"] += 1
                action = "Count"
                for rule in rules:
                    codes = rule.get("onExitCodes")
                    if codes and codes.get("operator") == "In" and exit_code in codes.get("values", []):
                        action = rule["action"]
                        break
                if action == "FailJob":
                    with lock:
                        failed.append(index)
                        job_failure.append("PodFailurePolicy")
                    break
                if action == "FailIndex" or (action == "Count" and failures + 1 > limit):
                    with lock:
                        failed.append(index)
                        if max_failed is not None and len(failed) > int(max_failed):
                            job_failure.append("MaxFailedIndexesExceeded")
                    break
                if action == "Count":
                    failures += 1
            publish()

        with ThreadPoolExecutor(max_workers=int(spec.get("parallelism") or 1)) as pool:
            list(pool.map(run_index, range(int(spec["completions"]))))
        publish()
        finished = "Failed" if failed else "Complete"
        condition = {
            "type": finished,
            "status": "True",
            "reason": (job_failure[0] if job_failure else "FailedIndexes") if failed else "",
            "lastTransitionTime": _now(),
        }
        if finished == "Failed":
            conditions = [condition]
        else:
            conditions = [
                {"type": "SuccessCriteriaMet", "status": "True", "lastTransitionTime": _now()},
                condition,
            ]
        status: dict[str, Any] = {"conditions": conditions}
        if finished == "Complete":
            status["completionTime"] = _now()
        self._patch_status(job, status)


def wait_for(predicate: Any, timeout: float, what: str, interval: float = 0.2) -> Any:
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        last = predicate()
        if last:
            return last
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout} s waiting for {what} (last: {last!r})")


def operator_env(s3_endpoint: str) -> dict[str, str]:
    return {
        "CARLOS_DEFAULT_S3_ENDPOINT": s3_endpoint,
        "CARLOS_RESYNC_SECONDS": "0.5",
        "CARLOS_SECRET_NAMESPACES": "default",
        "CARLOS_IMAGE_SIMCORE": "local/simcore:test",
        "CARLOS_IMAGE_BRIDGE": "local/bridge:test",
        "CARLOS_IMAGE_RECORDER": "local/recorder:test",
    }


__all__ = ["Cluster", "JobRunner", "cluster", "operator_env", "os", "wait_for", "write_kubeconfig"]
