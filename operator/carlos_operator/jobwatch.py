"""The operator's Job watch: only the Jobs it made, selected by the API server (label `carlos.dev/run`).

kopf filters a watch's labels on the client, so every Job of the cluster would be streamed to the operator;
this watch sends the label selector with the list and the watch, as `kubectl get jobs -l` does. One thread
per watched namespace (or one for every namespace): list (every Job → ADDED), then watch from the list's
resourceVersion; a 410 Gone (the version expired, also as the client's KeyError after an API server
restart) lists again; other errors retry with backoff.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any

from carlos_operator.builders import RUN_LABEL
from carlos_operator.kube import Kube

log = logging.getLogger("carlos.operator")

#: seconds a watch request stays open before it is renewed (the server closes it then)
WATCH_SECONDS = 60
MAX_BACKOFF_S = 30.0


class JobWatch:
    def __init__(
        self,
        kube: Kube,
        namespaces: Sequence[str],
        on_event: Callable[[str, dict[str, Any]], None],
        *,
        selector: str = RUN_LABEL,
    ) -> None:
        self.kube = kube
        self.namespaces: list[str | None] = list(namespaces) or [None]
        self.on_event = on_event
        self.selector = selector
        self.stop_flag = threading.Event()
        self.threads: list[threading.Thread] = []
        self._streams: dict[str | None, Any] = {}  # namespace → the open watch (closed by stop)

    def start(self) -> None:
        for namespace in self.namespaces:
            thread = threading.Thread(
                target=self._run, args=(namespace,), name=f"carlos-jobs-{namespace or 'all'}", daemon=True
            )
            thread.start()
            self.threads.append(thread)

    def stop(self) -> None:
        """Stop every thread and close their open watch connections (the server need not wait for them)."""
        self.stop_flag.set()
        for stream in list(self._streams.values()):
            stream.stop()
            response = getattr(stream, "_resp", None)
            if response is not None:
                with contextlib.suppress(Exception):
                    response.close()

    def _run(self, namespace: str | None) -> None:
        from kubernetes import watch
        from kubernetes.client.rest import ApiException

        version: str | None = None
        failures = 0
        while not self.stop_flag.is_set():
            try:
                if version is None:
                    listing = self.kube.list_jobs(namespace, self.selector)
                    version = str((listing.get("metadata") or {}).get("resourceVersion") or "") or None
                    for job in listing.get("items") or []:
                        self.on_event("ADDED", job)
                if namespace:
                    func: Any = self.kube.batch.list_namespaced_job
                    args: tuple[Any, ...] = (namespace,)
                else:
                    func, args = self.kube.batch.list_job_for_all_namespaces, ()
                stream = self._streams[namespace] = watch.Watch()
                for event in stream.stream(
                    func,
                    *args,
                    label_selector=self.selector,
                    resource_version=version,
                    timeout_seconds=WATCH_SECONDS,
                    _request_timeout=WATCH_SECONDS + 30,
                    deserialize=False,
                ):
                    if self.stop_flag.is_set():
                        stream.stop()
                        return
                    job = event.get("raw_object") or event.get("object") or {}
                    if event.get("type") == "ERROR":
                        if job.get("code") == 410:
                            version = None  # expired: list again
                        break
                    version = str((job.get("metadata") or {}).get("resourceVersion") or version or "") or None
                    self.on_event(str(event.get("type")), job)
                failures = 0
            except ApiException as exc:
                if exc.status == 410:
                    version = None
                    continue
                failures += 1
                log.warning(
                    "watching Jobs (%s) failed: %s; retrying", namespace or "all namespaces", exc.reason
                )
            except KeyError as exc:
                # a restarted API server answers a watch from an expired version with an ERROR event, which
                # the client library fails to read without deserialising (KeyError 'raw_object'): list again
                version = None
                failures += 1
                log.warning(
                    "watching Jobs (%s) failed: %r; listing again", namespace or "all namespaces", exc
                )
            except Exception as exc:
                failures += 1
                log.warning("watching Jobs (%s) failed: %s; retrying", namespace or "all namespaces", exc)
            if failures:
                self.stop_flag.wait(min(2.0**failures, MAX_BACKOFF_S))
