"""`carlos conformance`: running a directory of scenarios and comparing with reference trajectories."""

from __future__ import annotations

import csv
import gzip
import json
import subprocess
import sys
from pathlib import Path

import pytest

from simcore import conformance
from tests.tooling import corpus_dir
from tests.xosc_fixtures import (
    openscenario,
    private_actions,
    scenario_object,
    sim_time,
    speed_action,
    teleport_world,
    vehicle,
    write_scenario,
)

ROOT = Path(__file__).resolve().parents[1]


def straight(controller: str = "") -> str:
    """Car (with `controller`) on no road, from the origin along +x at 10 m/s until t > 2 s."""
    car = vehicle(z=0.8, width=2, max_speed=50, max_deceleration=10, track_width=1.8)
    return openscenario(
        minor=1,
        entities=scenario_object("Car", car, controller),
        init=private_actions("Car", teleport_world(0), speed_action("step", "time", 0, 10)),
        stop=sim_time("greaterThan", 2, name="end"),
    )


def write_reference(path: Path, shift: float, end: float = 2.0) -> None:
    rows = ["time,id,name,x,y,z,h,p,r,speed,roadId,laneId,s,t,offset"]
    for k in range(round(end / 0.1) + 1):
        t = k * 0.1
        rows.append(f"{t:.4f},0,Car,{10 * t + shift:.4f},0,0,0,0,0,10,0,0,0,0,0")
    with gzip.open(path, "wt") as handle:
        handle.write("\n".join(rows) + "\n")


@pytest.fixture
def suite(tmp_path: Path) -> tuple[Path, Path]:
    scenarios = tmp_path / "scenarios" / "set"
    scenarios.mkdir(parents=True)
    (scenarios / "straight.xosc").write_text(straight())
    (scenarios / "broken.xosc").write_text("<OpenSCENARIO><Storyboard></OpenSCENARIO>")
    reference = tmp_path / "reference"
    reference.mkdir()
    return scenarios.parent, reference


def test_agreement_needs_position_and_end_time(suite: tuple[Path, Path]) -> None:
    scenarios, reference = suite
    write_reference(reference / "set__straight.csv.gz", shift=0.0, end=2.05)
    results = {Path(r.file).name: r for r in conformance.run_directory(scenarios, reference)}
    good = results["straight.xosc"]
    assert good.loaded and good.ended and good.agreed
    assert good.sim_seconds == pytest.approx(2.05)  # the first step where t > 2 holds
    assert good.max_rmse is not None and good.max_rmse < 1e-6
    bad = results["broken.xosc"]
    assert bad.status == "bad_input" and not bad.loaded and "not well-formed" in bad.message
    totals = conformance.totals(list(results.values()))
    assert (totals["scenarios"], totals["loaded"], totals["ended"], totals["agreed"]) == (2, 1, 1, 1)

    # 0.6 m off everywhere: over the 0.5 m limit
    write_reference(reference / "set__straight.csv.gz", shift=0.6, end=2.05)
    shifted = conformance.run_directory(scenarios, reference, include=["*/straight.xosc"])[0]
    assert shifted.max_rmse == pytest.approx(0.6, abs=1e-6) and not shifted.agreed

    # the right track but the reference ended 0.55 s later: the end time disagrees
    write_reference(reference / "set__straight.csv.gz", shift=0.0, end=2.6)
    late = conformance.run_directory(scenarios, reference, include=["*/straight.xosc"])[0]
    assert late.max_rmse is not None and late.max_rmse < 1e-6
    assert late.end_error == pytest.approx(0.55, abs=1e-6) and not late.agreed


