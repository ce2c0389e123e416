"""The Helm chart (helm/carlos): lint, render with several value sets, validate every object against the
Kubernetes API schemas (kubernetes-validate, offline), and check least privilege and Pod Security "restricted".

helm is not on the machine: the `helm` fixture (tests/conftest.py) fetches the pinned helm v4 binary with
tools/get_helm.py into .tools/bin (once; checksum verified), or takes $HELM.
"""

from __future__ import annotations

import subprocess
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.apiserver import Invalid, admit

ROOT = Path(__file__).resolve().parents[1]
CHART = ROOT / "helm" / "carlos"
RELEASE_NAMESPACE = "carlos-system"

#: The operator's declared needs (operator/carlos_operator/rbac.py), as (apiGroup, resource) → verbs. The
#: chart must grant exactly these: namespaced rules in a Role per watched namespace (or the ClusterRole when
#: watching all), cluster rules in a ClusterRole in both modes.
try:
    from carlos_operator.rbac import CLUSTER_RULES as _CLUSTER
    from carlos_operator.rbac import NAMESPACED_RULES as _NAMESPACED
    from carlos_operator.rbac import SECRET_RULES as _SECRET

    def _table(rules: list[dict[str, list[str]]]) -> dict[tuple[str, str], set[str]]:
        table: dict[tuple[str, str], set[str]] = {}
        for rule in rules:
            for group in rule["apiGroups"]:
                for resource in rule["resources"]:
                    table.setdefault((group, resource), set()).update(rule["verbs"])
        return table

    NAMESPACED_RULES = _table(_NAMESPACED)
    SECRET_RULES = _table(_SECRET)
    CLUSTER_RULES = _table(_CLUSTER)
except ModuleNotFoundError:  # until the operator declares them: the issue's list
    NAMESPACED_RULES = {
        ("carlos.dev", "simulationruns"): {"get", "list", "watch"},
        ("carlos.dev", "simulationruns/status"): {"patch"},
        ("batch", "jobs"): {"get", "list", "watch", "create", "patch"},
        ("", "configmaps"): {"get", "create"},
        ("", "events"): {"create"},
    }
    SECRET_RULES = {("", "secrets"): {"get"}}
    CLUSTER_RULES = {("", "namespaces"): {"get", "list", "watch"}}


def run_helm(helm: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(helm), *args], capture_output=True, text=True, timeout=120)


def render(
    helm: Path, values: dict[str, Any], tmp_path: Path, *, include_crds: bool = False
) -> list[dict[str, Any]]:
    """`helm template` with these values; the rendered objects."""
    values_file = tmp_path / "values.yaml"
    values_file.write_text(yaml.safe_dump(values))
    args = ["template", "carlos", str(CHART), "--namespace", RELEASE_NAMESPACE, "-f", str(values_file)]
    if include_crds:
        args.append("--include-crds")
    result = run_helm(helm, *args)
    assert result.returncode == 0, result.stderr
    return [doc for doc in yaml.safe_load_all(result.stdout) if doc]


