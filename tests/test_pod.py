"""The pod roles as separate processes (bridge, recorder, simcore), run by the test kubelet from the
operator's own pod template, with results in the real S3 server: over DDS (the template's default) and over
the loopback TCP hub (the operator's `CARLOS_POD_TRANSPORT=loopback`)."""

from __future__ import annotations

import base64
import json
import threading
from pathlib import Path
from typing import Any

import pytest
from carlos_operator.builders import OperatorSettings, build_configmap, build_job, resolve_output
from mcap.reader import make_reader

from simcore.manifest import parse_manifest
from simcore.pod import RECORDER_TOPIC, STATUS_TOPIC, STATUS_TYPE, _status_message
from simcore.store import open_store
from simcore.transport.bus import Message
from simcore.transport.loopback import LoopbackBus, LoopbackHub
from tests.kubelet import Kubelet
from tests.s3server import S3Server

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = (ROOT / "examples/scenarios/braking.xosc").as_uri()


def body(name: str, bucket: str, criteria: list[str], **extra: Any) -> dict[str, Any]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": "default", "uid": f"uid-{name}"},
        "spec": {
            "scenarios": [{"name": "braking", "openscenario": SCENARIO}],
            "sweep": {"matrix": {"Speed": [15.0, 20.0]}},
            "simulation": {"stepSeconds": 0.1, "maxSeconds": 4},
            "evaluation": {"criteria": criteria},
            "output": {"url": f"s3://{bucket}/pods", "credentialsSecretRef": {"name": "s3"}},
            **extra,
        },
    }


def kubelet_for(
    manifest: dict[str, Any], s3: S3Server, tmp_path: Path, transport: str = "dds"
) -> tuple[Kubelet, dict[str, Any]]:
    run = parse_manifest(json.loads(json.dumps(manifest)), source="test")
    settings = OperatorSettings.from_env(
        {"CARLOS_DEFAULT_S3_ENDPOINT": s3.endpoint, "CARLOS_POD_TRANSPORT": transport}
    )
    output = resolve_output(run, settings)
    cm = build_configmap(run, manifest, settings)
    job = build_job(run, manifest, settings, output)
    secret = {
        "AWS_ACCESS_KEY_ID": base64.b64encode(s3.access_key.encode()).decode(),
        "AWS_SECRET_ACCESS_KEY": base64.b64encode(s3.secret_key.encode()).decode(),
    }
    kubelet = Kubelet(
        configmaps={cm["metadata"]["name"]: cm["data"]},
        secrets={"s3": secret},
        workdir=tmp_path,
        extra_env={"AWS_REGION": s3.region},
    )
    return kubelet, job["spec"]["template"]["spec"]


def results_store(s3: S3Server, monkeypatch: pytest.MonkeyPatch) -> Any:
    for key, value in s3.env().items():
        monkeypatch.setenv(key, value)
    return open_store(f"s3://{s3.bucket}/pods", endpoint=s3.endpoint, region=s3.region)


def test_hub_relays_in_order_between_processes_and_acknowledges_subscriptions() -> None:
    from simcore.transport.messages import TYPESTORE

    Clock = TYPESTORE.types["rosgraph_msgs/msg/Clock"]
    Time = TYPESTORE.types["builtin_interfaces/msg/Time"]
    hub = LoopbackHub("127.0.0.1", 0).start()
    try:
        received: list[Message] = []
        got_all = threading.Event()

        def on_clock(message: Message) -> None:
            received.append(message)
            if len(received) == 500:
                got_all.set()

        subscriber = LoopbackBus("127.0.0.1", hub.port)
        subscriber.subscribe("/cl*", on_clock)
        other: list[str] = []
        subscriber.subscribe("/nothing", lambda m: other.append(m.topic))
        publisher = LoopbackBus("127.0.0.1", hub.port)
        own: list[float] = []
        publisher.subscribe("/clock", lambda m: own.append(m.time_s))
        clock = publisher.advertise("/clock", "rosgraph_msgs/msg/Clock")
        for i in range(500):
            clock.publish(Clock(clock=Time(sec=i, nanosec=0)), float(i))
        assert got_all.wait(10)
        assert [m.time_s for m in received] == [float(i) for i in range(500)]
        assert [m.obj().clock.sec for m in received[:3]] == [0, 1, 2]
        assert own == [float(i) for i in range(500)]  # own publications reach own subscriptions once
        assert other == []
        publisher.close()
        subscriber.close()
    finally:
        hub.close()


