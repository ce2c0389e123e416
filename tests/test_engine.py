"""The scenario engine on the example highway: transition shapes, lane changes, storyboard semantics.

Entities here are moved by the scenario alone (no SUMO), so every number is exact."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from simcore.errors import BadInput
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests.xosc_fixtures import (
    HIGHWAY,
    act,
    event,
    openscenario,
    place,
    road_network,
    scenario_object,
    sim_time,
    speed_action,
    story,
    vehicle,
    write_scenario,
)

CAR = vehicle()
TARGET = (
    '<ParameterDeclarations><ParameterDeclaration name="Target" parameterType="double" value="10"/>'
    "</ParameterDeclarations>"
)


def scenario(
    tmp_path: Path,
    events: str,
    *,
    stop: str = "",
    entities: tuple[str, ...] = ("Ego",),
    init: str = "",
    actor: str = "Ego",
    lead_events: str = "",
    controllers: dict[str, str] | None = None,
    more_entities: str = "",
    minor: int = 2,
    road_file: Path = HIGHWAY,
) -> Path:
    """A scenario on the highway (or `road_file`) declaring the parameter Target: cars named `entities`
    (with `controllers` by name) then `more_entities`; `init` (default: Ego at s = 100 m, 20 m/s); `events`
    in one maneuver of `actor`, and `lead_events` in one of the Lead in an act of its own; the stop
    trigger's conditions `stop`."""
    controllers = controllers or {}
    acts = act(events, actor=actor)
    if lead_events:
        acts += act(lead_events, actor="Lead", name="B", group="L", maneuver="LM")
    text = openscenario(
        minor=minor,
        parameters=TARGET,
        road=road_network(road_file),
        entities="".join(scenario_object(n, CAR, controllers.get(n, "")) for n in entities) + more_entities,
        init=init or place("Ego", 100.0),
        stories=story(acts),
        stop=stop,
    )
    return write_scenario(tmp_path, text)


@pytest.fixture(scope="module")
def road() -> OpenDrive:
    return OpenDrive.from_file(HIGHWAY)


def run(
    path: Path, road: OpenDrive, seconds: float, overrides: dict[str, float] | None = None
) -> tuple[ScenarioEngine, dict[float, dict[str, float]]]:
    engine = ScenarioEngine(load_scenario(path, overrides or {}), road=road, sumo=None, step_seconds=0.05)
    trace = {}
    while engine.time < seconds - 1e-9 and not engine.ended:
        frame = engine.step()
        ego = frame.entity("Ego")
        trace[round(frame.time, 2)] = {
            "speed": ego.speed,
            "x": ego.x,
            "y": ego.y,
            "lane": ego.lane.lane_id if ego.lane else 0,
            "offset": ego.lane.offset if ego.lane else 0.0,
            "s": ego.lane.s if ego.lane else 0.0,
        }
    return engine, trace


@pytest.mark.parametrize(
    ("shape", "dimension", "value", "checks"),
    [
        ("linear", "time", 4.0, {1.05: 20 - 10 * 1 / 4, 2.05: 15.0, 4.05: 10.0, 6.0: 10.0}),
        ("cubic", "time", 4.0, {1.05: 20 - 10 * (3 * 0.25**2 - 2 * 0.25**3), 4.05: 10.0}),
        ("sinusoidal", "time", 4.0, {2.05: 15.0, 1.05: 20 - 10 * (0.5 - 0.5 * math.cos(math.pi / 4))}),
        ("linear", "rate", 2.5, {2.05: 15.0, 4.05: 10.0}),  # 10 m/s at 2.5 m/s² takes 4 s
        ("step", "time", 0.0, {0.1: 10.0}),
    ],
)
def test_speed_action_shapes(
    tmp_path: Path, road: OpenDrive, shape: str, dimension: str, value: float, checks: dict[float, float]
) -> None:
    # the event starts at t = 0.05 (its trigger is evaluated at the start of the step from 0.05): speeds are
    # checked at times shifted by that step
    path = scenario(
        tmp_path, event("Slow", speed_action(shape, dimension, value, 10.0), sim_time("greaterThan", 0.0))
    )
    _, trace = run(path, road, 6.0)
    for t, expected in checks.items():
        assert trace[t]["speed"] == pytest.approx(expected, abs=1e-6), f"t={t}"


def test_speed_over_distance_and_parameter_override(tmp_path: Path, road: OpenDrive) -> None:
    action = speed_action("linear", "distance", 50.0, 10.0).replace('value="10.0"', 'value="$Target"')
    path = scenario(tmp_path, event("Slow", action, sim_time("greaterThan", 0.0)))
    _, trace = run(path, road, 8.0, {"Target": 0.0})
    assert trace[8.0]["speed"] == pytest.approx(0.0)
    # from 20 to 0 within 50 m (the transition starts with the step from t = 0.05; Euler steps: ±1 m)
    travelled = trace[8.0]["s"] - trace[0.05]["s"]
    assert travelled == pytest.approx(50.0, abs=1.0)


def test_lane_change_moves_to_the_target_lane_centre(tmp_path: Path, road: OpenDrive) -> None:
    change = """<PrivateAction><LateralAction><LaneChangeAction>
      <LaneChangeActionDynamics dynamicsShape="sinusoidal" dynamicsDimension="time" value="3"/>
      <LaneChangeTarget><RelativeTargetLane entityRef="Ego" value="1"/></LaneChangeTarget></LaneChangeAction></LateralAction></PrivateAction>"""
    path = scenario(tmp_path, event("Change", change, sim_time("greaterThan", 1.0)))
    engine, trace = run(path, road, 6.0)
    assert trace[1.0]["lane"] == -2
    assert trace[6.0]["lane"] == -1  # one lane to the left of -2 when driving toward +s
    assert trace[6.0]["offset"] == pytest.approx(0.0, abs=1e-9)
    # halfway through a sinusoidal change the vehicle is on the lane border: 1.75 m from either centre
    mid = trace[2.55]
    assert abs(mid["offset"]) == pytest.approx(1.75, abs=0.1)
    centre = road.lane_to_world("1", -1, trace[6.0]["s"])
    assert (trace[6.0]["x"], trace[6.0]["y"]) == pytest.approx((centre.x, centre.y), abs=1e-6)
    assert any("Change: endTransition" in line for line in engine.log)