def of_kind(objects: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [o for o in objects if o["kind"] == kind]


def rule_triples(rules: list[dict[str, Any]]) -> set[tuple[str, str, str]]:
    """RBAC rules as (apiGroup, resource, verb) triples: equal triples = equal permissions."""
    return {
        (group, resource, verb)
        for rule in rules
        for group in rule.get("apiGroups", [])
        for resource in rule.get("resources", [])
        for verb in rule.get("verbs", [])
    }


def triples(table: dict[tuple[str, str], set[str]]) -> set[tuple[str, str, str]]:
    return {(g, r, v) for (g, r), verbs in table.items() for v in verbs}


VALUE_SETS: dict[str, dict[str, Any]] = {
    "defaults": {},
    "namespaced": {"watchNamespaces": ["sim-a", "sim-b"]},
    "one-namespace": {"watchNamespaces": ["carlos-runs"]},
    "cluster-wide-with-object-store": {
        "watchNamespaces": [],
        "objectStore": {
            "bucket": "carlos-results",
            "prefix": "team/nightly",
            "endpoint": "http://minio.minio.svc:9000",
            "credentialsSecret": "carlos-s3",
        },
    },
    "metrics-off": {"metrics": {"enabled": False}},
    "service-monitor": {
        "metrics": {"enabled": True, "port": 8443, "serviceMonitor": {"enabled": True, "interval": "15s"}}
    },
    "custom-images": {
        "imagePullSecrets": ["regcred"],
        "images": {
            role: {
                "repository": f"registry.example.com:5000/sim/carlos-{role}",
                "tag": "1.2.3-rc.1",
                "digest": "sha256:" + "ab" * 32 if role == "bridge" else "",
                "pullPolicy": "Always",
                "pullSecrets": ["private-pull"] if role in ("simcore", "operator") else [],
            }
            for role in ("operator", "simcore", "bridge", "recorder", "detector")
        },
    },
    "job-ttl": {"jobTTLSeconds": 3600},
    "secret-namespaces": {
        "watchNamespaces": ["sim-a", "sim-b"],
        "secretReferences": {"namespaces": ["sim-b"]},
    },
    "secret-namespaces-cluster-wide": {"secretReferences": {"namespaces": ["team-x"]}},
    "run-pods": {
        "runPods": {
            "resources": {
                "requests": {"cpu": 4, "memory": "8Gi", "ephemeral-storage": "20Gi"},
                "limits": {"cpu": 8, "memory": "16Gi", "ephemeral-storage": "30Gi"},
            },
            "sidecarResources": {"requests": {"cpu": "50m", "memory": "64Mi"}, "limits": {"memory": "256Mi"}},
        }
    },
    "existing-service-account": {"serviceAccount": {"create": False, "name": "carlos-operator"}},
    "no-rbac": {"rbac": {"create": False}},
    "scheduling": {
        "nodeSelector": {"kubernetes.io/os": "linux"},
        "tolerations": [{"key": "dedicated", "operator": "Equal", "value": "sim", "effect": "NoSchedule"}],
        "podAnnotations": {"example.com/team": "adas"},
        "priorityClassName": "batch-low",
        "resources": {"requests": {"cpu": "250m", "memory": "256Mi"}, "limits": {"memory": "1Gi"}},
    },
}


@pytest.fixture(scope="module", params=sorted(VALUE_SETS))
def rendered(
    request: pytest.FixtureRequest, helm: Path, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[str, dict[str, Any], list[dict[str, Any]]]]:
    name = request.param
    values = VALUE_SETS[name]
    yield name, values, render(helm, values, tmp_path_factory.mktemp(name), include_crds=True)


def test_chart_app_version_is_the_package_version() -> None:
    chart = yaml.safe_load((CHART / "Chart.yaml").read_text())
    package = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert chart["appVersion"] == package, "set appVersion in helm/carlos/Chart.yaml to the pyproject version"


def test_every_value_is_documented() -> None:
    """values.yaml: a comment above every key (nested keys too)."""
    lines = (CHART / "values.yaml").read_text().splitlines()
    undocumented = []
    for i, line in enumerate(lines):
        stripped = line.strip()
        if not stripped or stripped.startswith("#") or ":" not in stripped or stripped.startswith("-"):
            continue
        key = stripped.split(":", 1)[0]
        if key in (
            "repository",
            "tag",
            "digest",
            "pullPolicy",
            "pullSecrets",
            "requests",
            "limits",
            "cpu",
            "memory",
            "ephemeral-storage",
        ):
            continue  # documented once above `images` and `resources`
        if i == 0 or not lines[i - 1].strip().startswith("#"):
            undocumented.append(key)
    assert not undocumented, f"values.yaml keys without a comment: {undocumented}"


@pytest.mark.parametrize("name", sorted(VALUE_SETS))
def test_helm_lint_strict(helm: Path, name: str, tmp_path: Path) -> None:
    values_file = tmp_path / "values.yaml"
    values_file.write_text(yaml.safe_dump(VALUE_SETS[name]))
    result = run_helm(helm, "lint", "--strict", str(CHART), "-f", str(values_file))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 chart(s) failed" in result.stdout


def test_every_object_passes_the_kubernetes_api_schema(
    rendered: tuple[str, dict[str, Any], list[dict[str, Any]]],
) -> None:
    """`helm install` through the strict stand-in (tests/apiserver.py): strict schemas (unknown fields are
    errors) of the oldest supported Kubernetes version; the CRD structural with every CEL rule compiled."""
    _, _, objects = rendered
    assert objects
    for obj in objects:
        if obj["kind"] == "ServiceMonitor":
            continue  # a prometheus-operator CRD: no bundled schema; checked in test_service_monitor
        try:
            admit(obj)
        except Invalid as exc:
            pytest.fail(f"{obj['kind']}/{obj['metadata']['name']}: {exc}")


def test_names_and_namespaces(rendered: tuple[str, dict[str, Any], list[dict[str, Any]]]) -> None:
    _, values, objects = rendered
    watched = set(values.get("watchNamespaces", [])) | set(
        values.get("secretReferences", {}).get("namespaces", [])
    )
    cluster_scoped = {"ClusterRole", "ClusterRoleBinding", "CustomResourceDefinition"}
    seen = set()
    for obj in objects:
        meta = obj["metadata"]
        key = (obj["kind"], meta.get("namespace"), meta["name"])
        assert key not in seen, f"rendered twice: {key}"
        seen.add(key)
        if obj["kind"] in cluster_scoped:
            assert "namespace" not in meta
        elif obj["kind"] in ("Role", "RoleBinding"):
            assert meta["namespace"] in watched
        else:
            assert meta["namespace"] == RELEASE_NAMESPACE


def test_crd_is_shipped_with_the_chart(rendered: tuple[str, dict[str, Any], list[dict[str, Any]]]) -> None:
    if not (ROOT / "crds" / "simulationrun.yaml").exists():
        pytest.skip("crds/simulationrun.yaml is not generated yet (make crds, issue 5)")
    _, _, objects = rendered
    crds = of_kind(objects, "CustomResourceDefinition")
    assert [c["metadata"]["name"] for c in crds] == ["simulationruns.carlos.dev"]


def test_chart_crd_matches_the_generated_crd() -> None:
    """helm/carlos/crds/ is a copy of crds/ (both written by `make crds`)."""
    top = ROOT / "crds" / "simulationrun.yaml"
    if not top.exists():
        pytest.skip("crds/simulationrun.yaml is not generated yet (make crds, issue 5)")
    in_chart = CHART / "crds" / "simulationrun.yaml"
    assert in_chart.exists(), "helm/carlos/crds/simulationrun.yaml is missing: run `make crds`"
    assert in_chart.read_text() == top.read_text(), "the chart's CRD drifted from crds/: run `make crds`"
    assert sorted(p.name for p in (CHART / "crds").iterdir()) == ["simulationrun.yaml"]


def operator_roles(roles: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The operator's own roles: not the ClusterRoles the chart aggregates into `admin`/`edit`/`view`."""
    return [r for r in roles if not any(k.startswith(AGGREGATE) for k in r["metadata"].get("labels", {}))]


AGGREGATE = "rbac.authorization.k8s.io/aggregate-to-"


def test_users_get_simulationruns_through_the_aggregated_roles(
    rendered: tuple[str, dict[str, Any], list[dict[str, Any]]],
) -> None:
    """Whoever may edit (view) a namespace may edit (view) its SimulationRuns, and nothing else is granted."""
    _, values, objects = rendered
    user_roles = [r for r in of_kind(objects, "ClusterRole") if r not in operator_roles([r])]
    if not values.get("rbac", {}).get("create", True):
        assert not user_roles
        return
    by_label = {
        kind: [r for r in user_roles if r["metadata"]["labels"].get(AGGREGATE + kind) == "true"]
        for kind in ("admin", "edit", "view")
    }
    assert all(len(roles) == 1 for roles in by_label.values()), by_label
    for role in user_roles:
        assert {(g, r) for rule in role["rules"] for g in rule["apiGroups"] for r in rule["resources"]} == {
            ("carlos.dev", "simulationruns")
        }
    assert rule_triples(by_label["view"][0]["rules"]) == {
        ("carlos.dev", "simulationruns", verb) for verb in ("get", "list", "watch")
    }


def test_rbac_is_least_privilege(rendered: tuple[str, dict[str, Any], list[dict[str, Any]]]) -> None:
    name, values, objects = rendered
    roles = of_kind(objects, "Role") + operator_roles(of_kind(objects, "ClusterRole"))
    if not values.get("rbac", {}).get("create", True):
        assert not roles and not of_kind(objects, "RoleBinding") + of_kind(objects, "ClusterRoleBinding")
        return
    for role in roles:
        for rule in role["rules"]:
            assert set(rule) == {"apiGroups", "resources", "verbs"}, f"{name}: unexpected rule keys {rule}"
            for field in ("apiGroups", "resources", "verbs"):
                assert "*" not in rule[field], f"{name}: wildcard in {role['metadata']['name']}: {rule}"
                assert all("*" not in item for item in rule[field])
            if "secrets" in rule["resources"]:
                assert rule["verbs"] == ["get"], "Secrets: get by name only, never list or watch"
            assert not {"deletecollection", "escalate", "bind", "impersonate"} & set(rule["verbs"])
            if "delete" in rule["verbs"]:  # only an earlier run's own Job and ConfigMap (uid precondition)
                assert set(rule["resources"]) <= {"jobs", "configmaps"}, rule

    # blockOwnerDeletion on the Job's and ConfigMap's owner references needs update on the finalizers
    assert any(
        ("carlos.dev", "simulationruns/finalizers", "update") in rule_triples(role["rules"]) for role in roles
    )
    watched = values.get("watchNamespaces", [])
    secret_roles = [r for r in of_kind(objects, "Role") if r["metadata"]["name"].endswith("-secrets")]
    namespaced = [r for r in of_kind(objects, "Role") if r not in secret_roles]
    cluster = operator_roles(of_kind(objects, "ClusterRole"))
    allowed = values.get("secretReferences", {}).get("namespaces", [])
    assert sorted(r["metadata"]["namespace"] for r in secret_roles) == sorted(allowed)
    for role in secret_roles:
        assert rule_triples(role["rules"]) == triples(SECRET_RULES)
    for role in [*namespaced, *cluster]:
        assert not any(rule["resources"] == ["secrets"] for rule in role["rules"]), "Secrets: opt-in only"
    assert _env(objects).get("CARLOS_SECRET_NAMESPACES", "") == ",".join(allowed)
    if watched:
        assert sorted(r["metadata"]["namespace"] for r in namespaced) == sorted(watched)
        for role in namespaced:
            assert rule_triples(role["rules"]) == triples(NAMESPACED_RULES)
        assert len(cluster) == 1
        assert rule_triples(cluster[0]["rules"]) == triples(CLUSTER_RULES), "cluster-scoped reads only"
    else:
        assert not namespaced
        assert len(cluster) == 1
        expected = triples(NAMESPACED_RULES) | triples(CLUSTER_RULES)
        assert rule_triples(cluster[0]["rules"]) == expected

    # every role is bound to the operator's ServiceAccount, in the operator's namespace
    sa = _deployment(objects)["spec"]["template"]["spec"]["serviceAccountName"]
    bindings = of_kind(objects, "RoleBinding") + of_kind(objects, "ClusterRoleBinding")
    bound = set()
    for binding in bindings:
        assert binding["subjects"] == [{"kind": "ServiceAccount", "name": sa, "namespace": RELEASE_NAMESPACE}]
        ref = binding["roleRef"]
        namespace = binding["metadata"].get("namespace")
        target = next(
            r
            for r in roles
            if r["kind"] == ref["kind"]
            and r["metadata"]["name"] == ref["name"]
            and r["metadata"].get("namespace") == namespace
        )
        bound.add((target["kind"], target["metadata"].get("namespace"), target["metadata"]["name"]))
    assert bound == {(r["kind"], r["metadata"].get("namespace"), r["metadata"]["name"]) for r in roles}


def test_rules_equal_the_operators_rbac_rules(helm: Path, tmp_path: Path) -> None:
    """The chart grants exactly what the operator declares it needs (operator/carlos_operator/rbac.py)."""
    try:
        from carlos_operator.rbac import CLUSTER_RULES, NAMESPACED_RULES, RBAC_RULES, SECRET_RULES
    except ModuleNotFoundError:
        pytest.skip("operator/carlos_operator/rbac.py (RBAC_RULES) is not there yet (issue 5)")

    def diff(granted: set[tuple[str, str, str]], declared: set[tuple[str, str, str]]) -> str:
        return f"the chart grants {sorted(granted - declared)} beyond rbac.py and misses {sorted(declared - granted)}"

    objects = render(helm, {"secretReferences": {"namespaces": ["team-x"]}}, tmp_path)
    (cluster_role,) = operator_roles(of_kind(objects, "ClusterRole"))
    (secret_role,) = of_kind(objects, "Role")
    granted = rule_triples(cluster_role["rules"]) | rule_triples(secret_role["rules"])
    assert granted == rule_triples(RBAC_RULES), "cluster-wide: " + diff(granted, rule_triples(RBAC_RULES))
    assert rule_triples(secret_role["rules"]) == rule_triples(SECRET_RULES)

    objects = render(helm, {"watchNamespaces": ["sim-a", "sim-b"]}, tmp_path)
    for role in of_kind(objects, "Role"):
        granted = rule_triples(role["rules"])
        assert granted == rule_triples(NAMESPACED_RULES), "Role: " + diff(
            granted, rule_triples(NAMESPACED_RULES)
        )
    (cluster_role,) = operator_roles(of_kind(objects, "ClusterRole"))
    granted = rule_triples(cluster_role["rules"])
    assert granted == rule_triples(CLUSTER_RULES), "namespaced ClusterRole: " + diff(
        granted, rule_triples(CLUSTER_RULES)
    )


def _deployment(objects: list[dict[str, Any]]) -> dict[str, Any]:
    deployments = of_kind(objects, "Deployment")
    assert len(deployments) == 1
    return deployments[0]


def test_deployment(rendered: tuple[str, dict[str, Any], list[dict[str, Any]]]) -> None:
    _, values, objects = rendered
    deployment = _deployment(objects)
    spec = deployment["spec"]
    assert spec["replicas"] == 1
    assert spec["strategy"] == {"type": "Recreate"}
    pod = spec["template"]["spec"]
    assert spec["selector"]["matchLabels"].items() <= spec["template"]["metadata"]["labels"].items()
    (container,) = pod["containers"]
    ports = {p["name"]: p["containerPort"] for p in container["ports"]}
    for probe in ("livenessProbe", "readinessProbe", "startupProbe"):
        get = container[probe]["httpGet"]
        assert get["path"] == "/healthz"
        assert ports.get(get["port"], get["port"]) == 8080
    resources = container["resources"]
    assert resources["requests"]["cpu"] and resources["requests"]["memory"] and resources["limits"]["memory"]
    if values.get("resources"):
        assert resources == values["resources"]
    for key in ("nodeSelector", "tolerations", "priorityClassName"):
        if key in values:
            assert pod[key] == values[key]
    if "podAnnotations" in values:
        assert spec["template"]["metadata"]["annotations"] == values["podAnnotations"]


def test_deployment_args_match_the_watched_namespaces(
    rendered: tuple[str, dict[str, Any], list[dict[str, Any]]],
) -> None:
    _, values, objects = rendered
    container = _deployment(objects)["spec"]["template"]["spec"]["containers"][0]
    assert container["command"] == ["carlos"]
    args = container["args"]
    assert args[0] == "operator"
    watched = values.get("watchNamespaces", [])
    given = [args[i + 1] for i, a in enumerate(args) if a == "--namespace"]
    assert given == watched
    assert ("--all-namespaces" in args) == (not watched)
    metrics_port = args[args.index("--metrics-port") + 1]
    assert metrics_port == ("9090" if values.get("metrics", {}).get("enabled", True) else "0")
    assert args[args.index("--liveness-port") + 1] == "8080"


def test_deployment_args_parse_with_the_real_cli(helm: Path, tmp_path: Path) -> None:
    """The rendered args are accepted by `carlos operator` itself (parsed by its click command, not run)."""
    import typer.main

    from simcore.cli import app

    command = typer.main.get_command(app)
    operator = command.get_command(None, "operator")  # type: ignore[attr-defined,arg-type]  # entry point
    if operator is None:
        pytest.skip("`carlos operator` is not there yet (issue 5)")
    for values, expected in (
        ({"watchNamespaces": ["sim-a", "sim-b"]}, (["sim-a", "sim-b"], False)),
        ({}, ([], True)),
    ):
        objects = render(helm, values, tmp_path)
        container = _deployment(objects)["spec"]["template"]["spec"]["containers"][0]
        ctx = operator.make_context("operator", list(container["args"][1:]))
        assert (list(ctx.params["namespace"] or []), ctx.params["all_namespaces"]) == expected
        assert ctx.params["liveness_port"] == 8080
        assert ctx.params["metrics_port"] == 9090


def test_pod_security_restricted(rendered: tuple[str, dict[str, Any], list[dict[str, Any]]]) -> None:
    """The Pod Security Standard "restricted" profile, checked field by field."""
    _, _, objects = rendered
    pod = _deployment(objects)["spec"]["template"]["spec"]
    pod_sc = pod["securityContext"]
    for key in ("hostNetwork", "hostPID", "hostIPC"):
        assert not pod.get(key)
    assert pod_sc["seccompProfile"]["type"] == "RuntimeDefault"
    assert pod_sc["runAsNonRoot"] is True
    assert pod_sc.get("runAsUser", 1) != 0
    allowed_volumes = {
        "configMap",
        "csi",
        "downwardAPI",
        "emptyDir",
        "ephemeral",
        "persistentVolumeClaim",
        "projected",
        "secret",
    }
    for volume in pod.get("volumes", []):
        assert set(volume) - {"name"} <= allowed_volumes, volume
    for container in pod["containers"] + pod.get("initContainers", []):
        sc = container["securityContext"]
        assert sc["allowPrivilegeEscalation"] is False
        assert sc["capabilities"]["drop"] == ["ALL"]
        assert not sc["capabilities"].get("add")
        assert sc.get("privileged", False) is False
        assert sc["readOnlyRootFilesystem"] is True
        assert sc.get("runAsNonRoot", pod_sc["runAsNonRoot"]) is True
        assert sc.get("runAsUser", pod_sc.get("runAsUser", 1)) != 0
        assert sc.get("seccompProfile", pod_sc["seccompProfile"])["type"] == "RuntimeDefault"
        assert not any(p.get("hostPort") for p in container.get("ports", []))


def _env(objects: list[dict[str, Any]]) -> dict[str, str]:
    container = _deployment(objects)["spec"]["template"]["spec"]["containers"][0]
    return {e["name"]: e["value"] for e in container["env"]}


def test_images_and_operator_settings(rendered: tuple[str, dict[str, Any], list[dict[str, Any]]]) -> None:
    _, values, objects = rendered
    chart = yaml.safe_load((CHART / "Chart.yaml").read_text())
    defaults = yaml.safe_load((CHART / "values.yaml").read_text())
    images = {
        role: {**defaults["images"][role], **values.get("images", {}).get(role, {})}
        for role in defaults["images"]
    }

    def ref(role: str) -> str:
        image = images[role]
        if image["digest"]:
            return f"{image['repository']}@{image['digest']}"
        return f"{image['repository']}:{image['tag'] or chart['appVersion']}"

    pod = _deployment(objects)["spec"]["template"]["spec"]
    container = pod["containers"][0]
    assert container["image"] == ref("operator")
    assert container["imagePullPolicy"] == images["operator"]["pullPolicy"]
    env = _env(objects)
    for role in ("simcore", "bridge", "recorder", "detector"):
        assert env[f"CARLOS_IMAGE_{role.upper()}"] == ref(role)
        assert env[f"CARLOS_IMAGE_{role.upper()}_PULL_POLICY"] == images[role]["pullPolicy"]
    global_secrets = values.get("imagePullSecrets", [])
    operator_secrets = list(dict.fromkeys(global_secrets + images["operator"]["pullSecrets"]))
    assert [s["name"] for s in pod.get("imagePullSecrets", [])] == operator_secrets
    run_secrets = list(
        dict.fromkeys(
            global_secrets
            + [s for r in ("simcore", "bridge", "recorder", "detector") for s in images[r]["pullSecrets"]]
        )
    )
    assert env.get("CARLOS_IMAGE_PULL_SECRETS", "") == ",".join(run_secrets)

    store = values.get("objectStore", {})
    if store.get("bucket"):
        url = f"s3://{store['bucket']}" + (f"/{store['prefix']}" if store.get("prefix") else "")
        assert env["CARLOS_DEFAULT_OUTPUT_URL"] == url
    else:
        assert "CARLOS_DEFAULT_OUTPUT_URL" not in env
    assert env.get("CARLOS_DEFAULT_S3_ENDPOINT") == (store.get("endpoint") or None)
    assert env.get("CARLOS_DEFAULT_S3_SECRET") == (store.get("credentialsSecret") or None)
    assert env["CARLOS_JOB_TTL_SECONDS"] == str(values.get("jobTTLSeconds", 604800))
    from carlos_operator.builders import OperatorSettings

    settings = OperatorSettings.from_env(env)  # the run pods' resource defaults reach the operator
    for got, key in ((settings.run_resources, "resources"), (settings.sidecar_resources, "sidecarResources")):
        chosen = values.get("runPods", {}).get(key, {})
        for part in ("requests", "limits"):
            want = {**defaults["runPods"][key][part], **chosen.get(part, {})}  # helm merges maps
            assert got[part] == {k: str(v) for k, v in want.items()}, (key, part)
    assert not any("valueFrom" in e for e in container["env"]), "the operator reads no Secret"


def test_metrics_service_and_service_monitor(
    rendered: tuple[str, dict[str, Any], list[dict[str, Any]]],
) -> None:
    _, values, objects = rendered
    metrics = values.get("metrics", {})
    services = of_kind(objects, "Service")
    monitors = of_kind(objects, "ServiceMonitor")
    pod_template = _deployment(objects)["spec"]["template"]
    ports = {p["name"]: p["containerPort"] for p in pod_template["spec"]["containers"][0]["ports"]}
    if not metrics.get("enabled", True):
        assert not services and not monitors and "metrics" not in ports
        return
    (service,) = services
    assert service["spec"]["selector"].items() <= pod_template["metadata"]["labels"].items()
    (port,) = service["spec"]["ports"]
    assert port["port"] == metrics.get("port", 9090)
    assert ports[port["targetPort"]] == 9090
    if not metrics.get("serviceMonitor", {}).get("enabled", False):
        assert not monitors
        return
    (monitor,) = monitors
    assert monitor["apiVersion"] == "monitoring.coreos.com/v1"
    assert monitor["spec"]["selector"]["matchLabels"].items() <= service["metadata"]["labels"].items()
    assert monitor["spec"]["namespaceSelector"] == {"matchNames": [RELEASE_NAMESPACE]}
    assert monitor["spec"]["endpoints"] == [
        {"port": port["name"], "path": "/metrics", "interval": metrics["serviceMonitor"]["interval"]}
    ]


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"watchNamespaces": "sim-a"}, "/watchNamespaces"),
        ({"watchNamespaces": ["Sim_A"]}, "/watchNamespaces/0"),
        (
            {"images": {"simcore": {"repository": "x/carlos-simcore", "pullPolicy": "Sometimes"}}},
            "/images/simcore/pullPolicy",
        ),
        (
            {"images": {"bridge": {"repository": "x/bridge", "pullPolicy": "Always", "digest": "abc"}}},
            "/images/bridge/digest",
        ),
        (
            {"images": {"recorder": {"repository": "UPPER/case", "pullPolicy": "Always"}}},
            "/images/recorder/repository",
        ),
        ({"watchNamespace": ["sim-a"]}, "'watchNamespace' not allowed"),
        ({"metrics": {"port": 70000}}, "/metrics/port"),
        ({"jobTTLSeconds": -1}, "/jobTTLSeconds"),
        ({"objectStore": {"bucket": "results", "endpoint": "ftp://store"}}, "/objectStore/endpoint"),
        ({"objectStore": {"bucket": "results", "prefix": "/leading"}}, "/objectStore/prefix"),
        (
            {"metrics": {"serviceMonitor": {"enabled": True, "interval": "soon"}}},
            "/metrics/serviceMonitor/interval",
        ),
        ({"metrics": {"enabled": False, "serviceMonitor": {"enabled": True}}}, "needs metrics.enabled: true"),
        ({"objectStore": {"credentialsSecret": "s3"}}, "set objectStore.bucket too"),
        ({"serviceAccount": {"create": False}}, "serviceAccount.name"),
    ],
)
def test_bad_values_fail_with_a_clear_message(
    helm: Path, tmp_path: Path, values: dict[str, Any], message: str
) -> None:
    values_file = tmp_path / "values.yaml"
    values_file.write_text(yaml.safe_dump(values))
    result = run_helm(helm, "template", "carlos", str(CHART), "-f", str(values_file))
    assert result.returncode != 0
    assert message in result.stderr, result.stderr
    assert "panic" not in result.stderr


