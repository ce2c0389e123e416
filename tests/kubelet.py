"""A test kubelet: runs one pod of a Job's pod template as local processes.

What it honours from the pod template, as a kubelet would: every container's `command` and `args` (without
a command, the args are run by this virtualenv's `carlos` in place of the image's entrypoint), `env` (values, `fieldRef` to the pod's
annotations), `envFrom` secretRef (the Secret's data, base64-decoded), `volumeMounts` (ConfigMap volumes
materialised from the given ConfigMaps, emptyDirs as fresh directories; an env value under a mount path is
rewritten to the local directory), native sidecars (initContainers with `restartPolicy: Always`) started
first and in order, each waited for through its tcpSocket startup probe, then the main containers; when the
main containers have exited, the sidecars get SIGTERM in reverse order.

One deliberate difference: pods of a real cluster each have their own loopback, these share the host's, so
the ports of the startup probes (and the env vars naming them) are replaced by free ports per pod, and
ROS_DOMAIN_ID (the same in every pod of a cluster: DDS stays inside a pod's loopback) by a domain no other
process on this host uses, the same for all containers of one pod.
"""

from __future__ import annotations

import base64
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CARLOS = str(Path(sys.executable).with_name("carlos"))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _domain_in_use(domain: int) -> bool:
    """Whether a cyclonedds participant with participant index 0..3 (unicast discovery, as with the pods'
    loopback config) holds a port of `domain`."""
    for index in range(4):
        port = 7400 + 250 * domain + 10 + 2 * index  # cyclonedds' default port mapping
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("", port))
            except OSError:
                return True
    return False


def worker_share(candidates: range) -> list[int]:
    """This pytest-xdist worker's share of `candidates` (every n-th, n the number of workers): two workers
    that both find a domain unused before either has joined it never pick the same one."""
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    return [c for c in candidates if c % count == index % count]


#: domains handed to pods of this process that have not ended: two pods that start at once (a Job's
#: parallelism) both find a domain unused before either has joined it, so the check alone is not enough
_reserved: set[int] = set()
_reserved_lock = threading.Lock()


def _pick_domain() -> int:
    candidates = [d for d in worker_share(range(1, 100)) if d not in _reserved]
    random.shuffle(candidates)
    for domain in candidates:
        if not _domain_in_use(domain):
            return domain
    raise RuntimeError("no free DDS domain in 1..99")


def free_domain() -> int:
    """A DDS domain in 1..99 that no participant on this host uses (tests/test_dds.py takes 100..229), nor a
    pod of this process that has not ended."""
    with _reserved_lock:
        return _pick_domain()


def reserve_domain() -> int:
    """`free_domain`, held for one pod until `release_domain`."""
    with _reserved_lock:
        domain = _pick_domain()
        _reserved.add(domain)
        return domain


def release_domain(domain: int) -> None:
    with _reserved_lock:
        _reserved.discard(domain)


def _wait_port(port: int, timeout: float, proc: subprocess.Popen[bytes]) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"sidecar exited with {proc.returncode} before its startup probe passed")
        with socket.socket() as s:
            s.settimeout(0.5)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"startup probe on port {port} did not pass within {timeout} s")


@dataclass
class PodResult:
    exit_codes: dict[str, int]  # container → exit code
    logs: dict[str, str] = field(default_factory=dict)

    @property
    def main_exit_code(self) -> int:
        return max(code for name, code in self.exit_codes.items() if name == "simcore")


