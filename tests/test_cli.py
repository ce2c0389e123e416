"""`carlos run` end to end on the embedded default: real SUMO, real MCAP files, real exit codes."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from simcore.transport import messages

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "examples" / "runs"
CARLOS = [sys.executable, "-m", "simcore.cli"]


def carlos(*args: str | Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*CARLOS, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
        env={**os.environ, "COLUMNS": "200", **(env or {})},
        check=False,
    )


@pytest.fixture(scope="module")
def testing_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path]:
    out = tmp_path_factory.mktemp("results")
    return carlos(
        "run", RUNS / "automated-testing.yaml", "--output", f"file://{out}", "-j", "2"
    ), out / "automated-testing"


def test_automated_testing_passes_with_exit_0_and_writes_the_layout(
    testing_run: tuple[subprocess.CompletedProcess[str], Path],
) -> None:
    result, run_dir = testing_run
    assert result.returncode == 0, result.stderr + result.stdout
    assert (run_dir / "run.yaml").is_file()
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "passed" and summary["exitCode"] == 0
    assert summary["counts"]["total"] == 4
    for index in range(4):
        per_index = json.loads((run_dir / str(index) / "summary.json").read_text())
        assert per_index["index"] == index
        assert per_index["status"] == "passed"
        assert per_index["endReason"] == "stopTrigger"
        assert per_index["metrics"]["collision"] == 0.0
        assert per_index["simSeconds"] > 5
        assert all(c["passed"] for c in per_index["criteria"])
        assert (run_dir / str(index) / "recording.mcap").stat().st_size > 10_000
    assert not list(run_dir.rglob("*.part")) and not list(run_dir.rglob(".carlos-tmp-*"))
    suites = ET.fromstring((run_dir / "junit.xml").read_text())
    assert suites.get("tests") == "4"
    assert suites.get("failures") == "0" and suites.get("errors") == "0"


def test_braking_run_is_physically_plausible(
    testing_run: tuple[subprocess.CompletedProcess[str], Path],
) -> None:
    """The SUMO-driven ego brakes behind the braking lead and stops behind it without touching it."""
    _, run_dir = testing_run
    braking = next(
        json.loads(p.read_text())
        for p in run_dir.glob("*/summary.json")
        if json.loads(p.read_text())["scenario"] == "braking"
    )
    metrics = braking["metrics"]
    assert 0.5 < metrics["minDistance"] < 10.0
    assert 3.0 < metrics["maxDeceleration"] < 9.5
    assert metrics["maxSpeed"] == pytest.approx(25.0, abs=0.5)


def test_recording_reads_back_with_mcap_and_rosbags(
    testing_run: tuple[subprocess.CompletedProcess[str], Path],
) -> None:
    _, run_dir = testing_run
    path = run_dir / "1" / "recording.mcap"
    summary = json.loads((run_dir / "1" / "summary.json").read_text())
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        metadata = {record.name: record.metadata for record in reader.iter_metadata()}
        assert json.loads(metadata["carlos.run"]["parameters"]) == summary["parameters"]
        assert metadata["carlos.run"]["seed"] == str(summary["seed"])
        assert "apiVersion: carlos.dev/v1alpha1" in metadata["carlos.spec"]["manifest"]
        clock_times = [
            msg.clock.sec + msg.clock.nanosec * 1e-9
            for _, _, _, msg in reader.iter_decoded_messages(topics=["/clock"])
        ]
    assert clock_times[0] == 0.0
    assert clock_times[-1] == pytest.approx(summary["simSeconds"], abs=1e-6)
    assert len(clock_times) == round(summary["simSeconds"] / 0.05) + 1
    with AnyReader([path], default_typestore=messages.TYPESTORE) as bag:
        topics = {c.topic: c.msgtype for c in bag.connections}
        assert topics["/tf"] == "tf2_msgs/msg/TFMessage"
        assert topics["/carlos/objects"] == "vision_msgs/msg/Detection3DArray"
        assert topics["/carlos/Ego/odometry"] == "nav_msgs/msg/Odometry"
        odometry = [c for c in bag.connections if c.topic == "/carlos/Ego/odometry"]
        speeds = [
            bag.deserialize(raw, c.msgtype).twist.twist.linear.x
            for c, _, raw in bag.messages(connections=odometry)
        ]
    assert max(speeds) == pytest.approx(summary["metrics"]["maxSpeed"], abs=1e-6)


def test_failing_manifest_exits_1(tmp_path: Path) -> None:
    result = carlos("run", RUNS / "automated-testing-failing.yaml", "--output", f"file://{tmp_path}", "-q")
    assert result.returncode == 1, result.stderr
    summary = json.loads((tmp_path / "automated-testing-failing" / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["counts"]["failed"] >= 1
    suites = ET.fromstring((tmp_path / "automated-testing-failing" / "junit.xml").read_text())
    assert int(suites.get("failures", "0")) >= 1


def _manifest(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text("apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: t}\n" + body)
    return path


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (
            "spec:\n  scenarios: [{name: a, openscenario: nowhere.xosc}]\n",
            "spec.scenarios[0].openscenario: scenario file",
        ),
        (
            "spec:\n  scenarios: [{name: a, openscenario: SCEN}]\n  sweep: {matrix: {Speeed: [1, 2]}}\n",
            "spec.sweep.matrix: parameter(s) Speeed not declared",
        ),
        (
            "spec:\n  scenarios: [{name: a, openscenario: SCEN}]\n  simulation: {stepSecond: 0.1}\n",
            "spec.simulation.stepSecond: unknown field",
        ),
        (
            "spec:\n  scenarios: [{name: a, openscenario: SCEN}]\n  simulation: {stepSeconds: -1}\n",
            "spec.simulation.stepSeconds: Input should be greater than 0",
        ),
        ("spec: [\n", "invalid YAML at line"),
    ],
)
def test_bad_input_exits_2_with_one_clear_line(tmp_path: Path, body: str, expected: str) -> None:
    body = body.replace("SCEN", str(ROOT / "examples" / "scenarios" / "braking.xosc"))
    result = carlos("run", _manifest(tmp_path, body), "--output", f"file://{tmp_path / 'out'}")
    assert result.returncode == 2
    assert expected in result.stderr
    assert "m.yaml" in result.stderr or "spec.scenarios[0].openscenario" in result.stderr
    assert "Traceback" not in result.stderr + result.stdout
    assert len(result.stderr.strip().splitlines()) <= 3


def test_missing_road_file_is_bad_input(tmp_path: Path) -> None:
    scenario = tmp_path / "s.xosc"
    scenario.write_text(
        (ROOT / "examples" / "scenarios" / "braking.xosc")
        .read_text()
        .replace("../maps/highway.xodr", "gone.xodr")
    )
    result = carlos(
        "run", _manifest(tmp_path, f"spec:\n  scenarios: [{{name: a, openscenario: {scenario}}}]\n")
    )
    assert result.returncode == 2
    assert "gone.xodr" in result.stderr and "RoadNetwork/LogicFile" in result.stderr


def test_an_index_that_errors_does_not_stop_the_sweep_and_resume_keeps_results(tmp_path: Path) -> None:
    scenario = ROOT / "examples" / "scenarios" / "braking.xosc"
    body = f"spec:\n  scenarios: [{{name: b, openscenario: {scenario}}}]\n  sweep: {{matrix: {{Lane: ['-2', '-9']}}}}\n  simulation: {{maxSeconds: 8}}\n"
    manifest = _manifest(tmp_path, body)
    out = tmp_path / "out"
    result = carlos("run", manifest, "--output", f"file://{out}", "-j", "2")
    assert result.returncode == 2, result.stderr  # a required run errored on bad input (not a test failure)
    good = json.loads((out / "t" / "0" / "summary.json").read_text())
    bad = json.loads((out / "t" / "1" / "summary.json").read_text())
    assert good["status"] == "passed"
    assert bad["status"] == "error" and "-9" in bad["error"] and bad["badInput"] is True
    assert bad["attempts"] == 1  # bad input is never retried
    assert "error" in (out / "t" / "1" / "log.txt").read_text()
    # a second invocation resumes: the passed index is kept, the errored one runs again
    before = (out / "t" / "0" / "recording.mcap").stat().st_mtime_ns
    again = carlos("run", manifest, "--output", f"file://{out}")
    assert "1 of 2 runs already complete" in again.stderr + again.stdout
    assert (out / "t" / "0" / "recording.mcap").stat().st_mtime_ns == before
    assert json.loads((out / "t" / "1" / "summary.json").read_text())["status"] == "error"
    # a summary cut short (a power cut before the store was flushed) counts as not run: the index runs again
    (out / "t" / "0" / "summary.json").write_bytes(b"")
    carlos("run", manifest, "--output", f"file://{out}")
    assert json.loads((out / "t" / "0" / "summary.json").read_text())["status"] == "passed"
    assert (out / "t" / "0" / "recording.mcap").stat().st_mtime_ns != before
    # a changed spec under the same name is refused instead of mixing results
    manifest.write_text(manifest.read_text().replace("maxSeconds: 8", "maxSeconds: 9"))
    changed = carlos("run", manifest, "--output", f"file://{out}")
    assert changed.returncode == 2 and "different spec" in changed.stderr


def test_plan_and_validate_commands() -> None:
    result = carlos("plan", RUNS / "data-generation.yaml", "--index", "11")
    assert result.returncode == 0
    assert "EgoSpeed=28.0,CutInGap=15.0,AdversarySpeed=36.0" in result.stdout
    result = carlos("validate", RUNS / "data-generation.yaml")
    assert result.returncode == 0 and "12 runs" in result.stdout


def test_console_script_is_installed() -> None:
    assert shutil.which("carlos", path=str(Path(sys.executable).parent)) is not None


@pytest.mark.s3
def test_results_go_to_s3_and_scenarios_come_from_s3(s3_server: object, tmp_path: Path) -> None:
    """Against a real S3 server on loopback: the scenario and its road are fetched from s3://, the results
    are uploaded under <prefix>/<run>/<index>/ and read back with boto3."""
    import boto3

    server = s3_server
    env = server.env()  # type: ignore[attr-defined]
    client = boto3.client(
        "s3",
        endpoint_url=env["AWS_ENDPOINT_URL"],
        aws_access_key_id=env["AWS_ACCESS_KEY_ID"],
        aws_secret_access_key=env["AWS_SECRET_ACCESS_KEY"],
        region_name=env["AWS_REGION"],
    )
    bucket = server.bucket  # type: ignore[attr-defined]
    client.upload_file(
        str(ROOT / "examples" / "scenarios" / "braking.xosc"), bucket, "catalogue/scenarios/braking.xosc"
    )
    client.upload_file(
        str(ROOT / "examples" / "maps" / "highway.xodr"), bucket, "catalogue/maps/highway.xodr"
    )
    manifest = _manifest(
        tmp_path,
        f"spec:\n  scenarios: [{{name: b, openscenario: 's3://{bucket}/catalogue/scenarios/braking.xosc'}}]\n"
        "  simulation: {maxSeconds: 6}\n",
    )
    # the scenario names its road as ../maps/highway.xodr: resolved within the bucket, as on disk
    result = carlos("run", manifest, "--output", f"s3://{bucket}/results", "-q", env=env)
    assert result.returncode == 0, result.stderr
    keys = {o["Key"] for o in client.list_objects_v2(Bucket=bucket, Prefix="results/t/")["Contents"]}
    assert {
        "results/t/run.yaml",
        "results/t/0/recording.mcap",
        "results/t/0/summary.json",
        "results/t/0/log.txt",
        "results/t/summary.json",
        "results/t/junit.xml",
    } <= keys
    run_summary = json.loads(client.get_object(Bucket=bucket, Key="results/t/summary.json")["Body"].read())
    assert run_summary["status"] == "passed"
    assert run_summary["outputUrl"] == f"s3://{bucket}/results/t"
    assert env["AWS_SECRET_ACCESS_KEY"] not in result.stdout + result.stderr
    # a road outside the bucket is refused with a clear message, for that run only
    text = (
        (ROOT / "examples" / "scenarios" / "braking.xosc")
        .read_text()
        .replace("../maps/highway.xodr", "../../x.xodr")
    )
    client.put_object(Bucket=bucket, Key="bad/braking.xosc", Body=text.encode())
    manifest.write_text(
        manifest.read_text()
        .replace("catalogue/scenarios/braking.xosc", "bad/braking.xosc")
        .replace("name: t", "name: t2")
    )
    result = carlos("run", manifest, "--output", f"s3://{bucket}/results", "-q", env=env)
    assert result.returncode == 2  # bad input, kept apart from infrastructure errors
    summary = json.loads(client.get_object(Bucket=bucket, Key="results/t2/0/summary.json")["Body"].read())
    assert summary["status"] == "error" and "outside the bucket" in summary["error"] and summary["badInput"]


_GC_PROBE = """
import gc, sys
from simcore import cli, startup
seen = []
resume = startup.resume_gc
def probe() -> None:
    seen.append(gc.isenabled())
    resume()