@pytest.mark.s3
@pytest.mark.parametrize("transport", ["dds", "loopback"])
def test_pod_roles_run_an_index_and_upload_results(
    transport: str, s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    name = f"pod-pass-{transport}"
    manifest = body(name, s3_server.bucket, ["simSeconds <= 100"], execution={"runsPerPod": 1})
    kubelet, pod = kubelet_for(manifest, s3_server, tmp_path, transport)
    result = kubelet.run_pod(pod, index=1)
    assert result.exit_codes == {"simcore": 0, "bridge": 0, "recorder": 0}, result.logs
    assert ("on DDS domain" in result.logs["bridge"]) == (transport == "dds")
    store = results_store(s3_server, monkeypatch)
    keys = set(store.list(f"{name}/1/"))
    assert {f"{name}/1/recording.mcap", f"{name}/1/summary.json", f"{name}/1/log.txt"} <= keys
    summary = json.loads(store.get_bytes(f"{name}/1/summary.json"))
    assert summary["index"] == 1 and summary["status"] == "passed"
    assert summary["parameters"] == {"Speed": 20.0}
    recording = tmp_path / "recording.mcap"
    recording.write_bytes(store.get_bytes(f"{name}/1/recording.mcap"))
    with recording.open("rb") as f:
        reader = make_reader(f)
        topics = {channel.topic for channel in reader.get_summary().channels.values()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert {"/clock", "/tf", "/carlos/objects", "/carlos/status"} <= topics
    assert metadata["carlos.run"]["index"] == "1"
    assert "Speed" in metadata["carlos.run"]["parameters"]
    assert metadata["carlos.run"]["scenarioTimeOffsetSeconds"] == "0.0"  # as a local recording's


def test_the_recorder_writes_the_run_record_with_the_verdicts_scenario_time_offset(tmp_path: Path) -> None:
    """A FollowGhost's head start is known when simcore has run the index: the recorder pod writes the
    `carlos.run` metadata with the verdict, so the pod's MCAP says what a local one says."""
    from simcore.pod import _Recording, _run_record

    done = _Recording(3, None, tmp_path, "1", {"run": "r", "index": "3"})
    summary = {"index": 3, "scenarioTimeOffsetSeconds": -1.5}
    assert _run_record(done, summary) == {"run": "r", "index": "3", "scenarioTimeOffsetSeconds": "-1.5"}
    assert _run_record(done, None)["scenarioTimeOffsetSeconds"] == "0.0"  # terminated before a verdict


@pytest.mark.s3
def test_a_test_failure_exits_1_and_bad_input_exits_2(
    s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    manifest = body("pod-fail", s3_server.bucket, ["minDistance >= 10000"], execution={"runsPerPod": 1})
    kubelet, pod = kubelet_for(manifest, s3_server, tmp_path)
    result = kubelet.run_pod(pod, index=0)
    assert result.exit_codes["simcore"] == 1, result.logs
    store = results_store(s3_server, monkeypatch)
    summary = json.loads(store.get_bytes("pod-fail/0/summary.json"))
    assert summary["status"] == "failed"
    assert summary["criteria"][0]["passed"] is False

    bad = body("pod-bad", s3_server.bucket, [])
    bad["spec"]["scenarios"][0]["openscenario"] = "file:///nonexistent/scenario.xosc"
    kubelet, pod = kubelet_for(bad, s3_server, tmp_path)
    result = kubelet.run_pod(pod, index=0)
    assert result.exit_codes["simcore"] == 2, result.logs
    assert "nonexistent" in result.logs["simcore"]
    summary = json.loads(store.get_bytes("pod-bad/0/summary.json"))
    assert summary["status"] == "error"


@pytest.mark.s3
def test_recorder_on_sigterm_keeps_every_message_and_writes_no_summary(
    s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import signal
    import subprocess

    from simcore.transport.messages import TYPESTORE
    from tests.kubelet import CARLOS, free_port

    manifest = body("pod-term", s3_server.bucket, [])
    kubelet, _ = kubelet_for(manifest, s3_server, tmp_path)
    spec_file = tmp_path / "simulationrun.yaml"
    spec_file.write_text(next(iter(kubelet.configmaps.values()))["simulationrun.yaml"])
    bus_port, ready_port = free_port(), free_port()
    count = 20_000
    env = {
        **s3_server.env(),
        "PATH": "/usr/bin:/bin",
        "JOB_COMPLETION_INDEX": "0",
        "CARLOS_SPEC": str(spec_file),
        "CARLOS_OUTPUT_URL": f"s3://{s3_server.bucket}/pods",
        "CARLOS_BUS_PORT": str(bus_port),
        "CARLOS_RECORDER_READY_PORT": str(ready_port),
        "CARLOS_SCRATCH": str(tmp_path / "scratch"),
    }
    bridge = subprocess.Popen([CARLOS, "pod", "--role", "bridge"], env=env)
    recorder = subprocess.Popen([CARLOS, "pod", "--role", "recorder"], env=env)
    try:
        from tests.kubelet import _wait_port

        _wait_port(bus_port, 30, bridge)
        _wait_port(ready_port, 30, recorder)
        Clock = TYPESTORE.types["rosgraph_msgs/msg/Clock"]
        Time = TYPESTORE.types["builtin_interfaces/msg/Time"]
        bus = LoopbackBus("127.0.0.1", bus_port)
        # as simcore does: announce index 0 and wait until the recorder has opened its recording
        opened = threading.Event()
        bus.subscribe(RECORDER_TOPIC, lambda m: opened.set())
        bus.advertise(STATUS_TOPIC, STATUS_TYPE).publish(
            _status_message("start", 0.0, {"index": "0", "attempt": "1"}), 0.0
        )
        assert opened.wait(30)
        clock = bus.advertise("/clock", "rosgraph_msgs/msg/Clock")
        # stopped while they are published, the recorder has read none of them when SIGTERM arrives: every
        # one is in flight (with the hub and in the recorder's socket), and reading and writing them all takes
        # it longer than noticing SIGTERM (without its drain it records a few hundred at most)
        recorder.send_signal(signal.SIGSTOP)
        for i in range(count):
            clock.publish(Clock(clock=Time(sec=i, nanosec=0)), float(i))
        bus.close()
        assert bus.disconnected.is_set()  # the hub read them all and passed them on before closing on us
        recorder.send_signal(signal.SIGTERM)
        recorder.send_signal(signal.SIGCONT)
        assert recorder.wait(30) == 0
    finally:
        for proc in (recorder, bridge):
            if proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
                proc.send_signal(signal.SIGTERM)
                proc.wait(30)
    store = results_store(s3_server, monkeypatch)
    assert not store.exists("pod-term/0/summary.json")
    assert "terminated before the end" in store.get_bytes("pod-term/0/log.txt").decode()
    recording = tmp_path / "term.mcap"
    recording.write_bytes(store.get_bytes("pod-term/0/recording.mcap"))
    with recording.open("rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == count
        seconds = [
            TYPESTORE.deserialize_cdr(message.data, "rosgraph_msgs/msg/Clock").clock.sec
            for _, _, message in reader.iter_messages()
        ]
    assert seconds == list(range(count))  # every message sent, each once, in order


@pytest.mark.s3
@pytest.mark.parametrize("transport", ["dds", "loopback"])
def test_a_shard_pod_runs_its_slice_and_skips_finished_indexes_when_retried(
    transport: str, s3_server: S3Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both indexes of the sweep in one pod (the default slice of a 2-run sweep): each index gets its own
    files and recording; a second attempt of the pod finds them and runs nothing again."""
    name = f"pod-shard-{transport}"
    manifest = body(name, s3_server.bucket, ["simSeconds <= 100"])
    kubelet, pod = kubelet_for(manifest, s3_server, tmp_path, transport)
    assert {"name": "CARLOS_RUNS_PER_POD", "value": "2"} in pod["containers"][0]["env"]
    result = kubelet.run_pod(pod, index=0)
    assert result.exit_codes == {"simcore": 0, "bridge": 0, "recorder": 0}, result.logs
    store = results_store(s3_server, monkeypatch)
    first: dict[str, bytes] = {}
    for index, speed in ((0, 15.0), (1, 20.0)):
        summary = json.loads(store.get_bytes(f"{name}/{index}/summary.json"))
        assert summary["index"] == index and summary["status"] == "passed"
        assert summary["parameters"] == {"Speed": speed}
        for key in ("recording.mcap", "log.txt", "summary.json"):
            first[f"{index}/{key}"] = store.get_bytes(f"{name}/{index}/{key}")
        recording = tmp_path / f"recording-{index}.mcap"
        recording.write_bytes(first[f"{index}/recording.mcap"])
        with recording.open("rb") as f:
            metadata = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
        assert metadata["carlos.run"]["index"] == str(index)
    again = kubelet.run_pod(pod, index=0, failures=1)
    assert again.exit_codes["simcore"] == 0, again.logs
    assert again.logs["simcore"].count("done by an earlier attempt (passed), skipped") == 2
    for key, data in first.items():
        assert store.get_bytes(f"{name}/{key}") == data


def test_the_test_kubelet_gives_pods_that_run_at_once_their_own_dds_domain(tmp_path: Path) -> None:
    """Pods of a real cluster each have their own loopback; here they share the host's, so two pods in one
    DDS domain would hear each other (a run's verdict then comes out wrong). 30 pods started at once, each
    printing its domain while the others still run: all different (the domains were drawn at random and
    checked only for a joined participant: 30 pods that had not joined yet shared one almost surely)."""
    import sys

    code = "import os, time; print(os.environ['ROS_DOMAIN_ID'], flush=True); time.sleep(1.5)"
    pod = {
        "containers": [
            {
                "name": "simcore",
                "command": [sys.executable, "-c", code],
                "env": [{"name": "ROS_DOMAIN_ID", "value": "0"}],
            }
        ]
    }
    kubelet = Kubelet(configmaps={}, secrets={}, workdir=tmp_path)
    results: list[Any] = [None] * 30
    threads = [
        threading.Thread(target=lambda i=i: results.__setitem__(i, kubelet.run_pod(pod, index=i)))
        for i in range(30)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    domains = [r.logs["simcore"].strip() for r in results]
    assert all(d.isdigit() and d != "0" for d in domains), domains
    assert len(set(domains)) == 30, sorted(domains)


def test_pod_env_names_the_slice_of_its_completion_index() -> None:
    from simcore.errors import BadInput
    from simcore.pod import PodEnv

    base = {"CARLOS_SPEC": "/s.yaml", "CARLOS_OUTPUT_URL": "file:///out", "JOB_COMPLETION_INDEX": "2"}
    env = PodEnv.from_env({**base, "CARLOS_RUNS_PER_POD": "3", "CARLOS_INDEX_OFFSET": "100"})
    assert (env.completion, env.position, env.runs_per_pod) == (2, 6, 3)
    assert list(env.positions(8)) == [6, 7]  # the last slice is short
    assert [env.offset + p for p in env.positions(8)] == [106, 107]  # the run's indexes
    assert list(PodEnv.from_env(base).positions(8)) == [2]  # default: one run per pod
    with pytest.raises(BadInput, match="CARLOS_RUNS_PER_POD"):
        PodEnv.from_env({**base, "CARLOS_RUNS_PER_POD": "0"})


def test_a_rerun_of_failed_indexes_is_sliced_like_any_sweep() -> None:
    manifest = body("rerun", "bucket", [], execution={"runsPerPod": 2})
    manifest["spec"]["sweep"] = {"matrix": {"Speed": [10.0, 12.0, 14.0, 16.0, 18.0]}, "indexes": [4, 1, 3]}
    run = parse_manifest(json.loads(json.dumps(manifest)), source="test")
    settings = OperatorSettings.from_env({"CARLOS_DEFAULT_S3_ENDPOINT": "http://s3"})
    job = build_job(run, manifest, settings, resolve_output(run, settings))
    assert job["spec"]["completions"] == 2  # 3 runs in slices of 2
    assert job["metadata"]["annotations"]["carlos.dev/runs"] == "3"
