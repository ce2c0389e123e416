"""`carlos export --format omega-prime`: ASAM OSI GroundTruth per step + the OpenDRIVE map, read back by
omega-prime's own validating reader."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from simcore.export_omega import _Seen, osi_rows
from simcore.osi import TYPE_OTHER, TYPE_PEDESTRIAN, TYPE_VEHICLE, osi_type
from tests.test_cli import ROOT, RUNS, carlos

#: index 0 of the data-generation example: EgoSpeed 20, CutInGap 8, AdversarySpeed 32
SAMPLED = (0, 7, 100, 250)


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(index 0's recording.mcap, its omega-prime export) of examples/runs/data-generation.yaml."""
    tmp = tmp_path_factory.mktemp("omega")
    done = carlos("run", RUNS / "data-generation.yaml", "-i", "0", "-q", "--output", f"file://{tmp}/out")
    assert done.returncode == 0, done.stderr
    run = tmp / "out" / "data-generation"
    done = carlos("export", run.as_uri(), "--format", "omega-prime", "--out", tmp / "export")
    assert done.returncode == 0, done.stderr
    assert "1 omega-prime files" in done.stdout
    return run / "0" / "recording.mcap", tmp / "export" / "data-generation" / "0.mcap"


def _tf(recording: Path) -> dict[int, dict[str, tuple[float, float, float]]]:
    from mcap.reader import make_reader

    from simcore.transport.messages import deserialize

    out: dict[int, dict[str, tuple[float, float, float]]] = {}
    with recording.open("rb") as f:
        for schema, _, message in make_reader(f).iter_messages(topics=["/tf"]):
            assert schema is not None
            msg = deserialize(message.data, schema.name)
            out[message.log_time] = {
                t.child_frame_id.removesuffix("/base_link"): (
                    t.transform.translation.x,
                    t.transform.translation.y,
                    t.transform.translation.z,
                )
                for t in msg.transforms
            }
    return out


def test_osi_type_of_categories() -> None:
    assert osi_type("car") == (TYPE_VEHICLE, 4, 1)
    assert osi_type("Truck")[0] == TYPE_VEHICLE
    assert osi_type("pedestrian") == (TYPE_PEDESTRIAN, -1, -1)
    assert osi_type("obstacle") == (TYPE_OTHER, -1, -1)


def test_rows_velocity_and_acceleration_from_speed_and_heading() -> None:
    yaw = math.pi / 2  # facing +y
    q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    steps = [
        (
            n * 100_000_000,
            {"A": _Seen((0.0, n * 1.0, 0.0), q, (0.0, n + 1.5, 0.7), (4.0, 2.0, 1.4), "car", 10.0 + n)},
        )
        for n in range(4)
    ]
    rows = osi_rows(steps, ["A"])
    assert [len(r) for r in rows] == [1, 1, 1, 1]
    row = rows[2][0]
    assert row.position == (0.0, 3.5, 0.7) and row.idx == 0
    assert row.orientation[2] == pytest.approx(yaw)
    assert row.velocity == pytest.approx((0.0, 12.0, 0.0), abs=1e-9)
    assert row.acceleration == pytest.approx((0.0, 10.0, 0.0), abs=1e-6)  # +1 m/s per 0.1 s


def test_export_reads_back_valid_with_every_entity(exported: tuple[Path, Path]) -> None:
    import omega_prime

    recording, path = exported
    rec = omega_prime.Recording.from_file(str(path), validate=True)
    df = rec._df.sort(["total_nanos", "idx"])
    tf = _tf(recording)
    names = sorted({name for frame in tf.values() for name in frame if not name.endswith("_ghost")})
    assert df["idx"].n_unique() == len(names) == 2  # Ego and Adversary
    assert rec.host_vehicle_idx == 0
    assert rec.map is not None and "OpenDRIVE" in rec.map.odr_xml
    nanos = sorted(tf)
    assert sorted(df["total_nanos"].unique().to_list()) == nanos
    # positions are the box centres: the /tf reference point moved by the box's offset along the heading
    objects = _objects(recording)
    offsets = _offsets(recording, objects, tf)
    for step in SAMPLED:
        t = nanos[step]
        frame = df.filter(df["total_nanos"] == t)
        for i, name in enumerate(objects[t]):
            row = frame.filter(frame["idx"] == i).row(0, named=True)
            x, y, _z = tf[t][name]
            cx, cy, cz = objects[t][name]
            assert (row["x"], row["y"], row["z"]) == pytest.approx((cx, cy, cz), abs=1e-9)
            # box centre minus the reference point: the entity's fixed box offset turned by its yaw
            dx, dy = cx - x, cy - y
            c, s = math.cos(row["yaw"]), math.sin(row["yaw"])
            local = (c * dx + s * dy, -s * dx + c * dy)
            assert local == pytest.approx(offsets[name], abs=1e-6)
    assert np.isfinite(df.select(["acc_x", "acc_y", "vel_x", "vel_y"]).to_numpy()).all()


