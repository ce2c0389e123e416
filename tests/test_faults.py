"""Fault injection on the local executor: kill -9 of `carlos run` and of its workers at random moments, and
the S3 server unreachable mid-sweep. Invariants: no process outlives `carlos run`, no scratch is left
behind, a rerun completes with results identical to an undisturbed run (recordings byte for byte, summaries
except wall times and attempt counts), and an outage ends in one line with exit code 3 (or is survived)."""

from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.s3server import S3Server, s3_server  # noqa: F401 (the session fixture)

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "examples" / "scenarios" / "curve-following.xosc"
SPEEDS = [18.0, 19.0, 20.0, 21.0, 22.0, 23.0]
#: the outage tests' sweep: long enough that its runs are still writing a second after the workers start,
#: however quick a run has become
OUTAGE_SPEEDS = [18.0 + 0.25 * i for i in range(40)]


def _manifest(tmp_path: Path, name: str, retries: int = 0, speeds: list[float] = SPEEDS) -> Path:
    """The sweep every test runs (the recordings hold the manifest: the same one for identical bytes)."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(
        f"apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {{name: {name}}}\n"
        f"spec:\n  scenarios: [{{name: c, openscenario: {SCENARIO}}}]\n"
        f"  sweep: {{matrix: {{LeadSpeed: {speeds}}}}}\n"
        f"  simulation: {{maxSeconds: 20}}\n  execution: {{retries: {retries}}}\n"
    )
    return path


def _start(manifest: Path, output: str, env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "simcore.cli", "run", str(manifest), "-o", output, "-j", "2", "-q"],
        cwd=ROOT,
        env={**os.environ, **env},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _run(manifest: Path, output: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    process = _start(manifest, output, env)
    stdout, stderr = process.communicate(timeout=300)
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def _descendants(pid: int) -> list[int]:
    found, stack = [], [pid]
    while stack:
        out = subprocess.run(["pgrep", "-P", str(stack.pop())], capture_output=True, text=True, check=False)
        children = [int(p) for p in out.stdout.split()]
        found.extend(children)
        stack.extend(children)
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        status = Path(f"/proc/{pid}/status").read_text()
    except (ProcessLookupError, FileNotFoundError):
        return False
    return "State:\tZ" not in status


def _wait_for_workers(process: subprocess.Popen[str], count: int = 2, timeout: float = 60) -> list[int]:
    """The worker processes once `count` are up; [] when the run ends first (nothing was left to run)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        workers = [p for p in _descendants(process.pid) if _is_worker(p)]
        if len(workers) >= count:
            return workers
        if process.poll() is not None:
            return []
        time.sleep(0.05)
    raise AssertionError("no worker processes appeared")


def _is_worker(pid: int) -> bool:
    try:
        return b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


def _results(root: Path) -> dict[str, object]:
    """Everything a run wrote, comparable between runs: recordings as bytes, summaries without wall times,
    attempt counts or the output URL."""
    found: dict[str, object] = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        if path.name == "recording.mcap":
            found[key] = path.read_bytes()
        elif path.name == "summary.json":
            data = json.loads(path.read_text())
            for volatile in ("wallSeconds", "attempts", "outputUrl"):
                data.pop(volatile, None)
            found[key] = data
    return found


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("undisturbed")
    result = _run(_manifest(tmp, "faults"), f"file://{tmp / 'out'}", {})
    assert result.returncode == 0, result.stderr
    return tmp / "out" / "faults"


@pytest.mark.slow
def test_kill_9_of_carlos_run_leaves_nothing_behind_and_a_rerun_completes_identically(
    tmp_path: Path, undisturbed: Path
) -> None:
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {"TMPDIR": str(scratch)}
    manifest = _manifest(tmp_path, "faults")
    out = tmp_path / "out"
    rng = random.Random(15)
    kills = 0
    for _ in range(3):
        process = _start(manifest, f"file://{out}", env)
        if not _wait_for_workers(process):
            break  # the earlier runs left nothing to do
        time.sleep(rng.uniform(0.05, 0.6))  # a random moment of the sweep
        family = _descendants(process.pid)  # the workers and multiprocessing's resource tracker
        if process.poll() is not None:
            break  # it finished first
        process.kill()
        kills += 1
        process.communicate(timeout=30)
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in family) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not [p for p in family if _alive(p)], "processes outlived carlos run"
    assert kills >= 1
    result = _run(manifest, f"file://{out}", env)
    assert result.returncode == 0, result.stderr
    assert _results(out / "faults") == _results(undisturbed)
    assert list(scratch.iterdir()) == []  # the killed runs' scratch was removed by the next run


