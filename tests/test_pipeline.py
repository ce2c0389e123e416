"""The run pipeline (simcore.pipeline): `carlos run` and `carlos conformance` run the same thing; parts start
only when something uses them; simcore never imports the operator package."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from simcore import conformance
from simcore.errors import BadInput
from simcore.executor import execute
from simcore.manifest import load_manifest
from simcore.transport.bus import InProcessBus, Message
from simcore.transport.messages import ros_name
from tests.tooling import NO_CORPUS, esmini_corpus

ROOT = Path(__file__).resolve().parents[1]
_CORPUS_ROOT = esmini_corpus()
CORPUS = (_CORPUS_ROOT or ROOT) / "resources" / "xosc"
needs_corpus = pytest.mark.skipif(_CORPUS_ROOT is None, reason=NO_CORPUS)


def _manifest(directory: Path, scenario: Path, *, name: str = "pipeline", max_seconds: float = 300) -> Path:
    path = directory / f"{name}.yaml"
    path.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\n"
        f"metadata: {{name: {name}}}\n"
        "spec:\n"
        f"  scenarios: [{{name: s, openscenario: {json.dumps(str(scenario))}}}]\n"
        f"  simulation: {{stepSeconds: 0.05, maxSeconds: {max_seconds}, seed: 1}}\n"
        "  recording: {enabled: false}\n"
        f"  output: {{url: {json.dumps((directory / 'results').as_uri())}}}\n"
    )
    return path


def _carlos_run_tracks(
    directory: Path, scenario: Path, max_seconds: float = 300
) -> tuple[dict[str, object], dict[str, dict[int, tuple]]]:
    """Run `scenario` as `carlos run` does (executor → runner → pipeline), listening to every odometry
    topic: (index summary, ROS name → {step: (x, y)})."""
    run = load_manifest(_manifest(directory, scenario, max_seconds=max_seconds))
    bus = InProcessBus()
    tracks: dict[str, dict[int, tuple]] = {}

    def on_odometry(message: Message) -> None:
        position = message.obj().pose.pose.position
        step = round(message.time_s / 0.05)
        tracks.setdefault(message.topic.split("/")[2], {})[step] = (position.x, position.y)

    bus.subscribe("/carlos/*/odometry", on_odometry)
    report = execute(run, base_dir=directory, bus=bus)
    return report.outcomes[0], tracks


@needs_corpus
@pytest.mark.parametrize(
    "name", ["cut-in", "slow-lead-vehicle", "highway_merge", "follow_ghost", "trajectory-test"]
)
def test_carlos_run_and_conformance_run_the_same_trajectories(tmp_path: Path, name: str) -> None:
    scenario = CORPUS / f"{name}.xosc"
    result, trace = conformance.run_scenario(scenario)
    assert result.status == "ended", result.message
    assert _same_trajectories(tmp_path, scenario, trace, 300) > 50


def _corpus_files() -> list[Path]:
    return sorted((_CORPUS_ROOT / "resources").rglob("*.xosc")) if _CORPUS_ROOT is not None else []


@pytest.mark.slow
@needs_corpus
@pytest.mark.parametrize(
    "scenario",
    _corpus_files() or [None],
    ids=lambda p: str(p.relative_to(_CORPUS_ROOT / "resources")) if _CORPUS_ROOT and p else "no-corpus",
)
def test_every_corpus_scenario_conformance_runs_to_its_end_runs_the_same_through_carlos_run(
    tmp_path: Path, scenario: Path
) -> None:
    result, trace = conformance.run_scenario(scenario)
    if result.status != "ended":
        pytest.skip(f"conformance does not run it to its end ({result.status}: {result.message})")
    # externally driven entities included: without a command both hold them, as the reference player
    assert _same_trajectories(tmp_path, scenario, trace, conformance.DEFAULT_CAP_SECONDS) > 0


def _same_trajectories(tmp_path: Path, scenario: Path, trace: conformance.Trace, max_seconds: float) -> int:
    """Run `scenario` through `carlos run` and compare every traced sample of conformance's run with what
    it published; returns how many samples were compared."""
    summary, tracks = _carlos_run_tracks(tmp_path, scenario, max_seconds)
    assert summary["status"] != "error", summary.get("error")
    assert summary["endReason"] == "stopTrigger"
    offset = min(t for samples in trace.tracks.values() for t, _, _ in samples)  # a ghost's headstart
    compared = 0
    for entity, samples in trace.tracks.items():
        ours = tracks.get(ros_name(entity))
        if ours is None:
            continue  # a ghost: in the trace, not a world object
        for t, x, y in samples:
            position = ours.get(round((t - offset) / 0.05))
            assert position is not None, f"{entity} at t={t}: not published by carlos run"
            assert position == pytest.approx((x, y), abs=1e-6), f"{entity} at t={t}"
            compared += 1
    return compared


@needs_corpus
def test_a_scenario_without_sumo_driven_entities_starts_no_sumo_and_builds_no_messages(
    tmp_path: Path,
) -> None:
    """A fresh process runs the corpus cut-in (recording off) without importing libsumo, rosbags' message
    types or the operator, and without a worker process."""
    manifest = _manifest(tmp_path, CORPUS / "cut-in.xosc")
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "from simcore.executor import execute\n"
        "from simcore.manifest import load_manifest\n"
        f"report = execute(load_manifest({str(manifest)!r}), base_dir=Path({str(tmp_path)!r}))\n"
        "print(report.exit_code)\n"
        "print(sorted(m for m in ('libsumo', 'libsumo._libsumo', 'simcore.transport.messages', 'rosbags.typesys', "
        "'carlos_operator', 'simcore.world.sumo') if m in sys.modules))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    exit_code, imported = done.stdout.strip().splitlines()[-2:]
    assert exit_code == "0"
    assert imported == "[]"


@needs_corpus
def test_a_road_netconvert_cannot_convert_fails_only_a_run_that_needs_sumo(tmp_path: Path) -> None:
    from simcore import pipeline
    from simcore.scenario.xosc import load_scenario

    source = (CORPUS / "slow-lead-vehicle.xosc").read_text()
    text = source.replace('"../', f'"{CORPUS.parent.resolve()}/')  # the copy finds the corpus' road, catalogs
    assert text != source
    (tmp_path / "scripted.xosc").write_text(text)
    scripted = load_scenario(tmp_path / "scripted.xosc")
    assert pipeline.sumo_driven(scripted) == []
    assert pipeline.start_sumo(scripted, 0.05, 1) is None  # no netconvert at all
    sumo_text = text.replace(
        'entryName="$EgoVehicle"/>',
        'entryName="$EgoVehicle"/><ObjectController><Controller name="s"><Properties>'
        '<Property name="carlos.driver" value="sumo"/></Properties></Controller></ObjectController>',
    )
    assert sumo_text != text
    (tmp_path / "sumo.xosc").write_text(sumo_text)
    driven = load_scenario(tmp_path / "sumo.xosc")
    assert pipeline.sumo_driven(driven)
    with pytest.raises(BadInput) as caught:
        pipeline.start_sumo(driven, 0.05, 1)
    message = str(caught.value)
    assert "netconvert could not convert" in message
    assert "carlos.driver=sumo" in message and pipeline.sumo_driven(driven)[0] in message


def test_no_simcore_module_imports_the_operator_package() -> None:
    offenders = []
    for path in sorted((ROOT / "simcore").rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                names = [node.value] if node.value.startswith("carlos_operator") else []
            offenders.extend(
                f"{path.relative_to(ROOT)}:{node.lineno}"
                for n in names
                if n.split(".")[0] == "carlos_operator"
            )
    assert offenders == []


def test_operator_commands_come_from_the_operator_package_entry_points() -> None:
    from simcore.cli import app

    runner = CliRunner()
    listed = runner.invoke(app, ["--help"])
    assert listed.exit_code == 0
    assert "operator" in listed.output and "crds" in listed.output
    crd = runner.invoke(app, ["crds"])
    assert crd.exit_code == 0, crd.output
    assert "kind: CustomResourceDefinition" in crd.output
    bad = subprocess.run(
        [str(Path(sys.executable).parent / "carlos"), "operator"], capture_output=True, text=True, timeout=60
    )
    assert bad.returncode == 2
    assert "--namespace" in bad.stderr + bad.stdout


def test_point_grid_finds_what_a_kd_tree_finds() -> None:
    """OpenDrive's world→road index (no scipy import) against scipy's cKDTree on the same points."""
    import numpy as np
    from scipy.spatial import cKDTree

    from simcore.world.opendrive import PointGrid

    rng = np.random.default_rng(7)
    points = np.vstack([rng.uniform(-500.0, 500.0, (3000, 2)), rng.normal(0.0, 3.0, (500, 2))])
    for radius in (0.5, 7.0, 40.0):
        grid, tree = PointGrid(points, radius), cKDTree(points)
        for query in [*rng.uniform(-520.0, 520.0, (200, 2)), (0.0, 0.0), points[5]]:
            assert grid.query_ball_point(query, radius) == sorted(tree.query_ball_point(query, radius))


@pytest.mark.parametrize("recording", [False, True])
def test_a_run_makes_a_scratch_directory_only_for_files_it_writes(tmp_path: Path, recording: bool) -> None:
    """A run that records writes its recording into a scratch directory, uploads it and removes the
    directory; a run that writes no file of its own (recording off, a local scenario) makes none."""
    from simcore.runner import run_index
    from simcore.store import FileStore

    manifest = _manifest(tmp_path, ROOT / "examples" / "scenarios" / "braking.xosc", max_seconds=2)
    if recording:
        manifest.write_text(
            manifest.read_text().replace("recording: {enabled: false}", "recording: {enabled: true}")
        )
    run = load_manifest(manifest)
    scratch_root = tmp_path / "scratch"
    scratch_root.mkdir()
    made: list[str] = []
    original = __import__("tempfile").TemporaryDirectory

    def spy(*args: object, **kwargs: object) -> object:
        made.append(str(kwargs.get("dir")))
        return original(*args, **kwargs)  # type: ignore[call-overload]

    store = FileStore(tmp_path / "results")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("simcore.runner.tempfile.TemporaryDirectory", spy)
        outcome = run_index(
            run, 0, base_dir=tmp_path, store=store, store_factory=FileStore, scratch_root=scratch_root
        )
    assert outcome.summary["status"] == "passed", outcome.summary
    assert made == ([str(scratch_root)] if recording else [])
    assert list(scratch_root.iterdir()) == []
    assert store.exists("pipeline/0/recording.mcap") == recording
    assert store.exists("pipeline/0/summary.json") and store.exists("pipeline/0/log.txt")
