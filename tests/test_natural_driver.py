"""esmini's NaturalDriver controller as CARLOS runs it (simcore.scenario.drivers.NaturalDriver) on small
synthetic scenarios: the IDM speed on a free road and behind a slower vehicle, lane changes to a faster lane
(sinusoidal, speed kept), back to its route lane, none into a lane where it would cut someone off, speed
actions ignored while it drives — and that conformance compares its entities."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from simcore import conformance
from simcore.scenario import model as m
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests.test_driver_controllers import activate, controller, highway_scenario, private
from tests.xosc_fixtures import HIGHWAY, event, scenario_object, sim_time, speed_action

# road 1 of the test highway: driving lanes -1, -2, -3 (left to right), 3.5 m wide, straight along +x
DRIVER = {
    "desiredSpeed": 25,
    "desiredDistance": 5,
    "thw": 1.5,
    "maxAcc": 2,
    "maxDec": -4,
    "lookAheadDistance": 150,
    "laneChangeDuration": 2,
    "laneChangeDelay": 1,
    "maxImposedBraking": 3,
    "laneChangeAccGain": 0.3,
    "politeness": 0,
    "route": -1,
}
NO_LANE_CHANGES = {**DRIVER, "laneChangeAccGain": 1e9, "route": 5}
# Ego 4.5 m long, reference point 1.4 m behind its box centre: bumper to bumper = ds − 4.5
LENGTH = 4.5


def write(
    tmp_path: Path, properties: dict[str, float], init: str, others: tuple[str, ...], events: str = ""
) -> Path:
    ego = scenario_object("Ego", controller=controller("NaturalDriver", **properties))
    entities = ego + "".join(scenario_object(n) for n in others)
    return highway_scenario(tmp_path / "natural.xosc", entities, init, events)


@pytest.fixture(scope="module")
def road() -> OpenDrive:
    return OpenDrive.from_file(HIGHWAY)


def run(
    path: Path, road: OpenDrive, seconds: float
) -> tuple[ScenarioEngine, dict[float, tuple[float, float, int]]]:
    """The engine after `seconds`, and Ego's (speed, road t, lane) at every step."""
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    ego = engine.bodies["Ego"]
    trace = {}
    while engine.time < seconds - 1e-9:
        engine.advance()
        t = road.lane_center_t(ego.road_id or "1", ego.lane_id, ego.s) + ego.offset
        trace[round(engine.time, 2)] = (ego.speed, t, ego.lane_id)
    return engine, trace


def test_on_a_free_road_it_accelerates_by_the_idm_to_its_desired_speed(
    tmp_path: Path, road: OpenDrive
) -> None:
    path = write(tmp_path, NO_LANE_CHANGES, private("Ego", 50, 10, extra=activate()), ())
    assert not any("not modelled" in w for w in load_scenario(path).warnings)
    _, trace = run(path, road, 30.0)
    # a·(1 − (v/v0)⁴) from 10 m/s: 2·(1 − 0.4⁴) = 1.9488 m/s² in the first step
    assert trace[0.05][0] == pytest.approx(10 + 0.05 * 2 * (1 - 0.4**4))
    speeds = [v for v, _, _ in trace.values()]
    assert all(b >= a for a, b in itertools.pairwise(speeds))
    assert max(speeds) <= 25.0 and speeds[-1] == pytest.approx(25.0, abs=0.2)


def test_behind_a_slower_vehicle_it_settles_at_the_idm_equilibrium_gap(
    tmp_path: Path, road: OpenDrive
) -> None:
    path = write(
        tmp_path,
        NO_LANE_CHANGES,
        private("Ego", 50, 20, extra=activate()) + private("Lead", 150, 15),
        ("Lead",),
    )
    engine, trace = run(path, road, 100.0)
    ego, lead = engine.bodies["Ego"], engine.bodies["Lead"]
    assert trace[100.0][0] == pytest.approx(15.0, abs=1e-4)
    # equal speeds: a·(1 − (v/v0)⁴) = a·(s*/s)², s* = s0 + v·T; the gap it sees is measured after the Lead
    # moved and before it moves itself (as esmini steps its controllers), one step's 0.75 m more than now
    expected = (5 + 15 * 1.5) / math.sqrt(1 - (15 / 25) ** 4)
    assert lead.s - ego.s - LENGTH + 15 * 0.05 == pytest.approx(expected, abs=1e-3)
    assert all(lane == -2 for _, _, lane in trace.values())  # no lane changes with that gain