@dataclass
class Kubelet:
    """Runs pods of a pod template. `configmaps` and `secrets` map names to their `data`."""

    configmaps: Mapping[str, Mapping[str, str]]
    secrets: Mapping[str, Mapping[str, str]]  # base64 values, as in the API
    workdir: Path
    extra_env: Mapping[str, str] = field(default_factory=dict)
    #: called with (container name, Popen) right after a container starts (fault injection)
    on_start: Callable[[str, subprocess.Popen[bytes]], None] | None = None
    timeout: float = 300.0

    def _volumes(self, pod: Mapping[str, Any], root: Path) -> dict[str, Path]:
        out: dict[str, Path] = {}
        for volume in pod.get("volumes", []):
            path = root / "volumes" / volume["name"]
            path.mkdir(parents=True)
            if "configMap" in volume:
                data = self.configmaps[volume["configMap"]["name"]]
                for key, value in data.items():
                    (path / key).write_text(value)
            elif "emptyDir" not in volume:
                raise ValueError(f"volume kind of {volume} is not supported by the test kubelet")
            out[volume["name"]] = path
        return out

    def _env(
        self,
        container: Mapping[str, Any],
        annotations: Mapping[str, str],
        mounts: list[tuple[str, Path]],
        ports: Mapping[int, int],
        domain: int,
    ) -> dict[str, str]:
        env = {"PATH": os.environ.get("PATH", ""), "LANG": "C.UTF-8"}
        for source in container.get("envFrom", []):
            secret = self.secrets[source["secretRef"]["name"]]
            env.update({k: base64.b64decode(v).decode() for k, v in secret.items()})
        for item in container.get("env", []):
            if "value" in item:
                value = str(item["value"])
            else:
                path = item["valueFrom"]["fieldRef"]["fieldPath"]
                prefix = "metadata.annotations['"
                assert path.startswith(prefix), path
                value = annotations.get(path[len(prefix) : -2], "")
            for mount_path, local in mounts:
                if value == mount_path or value.startswith(mount_path + "/"):
                    value = str(local) + value[len(mount_path) :]
                    break
            if value.isdigit() and int(value) in ports:
                value = str(ports[int(value)])
            env[item["name"]] = value
        if "ROS_DOMAIN_ID" in env:
            env["ROS_DOMAIN_ID"] = str(domain)
        env.update(self.extra_env)
        return env

    def run_pod(self, pod: Mapping[str, Any], index: int, failures: int = 0) -> PodResult:
        root = Path(tempfile.mkdtemp(prefix=f"pod-{index}-", dir=self.workdir))
        volumes = self._volumes(pod, root)
        annotations = {
            "batch.kubernetes.io/job-completion-index": str(index),
            "batch.kubernetes.io/job-index-failure-count": str(failures),
        }
        probe_ports = {
            c["startupProbe"]["tcpSocket"]["port"]
            for c in pod.get("initContainers", [])
            if "startupProbe" in c
        }
        ports = {port: free_port() for port in probe_ports}
        domain = reserve_domain()  # released when the pod has ended
        procs: list[tuple[str, subprocess.Popen[bytes], Path]] = []

        def start(container: Mapping[str, Any]) -> subprocess.Popen[bytes]:
            mounts = sorted(
                ((m["mountPath"], volumes[m["name"]]) for m in container.get("volumeMounts", [])),
                key=lambda m: -len(m[0]),
            )
            env = self._env(container, annotations, mounts, ports, domain)
            log_path = root / f"{container['name']}.log"
            with open(log_path, "wb") as log_file:
                proc = subprocess.Popen(
                    [*container.get("command", [CARLOS]), *container.get("args", [])],
                    env=env,
                    cwd=root,
                    stdout=log_file,
                    stderr=subprocess.STDOUT,
                )
            procs.append((container["name"], proc, log_path))
            if self.on_start is not None:
                self.on_start(container["name"], proc)
            return proc

        exit_codes: dict[str, int] = {}
        try:
            sidecars = []
            for container in pod.get("initContainers", []):
                proc = start(container)
                if container.get("restartPolicy") == "Always":
                    sidecars.append((container["name"], proc))
                    probe = container.get("startupProbe", {}).get("tcpSocket")
                    if probe:
                        _wait_port(ports[probe["port"]], 60.0, proc)
                else:
                    exit_codes[container["name"]] = proc.wait(self.timeout)
            mains = [(c["name"], start(c)) for c in pod["containers"]]
            for name, proc in mains:
                exit_codes[name] = proc.wait(self.timeout)
            for name, proc in reversed(sidecars):
                if proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
                try:
                    exit_codes[name] = proc.wait(30)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    exit_codes[name] = proc.wait()
        finally:
            for _, proc, _ in procs:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
            release_domain(domain)
        logs = {name: path.read_text(errors="replace") for name, _, path in procs}
        return PodResult(exit_codes=exit_codes, logs=logs)
