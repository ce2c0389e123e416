"""Scenario semantics the public catalogues (Euro NCAP, ASAM examples) rely on, each as the esmini player does
it: a plain test on the engine, and a differential one on a generated scenario (skipped without esmini)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from simcore import conformance
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests import differential_scenarios as gen
from tests.tooling import esmini_player
from tests.xosc_fixtures import act, event, openscenario, scenario_object, sim_time, story, write_scenario


def _engine(path: Path) -> ScenarioEngine:
    scenario = load_scenario(path)
    road = OpenDrive.from_file(scenario.road_file) if scenario.road_file else None
    return ScenarioEngine(scenario, road=road, sumo=None, step_seconds=0.05)


def _agrees_with_esmini(path: Path) -> None:
    results = conformance.run_files([path], esmini=esmini_player(), cap_seconds=60.0)
    (result,) = results
    assert result.agreed, (result.status, result.max_rmse, result.end_error, result.message)


def _angle(a: float, b: float) -> float:
    return abs(math.remainder(a - b, math.tau))


# --- RoutePosition: heading and Orientation ----------------------------------------------------------------


def _route_scenario(orientation: str, after: bool) -> str:
    # a route that runs against the road's s (lane 1 of the rural road, from s=900 to s=100), entities placed
    # in lane -1 along it: each faces its lane's driving direction, an Orientation turns it from there, and
    # one written after InRoutePosition (out of the schema's order) is ignored, as esmini ignores it
    route = (
        '<Route name="Back" closed="false">'
        f'<Waypoint routeStrategy="shortest">{gen.lane_position(900.0, 1, road=1)}</Waypoint>'
        f'<Waypoint routeStrategy="shortest">{gen.lane_position(100.0, 1, road=1)}</Waypoint></Route>'
    )

    def at(path_s: float, lane: int, extra: str = "", extra_after: str = "") -> str:
        return (
            f"<Position><RoutePosition><RouteRef>{route}</RouteRef>{extra}<InRoutePosition>"
            f'<FromLaneCoordinates pathS="{path_s}" laneId="{lane}" laneOffset="0.3"/></InRoutePosition>'
            f"{extra_after}</RoutePosition></Position>"
        )

    placed = at(300.0, -1, "" if after else orientation, orientation if after else "")
    init = (
        gen.private("Ego", gen.teleport(at(100.0, 1)), gen.speed_to(10.0))
        + gen.private("Target", gen.teleport(placed), gen.speed_to(8.0))
        + gen.private(
            "Near",
            gen.teleport('<Position><RelativeObjectPosition entityRef="Target" dx="12" dy="2"/></Position>'),
        )
    )
    return openscenario(
        entities="".join(scenario_object(n) for n in ("Ego", "Target", "Near")),
        init=init,
        stories=story(act(event("E", gen.speed_to(12.0), sim_time("greaterThan", 1.0)))),
        stop=sim_time("greaterThan", 4.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.RURAL.path}"/></RoadNetwork>',
    )


ROUTE_CASES = {
    "relative_before": ('<Orientation type="relative" h="0.4"/>', False),
    "relative_after": ('<Orientation type="relative" h="3.14159"/>', True),
    "none": ("", False),
}


@pytest.mark.parametrize("case", sorted(ROUTE_CASES))
def test_route_position_faces_the_lane_and_turns_by_an_orientation_before_in_route_position(
    tmp_path: Path, case: str
) -> None:
    orientation, after = ROUTE_CASES[case]
    path = write_scenario(tmp_path, _route_scenario(orientation, after))
    engine = _engine(path)
    target, near = engine.bodies["Target"], engine.bodies["Near"]
    assert engine.road is not None
    lane_heading = engine.road.lane_to_world("1", -1, target.s).heading  # lane -1 drives toward +s
    turn = 0.4 if case == "relative_before" else 0.0
    assert _angle(target.heading, lane_heading + turn) < 1e-6
    # what is placed relative to it lands ahead of it, on its left
    ahead = (near.x - target.x) * math.cos(target.heading) + (near.y - target.y) * math.sin(target.heading)
    assert ahead == pytest.approx(12.0, abs=1e-6)
    if after:
        assert any("Orientation after InRoutePosition" in w for w in load_scenario(path).warnings)


@pytest.mark.parametrize("case", sorted(ROUTE_CASES))
def test_route_position_orientation_agrees_with_esmini(tmp_path: Path, case: str) -> None:
    orientation, after = ROUTE_CASES[case]
    _agrees_with_esmini(write_scenario(tmp_path, _route_scenario(orientation, after)))


# --- SynchronizeAction of an entity on a trajectory ----------------------------------------------------------


def _crossing_scenario(master_speed: float) -> str:
    # Walker crosses the motorway on a straight trajectory (its road s never changes); it synchronises with
    # Ego, which drives (or reverses) to its own target: Walker's distance is measured along its trajectory
    forward = master_speed > 0
    ego_s, master_s = (40.0, 140.0) if forward else (160.0, 90.0)
    trajectory = (
        '<Trajectory name="Cross" closed="false"><Shape><Polyline>'
        '<Vertex><Position><WorldPosition x="200" y="-16" h="1.5708"/></Position></Vertex>'
        '<Vertex><Position><WorldPosition x="200" y="6" h="1.5708"/></Position></Vertex>'
        "</Polyline></Shape></Trajectory>"
    )
    follow = (
        "<PrivateAction><RoutingAction><FollowTrajectoryAction><TrajectoryRef>"
        f"{trajectory}</TrajectoryRef><TimeReference><None/></TimeReference>"
        '<TrajectoryFollowingMode followingMode="position"/></FollowTrajectoryAction></RoutingAction>'
        "</PrivateAction>"
    )
    init = gen.private(
        "Ego", gen.teleport(gen.lane_position(ego_s, -2)), gen.speed_to(master_speed)
    ) + gen.private(
        "Walker", gen.teleport('<Position><WorldPosition x="200" y="-16" h="1.5708"/></Position>'), follow
    )
    sync = f"""<PrivateAction><SynchronizeAction masterEntityRef="Ego">
      <TargetPositionMaster><LanePosition roadId="1" laneId="-2" s="{master_s}" offset="0"/>
      </TargetPositionMaster><TargetPosition><WorldPosition x="200" y="-5.25"/></TargetPosition>
      <FinalSpeed><AbsoluteSpeed value="2.0"/></FinalSpeed></SynchronizeAction></PrivateAction>"""
    return openscenario(
        entities="".join(scenario_object(n) for n in ("Ego", "Walker")),
        init=init,
        stories=story(act(event("Sync", sync, sim_time("greaterThan", 0.0)), actor="Walker")),
        stop=sim_time("greaterThan", 12.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


@pytest.mark.parametrize("master_speed", [12.0, -8.0])
def test_synchronize_measures_an_entity_on_a_trajectory_along_it(tmp_path: Path, master_speed: float) -> None:
    engine = _engine(write_scenario(tmp_path, _crossing_scenario(master_speed)))
    ego, walker = engine.bodies["Ego"], engine.bodies["Walker"]
    master_x = 140.0 if master_speed > 0 else 90.0
    arrival = abs(ego.x - master_x) / abs(master_speed)
    while engine.time < arrival - 1e-9:
        engine.advance()
    # the walker is at its target (y = -5.25, 10.75 m along its trajectory) when Ego is at its own
    assert walker.y == pytest.approx(-5.25, abs=0.3)
    assert walker.speed == pytest.approx(2.0, abs=0.3)


@pytest.mark.parametrize("master_speed", [12.0, -8.0])
def test_synchronize_on_a_trajectory_agrees_with_esmini(tmp_path: Path, master_speed: float) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _crossing_scenario(master_speed)))


# --- RelativeDistanceCondition, lateral, in the entity's coordinates ---------------------------------------


def _lateral_scenario() -> str:
    # A1, 25 m ahead of Ego, changes from lane -1 into Ego's lane -2; the scenario ends 1 s after A1's
    # lateral distance to Ego falls below 0.5 m: measured across A1's own heading (which turns during the
    # lane change), not across the road, as esmini measures it
    change = gen.lateral(
        '<LaneChangeAction><LaneChangeActionDynamics dynamicsShape="sinusoidal" value="4"'
        ' dynamicsDimension="time"/><LaneChangeTarget><AbsoluteTargetLane value="-2"/></LaneChangeTarget>'
        "</LaneChangeAction>"
    )
    near = gen.by_entity(
        "A1",
        '<RelativeDistanceCondition entityRef="Ego" freespace="false" relativeDistanceType="lateral"'
        ' value="0.5" rule="lessThan" coordinateSystem="entity"/>',
        name="near",
        delay=1.0,
    )
    init = gen.private("Ego", gen.teleport(gen.lane_position(50.0, -2)), gen.speed_to(20.0)) + gen.private(
        "A1", gen.teleport(gen.lane_position(75.0, -1)), gen.speed_to(20.0)
    )
    return openscenario(
        entities="".join(scenario_object(n) for n in ("Ego", "A1")),
        init=init,
        stories=story(act(event("LC", change, sim_time("greaterThan", 1.0)), actor="A1")),
        stop=near + "</ConditionGroup><ConditionGroup>" + sim_time("greaterThan", 20.0, name="cap"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


def test_lateral_relative_distance_is_across_the_entitys_own_heading(tmp_path: Path) -> None:
    engine = _engine(write_scenario(tmp_path, _lateral_scenario()))
    ego, a1 = engine.bodies["Ego"], engine.bodies["A1"]
    first_own = first_road = None
    while not engine.ended and engine.time < 20.0:
        engine.advance()
        c, s = math.cos(a1.heading), math.sin(a1.heading)
        own = -s * (ego.x - a1.x) + c * (ego.y - a1.y)
        if first_own is None and abs(own) < 0.5:
            first_own = engine.time
        if first_road is None and abs(ego.y - a1.y) < 0.5:  # the motorway runs along x
            first_road = engine.time
    assert first_own is not None and first_road is not None
    assert first_own - first_road > 0.2  # the two measures part here
    assert engine.ended
    assert engine.time == pytest.approx(first_own + 1.0, abs=0.051)


def test_lateral_relative_distance_agrees_with_esmini(tmp_path: Path) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _lateral_scenario()))


# --- NURBS control-point times ----------------------------------------------------------------------------


def _nurbs_scenario() -> str:
    # a timed NURBS over the motorway's lanes, past its end (5 s) the entity drives on at the speed it had
    points = [
        (100.0, -5.25, 0.0),
        (115.0, -2.0, 1.25),
        (130.0, -8.0, 2.5),
        (160.0, -5.25, 3.75),
        (200.0, -8.75, 5.0),
    ]
    control = "".join(
        f'<ControlPoint time="{t}" weight="1"><Position><WorldPosition x="{x}" y="{y}" h="0"/></Position>'
        "</ControlPoint>"
        for x, y, t in points
    )
    knots = "".join(f'<Knot value="{k}"/>' for k in (0, 0, 0, 1, 2, 3, 3, 3))
    follow = (
        "<PrivateAction><RoutingAction><FollowTrajectoryAction><TrajectoryRef>"
        f'<Trajectory name="n" closed="false"><Shape><Nurbs order="3">{control}{knots}</Nurbs></Shape>'
        "</Trajectory></TrajectoryRef>"
        '<TimeReference><Timing domainAbsoluteRelative="absolute" scale="1" offset="0"/></TimeReference>'
        '<TrajectoryFollowingMode followingMode="position"/></FollowTrajectoryAction></RoutingAction>'
        "</PrivateAction>"
    )
    return openscenario(
        entities=scenario_object("Ego"),
        init=gen.private("Ego", gen.teleport(gen.lane_position(100.0, -2)), gen.speed_to(20.0)),
        stories=story(act(event("Fly", follow, sim_time("greaterThan", 0.0)))),
        stop=sim_time("greaterThan", 10.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


def test_nurbs_control_point_times_agree_with_esmini(tmp_path: Path) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _nurbs_scenario()))


# --- AddEntityAction on an entity already in the world ------------------------------------------------------


def _add_active_scenario() -> str:
    # Target is placed in Init and never deleted: the AddEntityAction at 1 s leaves it where it is (esmini
    # skips the action for an active entity)
    add = gen._global_event(
        "Add",
        f'<EntityAction entityRef="Target"><AddEntityAction>{gen.lane_position(400.0, -3)}'
        "</AddEntityAction></EntityAction>",
        gen.at(1.0),
    )
    init = gen.private("Ego", gen.teleport(gen.lane_position(50.0, -2)), gen.speed_to(20.0)) + gen.private(
        "Target", gen.teleport(gen.lane_position(80.0, -1)), gen.speed_to(15.0)
    )
    return openscenario(
        entities="".join(scenario_object(n) for n in ("Ego", "Target")),
        init=init,
        stories=story(act(add)),
        stop=sim_time("greaterThan", 4.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


def test_add_entity_on_an_entity_in_the_world_is_skipped(tmp_path: Path) -> None:
    engine = _engine(write_scenario(tmp_path, _add_active_scenario()))
    while engine.time < 2.0 - 1e-9:
        engine.advance()
    target = engine.bodies["Target"]
    assert target.x == pytest.approx(80.0 + 15.0 * 2.0, abs=1e-6)  # on at its speed, not teleported to 400
    assert any("AddEntityAction: Target is already in the world" in line for line in engine.log)


def test_add_entity_on_an_entity_in_the_world_agrees_with_esmini(tmp_path: Path) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _add_active_scenario()))


# --- LanePosition past the end of a road with no link there -------------------------------------------------


def _past_the_end_scenario(s: float) -> str:
    init = gen.private("Ego", gen.teleport(gen.lane_position(s, -2)), gen.speed_to(20.0))
    return openscenario(
        entities=scenario_object("Ego"),
        init=init,
        stop=sim_time("greaterThan", 3.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


@pytest.mark.parametrize("s", [-30.0, 2100.0])
def test_lane_position_past_a_road_end_runs_placed_at_the_end(tmp_path: Path, s: float) -> None:
    # the motorway (2,000 m) has no links: the entity is placed at the end it is past, with a warning, and
    # the run goes on (esmini runs such files; they are not bad input)
    path = write_scenario(tmp_path, _past_the_end_scenario(s))
    result, trace = conformance.run_scenario(path, 10.0)
    assert result.status == "ended", result.message
    assert any("lies beyond the road's end" in w for w in result.warnings)
    engine = _engine(path)
    assert engine.road is not None
    end = engine.road.lane_to_world("1", -2, 0.0 if s < 0 else 2000.0, 0.0)
    (_, x0, y0) = trace.tracks["Ego"][0]
    assert (x0, y0) == (pytest.approx(end.x, abs=1e-6), pytest.approx(end.y, abs=1e-6))


@pytest.mark.parametrize("s", [-30.0, 2100.0])
def test_lane_position_past_a_road_end_agrees_with_esmini(tmp_path: Path, s: float) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _past_the_end_scenario(s)))


# --- ReachPositionCondition with an Orientation: heading within 0.05 rad -----------------------------------


def _reach_scenario(h: float) -> str:
    # Ego drives along the motorway (heading 0) through s=150; the position carries an absolute Orientation:
    # reached within 0.05 rad of it, headings compared in [0, 2π) (so -0.02 rad, i.e. 6.26, is not reached)
    init = gen.private("Ego", gen.teleport(gen.lane_position(50.0, -2)), gen.speed_to(20.0))
    reach = gen.by_entity(
        "Ego",
        '<ReachPositionCondition tolerance="5"><Position><LanePosition roadId="1" laneId="-2" s="150"'
        f' offset="0"><Orientation type="absolute" h="{h}"/></LanePosition></Position>'
        "</ReachPositionCondition>",
        name="reach",
        delay=0.5,
    )
    return openscenario(
        entities=scenario_object("Ego"),
        init=init,
        stop=reach + "</ConditionGroup><ConditionGroup>" + sim_time("greaterThan", 9.0, name="cap"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


REACH_CASES = {0.0: True, 0.049: True, 0.051: False, -0.02: False}


@pytest.mark.parametrize("h", sorted(REACH_CASES))
def test_reach_position_with_an_orientation_wants_the_heading_within_005_rad(
    tmp_path: Path, h: float
) -> None:
    engine = _engine(write_scenario(tmp_path, _reach_scenario(h)))
    while not engine.ended and engine.time < 10.0:
        engine.advance()
    # 100 m at 20 m/s: within 5 m of the position from 4.8 s on, the stop 0.5 s later; else the 9 s cap
    expected = 5.3 if REACH_CASES[h] else 9.05
    assert engine.time == pytest.approx(expected, abs=0.051)


@pytest.mark.parametrize("h", sorted(REACH_CASES))
def test_reach_position_with_an_orientation_agrees_with_esmini(tmp_path: Path, h: float) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _reach_scenario(h)))


# --- RelativeLanePosition: ds along the road's s ------------------------------------------------------------


def _relative_lane_scenario(ds: float, d_lane: int, lane: int, attribute: str = "ds") -> str:
    # Ego in lane `lane` of the two-way rural road (lane 1 travels toward decreasing s); T placed relative
    # to it: ds along the road's s, dLane and offset across the road's direction, facing the road's s;
    # dsLane along Ego's lane in its travel direction, facing the driving direction of the lane T lands in
    relative = (
        f'<Position><RelativeLanePosition entityRef="Ego" dLane="{d_lane}" {attribute}="{ds}" offset="0.2"/>'
        "</Position>"
    )
    init = gen.private("Ego", gen.teleport(gen.lane_position(500.0, lane)), gen.speed_to(10.0)) + gen.private(
        "T", gen.teleport(relative), gen.speed_to(5.0)
    )
    return openscenario(
        entities="".join(scenario_object(n) for n in ("Ego", "T")),
        init=init,
        stop=sim_time("greaterThan", 2.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.RURAL.path}"/></RoadNetwork>',
    )


RELATIVE_LANE_CASES = [(20.0, 0, 1), (20.0, -1, 1), (-30.0, 1, 1), (-15.0, 1, -1)]


@pytest.mark.parametrize(("ds", "d_lane", "lane"), RELATIVE_LANE_CASES)
def test_relative_lane_position_ds_is_along_the_roads_s(
    tmp_path: Path, ds: float, d_lane: int, lane: int
) -> None:
    engine = _engine(write_scenario(tmp_path, _relative_lane_scenario(ds, d_lane, lane)))
    assert engine.road is not None
    target = engine.bodies["T"]
    expected_lane = lane + d_lane
    if expected_lane == 0 or (lane > 0) != (expected_lane > 0):
        expected_lane += 1 if d_lane > 0 else -1  # there is no lane 0
    pose = engine.road.lane_to_world("1", expected_lane, 500.0 + ds, 0.2)
    assert (target.x, target.y) == (pytest.approx(pose.x, abs=1e-6), pytest.approx(pose.y, abs=1e-6))
    assert _angle(target.heading, pose.heading) < 1e-6


def test_relative_lane_position_ds_lane_is_along_the_lane_facing_the_lane_landed_in(tmp_path: Path) -> None:
    # Ego in lane -1 (toward +s): dsLane -15 is 15 m behind it; dLane 1 lands in lane 1, which drives toward -s
    engine = _engine(write_scenario(tmp_path, _relative_lane_scenario(-15.0, 1, -1, "dsLane")))
    assert engine.road is not None
    target = engine.bodies["T"]
    pose = engine.road.lane_to_world("1", 1, 485.0, 0.2)
    assert (target.x, target.y) == (pytest.approx(pose.x, abs=1e-6), pytest.approx(pose.y, abs=1e-6))
    assert _angle(target.heading, pose.heading + math.pi) < 1e-6


@pytest.mark.parametrize("attribute", ["ds", "dsLane"])
@pytest.mark.parametrize(("ds", "d_lane", "lane"), RELATIVE_LANE_CASES)
def test_relative_lane_position_agrees_with_esmini(
    tmp_path: Path, ds: float, d_lane: int, lane: int, attribute: str
) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _relative_lane_scenario(ds, d_lane, lane, attribute)))


# --- EndOfRoadCondition: the step that reaches the end counts ---------------------------------------------


def _end_of_road_scenario(duration: float, s: float) -> str:
    # the motorway (2,000 m) ends with no link: Ego at 20 m/s from s reaches its end at (2000 - s) / 20 s
    end = gen.by_entity("Ego", f'<EndOfRoadCondition duration="{duration}"/>', name="end", edge="none")
    return openscenario(
        entities=scenario_object("Ego"),
        init=gen.private("Ego", gen.teleport(gen.lane_position(s, -2)), gen.speed_to(20.0)),
        stop=end + "</ConditionGroup><ConditionGroup>" + sim_time("greaterThan", 15.0, name="cap"),
        road=f'<RoadNetwork><LogicFile filepath="{gen.HIGHWAY.path}"/></RoadNetwork>',
    )


END_OF_ROAD_CASES = [(0.0, 1950.0), (1.0, 1950.0), (0.0, 1953.3)]


@pytest.mark.parametrize(("duration", "s"), END_OF_ROAD_CASES)
def test_end_of_road_holds_from_the_step_that_reaches_the_end(
    tmp_path: Path, duration: float, s: float
) -> None:
    engine = _engine(write_scenario(tmp_path, _end_of_road_scenario(duration, s)))
    while not engine.ended and engine.time < 15.0:
        engine.advance()
    reached = math.ceil((2000.0 - s) / 20.0 / 0.05 - 1e-6) * 0.05  # the first step at the end
    assert engine.time == pytest.approx(reached + duration, abs=1e-6)
    if duration > 0:
        assert engine.bodies["Ego"].speed == 0.0  # stopped there (two steps after it got there)


@pytest.mark.parametrize(("duration", "s"), END_OF_ROAD_CASES)
def test_end_of_road_agrees_with_esmini(tmp_path: Path, duration: float, s: float) -> None:
    _agrees_with_esmini(write_scenario(tmp_path, _end_of_road_scenario(duration, s)))
