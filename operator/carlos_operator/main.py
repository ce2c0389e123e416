"""`carlos operator`: start kopf with the CARLOS handlers, the liveness endpoint and Prometheus metrics.

Deploy one replica with the `Recreate` strategy (peering is off: two operators would both reconcile).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence


def run_operator(*, namespaces: Sequence[str], liveness_port: int = 8080, metrics_port: int = 9090) -> int:
    import kopf
    from prometheus_client import start_http_server

    import carlos_operator.handlers  # registers the handlers
    from carlos_operator.builders import OperatorSettings

    carlos_operator.handlers.WATCH_NAMESPACES[:] = list(namespaces)

    OperatorSettings.from_env()  # a bad setting (e.g. CARLOS_POD_TRANSPORT) fails here, exit code 2

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if metrics_port:
        start_http_server(metrics_port)
    kopf.run(
        clusterwide=not namespaces,
        namespaces=list(namespaces),
        standalone=True,
        liveness_endpoint=f"http://0.0.0.0:{liveness_port}/healthz",
    )
    return 0
