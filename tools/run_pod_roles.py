#!/usr/bin/env python3
"""Run a slice of two SimulationRun indexes as a pod would — `carlos pod --role bridge`, `--role recorder`,
then `--role simcore` (CARLOS_RUNS_PER_POD=2), three processes of the `carlos` next to this interpreter —
over the loopback hub and over DDS, with file:// results; check the exit codes, each index's summary and
recording. Used by
tools/wheel-check with the interpreter of a virtualenv holding only the built wheel. Standard library only.

    python tools/run_pod_roles.py SCENARIO.xosc WORKDIR
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

RUN_NAME = "wheel-pods"
START_TIMEOUT = 120.0
RUN_TIMEOUT = 600.0


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def wait_port(port: int, proc: subprocess.Popen[bytes], what: str) -> None:
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"{what} exited with {proc.returncode} before opening port {port}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            time.sleep(0.2)
    raise RuntimeError(f"{what} did not open port {port} within {START_TIMEOUT:.0f} s")


def manifest(scenario: Path, output: str) -> dict[str, object]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": RUN_NAME},
        "spec": {
            "scenarios": [{"name": "braking", "openscenario": scenario.resolve().as_uri()}],
            "sweep": {"repetitions": 2},
            "simulation": {"stepSeconds": 0.1, "maxSeconds": 4},
            "evaluation": {"criteria": ["simSeconds <= 100"]},
            "output": {"url": output},
        },
    }


def run_pod(scenario: Path, work: Path, transport: str) -> None:
    """A slice of two indexes through the three roles; raises with the logs when anything is off."""
    carlos = str(Path(sys.executable).with_name("carlos"))
    root = work / transport
    results = root / "results"
    (root / "scratch").mkdir(parents=True)
    (root / "scenarios").mkdir()
    spec = root / "simulationrun.json"
    output = results.as_uri()
    spec.write_text(json.dumps(manifest(scenario, output)))
    bus_port, ready_port = free_port(), free_port()
    env = {
        **os.environ,
        "JOB_COMPLETION_INDEX": "0",
        "CARLOS_RUNS_PER_POD": "2",
        "CARLOS_SPEC": str(spec),
        "CARLOS_OUTPUT_URL": output,
        "CARLOS_BUS_PORT": str(bus_port),
        "CARLOS_RECORDER_READY_PORT": str(ready_port),
        "CARLOS_SCRATCH": str(root / "scratch"),
        "CARLOS_SCENARIO_DIR": str(root / "scenarios"),
        "CARLOS_TRANSPORT": transport,
    }
    if transport == "dds":
        config = subprocess.run(
            [
                sys.executable,
                "-c",
                "from simcore.transport.dds_config import loopback_config as c; print(c())",
            ],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
        env.update(CYCLONEDDS_URI=config, ROS_DOMAIN_ID=str(5 + os.getpid() % 90))
    procs: dict[str, subprocess.Popen[bytes]] = {}

    def start(role: str) -> subprocess.Popen[bytes]:
        with open(root / f"{role}.log", "wb") as log:
            procs[role] = subprocess.Popen(
                [carlos, "pod", "--role", role], env=env, cwd=root, stdout=log, stderr=subprocess.STDOUT
            )
        return procs[role]

    try:
        wait_port(bus_port, start("bridge"), "bridge")
        wait_port(ready_port, start("recorder"), "recorder")
        code = start("simcore").wait(RUN_TIMEOUT)
        if code != 0:
            raise RuntimeError(f"simcore exited with {code}")
        for role in ("recorder", "bridge"):
            if procs[role].poll() is None:
                procs[role].send_signal(signal.SIGTERM)
            if procs[role].wait(60) != 0:
                raise RuntimeError(f"{role} exited with {procs[role].returncode}")
        for number in ("0", "1"):
            index = results / RUN_NAME / number
            summary = json.loads((index / "summary.json").read_text())
            if summary.get("status") != "passed" or summary.get("index") != int(number):
                raise RuntimeError(f"{number}/summary.json: not index {number} passed: {summary}")
            if (index / "recording.mcap").stat().st_size == 0:
                raise RuntimeError(f"{number}/recording.mcap is empty")
    except Exception as exc:
        logs = "\n".join(
            f"--- {log.name}\n{log.read_text(errors='replace')[-3000:]}" for log in sorted(root.glob("*.log"))
        )
        raise RuntimeError(f"pod roles over {transport}: {exc}\n{logs}") from exc
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def main(argv: list[str]) -> int:
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    scenario, work = Path(argv[1]), Path(argv[2])
    for transport in ("loopback", "dds"):
        started = time.monotonic()
        try:
            run_pod(scenario, work, transport)
        except RuntimeError as exc:
            print(f"run_pod_roles: {exc}", file=sys.stderr)
            return 1
        print(f"pod roles over {transport}: passed ({time.monotonic() - started:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