startup.resume_gc = probe
sys.argv = ["carlos", *sys.argv[1:]]
try:
    cli.main()
finally:
    print("GC", seen[:1], gc.isenabled(), gc.get_freeze_count() > 0, file=sys.stderr)
"""


@pytest.mark.parametrize("command", ["run", "validate"])
def test_the_collector_is_paused_for_start_up_only(command: str, tmp_path: Path) -> None:
    """`carlos` starts with the cyclic garbage collector paused; a run resumes it once under way, any other
    command when it starts, with start-up's objects frozen."""
    manifest = tmp_path / "one.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: one}\nspec:\n"
        f"  scenarios: [{{name: one, openscenario: {json.dumps(str(ROOT / 'examples/scenarios/cut-in.xosc'))}}}]\n"
        "  simulation: {stepSeconds: 0.1, maxSeconds: 3, seed: 1}\n  recording: {enabled: false}\n"
        f"  output: {{url: {json.dumps((tmp_path / 'results').as_uri())}}}\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", _GC_PROBE, command, str(manifest)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
        check=False,
    )
    assert result.returncode in (0, 1), result.stderr
    assert "GC [False] True True" in result.stderr, result.stderr


def test_help_is_whole_in_80_columns_and_the_version_is_printed() -> None:
    """Help in an 80-column terminal wraps at word boundaries: no field name or sentence cut short."""
    narrow = {"COLUMNS": "80"}
    run_help = carlos("run", "--help", env=narrow).stdout
    assert "spec.execution.parallelism" in run_help and "paralleli…" not in run_help
    assert all(len(line) <= 80 for line in run_help.splitlines() if " " in line.strip())
    top = carlos("--help", env=narrow).stdout
    commands = top[top.index("Commands:") :]
    assert "..." not in commands and "…" not in commands  # every command's first sentence whole
    version = carlos("--version")
    assert version.returncode == 0 and version.stdout.strip() == "carlos 0.1.0 (carlos-sim, pure Python)"


