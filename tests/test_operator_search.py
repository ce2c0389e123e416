"""A search (`spec.search`) on the cluster, end to end against kmock's emulator: one Indexed Job per round,
pods run by the test kubelet, the study and the results in the real S3 server; the operator restarted
between rounds and in the middle of one creates no second Job and loses no point."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from carlos_operator.builders import round_job_name
from carlos_operator.kube import Kube

from simcore.manifest import parse_manifest
from simcore.search import driver
from tests.kube_emulator import Cluster, wait_for
from tests.s3server import S3Server
from tests.test_operator import create, env, results, runner, status, terminal

__all__ = ["env"]  # the fixture

pytestmark = [pytest.mark.s3, pytest.mark.timeout(420)]

ROOT = Path(__file__).resolve().parent.parent
CUT_IN = ROOT / "examples/scenarios/cut-in.xosc"


def search_manifest(name: str, bucket: str) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default"},
        "spec": {
            "scenarios": [
                {"name": "cut-in", "openscenario": CUT_IN.as_uri(), "parameters": {"AdversaryEndSpeed": 5.0}}
            ],
            "search": {
                "parameters": [
                    {"name": "CutInGap", "min": 5.0, "max": 20.0},
                    {"name": "EgoSpeed", "min": 20.0, "max": 30.0},
                ],
                "objective": {"metric": "minDistance", "direction": "minimize"},
                "strategy": "tpe",
                "budget": 6,
                "batchSize": 3,
                "seed": 3,
            },
            "simulation": {"stepSeconds": 0.1, "maxSeconds": 15},
            "evaluation": {"criteria": ["simSeconds <= 1000"]},
            "recording": {"enabled": False},
            "output": {"url": f"s3://{bucket}/operator", "credentialsSecretRef": {"name": "s3"}},
            "execution": {"parallelism": 3, "retries": 1},  # default slices: a round of 3 points, 1 pod
        },
    }


def job_names(c: Cluster) -> list[str]:
    return sorted(j["metadata"]["name"] for j in c.objects("jobs"))


def test_search_runs_in_rounds_survives_restarts_and_succeeds(
    env: tuple[Cluster, Kube], s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    c, kube = env
    name = "search-e2e"
    body = search_manifest(name, s3_server.bucket)
    r0, r1 = round_job_name(name, 0), round_job_name(name, 1)
    c.start_operator()
    create(kube, body)
    wait_for(lambda: job_names(c) == [r0], 30, "round 0's Job")
    first = wait_for(lambda: status(kube, name).get("search") and status(kube, name), 30, "the status")
    assert first["search"]["rounds"] == "0/2" and first["jobName"] == r0 and first["total"] == 6
    # the operator stops; round 0 runs and finishes while it is down
    c.stop_operator()
    jobs = runner(kube, s3_server, tmp_path)
    try:
        wait_for(
            lambda: any(
                x.get("type") == "Complete"
                for x in c.objects("jobs")[0].get("status", {}).get("conditions") or []
            ),
            240,
            "round 0 to finish",
        )
        assert job_names(c) == [r0]  # nobody asked the study for round 1 yet
        c.start_operator()  # tells the study round 0, stores it, creates round 1
        wait_for(lambda: r1 in job_names(c), 60, "round 1's Job")
        c.stop_operator()  # in the middle of round 1
        c.start_operator()
        st = wait_for(lambda: terminal(kube, name), 300, "a terminal phase")
    finally:
        jobs.stop()
    assert jobs.errors == []
    assert st["phase"] == "Succeeded", json.dumps(st, indent=1)
    assert job_names(c) == [r0, r1]  # one Job per round, none twice
    assert c.emulator is not None and c.emulator.calls[("CREATE", "jobs")] == 2
    assert sorted(m["metadata"]["name"] for m in c.objects("configmaps")) == [r0, r1]
    by_name = {j["metadata"]["name"]: j for j in c.objects("jobs")}
    for number, job_name in enumerate((r0, r1)):
        spec = by_name[job_name]["spec"]
        # the round's 3 points in one pod (round 1 sized by round 0's measured wall seconds)
        assert spec["completionMode"] == "Indexed" and spec["completions"] == 1
        assert by_name[job_name]["metadata"]["annotations"]["carlos.dev/runs"] == "3"
        env_of = {e["name"]: e.get("value") for e in spec["template"]["spec"]["containers"][0]["env"]}
        assert env_of["CARLOS_INDEX_OFFSET"] == str(3 * number) and env_of["CARLOS_RUNS_PER_POD"] == "3"
    search = st["search"]
    assert (search["rounds"], search["roundsDone"], search["roundsTotal"], search["evaluated"]) == (
        "2/2",
        2,
        2,
        6,
    )
    assert search["failuresFound"] == 0 and "round" not in search
    assert (st["passed"], st["total"], st["progress"]) == (6, 6, "6/6")
    store = results(s3_server, monkeypatch)
    document = json.loads(store.get_bytes(f"{name}/search.json"))
    assert document["runs"] == 6 and [r["runs"] for r in document["rounds"]] == [3, 3]
    assert search["bestObjective"] == pytest.approx(document["best"]["objective"])
    assert search["searchURL"].endswith(f"/operator/default/{name}/search.json")
    # every point ran with its parameters under its global index, each exactly once
    for point in document["points"]:
        summary = json.loads(store.get_bytes(f"{name}/{point['index']}/summary.json"))
        assert summary["index"] == point["index"] and summary["status"] == "passed"
        assert {k: float(summary["parameters"][k]) for k in point["parameters"]} == pytest.approx(
            point["parameters"]
        )
        assert summary["metrics"]["minDistance"] == pytest.approx(point["objective"])
    assert len({json.dumps(p["parameters"], sort_keys=True) for p in document["points"]}) == 6
    # the stored study is the one the local search keeps: round 0 asks the same points again from nothing
    run = parse_manifest(json.loads(json.dumps(body)), source=name)
    space = driver.search_space(run, CUT_IN)
    asked = driver.ask_round(run, space, [], [])
    assert asked is not None
    assert [p["parameters"] for p in document["points"][:3]] == asked.asked
    log, points = driver.load_state(run, store)
    assert len(points) == 6 and log
    run_summary = json.loads(store.get_bytes(f"{name}/summary.json"))
    assert run_summary["counts"]["passed"] == 6
    assert store.get_bytes(f"{name}/junit.xml").decode().count("<testcase") == 6
    reasons = [e.get("reason") for e in c.objects("events")]
    assert reasons.count("JobCreated") == 2 and "Succeeded" in reasons
    # `carlos get` / `carlos watch` show the rounds
    from simcore.workflow.status import state_of_object

    obj = kube.custom.get_namespaced_custom_object(
        "carlos.dev", "v1alpha1", "default", "simulationruns", name
    )
    line = state_of_object(obj).line()
    assert (
        f"{name}: Succeeded · 6 finished · 6 passed" in line
        and f"rounds 2/2 · best {search['bestObjective']:.3g}" in line
    )