def test_command_prints_totals_and_writes_csv_and_json(suite: tuple[Path, Path], tmp_path: Path) -> None:
    scenarios, reference = suite
    write_reference(reference / "set__straight.csv.gz", shift=0.0, end=2.05)
    out = tmp_path / "out" / "table.csv"
    options = ["--reference", str(reference), "--out", str(out)]
    proc = subprocess.run(
        [sys.executable, "-m", "simcore.cli", "conformance", str(scenarios), *options],
        capture_output=True,
        text=True,
        check=False,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    assert "loaded 1" in proc.stdout and "agreed 1 of 1" in proc.stdout
    rows = {r["file"]: r for r in csv.DictReader(out.open())}
    assert rows["set/straight.xosc"]["agreed"] == "1"
    assert rows["set/broken.xosc"]["status"] == "bad_input"
    payload = json.loads(out.with_suffix(".json").read_text())
    assert payload["totals"]["agreed"] == 1


def test_markdown_table_has_the_totals_and_a_row_per_file(suite: tuple[Path, Path], tmp_path: Path) -> None:
    scenarios, reference = suite
    write_reference(reference / "set__straight.csv.gz", shift=0.6, end=2.05)
    results = conformance.run_directory(scenarios, reference)
    out = tmp_path / "table.md"
    conformance.write_results(results, out, scenarios)
    lines = out.read_text().splitlines()
    assert lines[0].startswith("Totals: 2 scenarios · loaded 1 · ran to their own end 1 · agreed 0 of 1")
    rows = {line.split(" | ")[0].lstrip("| "): line for line in lines if line.startswith("| set/")}
    assert set(rows) == {"set/straight.xosc", "set/broken.xosc"}
    assert "| ended | 2.05 / 2.00 | 0.600 | Car | no |" in rows["set/straight.xosc"]
    assert "bad_input: " in rows["set/broken.xosc"] and "not well-formed" in rows["set/broken.xosc"]


def test_corpus_subset_agrees_with_esmini() -> None:
    """A few corpus scenarios covering lane changes, speed shapes, trajectories, catalogs and headway
    triggers: each loads, ends on its own and agrees with esmini."""
    subset = [
        "xosc/cut-in.xosc",  # lane change, headway triggers, parameters in Story scope
        "xosc/acc-test.xosc",  # esmini's ACC controller (override mode), speed rates bounded by performance
        "xosc/alks-test.xosc",  # esmini's ALKS controller (the ACC in additive mode) on a curved road
        "xosc/cut-in_cr.xosc",  # LaneOffset, qualified Event::Action names
        "xosc/lane-change_trajectory_wp.xosc",  # polyline trajectory
        "xosc/lane-change_clothoid_based_trajectory.xosc",  # chained clothoids
        "xosc/bicycle_fall_over.xosc",  # timed polyline with pauses
        "scenario_construct_examples/scenario_nurb_curved_road.xosc",  # NURBS, maneuver catalogs
        "xosc/routing-test.xosc",  # routes, route positions, AcquirePosition
        "xosc/synch_with_steady_state.xosc",  # Synchronize with a steady state
        "xosc/drop-bike.xosc",  # LongitudinalDistance in road coordinates, Init action overridden
        "xosc/two_plus_one_road.xosc",  # RelativeClearance, lanes across lane sections
        "xosc/left-hand-traffic_using_road_rule.xosc",  # OpenDRIVE rule="LHT", edges
        "xosc/velodrome.xosc",  # Init speed transitions
        "xosc/speed-profile.xosc",  # SpeedProfile, follow (jerk-limited corners) and position modes
        "xosc/long_dist_action_with_jerk.xosc",  # LongitudinalDistance spring with jerk limits
        "xosc/trailers.xosc",  # trailer chains dragged by the hitch, a lane narrowing to nothing
        "xosc/pedestrian_traj_synch.xosc",  # Synchronize with a final speed, trajectory heading vs motion
        "xosc/follow_ghost.xosc",  # FollowGhost: a ghost ahead in time, the entity following its trail
        "xosc/highway_driver.xosc",  # esmini's NaturalDriver: IDM speed, lane changes past slower traffic
        "xosc/keep_lateral_distance.xosc",  # LateralDistance springs damped relative to a lane-changing entity
    ]
    corpus = corpus_dir()
    results = conformance.run_directory(
        corpus / "resources", corpus / "reference", include=subset, cap_seconds=60
    )
    assert len(results) == len(subset)
    for r in results:
        assert r.loaded and r.ended, (r.file, r.message)
        assert r.agreed, (r.file, r.max_rmse, r.worst_entity, r.end_error)


def test_a_ghost_head_start_shifts_the_reported_time_axis(tmp_path: Path) -> None:
    """esmini runs a FollowGhost controller's ghost `headstartTime` ahead and reports every time shifted back
    by it: results are put on that axis. The stop trigger's simulation time is on that axis too (esmini only
    shifts the triggers of the acts and of the events the ghost acts in); during the head start only the
    ghost moves."""
    ghost = """<ObjectController><Controller name="g"><Properties>
      <Property name="esminiController" value="FollowGhostController"/><Property name="headstartTime" value="1.5"/>
      </Properties></Controller></ObjectController>"""
    path = write_scenario(tmp_path, straight(controller=ghost), "ghost.xosc")
    result, trace = conformance.run_scenario(path, cap_seconds=10)
    assert result.ended
    assert result.sim_seconds == pytest.approx(2.05)  # the stop trigger (> 2 s) on esmini's time axis
    times = [t for t, _, _ in trace.tracks["Car"]]
    assert times[0] == pytest.approx(-1.5) and times[-1] == pytest.approx(2.0, abs=0.06)
    car = {round(t, 1): x for t, x, _ in trace.tracks["Car"]}
    ghost_x = {round(t, 1): x for t, x, _ in trace.tracks["Car_ghost"]}
    assert car[0.0] == pytest.approx(0.0) and ghost_x[0.0] == pytest.approx(15.0)  # 1.5 s ahead at 10 m/s
    # its controller is never activated: after the head start the entity moves on its own speed
    assert car[1.0] == pytest.approx(10.0)


# --- the comparison (shared by `carlos conformance` and bench/catalogues.py) --------------------------------


def _line(speed: float, shift: float = 0.0, end: float = 2.0) -> list[tuple[float, float, float]]:
    return [(round(k * 0.1, 6), speed * k * 0.1 + shift, 0.0) for k in range(round(end / 0.1) + 1)]


def test_track_error_is_the_rmse_over_the_common_times_and_the_distance_at_the_last() -> None:
    ours = _line(10.0, shift=0.3)
    theirs = _line(10.0)[5:]  # the reference starts later: only the common times count
    rmse, final, count = conformance.track_error(ours, theirs)
    assert count == len(theirs) == 16
    assert rmse == pytest.approx(0.3) and final == pytest.approx(0.3)
    # drifting apart: the RMSE is the root mean square over time, the final error the last distance
    rmse, final, count = conformance.track_error(_line(11.0), _line(10.0))
    assert final == pytest.approx(2.0)
    assert rmse == pytest.approx((sum((k * 0.1) ** 2 for k in range(21)) / 21) ** 0.5)
    assert conformance.track_error(_line(10.0), [(5.0, 0.0, 0.0)]) == (None, None, 0)


def _compared(
    ours: list[tuple[float, float, float]], end: float, controlled: frozenset[str] = frozenset()
) -> conformance.ScenarioResult:
    result = conformance.ScenarioResult(file="f", loaded=True, ended=True, status="ended", sim_seconds=end)
    trace = conformance.Trace({"Car": ours, "Other": _line(0.0)})
    conformance.compare(result, trace, {"Car": _line(10.0), "Other": _line(0.0)}, 2.0, set(controlled))
    return result


def test_the_final_position_rule_and_the_rmse_rule() -> None:
    same = _compared(_line(10.0), 2.0)
    assert same.agreed and same.agreed_final and same.final_error == pytest.approx(0.0)
    # 0.9 m off at the end, 0.52 m RMSE: the catalogue rule (final ≤ 1 m) agrees, the RMSE rule does not
    drift = _compared(_line(10.45), 2.0)
    assert drift.final_error == pytest.approx(0.9) and drift.max_rmse is not None and drift.max_rmse > 0.5
    assert drift.agreed_final and not drift.agreed
    assert drift.worst_entity == "Car"
    # 1.1 m off at the end: neither
    far = _compared(_line(10.55), 2.0)
    assert not far.agreed_final and not far.agreed
    # ... unless a controller CARLOS does not model drives it: reported, not compared
    assert _compared(_line(10.55), 2.0, frozenset({"Car"})).agreed_final
    # end 0.12 s late: the catalogue rule (0.15 s) agrees, the RMSE rule (0.1 s) does not
    late = _compared(_line(10.0), 2.12)
    assert late.agreed_final and not late.agreed
    assert not _compared(_line(10.0), 2.2).agreed_final
    entity = next(e for e in far.entities if e.name == "Car")
    assert entity.final_error == pytest.approx(1.1) and entity.samples == 21


def test_a_relative_esmini_path_is_resolved_before_esmini_runs_in_its_scratch_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`--esmini ../tools/esmini` (relative to where the user is) must work although esmini runs in a
    scratch directory: a stand-in player that writes a one-entity CSV."""
    from simcore.reference_player import find_esmini, run_esmini

    player = tmp_path / "tools" / "esmini"
    player.parent.mkdir()
    player.write_text(
        "#!/bin/sh\n"
        'while [ $# -gt 0 ]; do if [ "$1" = --csv_logger ]; then out="$2"; fi; shift; done\n'
        'printf "esmini stand-in\\nIndex [-], TimeStamp [s], #1 Entity_Name [-], #1 World_Position_X [m], '
        '#1 World_Position_Y [m], \\n0, 0.0, Car, 1.0, 2.0, \\n1, 0.1, Car, 2.0, 2.0, \\n" > "$out"\n'
    )
    player.chmod(0o755)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    relative = Path("../tools/esmini")
    found = find_esmini(relative)
    assert found is not None and found.is_absolute() and found == player.resolve()
    played = run_esmini(relative, write_scenario(tmp_path, straight(), "s.xosc"))
    assert played.ok, played.message
    assert played.tracks == {"Car": [(0.0, 1.0, 2.0), (0.1, 2.0, 2.0)]} and played.end == pytest.approx(0.1)


# --- `carlos run` and `carlos conformance`: the same trajectories -----------------------------------------


def _carlos_run(tmp_path: Path, scenario: Path) -> tuple[conformance.ScenarioResult, conformance.Trace, dict]:
    """`carlos run` (the CLI, recording on, conformance's step and seed) on `scenario`, read back from what
    it wrote."""
    from typer.testing import CliRunner

    from simcore.cli_app import app

    manifest = tmp_path / "run.yaml"
    out = tmp_path / "results"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: same}\nspec:\n"
        f"  scenarios: [{{name: s, openscenario: {json.dumps(str(scenario))}}}]\n"
        "  simulation: {stepSeconds: 0.05, maxSeconds: 60, seed: 1}\n"
        f"  output: {{url: {json.dumps(out.as_uri())}}}\n"
    )
    done = CliRunner().invoke(app, ["run", str(manifest), "-q"])
    assert done.exit_code == 0, done.output
    index = out / "same" / "0"
    result, trace = conformance.recorded_run(index, str(scenario), frozenset({"Car", "Car_ghost"}))
    return result, trace, json.loads((index / "summary.json").read_text())


def _assert_same(ours: conformance.Trace, theirs: conformance.Trace) -> None:
    assert set(ours.tracks) == set(theirs.tracks)
    for name, samples in theirs.tracks.items():
        flat = [value for sample in ours.tracks[name] for value in sample]
        assert flat == pytest.approx([value for sample in samples for value in sample], abs=1e-6), name


@pytest.mark.parametrize("controller", ["ExternalController", "InteractiveController"])
def test_an_external_entity_without_input_moves_alike_in_carlos_run_and_conformance(
    tmp_path: Path, controller: str
) -> None:
    """An active ExternalController with no system under test holds its entity (an InteractiveController
    rolls on) in both; `carlos run` used to let the closed loop brake it over metres instead."""
    object_controller = f"""<ObjectController><Controller name="ext"><Properties>
      <Property name="esminiController" value="{controller}"/></Properties></Controller></ObjectController>"""
    activate = '<PrivateAction><ActivateControllerAction longitudinal="true" lateral="true"/></PrivateAction>'
    car = vehicle(z=0.8, width=2, max_speed=50, max_deceleration=10, track_width=1.8)
    text = openscenario(
        minor=1,
        entities=scenario_object("Car", car, object_controller),
        init=private_actions("Car", teleport_world(0), speed_action("step", "time", 0, 10), activate),
        stop=sim_time("greaterThan", 2, name="end"),
    )
    path = write_scenario(tmp_path, text, "external.xosc")
    expected, trace = conformance.run_scenario(path, cap_seconds=60)
    result, recorded, _ = _carlos_run(tmp_path, path)
    assert expected.ended and result.ended and result.sim_seconds == pytest.approx(expected.sim_seconds)
    _assert_same(recorded, trace)
    xs = [x for _, x, _ in recorded.tracks["Car"]]
    if controller == "ExternalController":
        assert set(xs) == {0.0}
    else:
        assert xs[-1] > 15.0


def test_a_ghost_head_start_is_in_the_recording_and_the_summary_of_carlos_run(tmp_path: Path) -> None:
    """ROS time cannot be negative: the recording and simSeconds start at the ghost's start; the offset to
    the scenario's time (-headstartTime) is in the summary and the MCAP metadata, and read back the run is
    conformance's, on the scenario's time axis."""
    from mcap.reader import make_reader

    ghost = """<ObjectController><Controller name="g"><Properties>
      <Property name="esminiController" value="FollowGhostController"/><Property name="headstartTime" value="1.5"/>
      </Properties></Controller></ObjectController>"""
    path = write_scenario(tmp_path, straight(controller=ghost), "ghost.xosc")
    expected, trace = conformance.run_scenario(path, cap_seconds=60)
    result, recorded, summary = _carlos_run(tmp_path, path)
    assert summary["scenarioTimeOffsetSeconds"] == -1.5
    assert summary["simSeconds"] == pytest.approx(3.55)
    assert result.sim_seconds == pytest.approx(expected.sim_seconds) == pytest.approx(2.05)
    with (tmp_path / "results" / "same" / "0" / "recording.mcap").open("rb") as handle:
        metadata = {m.name: m.metadata for m in make_reader(handle).iter_metadata()}
    assert metadata["carlos.run"]["scenarioTimeOffsetSeconds"] == "-1.5"
    _assert_same(recorded, trace)


@pytest.mark.slow
def test_every_corpus_scenario_that_agrees_through_conformance_agrees_through_carlos_run(
    tmp_path: Path,
) -> None:
    """The whole esmini corpus: every scenario `carlos conformance` finds in agreement with esmini's
    reference agrees too when run by `carlos run` (a fresh process, recording on) and read back from the
    recording it wrote, FollowGhost (its head start) included."""
    from simcore.scenario.xosc import load_scenario

    corpus = corpus_dir()
    reference = corpus / "reference"
    agreed = [r for r in conformance.run_directory(corpus / "resources", reference, jobs=2) if r.agreed]
    assert "follow_ghost.xosc" in {Path(r.file).name for r in agreed}
    scenarios = ", ".join(f"{{name: s{i}, openscenario: {json.dumps(r.file)}}}" for i, r in enumerate(agreed))
    manifest = tmp_path / "run.yaml"
    out = tmp_path / "results"
    manifest.write_text(
        "apiVersion: carlos.dev/v1alpha1\nkind: SimulationRun\nmetadata: {name: corpus}\nspec:\n"
        f"  scenarios: [{scenarios}]\n"
        f"  simulation: {{stepSeconds: {conformance.STEP_SECONDS}, maxSeconds: {conformance.DEFAULT_CAP_SECONDS}, "
        "seed: 1}\n"
        f"  output: {{url: {json.dumps(out.as_uri())}}}\n"
    )
    done = subprocess.run(
        [sys.executable, "-m", "simcore.cli", "run", str(manifest), "-q", "-j", "2"],
        capture_output=True,
        text=True,
        timeout=3600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    ends = conformance.reference_end_times(reference)
    by_name = {f"s{i}": r for i, r in enumerate(agreed)}
    differing = []
    for summary in sorted((out / "corpus").glob("*/summary.json")):
        expected = by_name.pop(json.loads(summary.read_text())["scenario"])
        path = Path(expected.file)
        tracks = conformance.read_reference(reference / conformance.reference_name(path))
        scenario = load_scenario(path, {})
        names = {e.name for e in scenario.entities} | set(tracks)
        result, trace = conformance.recorded_run(summary.parent, expected.file, frozenset(names))
        ref_end = ends.get(conformance.reference_name(path))
        conformance.compare(result, trace, tracks, ref_end, conformance.uncompared_entities(scenario))
        if not result.agreed:
            differing.append(
                (path.name, result.status, result.sim_seconds, result.max_rmse, result.worst_entity)
            )
    assert not by_name, f"no result for {sorted(by_name)}"
    assert not differing


def test_an_entity_of_an_external_controller_is_compared(tmp_path: Path) -> None:
    """Without a command it holds as in esmini (in `carlos run` as in conformance), so its trajectory
    decides agreement like a scripted one's."""
    external = """<ObjectController><Controller name="ext"><Properties>
      <Property name="esminiController" value="ExternalController"/></Properties></Controller></ObjectController>"""
    from simcore.scenario.xosc import load_scenario

    path = write_scenario(tmp_path, straight(controller=external), "external.xosc")
    assert conformance.uncompared_entities(load_scenario(path, {})) == set()
