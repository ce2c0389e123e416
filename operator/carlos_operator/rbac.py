"""The Kubernetes permissions the operator needs, least privilege. The Helm chart's rules must equal
`RBAC_RULES` (the chart's test asserts it): `NAMESPACED_RULES` in a Role per watched namespace (or a
ClusterRole for `--all-namespaces`), `SECRET_RULES` in a Role per namespace allowed to name Secrets, and
`CLUSTER_RULES` in a ClusterRole in both modes.

- SimulationRuns: kopf lists and watches them (event handlers only: kopf stores no state on them, adds no
  finalizer); the controller merge-patches their status subresource. `simulationruns/finalizers` update:
  the Job and ConfigMap carry `blockOwnerDeletion: true` owner references, which the API server allows only
  to whoever may update the owner's finalizers (OwnerReferencesPermissionEnforcement, OpenShift).
- Jobs: created, read, listed and watched by label (their status drives the run's status), patched
  (spec.suspend), deleted (only the Job of an earlier, deleted run of the same name, by uid precondition).
- ConfigMaps: created and read (each run's spec; adoption after a restart; a run's scenario ConfigMaps are
  looked for before its Job is created), deleted (as Jobs).
- Pods: listed by label, a few at a time, to show why a run's pods cannot start.
- Secrets (`SECRET_RULES`, a Role in each namespace of the chart's `secretReferences.namespaces` only): read,
  only to get the object-store credentials a run names (`spec.output.credentialsSecretRef` or the
  operator's default Secret) for reading the per-index summaries and writing the run summary. Runs of other
  namespaces may not name Secrets at all.
- Events: created (core v1, by the controller and by kopf).
- Namespaces (cluster-scoped): kopf lists and watches them to serve the namespaces given by `--namespace`
  (it serves only namespaces that exist); with `--all-namespaces` too.
"""

from __future__ import annotations

NAMESPACED_RULES: list[dict[str, list[str]]] = [
    {"apiGroups": ["carlos.dev"], "resources": ["simulationruns"], "verbs": ["get", "list", "watch"]},
    {"apiGroups": ["carlos.dev"], "resources": ["simulationruns/status"], "verbs": ["patch"]},
    {"apiGroups": ["carlos.dev"], "resources": ["simulationruns/finalizers"], "verbs": ["update"]},
    {
        "apiGroups": ["batch"],
        "resources": ["jobs"],
        "verbs": ["get", "list", "watch", "create", "patch", "delete"],
    },
    {"apiGroups": [""], "resources": ["configmaps"], "verbs": ["get", "create", "delete"]},
    {"apiGroups": [""], "resources": ["pods"], "verbs": ["list"]},
    {"apiGroups": [""], "resources": ["events"], "verbs": ["create"]},
]

SECRET_RULES: list[dict[str, list[str]]] = [
    {"apiGroups": [""], "resources": ["secrets"], "verbs": ["get"]},
]

CLUSTER_RULES: list[dict[str, list[str]]] = [
    {"apiGroups": [""], "resources": ["namespaces"], "verbs": ["get", "list", "watch"]},
]

#: every rule the operator needs
RBAC_RULES: list[dict[str, list[str]]] = [*NAMESPACED_RULES, *SECRET_RULES, *CLUSTER_RULES]