@pytest.mark.slow
def test_a_rerun_retries_indexes_whose_workers_died_and_keeps_the_others(
    tmp_path: Path, undisturbed: Path
) -> None:
    manifest = _manifest(tmp_path, "faults")
    out = tmp_path / "out"
    process = _start(manifest, f"file://{out}", {})
    victims = _wait_for_workers(process)
    deadline = time.monotonic() + 120
    while not list(out.glob("faults/*/summary.json")) and time.monotonic() < deadline:
        time.sleep(0.02)  # the first index finished: the ones in flight now are killed
    for victim in victims:
        os.kill(victim, signal.SIGKILL)
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == 3, stderr  # no retries: the killed indexes ended in error
    statuses = {
        i: json.loads((out / "faults" / str(i) / "summary.json").read_text())["status"]
        for i in range(len(SPEEDS))
    }
    errored = [i for i, s in statuses.items() if s == "error"]
    assert errored and len(errored) < len(SPEEDS)
    kept = {
        i: (out / "faults" / str(i) / "summary.json").stat().st_mtime_ns for i in statuses if i not in errored
    }
    again = _run(manifest, f"file://{out}", {})
    assert again.returncode == 0, again.stderr
    assert f"{len(SPEEDS) - len(errored)} of {len(SPEEDS)} runs already complete" in again.stderr
    assert {i: (out / "faults" / str(i) / "summary.json").stat().st_mtime_ns for i in kept} == kept
    assert _results(out / "faults") == _results(undisturbed)


class FlakyProxy:
    """A TCP forwarder on 127.0.0.1 in front of the S3 server that can go down (connections refused and cut)
    and come back on the same port."""

    def __init__(self, upstream_port: int) -> None:
        self.upstream_port = upstream_port
        self.listener = self._listen(0)
        self.port = self.listener.getsockname()[1]
        self.connections: list[socket.socket] = []
        self.lock = threading.Lock()
        self.serving = True
        threading.Thread(target=self._accept, daemon=True).start()

    @staticmethod
    def _listen(port: int) -> socket.socket:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", port))
        listener.listen(64)
        listener.settimeout(0.2)
        return listener

    def _accept(self) -> None:
        while True:
            with self.lock:
                listener = self.listener if self.serving else None
            if listener is None:
                time.sleep(0.05)
                continue
            try:
                client, _ = listener.accept()
            except (TimeoutError, OSError):
                continue
            try:
                upstream = socket.create_connection(("127.0.0.1", self.upstream_port))
            except OSError:
                client.close()
                continue
            with self.lock:
                self.connections += [client, upstream]
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    @staticmethod
    def _pump(source: socket.socket, target: socket.socket) -> None:
        try:
            while data := source.recv(65536):
                target.sendall(data)
        except OSError:
            pass
        finally:
            for s in (source, target):
                with contextlib.suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)

    def down(self) -> None:
        with self.lock:
            self.serving = False
            self.listener.close()
            for connection in self.connections:
                with contextlib.suppress(OSError):
                    connection.shutdown(socket.SHUT_RDWR)
                connection.close()
            self.connections.clear()

    def up(self) -> None:
        with self.lock:
            self.listener = self._listen(self.port)
            self.serving = True


@pytest.fixture
def proxy(s3_server: S3Server) -> Iterator[FlakyProxy]:  # noqa: F811
    yield FlakyProxy(int(s3_server.endpoint.rsplit(":", 1)[1]))


def _s3_env(server: S3Server, proxy: FlakyProxy, budget: float) -> dict[str, str]:
    return {
        **server.env(),
        "AWS_ENDPOINT_URL": f"http://127.0.0.1:{proxy.port}",
        "CARLOS_STORE_OUTAGE_SECONDS": str(budget),
    }


def _outage_during_sweep(
    tmp_path: Path, server: S3Server, proxy: FlakyProxy, budget: float, down_seconds: float | None
) -> tuple[subprocess.CompletedProcess[str], float]:
    manifest = _manifest(
        tmp_path, f"outage-{os.getpid()}-{tmp_path.name}"[:50].lower().replace("_", "-"), speeds=OUTAGE_SPEEDS
    )
    name = manifest.stem
    process = _start(manifest, f"s3://{server.bucket}/faults", _s3_env(server, proxy, budget))
    _wait_for_workers(process)
    time.sleep(1.0)
    proxy.down()
    went_down = time.monotonic()
    if down_seconds is not None:
        time.sleep(down_seconds)
        proxy.up()
    stdout, stderr = process.communicate(timeout=600)
    assert name
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr), went_down


@pytest.mark.slow
def test_an_s3_outage_mid_sweep_is_survived(
    tmp_path: Path,
    s3_server: S3Server,  # noqa: F811
    proxy: FlakyProxy,
) -> None:
    result, _ = _outage_during_sweep(tmp_path, s3_server, proxy, budget=120, down_seconds=12)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert f"passed · {len(OUTAGE_SPEEDS)} runs" in result.stdout


@pytest.mark.slow
def test_an_s3_server_that_never_comes_back_ends_in_one_line_with_exit_3(
    tmp_path: Path,
    s3_server: S3Server,  # noqa: F811
    proxy: FlakyProxy,
) -> None:
    result, went_down = _outage_during_sweep(tmp_path, s3_server, proxy, budget=6, down_seconds=None)
    assert result.returncode == 3, result.stderr
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: S3 ") and "s of retries" in lines[0], lines
    assert time.monotonic() - went_down < 120  # bounded: the budget plus the requests in flight
