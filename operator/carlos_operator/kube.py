"""The few Kubernetes API calls the controller makes (the `kubernetes` client, plain dicts in and out).

Configuration: in-cluster (service account) when available, else the kubeconfig (KUBECONFIG). Every call
here needs a rule in `rbac.RBAC_RULES`.
"""

from __future__ import annotations

import base64
import contextlib
import datetime as dt
import json
import logging
import os
import threading
import uuid
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from kubernetes import client, config
from kubernetes.client.rest import ApiException

from simcore.spec import API_GROUP, API_VERSION, KIND

PLURAL = "simulationruns"
log = logging.getLogger("carlos.operator")


class Conflict(Exception):
    """The object exists already (HTTP 409)."""


class NotFound(Exception):
    """The object does not exist (HTTP 404)."""


def _raise(exc: ApiException) -> None:
    if exc.status == 409:
        raise Conflict(str(exc.reason)) from None
    if exc.status == 404:
        raise NotFound(str(exc.reason)) from None
    raise exc


def _json(response: Any) -> dict[str, Any]:
    data = response.data  # read to the end: the connection goes back to the pool
    return json.loads(data) if data else {}


def _done(response: Any) -> None:
    """A response whose body is not needed, read to the end so that its connection goes back to the pool:
    left unread (`_preload_content=False`), each one would hold a connection until collected and the next
    request would open a new one (a TLS handshake on both ends)."""
    response.read()
    response.release_conn()


def _any(body: dict[str, Any]) -> Any:
    """The client's typed signatures take model objects; it serialises plain dicts the same way."""
    return body


