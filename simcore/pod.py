"""The roles of a SimulationRun pod: `carlos pod --role simcore|bridge|recorder` (DESIGN.md, pod roles).

Each role is its own process (its own container on a cluster). They exchange ROS 2 messages over the
transport `CARLOS_TRANSPORT` names:

- `loopback` (the default when unset): the topic hub of simcore/transport/loopback.py on
  127.0.0.1:`CARLOS_BUS_PORT`, run by the bridge. ROS 2 nodes do not see these topics.
- `dds` (what the operator's pod template sets, unless the operator runs with CARLOS_POD_TRANSPORT=loopback):
  DDS (simcore/transport/dds.py, cyclonedds) on domain `ROS_DOMAIN_ID` (default 0), configured as a ROS 2
  node would be (simcore.transport.dds_config: `CYCLONEDDS_URI`; the template's is 127.0.0.1 only). Every role is a DDS participant and the topics are ROS 2 topics (`rt/…`, ROS 2
  type names and QoS): ROS 2 nodes in the pod (the system under test's container) or on its network see
  them and can publish `/carlos/<entity>/control`, as with any ROS 2 node; no relay is involved. simcore
  waits until the recorder announced its subscription before it runs, a writer waits for its announced
  subscribers before its first message, and simcore flushes (all data acknowledged) before the verdict,
  which the recorder handles after draining what arrived before it: the recording loses nothing. Without
  CYCLONEDDS_URI cyclonedds uses its defaults (first interface, multicast discovery, 1344-byte fragments);
  `simcore.transport.dds_config.loopback_config()` is the configuration for roles and nodes all in one pod.
  In lockstep (spec.control) simcore waits before the first frame until a node subscribed to each
  driven entity's odometry by name (the system under test's reader of /carlos/<entity>/odometry).

- `bridge` (first sidecar): loopback: runs the hub on 127.0.0.1:`CARLOS_BUS_PORT` until SIGTERM (its startup
  probe: the same port on the pod's own address, which the kubelet connects to). dds: joins
  the domain, accepts connections on `CARLOS_BUS_PORT` (every address of the pod) for its startup probe, and logs every
  ROS 2 topic (name, type) that appears on the domain until SIGTERM: it is the pod's view of the ROS 2
  graph (ROS 2 nodes talk to simcore's and the recorder's participants directly, nothing is relayed).
- `recorder` (second sidecar): subscribes to every topic (only to `/carlos/status` when the spec does not
  record), then opens `CARLOS_RECORDER_READY_PORT` (every address of the pod) for its startup probe. It serves the pod's
  slice: for each index simcore announces (`start` on `/carlos/status`) it opens the index's MCAP and answers
  `ready` on `/carlos/recorder/status`; when the index's verdict arrives (its values carry the index summary
  as JSON) — or on SIGTERM — it closes the MCAP with everything received, uploads `recording.mcap` and
  `log.txt` to `<output>/<run>/<index>/`, then `summary.json` last, and answers `uploaded` or `error`.
- `simcore` (main container): runs the pod's slice of indexes (`CARLOS_RUNS_PER_POD`, simcore.shards) one
  after another in this warm process — each with simcore.pipeline.simulate, on the pod's transport when the
  recorder records or a system under test has its own container, else on an in-process bus as a local
  worker — judges each, hands each verdict to the recorder and waits for its upload; it exits with the
  worst of DESIGN.md's codes over the slice: 0 passed, 1 test failure, 2 bad input (at once), 3
  infrastructure error (also when results could not be uploaded). See `run_simcore` for skips and retries.

A search's round (the operator's Job `carlos-<run>-r<N>`) mounts a spec that runs the round's points as a
sweep (`points.xosc` beside it) and sets `CARLOS_INDEX_OFFSET` to the round's first index: position k of the
round runs as the run's index offset+k (its results under `<run>/<offset+k>/`).

An infrastructure error on an attempt that will be retried (within the pod, or by Kubernetes:
`CARLOS_INDEX_FAILURES`, from the pod's `batch.kubernetes.io/job-index-failure-count` annotation, below
`execution.retries`) uploads the log but no summary, so the index does not look complete.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from simcore.errors import BadInput, CarlosError, ExitCode
from simcore.startup import settle_worker
from simcore.transport.bus import Callback, Message, Publisher

log = logging.getLogger("carlos.pod")

STATUS_TOPIC = "/carlos/status"
STATUS_TYPE = "diagnostic_msgs/msg/DiagnosticStatus"
RECORDER_TOPIC = "/carlos/recorder/status"
SUMMARY_KEY = "summary"
ROLES = ("simcore", "bridge", "recorder")
TRANSPORTS = ("loopback", "dds")


@dataclass(frozen=True)
class PodEnv:
    """The environment every role reads (set by the Job's pod template)."""

    index: int  # the run's index: JOB_COMPLETION_INDEX + CARLOS_INDEX_OFFSET
    spec_path: Path
    output_url: str
    failures: int  # earlier failed attempts of this index
    bus_port: int
    ready_port: int
    scratch: Path
    scenario_dir: Path
    upload_timeout: float
    transport: str = "loopback"  # CARLOS_TRANSPORT: loopback | dds
    domain_id: int = 0  # ROS_DOMAIN_ID (dds)
    #: CARLOS_INDEX_OFFSET: the run's index of the Job's position 0 (a search round's Job runs indexes
    #: offset… of the run; its spec lists only that round's points)
    offset: int = 0
    #: CARLOS_RUNS_PER_POD: the pod runs positions completion·R … completion·R+R-1 (simcore.shards)
    runs_per_pod: int = 1

    @property
    def completion(self) -> int:
        """The pod's JOB_COMPLETION_INDEX."""
        return self.index - self.offset

    @property
    def position(self) -> int:
        """The first index of the pod's slice in the mounted spec's plan."""
        return self.completion * self.runs_per_pod

    def positions(self, total: int) -> range:
        """The pod's slice of the mounted spec's plan (`total` points)."""
        from simcore.shards import slice_of

        return slice_of(self.completion, self.runs_per_pod, total)

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> PodEnv:
        env = dict(os.environ if env is None else env)

        def number(name: str, default: int | None = None) -> int:
            raw = env.get(name, "")
            if raw == "" and default is not None:
                return default
            try:
                value = int(raw)
            except ValueError:
                raise BadInput(
                    f"{name}={raw!r} is not a non-negative integer" if raw else f"{name} is not set",
                    field=name,
                ) from None
            if value < 0:
                raise BadInput(f"{name}={raw!r} is not a non-negative integer", field=name)
            return value

        spec = env.get("CARLOS_SPEC", "")
        if not spec:
            raise BadInput("CARLOS_SPEC (path of the mounted SimulationRun) is not set", field="CARLOS_SPEC")
        output = env.get("CARLOS_OUTPUT_URL", "")
        if not output:
            raise BadInput("CARLOS_OUTPUT_URL is not set", field="CARLOS_OUTPUT_URL")
        transport = env.get("CARLOS_TRANSPORT", "").strip() or "loopback"
        if transport not in TRANSPORTS:
            raise BadInput(
                f"CARLOS_TRANSPORT={transport!r} is not one of {', '.join(TRANSPORTS)}",
                field="CARLOS_TRANSPORT",
            )
        domain_id = 0
        if transport == "dds":
            from simcore.transport.dds_config import domain_id_from_env  # no cyclonedds import to read env

            domain_id = domain_id_from_env(env)
        offset = number("CARLOS_INDEX_OFFSET", 0)
        runs_per_pod = number("CARLOS_RUNS_PER_POD", 1)
        if runs_per_pod < 1:
            raise BadInput("CARLOS_RUNS_PER_POD=0 is not a positive integer", field="CARLOS_RUNS_PER_POD")
        return cls(
            runs_per_pod=runs_per_pod,
            index=number("JOB_COMPLETION_INDEX") + offset,
            offset=offset,
            spec_path=Path(spec),
            output_url=output,
            failures=number("CARLOS_INDEX_FAILURES", 0),
            bus_port=number("CARLOS_BUS_PORT", 7447),
            ready_port=number("CARLOS_RECORDER_READY_PORT", 7448),
            scratch=Path(env.get("CARLOS_SCRATCH") or tempfile.gettempdir()),
            scenario_dir=Path(env.get("CARLOS_SCENARIO_DIR") or "/etc/carlos/scenarios"),
            upload_timeout=float(env.get("CARLOS_UPLOAD_TIMEOUT") or 900),
            transport=transport,
            domain_id=domain_id,
        )


def _load(env: PodEnv) -> Any:
    from simcore.manifest import load_manifest
    from simcore.plan import Plan

    run = load_manifest(env.spec_path)
    total = len(Plan(run.spec))
    if env.position >= total:
        from simcore.shards import pods_for

        raise BadInput(
            f"JOB_COMPLETION_INDEX={env.completion} is out of range 0..{pods_for(total, env.runs_per_pod) - 1}",
            field="JOB_COMPLETION_INDEX",
        )
    return run


def _store(env: PodEnv, run: Any, url: str | None = None) -> Any:
    from simcore.store import open_store

    return open_store(
        url or env.output_url,
        endpoint=os.environ.get("AWS_ENDPOINT_URL") or run.spec.output.endpoint,
        region=os.environ.get("AWS_REGION") or run.spec.output.region,
    )


def _status_message(state: str, time_s: float, values: dict[str, str]) -> Any:
    from simcore.transport.messages import DiagnosticStatus, KeyValue

    return DiagnosticStatus(
        level=DiagnosticStatus.ERROR if state in ("error", "failed") else DiagnosticStatus.OK,
        name="carlos",
        message=state,
        hardware_id="",
        values=[KeyValue(key="state", value=state), *(KeyValue(key=k, value=v) for k, v in values.items())],
    )


def _values(msg: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in msg.values}


class _Borrowed:
    """A bus lent to `simulate`, which closes the bus it is given: here closing is the owner's business."""

    def __init__(self, bus: Any) -> None:  # a LoopbackBus or DdsBus (both count subscribers)
        self._bus = bus

    def advertise(self, topic: str, typename: str) -> Publisher:
        return self._bus.advertise(topic, typename)

    def subscribe(self, pattern: str, callback: Callback) -> None:
        self._bus.subscribe(pattern, callback)

    def subscriber_count(self, topic: str) -> int:
        """For lockstep's start (simcore.closedloop): nodes subscribed to `topic` by name."""
        count: int = self._bus.subscriber_count(topic)
        return count

    def close(self) -> None:
        pass


def _on_sigterm(handler: Callable[[], None]) -> None:
    def handle(signum: int, frame: Any) -> None:
        handler()

    signal.signal(signal.SIGTERM, handle)


def _connect(env: PodEnv, on_disconnect: Callable[[], None] | None = None) -> Any:
    """The role's bus on the pod's transport (raises ConnectionError when it cannot be reached)."""
    if env.transport == "dds":
        from simcore.transport.dds import DdsBus

        return DdsBus(env.domain_id)
    from simcore.transport.loopback import LoopbackBus

    return LoopbackBus("127.0.0.1", env.bus_port, connect_timeout=60.0, on_disconnect=on_disconnect)


# --- bridge ----------------------------------------------------------------------------------------------


def run_bridge(env: PodEnv) -> int:
    from simcore.transport.loopback import LoopbackHub

    stop = threading.Event()
    _on_sigterm(stop.set)
    if env.transport == "dds":
        return _run_dds_bridge(env, stop)
    hub = LoopbackHub("127.0.0.1", env.bus_port).start()
    # the topics stay on loopback; the kubelet's startup probe connects to the pod's own address
    address = _pod_address()
    ready = _ReadyPort(env.bus_port, address) if address else None
    log.info("bridge: topic hub on 127.0.0.1:%d, startup probe on %s", hub.port, address or "loopback")
    try:
        while not stop.wait(1.0):
            pass
    finally:
        if ready is not None:
            ready.close()
        hub.close()
    log.info("bridge: %d messages relayed", hub.relayed)
    return 0


def _run_dds_bridge(env: PodEnv, stop: threading.Event) -> int:
    try:
        bus = _connect(env)
    except ConnectionError as exc:
        print(f"error: {exc}", flush=True)
        return int(ExitCode.INFRASTRUCTURE)
    ready = _ReadyPort(env.bus_port)
    log.info("bridge: on DDS domain %d; startup probe on port %d", env.domain_id, env.bus_port)
    logged: set[str] = set()

    def log_new() -> None:
        for topic, typename in sorted(dict(bus.discovered).items()):
            if topic not in logged:
                logged.add(topic)
                log.info("bridge: ROS 2 topic %s [%s]", topic, typename)

    try:
        while not stop.wait(0.5):
            log_new()
    finally:
        ready.close()
        log_new()
        bus.close()
    log.info("bridge: %d ROS 2 topics seen on domain %d", len(logged), env.domain_id)
    return 0


# --- simcore ---------------------------------------------------------------------------------------------


def _needs_pod_bus(spec: Any) -> bool:
    """Whether the world's topics must leave simcore's process: the recorder sidecar records them, or a
    system under test runs in its own container. Otherwise an index runs on an in-process bus (as a local
    worker does) and only the verdict goes to the recorder."""
    sut = spec.system_under_test
    return bool(spec.recording.enabled or (sut is not None and sut.image))


class _Reports:
    """The recorder's reports on /carlos/recorder/status, by the index they are about."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._got: dict[tuple[str, str], dict[str, str]] = {}

    def on_message(self, message: Message) -> None:
        values = _values(message.obj())
        with self._cond:
            self._got[(values.get("index", ""), values.get("phase", "end"))] = values
            self._cond.notify_all()

    def wait(self, index: int, phase: str, timeout: float) -> dict[str, str] | None:
        key = (str(index), phase)
        with self._cond:
            self._cond.wait_for(lambda: key in self._got, timeout)
            return self._got.pop(key, None)


def run_simcore(env: PodEnv) -> int:
    """Run the pod's slice of indexes one after another in this (warm) process. Each index ends with its
    verdict, which the recorder turns into the index's files. Per index: an index whose summary exists (an
    earlier attempt of this pod) is skipped; an infrastructure error is retried here up to
    `execution.retries` times, then the pod fails (exit 3) so that Kubernetes retries the slice — unless this
    is the slice's last attempt, when the index is recorded as an error and the slice goes on; bad input
    stops the pod at once (exit 2). The exit code is the worst of the slice: 3, else 1 (a test failure),
    else 0."""
    from simcore.plan import Plan

    run = _load(env)
    spec = run.spec
    plan = Plan(spec)
    store = _store(env, run)
    try:
        bus = _connect(env)
    except ConnectionError as exc:
        print(f"error: {exc}", flush=True)
        return int(ExitCode.INFRASTRUCTURE)
    reports = _Reports()
    if env.transport == "dds":
        bus.subscribe(RECORDER_TOPIC, reports.on_message, typename=STATUS_TYPE)
        # the recorder subscribed before it reported ready; wait until this participant knows it
        if not bus.wait_for_subscribers(STATUS_TOPIC, 1, timeout=60.0):
            print("error: no recorder subscribed on the DDS domain within 60 s", flush=True)
            bus.close()
            return int(ExitCode.INFRASTRUCTURE)
    else:
        bus.subscribe(RECORDER_TOPIC, reports.on_message)
    status = bus.advertise(STATUS_TOPIC, STATUS_TYPE)
    last_pod_attempt = env.failures >= spec.execution.retries
    tries = spec.execution.retries + 1
    worst = ExitCode.PASSED
    # the slice's first unfinished index is the one an earlier attempt of this pod was running when it
    # failed: each earlier pod attempt counts one attempt of it (the later indexes had not started)
    earlier = env.failures
    try:
        for position in env.positions(len(plan)):
            index = env.offset + position
            kept = _kept_summary(store, f"{run.name}/{index}/summary.json")
            if kept is not None:
                print(
                    f"index {index}: done by an earlier attempt ({kept.get('status')}), skipped", flush=True
                )
                if kept.get("status") != "passed":
                    worst = max(worst, ExitCode.FAILED)
                continue
            code = ExitCode.INFRASTRUCTURE
            for attempt in range(1, tries + 1):
                final = last_pod_attempt and attempt == tries
                code = _run_one(
                    env, run, plan[position], index, earlier + attempt, final, bus, status, reports
                )
                settle_worker()  # a warm worker, as `carlos run`'s (simcore.executor)
                if code != ExitCode.INFRASTRUCTURE:
                    break
            earlier = 0
            if code == ExitCode.BAD_INPUT:
                return int(code)
            if code == ExitCode.INFRASTRUCTURE and not last_pod_attempt:
                return int(code)  # Kubernetes retries the slice; the finished indexes are skipped then
            worst = max(worst, code)
    finally:
        bus.close()
    return int(worst)


def _kept_summary(store: Any, key: str) -> dict[str, Any] | None:
    if not store.exists(key):
        return None
    try:
        summary = json.loads(store.get_bytes(key))
    except ValueError:  # cut short: the index runs again
        return None
    return summary if isinstance(summary, dict) else None


def _run_one(
    env: PodEnv,
    run: Any,
    point: Any,
    index: int,
    attempt: int,
    final_attempt: bool,
    bus: Any,
    status: Publisher,
    reports: _Reports,
) -> ExitCode:
    """One attempt of one index: announce it to the recorder, simulate, judge, hand the verdict to the
    recorder and wait for its upload. Returns the index's exit code (3 also when the upload failed)."""
    from simcore import pipeline
    from simcore.evaluation.report import summary_json
    from simcore.runner import judge, resolve_scenario_file

    started = time.monotonic()
    spec = run.spec
    announce = {"index": str(index), "attempt": str(attempt), "podAttempt": str(env.failures + 1)}
    status.publish(_status_message("start", 0.0, announce), 0.0)
    opened = reports.wait(index, "start", env.upload_timeout)
    if opened is None or opened.get("state") != "ready":
        why = "did not answer" if opened is None else opened.get("error", "failed")
        print(f"error: index {index}: the recorder {why}", flush=True)
        return ExitCode.INFRASTRUCTURE
    criteria = [*spec.evaluation.criteria, *point.scenario.criteria]
    log_lines = [
        f"carlos pod simcore: run {run.name} index {index} attempt {attempt} (pod attempt "
        f"{env.failures + 1}): scenario {point.scenario.name}, seed {point.seed}",
        f"parameters: {json.dumps(point.parameters, sort_keys=True)}",
    ]
    # the recorder role records (simulate must not write a second MCAP); a system under test with an image
    # is its own container of the pod, never also loaded in-process here
    update: dict[str, Any] = {"recording": spec.recording.model_copy(update={"enabled": False})}
    sut = spec.system_under_test
    if sut is not None and sut.image:
        update["system_under_test"] = sut.model_copy(update={"module": None})
    quiet = run.model_copy(update={"spec": spec.model_copy(update=update)})
    env.scratch.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="simcore-", dir=env.scratch) as scratch_name:
        scratch = Path(scratch_name)

        def simulate() -> Any:
            ref = point.scenario
            if ref.config_map_ref is not None:
                scenario_file = env.scenario_dir / ref.config_map_ref.name / ref.config_map_ref.key
                if not scenario_file.is_file():
                    raise BadInput(
                        f"{scenario_file} is not mounted (ConfigMap {ref.config_map_ref.name!r}, key "
                        f"{ref.config_map_ref.key!r})",
                        field=f"spec.scenarios[{ref.name}].configMapRef",
                    )
            else:
                scenario_file = resolve_scenario_file(
                    point, Path("/"), scratch, lambda url: _store(env, run, url)
                )
            return pipeline.simulate(
                quiet,
                point,
                scenario_file,
                scratch,
                deadline=started + spec.execution.timeout_seconds,
                bus=_Borrowed(bus) if _needs_pod_bus(spec) else None,
            )

        judged = judge(
            index, point, criteria, simulate, attempt=attempt, started=started, log_lines=log_lines
        )
    summary, exit_code, error, sim_seconds = (
        judged.summary,
        judged.exit_code,
        judged.error,
        judged.sim_seconds,
    )
    log_lines.append(f"status: {summary['status']} (exit code {int(exit_code)})")
    print("\n".join(log_lines), flush=True)
    write_summary = not (exit_code == ExitCode.INFRASTRUCTURE and not final_attempt)
    verdict = _status_message(
        "error" if error is not None else "ended",
        sim_seconds,
        {
            "index": str(index),
            SUMMARY_KEY: summary_json(summary).decode(),  # parameters in the manifest's order
            "log": "\n".join(log_lines) + "\n",
            "exitCode": str(int(exit_code)),
            "writeSummary": "true" if write_summary else "false",
        },
    )
    # everything sent before the verdict has arrived (DDS does not order topics among each other). Only when
    # the world's topics went over the bus: else this index sent only its start, on the verdict's own topic,
    # which keeps its order (and waiting for acknowledgements costs ~0.1 s of wall time per index)
    if env.transport == "dds" and _needs_pod_bus(spec) and not bus.flush(60.0):
        log.warning("simcore: not every message was acknowledged by the subscribers within 60 s")
    status.publish(verdict, sim_seconds)
    report = reports.wait(index, "end", env.upload_timeout)
    if report is None:
        print(f"error: the recorder did not report its upload within {env.upload_timeout:.0f} s", flush=True)
        return ExitCode.INFRASTRUCTURE
    if report.get("state") != "uploaded":
        print(f"error: the recorder failed: {report.get('error', 'unknown error')}", flush=True)
        return ExitCode.INFRASTRUCTURE
    return exit_code