def _objects(recording: Path) -> dict[int, dict[str, tuple[float, float, float]]]:
    from mcap.reader import make_reader

    from simcore.transport.messages import deserialize

    out: dict[int, dict[str, tuple[float, float, float]]] = {}
    with recording.open("rb") as f:
        for schema, _, message in make_reader(f).iter_messages(topics=["/carlos/objects"]):
            assert schema is not None
            msg = deserialize(message.data, schema.name)
            out[message.log_time] = {
                d.id: (d.bbox.center.position.x, d.bbox.center.position.y, d.bbox.center.position.z)
                for d in msg.detections
            }
    return out


def _offsets(recording: Path, objects: dict, tf: dict) -> dict[str, tuple[float, float]]:
    """Each entity's box offset in its own frame, from the first step (constant: the test compares others)."""
    from mcap.reader import make_reader

    from simcore.transport.messages import deserialize

    first = min(objects)
    with recording.open("rb") as f:
        for schema, _, message in make_reader(f).iter_messages(topics=["/tf"]):
            assert schema is not None
            msg = deserialize(message.data, schema.name)
            out = {}
            for t in msg.transforms:
                name = t.child_frame_id.removesuffix("/base_link")
                if name not in objects[first]:
                    continue
                q = t.transform.rotation
                yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
                dx = objects[first][name][0] - tf[first][name][0]
                dy = objects[first][name][1] - tf[first][name][1]
                c, s = math.cos(yaw), math.sin(yaw)
                out[name] = (c * dx + s * dy, -s * dx + c * dy)
            return out
    raise AssertionError("no /tf")


def test_export_is_deterministic(exported: tuple[Path, Path], tmp_path: Path) -> None:
    recording, path = exported
    run = recording.parents[1]
    done = carlos("export", run.as_uri(), "--format", "omega-prime", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "data-generation" / "0.mcap").read_bytes() == path.read_bytes()


def test_export_of_a_run_without_tf_is_bad_input(tmp_path: Path) -> None:
    manifest = tmp_path / "no-tf.yaml"
    cut_in = (ROOT / "examples" / "scenarios" / "cut-in.xosc").as_uri()
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: no-tf}\nspec:\n"
        f"  scenarios: [{{name: cut-in, openscenario: '{cut_in}'}}]\n"
        "  simulation: {stepSeconds: 0.05, maxSeconds: 0.5}\n"
        "  recording: {enabled: true, topics: ['/clock']}\n"
    )
    assert carlos("run", manifest, "-q", "--output", f"file://{tmp_path}/out").returncode == 0
    done = carlos(
        "export", (tmp_path / "out" / "no-tf").as_uri(), "--format", "omega-prime", "--out", tmp_path
    )
    assert done.returncode == 2
    assert "spec.recording.topics" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.slow