def test_event_repeats_up_to_its_maximum_execution_count(tmp_path: Path, road: OpenDrive) -> None:
    bump = """<PrivateAction><LongitudinalAction><SpeedAction>
      <SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
      <SpeedActionTarget><RelativeTargetSpeed entityRef="Ego" value="1" speedTargetValueType="delta" continuous="false"/></SpeedActionTarget>
      </SpeedAction></LongitudinalAction></PrivateAction>"""
    path = scenario(tmp_path, event("Bump", bump, sim_time("greaterThan", 1.0), count=3))
    engine, trace = run(path, road, 3.0)
    assert trace[3.0]["speed"] == pytest.approx(23.0)
    assert sum("event Bump: startTransition" in line for line in engine.log) == 3


def test_state_condition_chains_events_and_stop_trigger_delay(tmp_path: Path, road: OpenDrive) -> None:
    first = event("First", speed_action("linear", "time", 1.0, 15.0), sim_time("greaterThan", 1.0))
    after_first = """<Condition name="c" delay="0" conditionEdge="none"><ByValueCondition>
      <StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="First" state="endTransition"/>
      </ByValueCondition></Condition>"""
    second = event("Second", speed_action("step", "time", 0, 5.0), after_first)
    path = scenario(tmp_path, first + second, stop=sim_time("greaterThan", 3.0, edge="rising", delay=1.0))
    engine, trace = run(path, road, 20.0)
    assert engine.ended_by == "stopTrigger"
    assert engine.time == pytest.approx(4.05 + 0.05, abs=0.051)  # condition true at 3.05, +1 s delay
    starts = {
        line.split()[2].rstrip(":"): float(line.split()[0])
        for line in engine.log
        if "startTransition" in line and "event" in line
    }
    assert starts["Second"] - starts["First"] == pytest.approx(1.0 + 0.05, abs=0.051)
    assert trace[round(engine.time, 2)]["speed"] == pytest.approx(5.0)


def test_override_priority_stops_the_running_event(tmp_path: Path, road: OpenDrive) -> None:
    slow = event("Slow", speed_action("linear", "time", 10.0, 0.0), sim_time("greaterThan", 0.0))
    fast = event(
        "Fast", speed_action("step", "time", 0, 30.0), sim_time("greaterThan", 2.0), priority="override"
    )
    engine, trace = run(scenario(tmp_path, slow + fast), road, 4.0)
    assert any("event Slow: stopTransition" in line for line in engine.log)
    assert trace[4.0]["speed"] == pytest.approx(30.0)


def test_relative_distance_trigger_with_two_entities(tmp_path: Path, road: OpenDrive) -> None:
    init = place("Ego", 100.0, speed=30.0) + place("Lead", 200.0, speed=20.0)
    close = """<Condition name="near" delay="0" conditionEdge="rising"><ByEntityCondition>
      <TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="Ego"/></TriggeringEntities>
      <EntityCondition><RelativeDistanceCondition entityRef="Lead" relativeDistanceType="longitudinal" freespace="true"
        value="20" rule="lessThan"/></EntityCondition></ByEntityCondition></Condition>"""
    path = scenario(
        tmp_path,
        event("Match", speed_action("step", "time", 0, 20.0), close),
        entities=("Ego", "Lead"),
        init=init,
    )
    engine, trace = run(path, road, 12.0)
    start = next(float(line.split()[0]) for line in engine.log if "event Match: startTransition" in line)
    # free space 100 - 4.5 = 95.5 m closing at 10 m/s → below 20 m after 7.55 s
    assert start == pytest.approx(7.6, abs=0.1)
    assert trace[12.0]["speed"] == pytest.approx(20.0)


def test_unknown_parameter_override_is_bad_input(tmp_path: Path) -> None:
    path = scenario(
        tmp_path, event("Slow", speed_action("step", "time", 0, 1.0), sim_time("greaterThan", 0.0))
    )
    with pytest.raises(BadInput, match="Targt not declared"):
        load_scenario(path, {"Targt": 1.0})


def test_unsupported_action_names_the_element(tmp_path: Path) -> None:
    path = scenario(
        tmp_path,
        event(
            "X",
            "<PrivateAction><RoutingAction><Fly/></RoutingAction></PrivateAction>",
            sim_time("greaterThan", 0.0),
        ),
    )
    with pytest.raises(BadInput, match="RoutingAction/Fly is not supported") as info:
        load_scenario(path)
    assert "Maneuver[M]/Event[X]" in str(info.value)


