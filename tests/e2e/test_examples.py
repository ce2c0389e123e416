"""The examples applied with `kubectl apply -f` give the results `carlos run` gives for the same manifest.

Each manifest goes through `carlos submit --dry-run -o yaml` (its local scenarios and roads packed into a
ConfigMap owned by the run: the objects a GitOps repository holds) and then `kubectl apply -f`. The pods run
in real containers on the node; their results land in the S3 server. Compared with a local `carlos run` of
the same manifest: the phase against the exit code, every run's verdict (criteria, metrics, end reason),
junit.xml's cases (without wall times), and every recorded message byte for byte (topic, time, data; the file's
bytes differ: DDS delivers same-instant messages of different topics in no fixed order, and the file names
the run).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.e2e.conftest import CARLOS, IMAGE_PREFIX, ROOT, RUNS_NS, Cluster
from tests.e2e.results import by_point, index_files, junit_cases, messages

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(1500)]

#: the examples that fit two cores, with `carlos run`'s exit code
EXAMPLES = {
    "automated-testing": 0,
    "automated-testing-failing": 1,
    "data-generation": 0,
    "prototyping": 0,
}
# Not here: perception.yaml (its detector, a container beside simcore, keeps up with the lidar only on a node
# with cores to spare: on two shared cores it saw 0.5% of the frames, so its recall criterion fails there),
# closed-loop.yaml (needs a controller process), cooperative-perception.yaml and search-cut-in.yaml (minutes).
PHASE = {0: "Succeeded", 1: "Failed"}


@pytest.fixture(scope="module")
def applied(cluster: Cluster) -> dict[str, str]:
    """Every example applied at once (the operator and the scheduler see them together), by name → run."""
    names = {}
    for example in EXAMPLES:
        name = f"ex-{example}"
        objects = cluster.submit_yaml(ROOT / f"examples/runs/{example}.yaml", name=name)
        # the examples name the published images; this cluster has them under the local prefix, never pulled
        cluster.apply(objects.replace("ghcr.io/carlos-sim/", f"{IMAGE_PREFIX}/"))
        names[example] = name
    return names


def _local(tmp: Path, example: str) -> tuple[int, Path]:
    out = tmp / "local"
    proc = subprocess.run(
        [
            CARLOS,
            "run",
            f"examples/runs/{example}.yaml",
            "--output",
            f"file://{out}",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    return proc.returncode, out


@pytest.mark.parametrize("example", list(EXAMPLES))
def test_example_on_the_cluster_equals_carlos_run(
    cluster: Cluster, applied: dict[str, str], example: str, tmp_path: Path
) -> None:
    from simcore.store import FileStore

    name = applied[example]
    status = cluster.wait_phase(name, timeout=900)
    code, out = _local(tmp_path, example)
    assert code == EXAMPLES[example]
    assert status["phase"] == PHASE[code], status
    assert status["resultsURL"].endswith(f"/{RUNS_NS}/{name}")
    remote_store = cluster.store(f"results/{RUNS_NS}")
    local_store = FileStore(out)
    local_run = next(p.name for p in out.iterdir())
    remote, local = index_files(remote_store, name), index_files(local_store, local_run)
    assert sorted(remote) == sorted(local) == list(range(status["total"]))
    remote_points, local_points = by_point(remote), by_point(local)
    assert sorted(remote_points) == sorted(local_points)
    for point, ran in local_points.items():
        assert remote_points[point]["summary"] | {"index": None} == ran["summary"] | {"index": None}, point
        if ran["recording"] is not None:  # every message, byte for byte
            assert messages(remote_points[point]["recording"]) == messages(ran["recording"]), point
    remote_junit = remote_store.get_bytes(f"{name}/junit.xml").decode().replace(name, local_run)
    assert junit_cases(remote_junit) == junit_cases(local_store.get_bytes(f"{local_run}/junit.xml").decode())


def test_printer_columns_and_conditions(cluster: Cluster, applied: dict[str, str]) -> None:
    name = applied["automated-testing-failing"]
    cluster.wait_phase(name)
    table = cluster.kubectl("-n", RUNS_NS, "get", "simulationruns").stdout.splitlines()
    header = table[0].split()
    assert header[:2] == ["NAME", "PHASE"]
    assert {"PROGRESS", "PASSED", "FAILED", "AGE"} <= set(header)
    row = next(line.split() for line in table[1:] if line.split()[0] == name)
    assert row[1] == "Failed"
    conditions = {c["type"]: c for c in cluster.run_object(name)["status"]["conditions"]}
    assert conditions["Accepted"]["status"] == "True"
    assert (conditions["Failed"]["status"], conditions["Failed"]["reason"]) == ("True", "TestFailures")
    assert conditions["Complete"]["status"] == "True"  # every index finished
    events = cluster.kubectl_json(
        "-n", RUNS_NS, "get", "events", "--field-selector", f"involvedObject.name={name}"
    )["items"]
    reasons = {e["reason"] for e in events}
    assert reasons, "no events for the run"