def test_export_reads_in_a_venv_with_only_omega_prime(exported: tuple[Path, Path], tmp_path: Path) -> None:
    """The issue's goal: a virtualenv that has only omega-prime installed reads the file, validating."""
    _, path = exported
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run(
        [str(python), "-m", "pip", "install", "-q", "omega-prime>=0.3.7,<0.4"],
        check=True,
        timeout=1200,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    script = textwrap.dedent(
        f"""
        import omega_prime
        rec = omega_prime.Recording.from_file({str(path)!r}, validate=True)
        print(rec._df["idx"].n_unique(), rec._df["total_nanos"].n_unique(), rec.map is not None)
        """
    )
    done = subprocess.run(
        [str(python), "-c", script], capture_output=True, text=True, timeout=600, cwd=tmp_path, check=False
    )
    assert done.returncode == 0, done.stderr
    objects, steps, has_map = done.stdout.split()
    assert objects == "2" and int(steps) > 100 and has_map == "True"


def test_recording_osi_channel_has_ground_truth_of_every_step(tmp_path: Path) -> None:
    """spec.recording.osi: protobuf osi3.GroundTruth per step in the run's MCAP, read by betterosi."""
    import betterosi
    from mcap.reader import make_reader

    from simcore.osi import OSI_TOPIC

    manifest = tmp_path / "osi.yaml"
    cut_in = (ROOT / "examples" / "scenarios" / "cut-in.xosc").as_uri()
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: osi}\nspec:\n"
        f"  scenarios: [{{name: cut-in, openscenario: '{cut_in}'}}]\n"
        "  simulation: {stepSeconds: 0.05, maxSeconds: 1.0}\n"
        "  recording: {enabled: true, osi: true, topics: ['/tf', '/carlos/objects', '/carlos/*/odometry']}\n"
    )
    done = carlos("run", manifest, "-q", "--output", f"file://{tmp_path}/out")
    assert done.returncode == 0, done.stderr
    recording = tmp_path / "out" / "osi" / "0" / "recording.mcap"
    with recording.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    channel = next(c for c in summary.channels.values() if c.topic == OSI_TOPIC)
    schema = summary.schemas[channel.schema_id]
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        "osi3.GroundTruth",
        "protobuf",
        "protobuf",
    )
    gts = list(betterosi.read(str(recording), return_ground_truth=True, mcap_topics=[OSI_TOPIC]))
    tf = _tf(recording)
    assert [g.timestamp.seconds * 1_000_000_000 + g.timestamp.nanos for g in gts] == sorted(tf)
    for gt in gts[::7]:
        t = gt.timestamp.seconds * 1_000_000_000 + gt.timestamp.nanos
        assert gt.host_vehicle_id.value == 0
        names = [m.source_reference[0].identifier[0] for m in gt.moving_object]
        assert names == ["Ego", "Adversary"]
        for m in gt.moving_object:
            x, y, _ = tf[t][m.source_reference[0].identifier[0]]
            # the box centre is the reference point moved along the heading (the box offset is fixed)
            yaw = m.base.orientation.yaw
            dx, dy = m.base.position.x - x, m.base.position.y - y
            assert -math.sin(yaw) * dx + math.cos(yaw) * dy == pytest.approx(0.0, abs=1e-6)
            assert m.base.dimension.length > 0 and m.base.dimension.width > 0
    # the export takes the recorded GroundTruth as it is (the engine's acceleration, not differences)
    done = carlos("export", (tmp_path / "out" / "osi").as_uri(), "--format", "omega-prime", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    exported = list(betterosi.read(str(tmp_path / "osi" / "0.mcap"), return_ground_truth=True))
    assert [g.to_binary() for g in exported] == [g.to_binary() for g in gts]


@pytest.mark.s3
def test_export_of_s3_results_with_an_s3_scenario(s3_server: object, tmp_path: Path) -> None:
    """Results and scenario on S3 (the run's local copy of the scenario is gone): the export reads the
    recording from s3:// and fetches the scenario and its road from the run's spec."""
    import boto3
    import omega_prime

    env = s3_server.env()  # type: ignore[attr-defined]
    bucket = s3_server.bucket  # type: ignore[attr-defined]
    client = boto3.client(
        "s3",
        endpoint_url=env["AWS_ENDPOINT_URL"],
        aws_access_key_id=env["AWS_ACCESS_KEY_ID"],
        aws_secret_access_key=env["AWS_SECRET_ACCESS_KEY"],
        region_name=env["AWS_REGION"],
    )
    client.upload_file(
        str(ROOT / "examples" / "scenarios" / "cut-in.xosc"), bucket, "om/scenarios/cut-in.xosc"
    )
    client.upload_file(str(ROOT / "examples" / "maps" / "highway.xodr"), bucket, "om/maps/highway.xodr")
    manifest = tmp_path / "s3.yaml"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: om}\nspec:\n"
        f"  scenarios: [{{name: c, openscenario: 's3://{bucket}/om/scenarios/cut-in.xosc'}}]\n"
        "  simulation: {stepSeconds: 0.05, maxSeconds: 1.0}\n"
    )
    done = carlos("run", manifest, "-q", "--output", f"s3://{bucket}/omres", env=env)
    assert done.returncode == 0, done.stderr
    done = carlos("export", f"s3://{bucket}/omres/om", "--format", "omega-prime", "--out", tmp_path, env=env)
    assert done.returncode == 0, done.stderr
    rec = omega_prime.Recording.from_file(str(tmp_path / "om" / "0.mcap"), validate=True)
    assert rec._df["idx"].n_unique() == 2 and rec.map is not None