def test_notes_tell_how_to_apply_the_first_run(helm: Path) -> None:
    """The SimulationRun printed by NOTES.txt is a valid run (spec models) using a scenario the image ships."""
    from simcore.spec import SimulationRun

    for values in ([], ["--set", "objectStore.bucket=carlos-results", "--set", "watchNamespaces={sim-a}"]):
        result = run_helm(
            helm,
            "install",
            "carlos",
            str(CHART),
            "--dry-run=client",
            "--namespace",
            RELEASE_NAMESPACE,
            *values,
        )
        assert result.returncode == 0, result.stderr
        notes = result.stdout.split("NOTES:", 1)[1]
        body = notes.split("<<'YAML'\n", 1)[1].split("     YAML\n", 1)[0]
        manifest = yaml.safe_load("\n".join(line[5:] for line in body.splitlines()))
        run = SimulationRun.model_validate(manifest)
        assert run.metadata.generate_name
        scenario = run.spec.scenarios[0].openscenario
        assert scenario is not None and scenario.startswith("file:///opt/carlos/")
        assert (ROOT / scenario.removeprefix("file:///opt/carlos/")).is_file()
        assert "get simruns" in notes
        namespace = "sim-a" if values else "default"
        assert f"kubectl -n {namespace} create -f -" in notes
