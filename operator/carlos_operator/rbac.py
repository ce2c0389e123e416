"""The Kubernetes permissions the operator needs, least privilege. The Helm chart's rules must equal
`RBAC_RULES` (the chart's test asserts it): `NAMESPACED_RULES` in a Role per watched namespace (or a
ClusterRole for `--all-namespaces`) and `CLUSTER_RULES` in a ClusterRole in both modes.

- SimulationRuns: kopf lists and watches them (event handlers only: kopf stores no state on them, adds no
  finalizer); the controller merge-patches their status subresource.
- Jobs: created, read, listed and watched (their status drives the run's status), patched (spec.suspend).
- ConfigMaps: created and read (each run's spec; adoption after a restart).
- Secrets: read, only to get the object-store credentials a run names (`spec.output.credentialsSecretRef`
  or the operator's default Secret) for reading the per-index summaries and writing the run summary.
- Events: created (core v1, by the controller and by kopf).
- Namespaces (cluster-scoped): kopf lists and watches them to serve the namespaces given by `--namespace`
  (it serves only namespaces that exist); with `--all-namespaces` too.
"""

from __future__ import annotations

NAMESPACED_RULES: list[dict[str, list[str]]] = [
    {"apiGroups": ["carlos.dev"], "resources": ["simulationruns"], "verbs": ["get", "list", "watch"]},
    {"apiGroups": ["carlos.dev"], "resources": ["simulationruns/status"], "verbs": ["patch"]},
    {"apiGroups": ["batch"], "resources": ["jobs"], "verbs": ["get", "list", "watch", "create", "patch"]},
    {"apiGroups": [""], "resources": ["configmaps"], "verbs": ["get", "create"]},
    {"apiGroups": [""], "resources": ["secrets"], "verbs": ["get"]},
    {"apiGroups": [""], "resources": ["events"], "verbs": ["create"]},
]

CLUSTER_RULES: list[dict[str, list[str]]] = [
    {"apiGroups": [""], "resources": ["namespaces"], "verbs": ["get", "list", "watch"]},
]

#: every rule the operator needs
RBAC_RULES: list[dict[str, list[str]]] = [*NAMESPACED_RULES, *CLUSTER_RULES]