def now_rfc3339() -> str:
    return dt.datetime.now(tz=dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


class Kube:
    """Thread-safe thin wrapper (the underlying ApiClient pools its connections)."""

    def __init__(self, api_client: client.ApiClient | None = None, *, connections: int = 32) -> None:
        """`connections`: kept open to the API server, at least one per thread that calls it at once (the
        reconcile workers, the events thread, the Job watch): a request beyond the pool opens a connection of
        its own, a TLS handshake on both ends, and closes it after."""
        if api_client is None:
            try:
                config.load_incluster_config()
            except config.ConfigException:
                # KUBECONFIG at call time (the client reads it once, at import)
                config.load_kube_config(config_file=os.environ.get("KUBECONFIG") or None)
            configuration = client.Configuration.get_default_copy()
            configuration.connection_pool_maxsize = connections
            api_client = client.ApiClient(configuration)
        self.api_client = api_client
        self.core = client.CoreV1Api(api_client)
        self.batch = client.BatchV1Api(api_client)
        self.custom = client.CustomObjectsApi(api_client)
        self._lock = threading.Lock()
        # events are best effort: posted in order by one thread, off the reconcile workers' path
        self._events = ThreadPoolExecutor(max_workers=1, thread_name_prefix="carlos-events")

    def close(self, timeout: float = 10.0) -> None:
        """Post the events still queued (at most `timeout` seconds), then stop the events thread."""
        done = self._events.submit(lambda: None)
        with contextlib.suppress(Exception):
            done.result(timeout=timeout)
        self._events.shutdown(wait=False, cancel_futures=True)

    def _post(self, path: str, namespace: str, body: dict[str, Any]) -> Any:
        """POST `body` (a plain dict) to `path` (with `{namespace}`) as the client's generated `create_*`
        methods do (its authentication, headers, connection pool), but without their typed model: those
        validate the dict into a model and serialise it back, ~15 ms of CPU for a Job. The raw response;
        ApiException when it is not a success."""
        request = self.api_client.param_serialize(
            method="POST",
            resource_path=path,
            path_params={"namespace": namespace},
            header_params={"Accept": "application/json", "Content-Type": "application/json"},
            body=body,
            auth_settings=["BearerToken"],
        )
        response = self.api_client.call_api(*request)
        if not 200 <= response.status <= 299:
            response.read()
            raise ApiException.from_response(http_resp=response, body=None, data=None)
        return response.response

    # ConfigMaps and Jobs
    def create_configmap(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        try:
            return _json(self._post("/api/v1/namespaces/{namespace}/configmaps", namespace, body))
        except ApiException as exc:
            _raise(exc)
            raise

    def read_configmap(self, namespace: str, name: str) -> dict[str, Any]:
        try:
            return _json(self.core.read_namespaced_config_map(name, namespace, _preload_content=False))
        except ApiException as exc:
            _raise(exc)
            raise

    def create_job(self, namespace: str, body: dict[str, Any]) -> dict[str, Any]:
        try:
            return _json(self._post("/apis/batch/v1/namespaces/{namespace}/jobs", namespace, body))
        except ApiException as exc:
            _raise(exc)
            raise

    def read_job(self, namespace: str, name: str) -> dict[str, Any]:
        try:
            return _json(self.batch.read_namespaced_job(name, namespace, _preload_content=False))
        except ApiException as exc:
            _raise(exc)
            raise

    def patch_job(self, namespace: str, name: str, patch: dict[str, Any]) -> dict[str, Any]:
        try:
            return _json(self.batch.patch_namespaced_job(name, namespace, patch, _preload_content=False))
        except ApiException as exc:
            _raise(exc)
            raise

    def delete(self, kind: str, namespace: str, name: str, uid: str) -> None:
        """Delete a Job or ConfigMap, only if it is still the object `uid` (a precondition: never a newer
        one of the same name); its pods go in the background."""
        body = {"preconditions": {"uid": uid}, "propagationPolicy": "Background"}
        call = self.batch.delete_namespaced_job if kind == "Job" else self.core.delete_namespaced_config_map
        try:
            _done(call(name, namespace, body=_any(body), _preload_content=False))
        except ApiException as exc:
            if exc.status == 404:
                return
            _raise(exc)

    def list_pods(self, namespace: str, selector: str, limit: int) -> list[dict[str, Any]]:
        """At most `limit` pods of `namespace` matching the label `selector` (selected by the server)."""
        try:
            data = _json(
                self.core.list_namespaced_pod(
                    namespace, label_selector=selector, limit=limit, _preload_content=False
                )
            )
        except ApiException as exc:
            _raise(exc)
            raise
        return list(data.get("items") or [])[:limit]

    def list_jobs(self, namespace: str | None, selector: str) -> dict[str, Any]:
        """Jobs matching the label `selector` (selected by the server), in `namespace` or every one."""
        if namespace:
            call = self.batch.list_namespaced_job(namespace, label_selector=selector, _preload_content=False)
        else:
            call = self.batch.list_job_for_all_namespaces(label_selector=selector, _preload_content=False)
        return _json(call)

    # Secrets (the object-store credentials a run names)
    def read_secret_data(self, namespace: str, name: str) -> dict[str, str]:
        try:
            secret = _json(self.core.read_namespaced_secret(name, namespace, _preload_content=False))
        except ApiException as exc:
            _raise(exc)
            raise
        return {k: base64.b64decode(v).decode() for k, v in (secret.get("data") or {}).items()}

    # SimulationRun status and events
    def patch_run_status(self, namespace: str, name: str, status: dict[str, Any]) -> None:
        try:
            _done(
                self.custom.patch_namespaced_custom_object_status(
                    API_GROUP,
                    API_VERSION,
                    namespace,
                    PLURAL,
                    name,
                    {"status": status},
                    _preload_content=False,
                )
            )
        except ApiException as exc:
            _raise(exc)

    def event(self, run: dict[str, Any], kind: str, reason: str, message: str) -> None:
        meta = run["metadata"]
        stamp = now_rfc3339()
        body = {
            "apiVersion": "v1",
            "kind": "Event",
            "metadata": {
                "name": f"{meta['name']}.{uuid.uuid4().hex[:16]}",
                "namespace": meta.get("namespace"),
            },
            "involvedObject": {
                "apiVersion": f"{API_GROUP}/{API_VERSION}",
                "kind": KIND,
                "name": meta["name"],
                "namespace": meta.get("namespace"),
                "uid": meta.get("uid"),
            },
            "type": kind,
            "reason": reason,
            "message": message[:1024],
            "source": {"component": "carlos-operator"},
            "reportingComponent": "carlos-operator",
            "firstTimestamp": stamp,
            "lastTimestamp": stamp,
            "count": 1,
        }
        with contextlib.suppress(RuntimeError):  # closed: the operator stops
            self._events.submit(self._post_event, meta.get("namespace"), body)

    def _post_event(self, namespace: str, body: dict[str, Any]) -> None:
        try:
            _done(self._post("/api/v1/namespaces/{namespace}/events", namespace, body))
        except Exception as exc:  # events are best effort
            log.debug("posting event %s failed: %s", body["metadata"]["name"], exc)