def test_hostile_xml_is_refused(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.xosc"
    bomb.write_text(
        '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]><OpenSCENARIO>&b;</OpenSCENARIO>'
    )
    with pytest.raises(BadInput, match="forbidden XML"):
        load_scenario(bomb)
    broken = tmp_path / "broken.xosc"
    broken.write_text("<OpenSCENARIO><Storyboard></OpenSCENARIO>")
    with pytest.raises(BadInput, match="not well-formed"):
        load_scenario(broken)


def test_speed_transition_is_stretched_to_the_vehicle_performance(tmp_path: Path, road: OpenDrive) -> None:
    # 20 → 40 m/s linearly in 1 s would need 20 m/s²; maxAcceleration is 5: it takes 4 s instead
    path = scenario(
        tmp_path, event("Go", speed_action("linear", "time", 1.0, 40.0), sim_time("greaterThan", 0.0))
    )
    _, trace = run(path, road, 6.0)
    assert trace[2.05]["speed"] == pytest.approx(30.0, abs=1e-6)
    assert trace[4.05]["speed"] == pytest.approx(40.0, abs=1e-6)


def test_rising_edge_needs_a_change(tmp_path: Path, road: OpenDrive) -> None:
    # true from the first evaluation: no rising edge, the event never starts
    path = scenario(
        tmp_path,
        event("Slow", speed_action("step", "time", 0, 5.0), sim_time("greaterOrEqual", 0.0, "rising")),
    )
    _, trace = run(path, road, 2.0)
    assert trace[2.0]["speed"] == pytest.approx(20.0)
    # false first, then true: it fires
    path = scenario(
        tmp_path, event("Slow", speed_action("step", "time", 0, 5.0), sim_time("greaterThan", 1.0, "rising"))
    )
    _, trace = run(path, road, 2.0)
    assert trace[2.0]["speed"] == pytest.approx(5.0)


def test_unsupported_lights_warn_with_file_and_line(tmp_path: Path, road: OpenDrive) -> None:
    light = """<PrivateAction><AppearanceAction><LightStateAction transitionTime="0">
      <LightType><VehicleLight vehicleLightType="brakeLights"/></LightType><LightState mode="on"/>
    </LightStateAction></AppearanceAction></PrivateAction>"""
    path = scenario(tmp_path, event("Lights", light, sim_time("greaterThan", 0.0)))
    loaded = load_scenario(path)
    assert len(loaded.warnings) == 1
    warning = loaded.warnings[0]
    assert str(path) in warning and "Event[Lights]" in warning and "LightStateAction" in warning
    line = int(warning.split(str(path) + ":", 1)[1].split(":", 1)[0])
    assert "<AppearanceAction>" in path.read_text().splitlines()[line - 1]
    _, trace = run(path, road, 1.0)  # and the run goes on
    assert trace[1.0]["speed"] == pytest.approx(20.0)


def test_follow_trajectory_polyline_with_times(tmp_path: Path, road: OpenDrive) -> None:
    trajectory = """<PrivateAction><RoutingAction><FollowTrajectoryAction>
      <TrajectoryRef><Trajectory name="T" closed="false"><Shape><Polyline>
        <Vertex time="0"><Position><RelativeLanePosition entityRef="Ego" dLane="0" ds="0" offset="0"/></Position></Vertex>
        <Vertex time="2"><Position><RelativeLanePosition entityRef="Ego" dLane="0" ds="20" offset="0"/></Position></Vertex>
      </Polyline></Shape></Trajectory></TrajectoryRef>
      <TimeReference><Timing domainAbsoluteRelative="relative" scale="1" offset="0"/></TimeReference>
      <TrajectoryFollowingMode followingMode="position"/>
    </FollowTrajectoryAction></RoutingAction></PrivateAction>"""
    path = scenario(tmp_path, event("Traj", trajectory, sim_time("greaterThan", 0.0)))
    _, trace = run(path, road, 3.0)
    start_s = trace[0.05]["s"]
    assert trace[1.05]["s"] == pytest.approx(start_s + 10.0, abs=0.05)  # 20 m in 2 s at a constant 10 m/s
    assert trace[1.05]["speed"] == pytest.approx(10.0, abs=1e-6)
    assert trace[2.05]["s"] == pytest.approx(start_s + 20.0, abs=0.05)


def speed_profile(mode: str, entries: list[tuple[float, float]], constraints: str = "") -> str:
    points = "".join(f'<SpeedProfileEntry time="{t}" speed="{v}"/>' for t, v in entries)
    return f"""<PrivateAction><LongitudinalAction><SpeedProfileAction followingMode="{mode}">{constraints}{points}
      </SpeedProfileAction></LongitudinalAction></PrivateAction>"""


JERKY = '<DynamicConstraints maxAcceleration="5" maxDeceleration="10" maxAccelerationRate="4" maxDecelerationRate="3" maxSpeed="50"/>'


def accelerations(trace: dict[float, dict[str, float]]) -> list[float]:
    times = sorted(trace)
    return [(trace[b]["speed"] - trace[a]["speed"]) / (b - a) for a, b in itertools.pairwise(times)]


def test_speed_profile_position_mode_is_straight_lines(tmp_path: Path, road: OpenDrive) -> None:
    action = speed_profile("position", [(4.0, 10.0), (2.0, 4.0)], JERKY)
    path = scenario(
        tmp_path, event("P", action, sim_time("greaterThan", 0.0)), init=place("Ego", 100.0, speed=0.0)
    )
    _, trace = run(path, road, 8.0)
    assert trace[2.05]["speed"] == pytest.approx(5.0, abs=1e-6)
    assert trace[4.05]["speed"] == pytest.approx(10.0, abs=1e-6)
    assert trace[5.05]["speed"] == pytest.approx(7.0, abs=1e-6)
    assert trace[7.0]["speed"] == pytest.approx(4.0, abs=1e-6)


def test_speed_profile_follow_mode_limits_jerk_and_reaches_a_single_target_on_time(
    tmp_path: Path, road: OpenDrive
) -> None:
    action = speed_profile("follow", [(4.0, 10.0)], JERKY)
    path = scenario(
        tmp_path, event("P", action, sim_time("greaterThan", 0.0)), init=place("Ego", 100.0, speed=0.0)
    )
    _, trace = run(path, road, 6.0)
    assert trace[4.05]["speed"] == pytest.approx(10.0, abs=1e-6)  # on time despite the rounded corners
    acc = accelerations(trace)
    assert max(acc) <= 5.0 + 1e-6
    jerks = [(b - a) / 0.05 for a, b in itertools.pairwise(acc)]
    assert max(jerks) <= 4.0 + 1e-6 and min(jerks) >= -3.0 - 1e-6
    assert trace[1.05]["speed"] < 4.0 * 1.0**2 / 2 + 1e-6  # starts with jerk 4 from standstill: ≤ ½ j t²


def test_speed_profile_follow_mode_rounds_every_corner(tmp_path: Path, road: OpenDrive) -> None:
    action = speed_profile("follow", [(4.0, 10.0), (4.0, 4.0), (2.0, 8.0)], JERKY)
    path = scenario(
        tmp_path, event("P", action, sim_time("greaterThan", 0.0)), init=place("Ego", 100.0, speed=0.0)
    )
    _, trace = run(path, road, 14.0)
    acc = accelerations(trace)
    jerks = [(b - a) / 0.05 for a, b in itertools.pairwise(acc)]
    assert max(jerks) <= 4.0 + 1e-6 and min(jerks) >= -3.0 - 1e-6
    assert trace[13.0]["speed"] == pytest.approx(8.0, abs=1e-6)
    peak = max(v["speed"] for v in trace.values())
    assert 8.0 < peak < 10.0  # the corner at 10 m/s is cut


def distance_keeping(constraints: str, *, continuous: bool = True) -> str:
    return f"""<PrivateAction><LongitudinalAction>
      <LongitudinalDistanceAction entityRef="Lead" distance="20" freespace="false" continuous="{str(continuous).lower()}">
        {constraints}</LongitudinalDistanceAction></LongitudinalAction></PrivateAction>"""


def test_longitudinal_distance_with_constraints_is_a_damped_spring_within_the_limits(
    tmp_path: Path, road: OpenDrive
) -> None:
    constraints = '<DynamicConstraints maxAcceleration="3" maxDeceleration="3" maxAccelerationRate="1" maxDecelerationRate="1" maxSpeed="30"/>'
    path = scenario(
        tmp_path,
        event("Keep", distance_keeping(constraints), sim_time("greaterThan", 0.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=20.0) + place("Lead", 160.0, speed=10.0),
    )
    engine, trace = run(path, road, 40.0)
    acc = accelerations(trace)
    assert min(acc) >= -3.0 - 1e-6 and max(acc) <= 3.0 + 1e-6
    # the acceleration grows in magnitude no faster than the jerk limits (it may drop back at once)
    for a, b in itertools.pairwise(acc):
        if b >= 0 and b > a:
            assert b - a <= 1.0 * 0.05 + 1e-6
        if b < 0 and b < a:
            assert a - b <= 1.0 * 0.05 + 1e-6
    gap = engine.bodies["Lead"].s - engine.bodies["Ego"].s
    assert gap == pytest.approx(20.0, abs=0.2)
    assert trace[40.0]["speed"] == pytest.approx(10.0, abs=0.05)


def test_longitudinal_distance_without_constraints_is_kept_exactly(tmp_path: Path, road: OpenDrive) -> None:
    path = scenario(
        tmp_path,
        event("Keep", distance_keeping(""), sim_time("greaterThan", 0.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=20.0) + place("Lead", 160.0, speed=10.0),
    )
    engine, trace = run(path, road, 2.0)
    assert engine.bodies["Lead"].s - engine.bodies["Ego"].s == pytest.approx(20.0, abs=1e-6)
    assert trace[2.0]["speed"] == pytest.approx(10.0)


def test_an_entity_stuck_at_the_end_of_its_road_stops(tmp_path: Path, road: OpenDrive) -> None:
    # 2000 m road without successor: at 25 m/s from s=1990 the end is reached within the first step
    stop = """<Condition name="end" delay="0" conditionEdge="none"><ByEntityCondition>
      <TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="Ego"/></TriggeringEntities>
      <EntityCondition><EndOfRoadCondition duration="1.0"/></EntityCondition></ByEntityCondition></Condition>"""
    path = scenario(tmp_path, "", init=place("Ego", 1999.0, speed=25.0), stop=stop)
    engine, trace = run(path, road, 5.0)
    assert trace[0.05]["s"] == pytest.approx(2000.0) and trace[0.05]["speed"] == pytest.approx(25.0)
    assert trace[0.15]["speed"] == 0.0  # two steps later it has stopped
    # standing at the end keeps it at the end: the EndOfRoadCondition (1 s) ends the run
    assert engine.ended and engine.time == pytest.approx(1.05)


def test_continuous_relative_speed_in_init_follows_the_other_within_performance(
    tmp_path: Path, road: OpenDrive
) -> None:
    follow = """<Private entityRef="Ego"><PrivateAction><LongitudinalAction><SpeedAction>
      <SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
      <SpeedActionTarget><RelativeTargetSpeed entityRef="Lead" value="0" speedTargetValueType="delta" continuous="true"/>
      </SpeedActionTarget></SpeedAction></LongitudinalAction></PrivateAction></Private>"""
    lead = speed_action("step", "time", 0, 0.0)
    # the Lead stops at 1 s (its own maneuver group), Ego follows its speed down at its maxDeceleration (9)
    path = scenario(
        tmp_path,
        "",
        entities=("Lead", "Ego"),
        init=place("Lead", 500.0, speed=20.0) + place("Ego", 100.0, speed=0.0) + follow,
        lead_events=event("Stop", lead, sim_time("greaterOrEqual", 1.0)),
    )
    _, trace = run(path, road, 4.0)
    assert trace[0.5]["speed"] == pytest.approx(20.0)  # took the Lead's speed at once
    assert trace[1.5]["speed"] == pytest.approx(20.0 - 9.0 * 0.5, abs=1e-6)
    assert trace[4.0]["speed"] == pytest.approx(0.0, abs=1e-9)


def test_longitudinal_distance_limits_are_bounded_by_the_vehicle_performance(
    tmp_path: Path, road: OpenDrive
) -> None:
    # maxAcceleration 50 in the action, 5 in the vehicle: the spring pulls at most with 5 m/s²
    constraints = '<DynamicConstraints maxAcceleration="50" maxDeceleration="50" maxSpeed="60"/>'
    path = scenario(
        tmp_path,
        event("Keep", distance_keeping(constraints), sim_time("greaterThan", 0.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=20.0) + place("Lead", 300.0, speed=20.0),
    )
    _, trace = run(path, road, 3.0)
    acc = accelerations(trace)
    assert max(acc) == pytest.approx(5.0, abs=1e-6)


def test_a_teleported_entity_stays_where_it_was_put_for_that_step(tmp_path: Path, road: OpenDrive) -> None:
    jump = """<PrivateAction><TeleportAction><Position>
      <LanePosition roadId="1" laneId="-2" s="50" offset="0"/></Position></TeleportAction></PrivateAction>"""
    path = scenario(tmp_path, event("Jump", jump, sim_time("greaterOrEqual", 1.0)))
    _, trace = run(path, road, 1.2)
    assert trace[1.0]["s"] == pytest.approx(120.0)
    assert trace[1.05]["s"] == pytest.approx(50.0)  # teleported at the start of the step from 1.0: not moved
    assert trace[1.1]["s"] == pytest.approx(51.0)  # then on at 20 m/s


LANE_CHANGE = """<PrivateAction><LateralAction><LaneChangeAction>
  <LaneChangeActionDynamics dynamicsShape="sinusoidal" dynamicsDimension="time" value="3"/>
  <LaneChangeTarget><RelativeTargetLane entityRef="Ego" value="1"/></LaneChangeTarget></LaneChangeAction></LateralAction></PrivateAction>"""


def test_actions_step_in_storyboard_order_and_a_lane_change_moves_at_the_speed_it_sees(
    tmp_path: Path, road: OpenDrive
) -> None:
    # the speed action starts first (t > 0: 20 → 30 m/s in 2 s, +0.25 m/s a step), the lane change at t > 1.
    # A lane change stepped before the speed action (defined before it) moves the entity at the speed before
    # that step's change; stepped after it, at the new one.
    speed = event("Faster", speed_action("linear", "time", 2.0, 30.0), sim_time("greaterThan", 0.0))
    change = event("Change", LANE_CHANGE, sim_time("greaterThan", 1.0))
    progress = {}
    for first, events in (("change", change + speed), ("speed", speed + change)):
        path = scenario(tmp_path, events.replace('priority="override"', 'priority="parallel"'))
        _, trace = run(path, road, 2.5)
        progress[first] = trace[2.5]["s"] - trace[1.0]["s"]
    # 20 steps (from 1.05 to 2.0) at the previous step's speed: 20 × 0.25 × 0.05 m less
    assert progress["speed"] - progress["change"] == pytest.approx(20 * 0.25 * 0.05, abs=0.002)


def timed_polyline(mode: str, points: list[tuple[float, float]]) -> str:
    vertices = "".join(
        f"""<Vertex time="{t}"><Position><LanePosition roadId="1" laneId="-2" s="{s}" offset="0"/></Position></Vertex>"""
        for t, s in points
    )
    return f"""<PrivateAction><RoutingAction><FollowTrajectoryAction>
      <TrajectoryRef><Trajectory name="T" closed="false"><Shape><Polyline>{vertices}</Polyline></Shape></Trajectory></TrajectoryRef>
      <TimeReference><Timing domainAbsoluteRelative="relative" scale="1" offset="0"/></TimeReference>
      <TrajectoryFollowingMode followingMode="{mode}"/>
    </FollowTrajectoryAction></RoutingAction></PrivateAction>"""


def test_timed_polyline_speed_per_segment_in_position_mode_and_linear_in_follow_mode(
    tmp_path: Path, road: OpenDrive
) -> None:
    # 20 m in 2 s, then 5 m in 1 s: position mode runs each segment at its mean speed (10, then 5 m/s);
    # follow mode changes the speed linearly between vertices from the entity's speed at the start (as
    # esmini): 20 → 0 (a mean of 10) → 10 (a mean of 5)
    points = [(0.0, 100.0), (2.0, 120.0), (3.0, 125.0)]
    speeds = {}
    for mode in ("position", "follow"):
        path = scenario(tmp_path, event("Traj", timed_polyline(mode, points), sim_time("greaterThan", 0.0)))
        _, trace = run(path, road, 3.1)
        speeds[mode] = trace
    assert speeds["position"][2.55]["speed"] == pytest.approx(5.0, abs=1e-6)
    assert speeds["follow"][1.05]["speed"] == pytest.approx(10.0, abs=0.6)
    assert speeds["follow"][2.55]["speed"] == pytest.approx(5.0, abs=0.3)
    assert speeds["follow"][2.3]["speed"] == pytest.approx(2.5, abs=0.3)
    assert speeds["position"][2.3]["speed"] == pytest.approx(5.0, abs=1e-6)
    for trace in speeds.values():
        assert trace[3.05]["s"] == pytest.approx(125.0, abs=1e-6)  # started at 0.05


def test_an_event_waiting_for_a_trajectory_to_end_starts_at_the_next_step(
    tmp_path: Path, road: OpenDrive
) -> None:
    first = event(
        "Traj", timed_polyline("position", [(0.0, 100.0), (1.0, 110.0)]), sim_time("greaterOrEqual", 0.0)
    )
    after = """<Condition name="done" delay="0" conditionEdge="none"><ByValueCondition>
      <StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="Traj" state="endTransition"/>
      </ByValueCondition></Condition>"""
    second = event("Stop", speed_action("step", "time", 0, 0.0), after, priority="parallel")
    path = scenario(tmp_path, first + second)
    _, trace = run(path, road, 2.0)
    # the trajectory starts at 0 and reaches its end (t = 1) in the step ending at 1.0; the next event starts
    # at the step from 1.0, so the entity does not move on after the trajectory's end
    assert trace[1.0]["s"] == pytest.approx(110.0, abs=1e-6)
    assert trace[1.05]["s"] == pytest.approx(110.0, abs=1e-6) and trace[1.05]["speed"] == 0.0


def lateral_distance(constraints: str, *, continuous: bool = True, distance: float = 4.0) -> str:
    return f"""<PrivateAction><LateralAction>
      <LateralDistanceAction entityRef="Lead" distance="{distance}" freespace="false" continuous="{str(continuous).lower()}"
        displacement="leftToReferencedEntity" coordinateSystem="road">{constraints}</LateralDistanceAction>
      </LateralAction></PrivateAction>"""


def test_lateral_distance_at_limited_lateral_speed_then_kept(tmp_path: Path, road: OpenDrive) -> None:
    # Lead in lane -2, Ego in lane -2 too: 4 m to the left of the Lead at 2 m/s lateral (0.1 m a step);
    # the step the action starts in moves nothing
    path = scenario(
        tmp_path,
        event("Side", lateral_distance('<DynamicConstraints maxSpeed="2"/>'), sim_time("greaterThan", 1.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0) + place("Lead", 130.0),
    )
    engine, trace = run(path, road, 5.0)
    t0 = trace[1.0]["y"]
    assert trace[1.1]["y"] == pytest.approx(t0)  # started at 1.05: that step moves nothing
    assert trace[1.6]["y"] - t0 == pytest.approx(1.0, abs=1e-6)  # 10 steps × 0.1 m, to the left (+y)
    lead = engine.bodies["Lead"]
    assert trace[5.0]["y"] - lead.y == pytest.approx(4.0, abs=1e-6)


def test_lateral_distance_with_acceleration_limit_is_a_damped_spring(tmp_path: Path, road: OpenDrive) -> None:
    path = scenario(
        tmp_path,
        event(
            "Side",
            lateral_distance('<DynamicConstraints maxAcceleration="5"/>', continuous=False),
            sim_time("greaterThan", 1.0),
        ),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0) + place("Lead", 130.0),
    )
    engine, trace = run(path, road, 12.0)
    ys = [trace[t]["y"] for t in sorted(trace)]
    velocity = [(b - a) / 0.05 for a, b in itertools.pairwise(ys)]
    accel = [(b - a) / 0.05 for a, b in itertools.pairwise(velocity)]
    assert max(abs(x) for x in accel) <= 5.0 + 1e-6
    assert max(ys) - engine.bodies["Lead"].y < 4.0 + 0.01  # critically damped: no overshoot
    assert any("Side: endTransition" in line for line in engine.log)  # within 1 cm it ends


def test_lateral_distance_spring_is_damped_on_the_lateral_speed_relative_to_the_other_entity(
    tmp_path: Path, road: OpenDrive
) -> None:
    # the Lead drifts right at a constant rate (a linear lane offset of 3 m: ~0.16 m/s from 3 s to ~22 s,
    # its heading kept along the road): damped on the relative lateral speed, the spring follows the ramp
    # with no lag (damped on its own speed it would lag 2·sqrt(k)·v/k ≈ 0.27 m behind)
    offset = """<PrivateAction><LateralAction><LaneOffsetAction continuous="false">
      <LaneOffsetActionDynamics maxLateralAcc="0.05" dynamicsShape="linear"/>
      <LaneOffsetTarget><AbsoluteTargetLaneOffset value="-3"/></LaneOffsetTarget></LaneOffsetAction></LateralAction>
      </PrivateAction>"""
    keep = lateral_distance('<DynamicConstraints maxAcceleration="5"/>')
    path = scenario(
        tmp_path,
        event("Side", keep, sim_time("greaterThan", 0.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0) + place("Lead", 130.0),
        lead_events=event("Shift", offset, sim_time("greaterOrEqual", 3.0)),
    )
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    ego, lead = engine.bodies["Ego"], engine.bodies["Lead"]
    gaps, lead_moves = [], []
    while engine.time < 12.0 - 1e-9:
        y = lead.y
        engine.advance()
        if engine.time > 7.0:
            gaps.append(ego.y - lead.y)
            lead_moves.append(lead.y - y)
    assert all(move < -0.007 for move in lead_moves)  # the Lead is moving sideways all along
    assert all(gap == pytest.approx(4.0, abs=0.002) for gap in gaps)


def test_lateral_speed_of_the_distance_spring_stays_below_the_entity_speed(
    tmp_path: Path, road: OpenDrive
) -> None:
    # Ego at 1 m/s, maxSpeed 3 m/s: the lateral speed is at most the entity's 1 m/s (as esmini)
    keep = lateral_distance('<DynamicConstraints maxSpeed="3" maxAcceleration="50"/>')
    path = scenario(
        tmp_path,
        event("Side", keep, sim_time("greaterThan", 0.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=1.0) + place("Lead", 130.0, speed=1.0),
    )
    _, trace = run(path, road, 3.0)
    ys = [trace[t]["y"] for t in sorted(trace)]
    moves = [b - a for a, b in itertools.pairwise(ys)]
    assert max(moves) == pytest.approx(1.0 * 0.05, abs=1e-9)
    assert min(moves) >= 0.0


TRUCK = """
<ScenarioObject name="Truck">
  <Vehicle name="truck" vehicleCategory="truck">
    <BoundingBox><Center x="2" y="0" z="1.5"/><Dimensions width="2.5" length="6" height="3"/></BoundingBox>
    <Performance maxSpeed="30" maxAcceleration="3" maxDeceleration="8"/>
    <Axles><FrontAxle maxSteering="0.5" wheelDiameter="0.8" trackWidth="2" positionX="4" positionZ="0.4"/>
      <RearAxle maxSteering="0" wheelDiameter="0.8" trackWidth="2" positionX="0" positionZ="0.4"/></Axles>
    <TrailerHitch dx="-1.0"/>
    {trailer}
  </Vehicle>
</ScenarioObject>
<ScenarioObject name="Trailer">
  <Vehicle name="trailer" vehicleCategory="trailer">
    <BoundingBox><Center x="0" y="0" z="1.5"/><Dimensions width="2.5" length="8" height="3"/></BoundingBox>
    <Performance maxSpeed="30" maxAcceleration="3" maxDeceleration="8"/>
    <Axles><FrontAxle maxSteering="0" wheelDiameter="0.8" trackWidth="2" positionX="0" positionZ="0.4"/>
      <RearAxle maxSteering="0" wheelDiameter="0.8" trackWidth="2" positionX="0" positionZ="0.4"/></Axles>
    <TrailerCoupler dx="5.0"/>
  </Vehicle>
</ScenarioObject>"""


def trailer_scenario(tmp_path: Path, events: str, *, towing: bool) -> Path:
    trailer = '<Trailer><TrailerRef entityRef="Trailer"/></Trailer>' if towing else ""
    return scenario(
        tmp_path,
        events,
        entities=("Ego",),
        init=place("Ego", 300.0) + place("Truck", 100.0, speed=10.0) + place("Trailer", 80.0, speed=0.0),
        actor="Truck",
        more_entities=TRUCK.format(trailer=trailer),
        minor=3,
    )


def test_a_towed_trailer_follows_the_hitch_of_its_tow_vehicle(tmp_path: Path, road: OpenDrive) -> None:
    change = LANE_CHANGE.replace('entityRef="Ego"', 'entityRef="Truck"')
    path = trailer_scenario(tmp_path, event("Change", change, sim_time("greaterThan", 1.0)), towing=True)
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    truck, trailer = engine.bodies["Truck"], engine.bodies["Trailer"]
    # its own Teleport is ignored: it starts straight behind, its coupler on the hitch (1 m + 5 m behind)
    assert trailer.s == pytest.approx(94.0) and trailer.lane_id == -2
    while engine.time < 6.0:
        engine.advance()
        hx, hy = truck.x - math.cos(truck.heading), truck.y - math.sin(truck.heading)
        assert math.hypot(trailer.x - hx, trailer.y - hy) == pytest.approx(5.0)
        assert trailer.speed == truck.speed
    # the truck changed lanes: the trailer followed it into the new lane, lagging behind in the turn
    assert trailer.lane_id == truck.lane_id == -1
    assert abs(trailer.heading - truck.heading) < 0.01


def test_connect_and_disconnect_trailer_actions(tmp_path: Path, road: OpenDrive) -> None:
    connect = "<PrivateAction><TrailerAction><ConnectTrailerAction trailerRef='Trailer'/></TrailerAction></PrivateAction>"
    disconnect = "<PrivateAction><TrailerAction><DisconnectTrailerAction/></TrailerAction></PrivateAction>"
    events = event("Hook", connect, sim_time("greaterThan", 1.0)) + event(
        "Unhook", disconnect, sim_time("greaterThan", 3.0), priority="parallel"
    )
    path = trailer_scenario(
        tmp_path, events.replace('priority="override"', 'priority="parallel"'), towing=False
    )
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    truck, trailer = engine.bodies["Truck"], engine.bodies["Trailer"]
    assert trailer.s == pytest.approx(80.0)  # not towed: placed by its own Teleport
    while engine.time < 2.0:
        engine.advance()
    assert truck.s - trailer.s == pytest.approx(6.0)  # hooked: on the hitch
    while engine.time < 5.0:
        engine.advance()
    assert trailer.speed == 0.0  # let go at 3 s: it stays where it was left
    assert truck.s - trailer.s == pytest.approx(6.0 + 10.0 * 1.95, abs=0.6)


def test_an_entity_in_a_lane_that_narrows_to_nothing_moves_to_the_next_inner_lane(tmp_path: Path) -> None:
    xodr = tmp_path / "merge.xodr"
    xodr.write_text(
        """<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="6"/>
        <road id="1" length="300" junction="-1"><link/><planView>
          <geometry s="0" x="0" y="0" hdg="0" length="300"><line/></geometry></planView>
          <lanes><laneSection s="0"><left/><center><lane id="0" type="none"/></center><right>
            <lane id="-1" type="driving"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
            <lane id="-2" type="driving"><link/><width sOffset="0" a="3.5" b="-0.05" c="0" d="0"/>
              <width sOffset="70" a="0" b="0" c="0" d="0"/></lane>
          </right></laneSection></lanes></road></OpenDRIVE>"""
    )
    path = scenario(tmp_path, "", init=place("Ego", 10.0, speed=10.0), road_file=xodr)
    _, trace = run(path, OpenDrive.from_file(xodr), 8.0)
    assert trace[5.0]["lane"] == -2  # s = 60: still 0.5 m wide
    assert trace[7.0]["lane"] == -1 and trace[7.0]["y"] == pytest.approx(-1.75)  # s = 80: at lane -1's centre


def synchronize(final: str) -> str:
    return f"""<PrivateAction><SynchronizeAction masterEntityRef="Ego" targetToleranceMaster="1.0" targetTolerance="1.0">
      <TargetPositionMaster><LanePosition roadId="1" laneId="-2" s="300" offset="0"/></TargetPositionMaster>
      <TargetPosition><LanePosition roadId="1" laneId="-1" s="250" offset="0"/></TargetPosition>
      {final}</SynchronizeAction></PrivateAction>"""


def synch_scenario(tmp_path: Path, final: str, ego_speed: float) -> Path:
    return scenario(
        tmp_path,
        event("Sync", synchronize(final), sim_time("greaterThan", 0.0)),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=ego_speed) + place("Lead", 100.0, lane=-1, speed=10.0),
        actor="Lead",
    )


def test_synchronize_reaches_the_target_with_the_final_speed_when_the_master_reaches_its_own(
    tmp_path: Path, road: OpenDrive
) -> None:
    path = synch_scenario(tmp_path, '<FinalSpeed><AbsoluteSpeed value="15"/></FinalSpeed>', 20.0)
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    ego, lead = engine.bodies["Ego"], engine.bodies["Lead"]
    while ego.s < 299.0 - 1e-9:  # the master is within its tolerance
        engine.advance()
    assert lead.s == pytest.approx(249.0, abs=1.0)  # … and so is the actor
    engine.advance()
    assert lead.speed == pytest.approx(15.0)  # the action ended with the final speed
    assert any("Sync: endTransition" in line for line in engine.log)


def test_synchronize_waits_while_the_master_stands_still(tmp_path: Path, road: OpenDrive) -> None:
    path = synch_scenario(tmp_path, '<FinalSpeed><AbsoluteSpeed value="15"/></FinalSpeed>', 0.0)
    engine, trace = run(path, road, 2.0)
    assert engine.bodies["Lead"].speed == 0.0
    assert trace[2.0]["x"] == pytest.approx(100.0)  # the master did not move either


def test_velocity_is_the_displacement_and_time_to_collision_uses_it(tmp_path: Path, road: OpenDrive) -> None:
    ttc = """<Condition name="ttc" delay="0" conditionEdge="none"><ByEntityCondition>
      <TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="Ego"/></TriggeringEntities>
      <EntityCondition><TimeToCollisionCondition value="2" freespace="false" rule="lessThan"
        coordinateSystem="entity" relativeDistanceType="longitudinal">
        <TimeToCollisionConditionTarget><EntityRef entityRef="Lead"/></TimeToCollisionConditionTarget>
      </TimeToCollisionCondition></EntityCondition></ByEntityCondition></Condition>"""
    path = scenario(
        tmp_path,
        event("Brake", speed_action("step", "time", 0, 10.0), ttc),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=20.0) + place("Lead", 160.0, speed=10.0),
    )
    engine, trace = run(path, road, 5.0)
    lead = engine.bodies["Lead"]
    assert math.hypot(lead.vx, lead.vy) == pytest.approx(10.0)
    # gap 60 m closing at 10 m/s: below 2 s (20 m) after 4 s; the step from 4.05 brakes
    assert trace[4.05]["speed"] == pytest.approx(20.0)
    assert trace[4.1]["speed"] == pytest.approx(10.0)


def test_an_alks_controller_brakes_for_a_vehicle_in_its_path_without_colliding(
    tmp_path: Path, road: OpenDrive
) -> None:
    alks = """<ObjectController><Controller name="ALKS_R157SM_Controller"><Properties>
      <Property name="model" value="Regulation"/></Properties></Controller></ObjectController>"""
    activate = """<Private entityRef="Ego"><PrivateAction><ControllerAction>
      <ActivateControllerAction longitudinal="true" lateral="false"/></ControllerAction></PrivateAction></Private>"""
    brake = event("Brake", speed_action("linear", "rate", 5.0, 0.0), sim_time("greaterThan", 2.0))
    path = scenario(
        tmp_path,
        brake,
        entities=("Ego", "Lead", "Side"),
        init=place("Ego", 100.0, speed=20.0)
        + place("Lead", 160.0, speed=15.0)
        + place("Side", 110.0, lane=-1, speed=5.0)  # slower, but in the next lane: no reason to brake
        + activate,
        actor="Lead",
        controllers={"Ego": alks},
    )
    loaded = load_scenario(path)
    assert not any("ALKS_R157SM" in w for w in loaded.warnings)  # modelled as esmini's
    engine = ScenarioEngine(loaded, road=road, sumo=None, step_seconds=0.05)
    ego, lead = engine.bodies["Ego"], engine.bodies["Lead"]
    speeds = []
    while engine.time < 15.0:
        engine.advance()
        speeds.append(ego.speed)
        assert lead.s - ego.s > ego.entity.box.length  # never into the vehicle ahead
    assert speeds[20] == pytest.approx(20.0)  # nothing in its path at first (the Side car is beside it)
    decelerations = [(a - b) / 0.05 for a, b in itertools.pairwise(speeds)]
    assert max(decelerations) <= 6.0 + 1e-6  # the Regulation model brakes at 6 m/s² at most
    assert max(decelerations) > 3.0  # and it does brake
    assert ego.speed < 0.1 and lead.speed == 0.0  # its cruise creeps toward its minimum distance
    assert lead.s - ego.s < 10.0  # stopped close behind it


def test_longitudinal_distance_with_one_limit_takes_the_other_from_the_vehicle(
    tmp_path: Path, road: OpenDrive
) -> None:
    # only maxAcceleration: braking to the wanted distance is bounded by the vehicle's maxDeceleration (9)
    path = scenario(
        tmp_path,
        event(
            "Keep",
            distance_keeping('<DynamicConstraints maxAcceleration="2"/>'),
            sim_time("greaterThan", 0.0),
        ),
        entities=("Ego", "Lead"),
        init=place("Ego", 100.0, speed=30.0) + place("Lead", 130.0, speed=10.0),
    )
    _, trace = run(path, road, 10.0)
    acc = accelerations(trace)
    assert min(acc) == pytest.approx(-9.0, abs=1e-6)
    assert max(acc) <= 2.0 + 1e-6
    assert all(0.0 <= v["speed"] <= 70.0 for v in trace.values())
