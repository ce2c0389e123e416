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