def test_plan_of_a_search_says_its_points_are_chosen_as_it_runs() -> None:
    done = carlos("plan", "examples/runs/search-cut-in.yaml")
    assert done.returncode == 0, done.stderr
    assert "a search of 64 runs in rounds of 16, its points chosen as it runs" in " ".join(
        done.stdout.split()
    )
    assert "(defaults)" not in done.stdout


def test_carlos_keeps_numpy_to_one_blas_thread_unless_the_environment_says_otherwise() -> None:
    """`carlos` runs in parallel as processes: numpy's OpenBLAS starts no pool of threads of its own in them
    (they would compete with the other workers for the cores), unless OPENBLAS_NUM_THREADS is set."""
    script = (
        "import os, sys\n"
        "if sys.argv[1] == 'carlos':\n"
        "    from simcore import cli\n"
        "    sys.argv = ['carlos', '--version']\n"
        "    try:\n"
        "        cli.main()\n"
        "    except SystemExit:\n"
        "        pass\n"
        "import numpy\n"
        "print(len(os.listdir('/proc/self/task')))\n"
    )
    blas = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")  # what OpenBLAS reads
    env = {k: v for k, v in os.environ.items() if k not in blas}

    def threads(how: str, **extra: str) -> int:
        out = subprocess.run(
            [sys.executable, "-c", script, how],
            env={**env, **extra},
            capture_output=True,
            text=True,
            check=True,
        )
        return int(out.stdout.strip().splitlines()[-1])

    if (os.cpu_count() or 1) > 1:
        assert threads("plain") > 1  # what numpy does by itself on this machine: a pool
    assert threads("carlos") == 1
    if (os.cpu_count() or 1) > 1:
        assert threads("carlos", OPENBLAS_NUM_THREADS="2") == 2  # the user's setting stands
