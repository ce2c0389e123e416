"""kopf handlers (thin): watch events in, the controller (controller.py) does the work.

Only event handlers: kopf keeps no handler state on the SimulationRuns and adds no finalizer, so deleting a
run never waits for the operator (owner references delete its Job and ConfigMap), and a restarted operator
simply sees every run again (kopf lists them first) and the controller adopts what exists.

The operator's Jobs are watched by jobwatch.py, not kopf: kopf filters labels on the client (every Job of
the cluster would be streamed), the JobWatch has the API server select them. `WATCH_NAMESPACES` (set by
`carlos operator` before kopf starts) names the namespaces it watches; empty: every namespace.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import threading
from typing import Any

import kopf

from carlos_operator import metrics
from carlos_operator.builders import OperatorSettings
from carlos_operator.controller import Controller, warm_up
from carlos_operator.jobwatch import JobWatch
from carlos_operator.kube import Kube
from simcore.spec import API_GROUP, API_VERSION

PLURAL = "simulationruns"
_controller: Controller | None = None
_jobs: JobWatch | None = None
#: the namespaces served (the same as kopf's); empty: every namespace
WATCH_NAMESPACES: list[str] = []


def _float_env(name: str, default: float) -> float:
    try:
        return float(os.environ.get(name) or default)
    except ValueError:
        return default


def _plain(body: Any) -> dict[str, Any]:
    return dict(json.loads(json.dumps(dict(body), default=str)))


@kopf.on.startup()
def startup(
    settings: kopf.OperatorSettings, logger: logging.Logger | logging.LoggerAdapter[Any], **_: Any
) -> None:
    global _controller, _jobs
    # without these, kopf's watch streams can hang forever on a silently dropped connection
    settings.watching.server_timeout = int(_float_env("CARLOS_WATCH_SERVER_TIMEOUT", 300))
    settings.watching.client_timeout = _float_env("CARLOS_WATCH_CLIENT_TIMEOUT", 330)
    settings.watching.connect_timeout = 30
    settings.networking.request_timeout = 60
    settings.peering.standalone = True
    # the SimulationRun CRD exists before the operator starts (the chart installs it): no watch on CRDs, which
    # its RBAC does not grant (least privilege); the namespaces served are the ones named, or all
    settings.scanning.disabled = True
    settings.posting.level = logging.WARNING
    settings.execution.max_workers = 8
    # the workers mostly wait for the API server: a burst of new runs gets its Jobs as fast as the API
    # server takes them (a new run's status pass queues behind the Jobs still to make: controller.py)
    workers = max(1, int(_float_env("CARLOS_RECONCILE_WORKERS", 32)))
    _controller = Controller(
        Kube(connections=workers + 4),  # and the events thread, the Job watch, the pod checks
        OperatorSettings.from_env(),
        resync=_float_env("CARLOS_RESYNC_SECONDS", 10.0),
        workers=workers,
    )
    _controller.start()
    threading.Thread(
        target=warm_up, args=(_controller.kube, _controller.settings), name="carlos-warm-up", daemon=True
    ).start()
    _jobs = JobWatch(_controller.kube, WATCH_NAMESPACES, _controller.observe_job)
    _jobs.start()
    logger.info("carlos operator started")


@kopf.on.login()
def login(**kwargs: Any) -> kopf.ConnectionInfo | None:
    """The service account in a pod, else the kubeconfig (KUBECONFIG), as the controller's client. In a pod
    the API server is the address in KUBERNETES_SERVICE_HOST/PORT, as client-go's in-cluster config and the
    controller's own client take it: kopf names `kubernetes.default.svc`, which needs cluster DNS."""
    info = kopf.login_with_service_account(**kwargs)
    host, port = os.environ.get("KUBERNETES_SERVICE_HOST"), os.environ.get("KUBERNETES_SERVICE_PORT")
    if info is not None and host and port:
        info = dataclasses.replace(info, server=f"https://{f'[{host}]' if ':' in host else host}:{port}")
    return info or kopf.login_with_kubeconfig(**kwargs)


@kopf.on.cleanup()
def cleanup(**_: Any) -> None:
    global _controller, _jobs
    if _jobs is not None:
        _jobs.stop()
        _jobs = None
    if _controller is not None:
        _controller.stop()
        _controller = None


@kopf.on.event(API_GROUP, API_VERSION, PLURAL)
def run_event(type: str | None, body: kopf.Body, **_: Any) -> None:
    if _controller is not None:
        _controller.observe_run(type or "ADDED", _plain(body))
        if type == "DELETED":
            metrics.forget(str(body.get("metadata", {}).get("uid")))


@kopf.on.probe(id="simulationruns")
def known_runs(**_: Any) -> int:
    return len(_controller.runs) if _controller is not None else 0