# --- recorder --------------------------------------------------------------------------------------------


def _pod_address() -> str | None:
    """The pod's own (non-loopback) address, as the kubelet writes it into the pod's /etc/hosts; None
    outside a pod network (processes on one host share the loopback: the probe reaches 127.0.0.1 there)."""
    try:
        address = socket.gethostbyname(socket.gethostname())
    except OSError:
        return None
    return None if address.startswith("127.") else address


class _ReadyPort:
    """Accepts (and closes) connections on the startup-probe port. The kubelet probes the pod's address, not
    its loopback, so by default it listens on every address of the pod's network namespace (it carries no
    data: a connection is closed at once)."""

    def __init__(self, port: int, host: str = "") -> None:
        self.server = socket.create_server((host, port))
        threading.Thread(target=self._serve, name="ready-port", daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            conn.close()

    def close(self) -> None:
        self.server.close()


class _Recording:
    """The recorder's state for the index in progress: its MCAP (when the spec records) and its verdict."""

    def __init__(
        self, index: int, recorder: Any, workdir: Path, attempt: str, run_record: dict[str, str]
    ) -> None:
        self.index = index
        self.recorder = recorder
        self.workdir = workdir
        self.attempt = attempt
        self.run_record = run_record


def run_recorder(env: PodEnv) -> int:
    """Serve the pod's slice: for each index simcore announces (`start`), open its MCAP and report `ready`;
    record what arrives; on its verdict close the MCAP, upload `recording.mcap` and `log.txt`, then
    `summary.json` last, and report `uploaded` (or `error`). On SIGTERM the index in progress is closed and
    uploaded with what was received (no summary)."""
    import queue

    from simcore.plan import Plan

    run = _load(env)
    spec = run.spec
    plan = Plan(spec)
    store = _store(env, run)
    env.scratch.mkdir(parents=True, exist_ok=True)
    lock = threading.Lock()
    events: queue.Queue[dict[str, str]] = queue.Queue()
    stop = threading.Event()
    current: list[_Recording] = []  # the index being recorded (at most one)

    def on_message(message: Message) -> None:
        if message.topic == RECORDER_TOPIC:
            return  # our own reports
        values: dict[str, str] = {}
        if message.topic == STATUS_TOPIC:
            values = _values(message.obj())
            if values.get("state") == "start" or SUMMARY_KEY in values:
                # simcore ↔ recorder, not part of the run's recording (the verdict's wall time would make
                # the same run's recordings differ; its content is the index's summary.json and log.txt)
                events.put(values)
                return
        with lock:
            if current and current[0].recorder is not None and current[0].recorder.wants(message.topic):
                # the CDR as received: no deserialising and serialising again
                current[0].recorder.write(message.topic, message.typename, message.cdr(), message.time_s)

    _on_sigterm(stop.set)
    try:
        bus = _connect(env, on_disconnect=stop.set)
    except ConnectionError as exc:
        print(f"error: {exc}", flush=True)
        return int(ExitCode.INFRASTRUCTURE)
    if spec.recording.enabled:
        bus.subscribe("*", on_message)
    elif env.transport == "dds":
        bus.subscribe(STATUS_TOPIC, on_message, typename=STATUS_TYPE)
    else:
        bus.subscribe(STATUS_TOPIC, on_message)
    report = bus.advertise(RECORDER_TOPIC, STATUS_TYPE)
    ready = _ReadyPort(env.ready_port)
    log.info("recorder: subscribed, ready on port %d", env.ready_port)
    failed = False
    while not stop.is_set():
        try:
            values = events.get(timeout=0.2)
        except queue.Empty:
            continue
        index = int(values.get("index", env.index))
        if values.get("state") == "start":
            try:
                opened = _open_recording(env, run, plan, index, values.get("attempt", "1"))
                state, error = "ready", ""
            except Exception as exc:  # the scratch volume is full, …: this attempt is an infrastructure error
                opened, state, error = None, "error", f"{type(exc).__name__}: {exc}"
            with lock:
                current[:] = [opened] if opened is not None else []
            extra = {"index": str(index), "phase": "start", **({"error": error} if error else {})}
            report.publish(_status_message(state, 0.0, extra), 0.0)
            continue
        if env.transport == "dds" and spec.recording.enabled:
            # topics are not ordered among each other: what simcore sent before the verdict (all
            # acknowledged) may still be queued here
            bus.drain()
        with lock:  # the verdict: no message of this index is written after this point
            done = current.pop() if current else None
        state, error = _finish(env, run, store, done, values)
        failed = failed or state != "uploaded"
        extra = {"index": str(index), "phase": "end", **({"error": error} if error else {})}
        report.publish(_status_message(state, 0.0, extra), 0.0)
    # SIGTERM (or the bus is gone) during an index: what is in flight to us still goes into its file
    bus.drain()
    with lock:
        done = current.pop() if current else None
    if done is not None:
        _finish(env, run, store, done, {})
    ready.close()
    bus.close()
    return int(ExitCode.INFRASTRUCTURE) if failed else 0


def _open_recording(env: PodEnv, run: Any, plan: Any, index: int, attempt: str) -> _Recording:
    from simcore.pipeline import manifest_yaml, versions
    from simcore.recorder import McapRecorder

    spec = run.spec
    point = plan[index - env.offset]
    workdir = Path(tempfile.mkdtemp(prefix=f"recorder-{index}-", dir=env.scratch))
    recorder = None
    if spec.recording.enabled:
        recorder = McapRecorder.for_recording(
            workdir / "recording.mcap",
            spec.recording,
            metadata={
                "carlos.spec": {"manifest": manifest_yaml(run)},
                "carlos.versions": versions(),
            },
        )
    run_record = {
        "run": run.name,
        "index": str(index),
        "scenario": point.scenario.name,
        "parameters": json.dumps(point.parameters, sort_keys=True),
        "seed": str(point.seed),
        "stepSeconds": repr(spec.simulation.step_seconds),
    }
    return _Recording(index, recorder, workdir, attempt, run_record)


def _run_record(done: _Recording, summary: dict[str, Any] | None) -> dict[str, str]:
    """The `carlos.run` metadata record, written when the verdict is known: with the index summary's
    `scenarioTimeOffsetSeconds` (scenario time = log time + it, as in a local recording; 0 without a
    verdict)."""
    offset = float((summary or {}).get("scenarioTimeOffsetSeconds", 0.0))
    return {**done.run_record, "scenarioTimeOffsetSeconds": repr(offset)}


def _finish(
    env: PodEnv, run: Any, store: Any, done: _Recording | None, verdict: dict[str, str]
) -> tuple[str, str]:
    """Close the index's MCAP and upload its files (the summary last); (state, error)."""
    import shutil

    if done is None:
        return "error", "no index was announced before its verdict"
    prefix = f"{run.name}/{done.index}"
    state, error = "uploaded", ""
    summary = json.loads(verdict[SUMMARY_KEY]) if verdict.get(SUMMARY_KEY) else None
    try:
        if done.recorder is not None:
            done.recorder.add_metadata("carlos.run", _run_record(done, summary))
            done.recorder.close()
        mcap = done.workdir / "recording.mcap"
        if mcap.is_file():
            store.put_file(f"{prefix}/recording.mcap", mcap)
        if verdict:
            store.put_bytes(f"{prefix}/log.txt", verdict.get("log", "").encode())
            if verdict.get("writeSummary") == "true" and summary is not None:
                from simcore.evaluation.report import summary_json

                store.put_bytes(f"{prefix}/summary.json", summary_json(summary))
        else:
            store.put_bytes(
                f"{prefix}/log.txt",
                f"recorder: terminated before the end of the run (attempt {done.attempt})\n".encode(),
            )
        store.sync()
    except Exception as exc:  # the object store failed: simcore turns this into exit code 3
        state, error = "error", f"{type(exc).__name__}: {exc}"
        print(f"recorder: upload failed: {error}", flush=True)
    finally:
        shutil.rmtree(done.workdir, ignore_errors=True)
    return state, error


def main(role: str) -> int:
    """Run `role`; returns the process exit code. Never raises for CARLOS' own errors."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if role not in ROLES:
        print(f"error: --role: {role!r} is not one of {', '.join(ROLES)}", flush=True)
        return int(ExitCode.BAD_INPUT)
    try:
        env = PodEnv.from_env()
        if role == "bridge":
            return run_bridge(env)
        if role == "recorder":
            return run_recorder(env)
        return run_simcore(env)
    except CarlosError as exc:
        print(f"error: {exc}", flush=True)
        return int(exc.exit_code)
