"""esmini's controllers that steer a vehicle model of their own, as CARLOS runs them: the FollowGhostController
(simcore.scenario.ghost: a ghost runs the scenario's actions a head start ahead, the entity follows its trail)
and the OffroadFollower (simcore.scenario.drivers), on small synthetic scenarios."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from simcore import conformance
from simcore.scenario import ghost as g
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests.test_driver_controllers import controller, private, write
from tests.xosc_fixtures import (
    HIGHWAY,
    event,
    openscenario,
    private_actions,
    scenario_object,
    sim_time,
    speed_action,
    teleport_world,
    write_scenario,
)

LANE_CHANGE = """<PrivateAction><LateralAction><LaneChangeAction>
  <LaneChangeActionDynamics dynamicsShape="sinusoidal" value="2" dynamicsDimension="time"/>
  <LaneChangeTarget><AbsoluteTargetLane value="-3"/></LaneChangeTarget></LaneChangeAction></LateralAction></PrivateAction>"""

BOTH = (
    '<PrivateAction><ControllerAction><ActivateControllerAction longitudinal="true" lateral="true"/>'
    "</ControllerAction></PrivateAction>"
)


@pytest.fixture(scope="module")
def road() -> OpenDrive:
    return OpenDrive.from_file(HIGHWAY)


def engine_for(path: Path, road: OpenDrive | None) -> ScenarioEngine:
    return ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)


def ghost_scenario(tmp_path: Path, mode: str = "position", headstart: float = 2.0) -> Path:
    ghost = controller(
        "followGhost",
        esminiController="FollowGhostController",
        headstartTime=headstart,
        followMode=mode,
        lookaheadSpeed=0.5,
        minLookaheadSpeed=7.0,
        lookaheadSteering=0.5,
        minLookaheadSteering=7.0,
    )
    events = event("Go", speed_action("linear", "rate", 5.0, 20.0), sim_time("greaterOrEqual", 0))
    events += event("Change", LANE_CHANGE, sim_time("greaterThan", 4.0))
    return write(tmp_path, ghost, private("Ego", 50.0, 0.0, extra=BOTH), events, target=False)


def test_the_ghost_runs_the_actions_ahead_and_the_entity_stands_still_meanwhile(
    tmp_path: Path, road: OpenDrive
) -> None:
    engine = engine_for(ghost_scenario(tmp_path), road)
    assert "Ego_ghost" in engine.bodies and engine.output_time_offset == pytest.approx(-2.0)
    start = engine.bodies["Ego"].s
    while engine.time < 2.0 - 1e-9:  # the head start: esmini's time -2 … 0
        engine.advance()
    ego, shadow = engine.bodies["Ego"], engine.bodies["Ego_ghost"]
    assert ego.s == pytest.approx(start) and ego.speed == 0.0
    assert shadow.speed == pytest.approx(10.0) and shadow.s - start == pytest.approx(10.0, abs=0.3)
    # the ghost is no object of the world
    assert [e.name for e in engine.frame().entities] == ["Ego"]


def test_the_entity_follows_the_ghost_trail_with_its_vehicle_model(tmp_path: Path, road: OpenDrive) -> None:
    engine = engine_for(ghost_scenario(tmp_path), road)
    speeds = []
    while engine.time < 16.0 - 1e-9:
        engine.advance()
        speeds.append(engine.bodies["Ego"].speed)
    # the vehicle model accelerates by at most 10 m/s² toward the trail's speed a look-ahead ahead
    assert max(b - a for a, b in itertools.pairwise(speeds)) <= 10.0 * 0.05 + 1e-9
    ego, shadow = engine.bodies["Ego"], engine.bodies["Ego_ghost"]
    # the ghost changed lanes at t = 4 on the storyboard: the entity followed its trail into lane -3
    assert shadow.lane_id == -3 and ego.lane_id == -3 and abs(ego.offset) < 0.2
    assert ego.speed == pytest.approx(20.0, abs=0.5)
    # it stays behind the ghost, closer than the head start (2 s at 20 m/s): it sped up faster than the ghost
    assert 10.0 < shadow.s - ego.s < 40.0


def test_time_mode_follows_the_trail_by_time(tmp_path: Path, road: OpenDrive) -> None:
    engine = engine_for(ghost_scenario(tmp_path, mode="time"), road)
    while engine.time < 12.0 - 1e-9:
        engine.advance()
    ego, shadow = engine.bodies["Ego"], engine.bodies["Ego_ghost"]
    # aiming at where the ghost was 2 s ago plus the look-ahead time (7 s: its trail's end): it closes up
    assert ego.lane_id == -3 and ego.speed == pytest.approx(20.0, abs=1.0)
    assert 0.0 < shadow.s - ego.s < 40.0


def test_stop_trigger_times_stay_on_esmini_axis_act_and_ghost_event_times_shift(tmp_path: Path) -> None:
    scenario = load_scenario(ghost_scenario(tmp_path, headstart=1.5))
    changed, setup = g.setup(scenario)
    assert setup is not None and setup.ghost == "Ego_ghost" and setup.headstart == 1.5
    group = changed.stories[0].acts[0].groups[0]
    assert group.actors == ("Ego_ghost",)
    # the ghost's events keep their times on the storyboard (esmini shifts them back by the head start)
    change = group.maneuvers[0].events[1]
    assert change.start_trigger is not None
    assert change.start_trigger.groups[0][0].value_condition.value == pytest.approx(4.0)  # type: ignore[union-attr]
    # its Init actions are copied to the ghost, not its controller actions
    copied = [type(i.action).__name__ for i in changed.init if i.entity == "Ego_ghost"]
    assert copied == ["TeleportAction", "SpeedAction"]


def test_trail_samples_and_lookups() -> None:
    trail = g.Trail()
    for k in range(30):
        trail.sample(float(k), 0.0, -1.0 + 0.125 * k, 1.0 if k < 20 else 0.0)
    # a sample whenever more than 0.2 s passed (every second step of 0.125 s here), none while standing still
    assert trail.time[:3] == pytest.approx([-1.0, -0.75, -0.5])
    assert trail.speed[-1] == 0.0 and trail.speed.count(0.0) == 1
    assert trail.s == pytest.approx(trail.x)
    # a sample over 0.4 s old is repeated 0.2 s before the next one (a start after standing still)
    trail.sample(40.0, 0.0, 10.0, 1.0)
    assert trail.time[-2:] == pytest.approx([9.8, 10.0]) and trail.x[-2] == trail.x[-3]
    index, s = trail.closest(7.3, 2.0, 0) or (0, 0.0)
    assert s == pytest.approx(7.3) and trail.x[index] <= 7.3 <= trail.x[index + 1]
    assert trail.at_s(7.3, index)[0] == pytest.approx(7.3)
    assert trail.at_s(1e6, 0)[0] == trail.x[-1]  # past the end: its last sample
    assert trail.at_time(-0.875)[0] == pytest.approx(1.0)


def test_follow_ghost_entities_are_compared(tmp_path: Path) -> None:
    scenario = load_scenario(ghost_scenario(tmp_path))
    assert conformance.uncompared_entities(scenario) == set()


def offroad_scenario(tmp_path: Path, lead: str = "Lead", lead_y: float = 0.0) -> Path:
    follower = controller(
        "offroad",
        esminiController="OffroadFollower",
        followEntity=lead,
        targetDistance=20.0,
        steeringRate=4.0,
    )
    text = openscenario(
        entities=scenario_object("Lead") + scenario_object("Follower", controller=follower),
        init=private_actions("Lead", teleport_world(60, lead_y))
        + private_actions("Follower", teleport_world(0), BOTH),
    )
    return write_scenario(tmp_path, text, "offroad.xosc")


def test_offroad_follower_stops_at_its_target_distance_behind_a_standing_lead(tmp_path: Path) -> None:
    engine = engine_for(offroad_scenario(tmp_path), None)
    top = 0.0
    while engine.time < 30.0 - 1e-9:
        engine.advance()
        top = max(top, engine.bodies["Follower"].speed)
    f = engine.bodies["Follower"]
    assert f.x == pytest.approx(40.0, abs=0.3) and f.speed == pytest.approx(0.0, abs=0.05)
    assert top <= 1.2 * 70 / 3.6 + 1e-9  # off every road: 1.2 × esmini's default limit of 70 km/h


def test_offroad_follower_steers_toward_its_lead(tmp_path: Path) -> None:
    engine = engine_for(offroad_scenario(tmp_path, lead_y=40.0), None)
    while engine.time < 30.0 - 1e-9:
        engine.advance()
    f = engine.bodies["Follower"]
    bearing = math.atan2(40.0 - f.y, 60.0 - f.x)
    assert abs(math.atan2(math.sin(bearing - f.heading), math.cos(bearing - f.heading))) < 0.1
    # the throttle only looks at the distance: it ends near it (bent path, no lateral correction)
    assert math.hypot(60.0 - f.x, 40.0 - f.y) == pytest.approx(20.0, abs=2.0)


def test_offroad_follower_without_a_lead_does_nothing(tmp_path: Path) -> None:
    engine = engine_for(offroad_scenario(tmp_path, lead="Nobody"), None)
    for _ in range(40):
        engine.advance()
    f = engine.bodies["Follower"]
    assert (f.x, f.y, f.speed) == (0.0, 0.0, 0.0)
    assert conformance.uncompared_entities(load_scenario(offroad_scenario(tmp_path))) == set()