def test_without_betterosi_the_export_and_the_osi_channel_are_bad_input(
    exported: tuple[Path, Path], tmp_path: Path
) -> None:
    """Without the extra: one line naming `carlos-sim[omega]`, exit 2, no traceback."""
    recording, _ = exported
    run = recording.parents[1]
    manifest = tmp_path / "osi.yaml"
    cut_in = (ROOT / "examples" / "scenarios" / "cut-in.xosc").as_uri()
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: osi}\nspec:\n"
        f"  scenarios: [{{name: cut-in, openscenario: '{cut_in}'}}]\n"
        "  simulation: {stepSeconds: 0.05, maxSeconds: 0.2}\n"
        "  recording: {enabled: true, osi: true}\n"
    )
    block = "import sys; sys.modules['betterosi'] = None; from simcore.cli import main; sys.argv[0] = 'carlos'; main()"
    for args in (
        ["export", run.as_uri(), "--format", "omega-prime", "--out", str(tmp_path)],
        ["run", str(manifest), "-q", "-j", "1", "--output", f"file://{tmp_path}/out"],
    ):
        done = subprocess.run(
            [sys.executable, "-c", block, *args],
            capture_output=True,
            text=True,
            timeout=600,
            cwd=ROOT,
            check=False,
        )
        assert "carlos-sim[omega]" in done.stderr + done.stdout, done.stderr
        assert "Traceback" not in done.stderr
        assert done.returncode == 2


def test_recording_and_export_paths_agree_for_any_entity_name(tmp_path: Path) -> None:
    """An entity whose name is no ROS token (`lead truck`: /tf says `lead_truck_<hash>/base_link`) is still
    exported; the export from the ROS topics and the recorded OSI channel give the same objects."""

    import betterosi

    from simcore.export_omega import _read_recording
    from simcore.osi import OsiFrames
    from simcore.recorder import McapRecorder
    from tests.test_recorder import _frame

    frames = []
    for step in range(6):
        frame = _frame(step)
        truck = frame.entities[1].replace(name="lead truck")
        frames.append(frame.replace(entities=(frame.entities[0], truck)))
    path = tmp_path / "r.mcap"
    with McapRecorder(path) as rec:
        for frame in frames:
            rec.write_frame(frame)
    recorded = _read_recording(path.read_bytes())
    steps, names = recorded.steps, recorded.names
    assert names == ["Ego", "lead truck"]
    exported = osi_rows(steps, names)
    osi = OsiFrames()
    for frame, rows in zip(frames, exported, strict=True):
        gt = betterosi.GroundTruth.from_binary(osi.encode(frame))  # type: ignore[attr-defined]
        assert [r.name for r in rows] == ["Ego", "lead truck"]
        for row, m in zip(rows, gt.moving_object, strict=True):
            assert row.idx == m.id.value and row.types[0] == m.type
            assert row.position == pytest.approx((m.base.position.x, m.base.position.y, m.base.position.z))
            assert row.velocity == pytest.approx((m.base.velocity.x, m.base.velocity.y, m.base.velocity.z))
            assert row.orientation == pytest.approx(
                (m.base.orientation.roll, m.base.orientation.pitch, m.base.orientation.yaw)
            )
            assert row.dimension == pytest.approx(
                (m.base.dimension.length, m.base.dimension.width, m.base.dimension.height)
            )


def test_a_manifest_without_osi_dumps_as_before() -> None:
    """`carlos.spec` in every recording is the manifest dumped without None fields: `recording.osi` unset
    must not appear, so recordings of manifests that do not ask for OSI keep their bytes."""
    from simcore.spec import Recording

    assert "osi" not in Recording().model_dump(by_alias=True, exclude_none=True)
    assert Recording.model_validate({"osi": True}).model_dump(by_alias=True, exclude_none=True)["osi"] is True