def test_it_changes_to_a_free_lane_past_a_slower_vehicle_keeping_its_speed(
    tmp_path: Path, road: OpenDrive
) -> None:
    # Lead 40 m ahead at 10 m/s in its lane, the lane to the left free: at once (the first frame) it decides
    # to change left (the gain, well above 0.3 m/s²), a sinusoidal change over 2 s from the first step
    properties = {**DRIVER, "route": -3}
    path = write(
        tmp_path,
        properties,
        private("Ego", 50, 20, extra=activate()) + private("Lead", 90, 10),
        ("Lead",),
    )
    engine, trace = run(path, road, 6.0)
    assert any("NaturalDriver changes to lane -1" in line for line in engine.log)
    t0, t1 = -5.25, -1.75
    assert trace[1.0][1] == pytest.approx(t0 + (t1 - t0) * (1 - math.cos(math.pi * 0.5)) / 2, abs=1e-6)
    assert trace[2.0][1] == pytest.approx(t1, abs=1e-9)
    # during the change it keeps its speed; after it, the IDM takes it toward its desired speed
    assert {trace[round(0.05 * k, 2)][0] for k in range(1, 41)} == {20.0}
    assert trace[6.0][0] > 20.0


def test_it_returns_to_its_route_lane_once_it_is_free(tmp_path: Path, road: OpenDrive) -> None:
    # starting left of its route lane (-2), nothing around: it changes back at once, a single change
    path = write(tmp_path, {**DRIVER, "route": -2}, private("Ego", 50, 25, lane=-1, extra=activate()), ())
    engine, trace = run(path, road, 8.0)
    assert trace[2.0][2] == -2 and trace[8.0][2] == -2
    assert sum("NaturalDriver changes to lane" in line for line in engine.log) == 1


def test_no_lane_change_that_would_make_the_vehicle_behind_there_brake_hard(
    tmp_path: Path, road: OpenDrive
) -> None:
    # a slow Lead ahead; in the lane to the left a fast vehicle just behind: changing there would impose
    # more than maxImposedBraking on it, so Ego stays and brakes behind the Lead
    path = write(
        tmp_path,
        {**DRIVER, "route": -3},
        private("Ego", 100, 20, extra=activate())
        + private("Lead", 140, 10)
        + private("Fast", 92, 25, lane=-1)
        + private("Right", 101, 20, lane=-3),
        ("Lead", "Fast", "Right"),
    )
    engine, trace = run(path, road, 1.0)
    assert not any("changes to lane" in line for line in engine.log)
    assert trace[1.0][2] == -2 and trace[1.0][0] < 20.0


def test_speed_actions_are_ignored_while_it_drives(tmp_path: Path, road: OpenDrive) -> None:
    events = event("Stop", speed_action("step", "time", 0, 0.0), sim_time("greaterThan", 1.0))
    path = write(tmp_path, NO_LANE_CHANGES, private("Ego", 50, 20, extra=activate()), (), events)
    _, trace = run(path, road, 3.0)
    assert trace[3.0][0] > 20.0


def test_conformance_compares_natural_driver_entities(tmp_path: Path) -> None:
    assert "NaturalDriver" in m.MODELLED_CONTROLLERS
    path = write(tmp_path, NO_LANE_CHANGES, private("Ego", 50, 20, extra=activate()), ())
    assert "Ego" not in conformance.uncompared_entities(load_scenario(path))
