"""Conditions and signals: what distance, headway and time-to-collision conditions measure (coordinate
system, distance type, freespace), traffic signal states and signal controller phases, and the catalog
errors a user sees. Scenarios run on the example highway, moved by the scenario alone (exact numbers)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from simcore.errors import BadInput
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests.xosc_fixtures import (
    HIGHWAY,
    act,
    file_header,
    openscenario,
    place,
    road_network,
    scenario_object,
    story,
    vehicle,
    write_scenario,
)

# moved by the scenario alone: no axles needed
CAR = vehicle(track_width=None)


def sim_time(value: float) -> str:
    return f"""<Condition name="t" delay="0" conditionEdge="none"><ByValueCondition>
  <SimulationTimeCondition value="{value}" rule="greaterOrEqual"/></ByValueCondition></Condition>"""


def by_ego(body: str, edge: str = "none") -> str:
    return f"""<Condition name="c" delay="0" conditionEdge="{edge}"><ByEntityCondition>
  <TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="Ego"/></TriggeringEntities>
  <EntityCondition>{body}</EntityCondition></ByEntityCondition></Condition>"""


def stop_ego() -> str:
    return """<PrivateAction><LongitudinalAction><SpeedAction>
  <SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
  <SpeedActionTarget><AbsoluteTargetSpeed value="0"/></SpeedActionTarget></SpeedAction></LongitudinalAction></PrivateAction>"""


def signal_state(name: str, state: str) -> str:
    return f"""<GlobalAction><InfrastructureAction><TrafficSignalAction>
  <TrafficSignalStateAction name="{name}" state="{state}"/></TrafficSignalAction></InfrastructureAction></GlobalAction>"""


def event(name: str, action: str, trigger: str) -> str:
    return f"""<Event name="{name}" priority="parallel" maximumExecutionCount="1">
  <Action name="{name}Action">{action}</Action>
  <StartTrigger><ConditionGroup>{trigger}</ConditionGroup></StartTrigger></Event>"""


def scenario(
    tmp_path: Path,
    events: str,
    *,
    entities: tuple[str, ...] = ("Ego",),
    init: str = "",
    network_extra: str = "",
    header_minor: int = 2,
) -> Path:
    text = openscenario(
        minor=header_minor,
        road=road_network(HIGHWAY, network_extra),
        entities="".join(scenario_object(n, CAR) for n in entities),
        init=init or place("Ego", 100.0),
        stories=story(act(events, start=sim_time(0))),
    )
    return write_scenario(tmp_path, text)


@pytest.fixture(scope="module")
def road() -> OpenDrive:
    return OpenDrive.from_file(HIGHWAY)


def run(path: Path, road: OpenDrive, seconds: float) -> ScenarioEngine:
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    while engine.time < seconds - 1e-9 and not engine.ended:
        engine.advance()
    return engine


def started(engine: ScenarioEngine, name: str) -> float | None:
    """Simulated time at which event `name` started (None: never)."""
    for line in engine.log:
        if f"event {name}: startTransition" in line:
            return float(line.split()[0])
    return None


# --- traffic signals ------------------------------------------------------------------------------------


def test_signal_state_action_and_condition(tmp_path: Path, road: OpenDrive) -> None:
    init = place("Ego", 100.0) + signal_state("7", "on;off;off")
    green = """<Condition name="g" delay="0.5" conditionEdge="rising"><ByValueCondition>
      <TrafficSignalCondition name="7" state="off;off;on"/></ByValueCondition></Condition>"""
    red = """<Condition name="r" delay="0" conditionEdge="none"><ByValueCondition>
      <TrafficSignalCondition name="7" state="on;off;off"/></ByValueCondition></Condition>"""
    events = (
        event("SwitchGreen", signal_state("7", "off;off;on"), sim_time(2.0))
        + event("Go", stop_ego(), green)
        + event(
            "RedAtStart",
            stop_ego().replace('value="0"/></SpeedActionTarget>', 'value="25"/></SpeedActionTarget>'),
            red,
        )
    )
    engine = run(scenario(tmp_path, events, init=init), road, 4.0)
    assert started(engine, "RedAtStart") == pytest.approx(0.0)
    assert started(engine, "SwitchGreen") == pytest.approx(2.0, abs=0.051)
    # the state changes during the step at 2.0; seen from the next evaluation, plus the 0.5 s delay
    assert started(engine, "Go") == pytest.approx(2.55, abs=0.051)
    assert engine.signals["7"] == "off;off;on"
    assert engine.bodies["Ego"].speed == 0.0


def test_signal_controller_cycles_its_phases_and_jumps_on_action(tmp_path: Path, road: OpenDrive) -> None:
    network = """<TrafficSignals>
      <TrafficSignalController name="main" delay="1">
        <Phase name="stop" duration="3"><TrafficSignalState trafficSignalId="7" state="on;off;off"/></Phase>
        <Phase name="go" duration="2"><TrafficSignalState trafficSignalId="7" state="off;off;on"/></Phase>
      </TrafficSignalController>
      <TrafficSignalController name="follower" delay="0.5" reference="main">
        <Phase name="only" duration="10"><TrafficSignalState trafficSignalId="8" state="on"/></Phase>
      </TrafficSignalController>
    </TrafficSignals>"""
    go = """<Condition name="go" delay="0" conditionEdge="rising"><ByValueCondition>
      <TrafficSignalControllerCondition trafficSignalControllerRef="main" phase="go"/></ByValueCondition></Condition>"""
    jump = """<GlobalAction><InfrastructureAction><TrafficSignalAction>
      <TrafficSignalControllerAction trafficSignalControllerRef="main" phase="go"/></TrafficSignalAction></InfrastructureAction></GlobalAction>"""
    path = scenario(tmp_path, event("Go", stop_ego(), go), network_extra=network)
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    seen: dict[float, tuple[str | None, str | None, str | None]] = {}
    while engine.time < 11.0 - 1e-9:
        engine.advance()
        seen[round(engine.time, 2)] = (
            engine.signal_phases.get("main"),
            engine.signals.get("7"),
            engine.signals.get("8"),
        )
    assert seen[0.9] == (None, None, None)  # before its delay
    assert seen[1.1][:2] == ("stop", "on;off;off")
    assert seen[4.1][:2] == ("go", "off;off;on")
    assert seen[6.1][:2] == ("stop", "on;off;off")  # the cycle starts over
    assert seen[1.4][2] is None and seen[1.6][2] == "on"  # the referencing controller starts 0.5 s after
    assert started(engine, "Go") == pytest.approx(4.05, abs=0.051)

    path = scenario(tmp_path, event("Jump", jump, sim_time(2.0)), network_extra=network)
    engine = run(path, road, 2.5)
    assert engine.signal_phases["main"] == "go"  # jumped at 2.0 instead of waiting for 4.0
    assert engine.signals["7"] == "off;off;on"


def test_signal_controller_action_naming_an_unknown_phase_is_bad_input(
    tmp_path: Path, road: OpenDrive
) -> None:
    network = """<TrafficSignals><TrafficSignalController name="main">
        <Phase name="stop" duration="3"/></TrafficSignalController></TrafficSignals>"""
    jump = """<GlobalAction><InfrastructureAction><TrafficSignalAction>
      <TrafficSignalControllerAction trafficSignalControllerRef="main" phase="amber"/></TrafficSignalAction></InfrastructureAction></GlobalAction>"""
    path = scenario(tmp_path, event("Jump", jump, sim_time(1.0)), network_extra=network)
    with pytest.raises(BadInput, match="no phase 'amber'"):
        run(path, road, 2.0)


# --- distances, headway, time to collision ----------------------------------------------------------------


def test_distance_condition_along_the_road(tmp_path: Path, road: OpenDrive) -> None:
    near = by_ego(
        """<DistanceCondition value="30" freespace="false" rule="lessThan" relativeDistanceType="longitudinal"
           coordinateSystem="road"><Position><LanePosition roadId="1" laneId="-3" s="300" offset="0"/></Position>
           </DistanceCondition>"""
    )
    engine = run(scenario(tmp_path, event("Near", stop_ego(), near)), road, 12.0)
    # s 100 → 270 at 20 m/s: 8.5 s; the lateral offset to lane -3 does not count along the road
    assert started(engine, "Near") == pytest.approx(8.55, abs=0.051)


def test_distance_condition_defaults_to_euclidean(tmp_path: Path, road: OpenDrive) -> None:
    near = by_ego(
        """<DistanceCondition value="30" freespace="false" rule="lessThan">
           <Position><LanePosition roadId="1" laneId="-3" s="300" offset="0"/></Position></DistanceCondition>"""
    )
    engine = run(scenario(tmp_path, event("Near", stop_ego(), near)), road, 12.0)
    # hypot(ds, 3.5) < 30 → ds < 29.795: s > 270.205 at 20 m/s
    assert started(engine, "Near") == pytest.approx(8.55, abs=0.051)
    assert engine.bodies["Ego"].s == pytest.approx(100 + 20 * 8.5, abs=1.01)


def test_time_headway_is_euclidean_by_default_and_undefined_to_an_entity_behind(
    tmp_path: Path, road: OpenDrive
) -> None:
    init = place("Ego", 100.0, lane=-2, speed=10.0) + place("Side", 110.0, lane=-1, speed=10.0)
    headway = by_ego(
        """<TimeHeadwayCondition entityRef="Side" value="1.03" freespace="false" rule="greaterThan"/>"""
    )
    engine = run(
        scenario(tmp_path, event("Far", stop_ego(), headway), entities=("Ego", "Side"), init=init), road, 1.0
    )
    # Euclidean: hypot(10, 3.5) / 10 = 1.06 s > 1.03 (longitudinally it would be 1.0 s)
    assert started(engine, "Far") == pytest.approx(0.0)

    longitudinal = by_ego(
        """<TimeHeadwayCondition entityRef="Side" value="1.05" freespace="false" rule="greaterThan"
           coordinateSystem="entity" relativeDistanceType="longitudinal"/>"""
    )
    engine = run(
        scenario(tmp_path, event("Far", stop_ego(), longitudinal), entities=("Ego", "Side"), init=init),
        road,
        1.0,
    )
    assert started(engine, "Far") is None  # 1.0 s, not above 1.05

    behind = place("Ego", 100.0, lane=-2, speed=10.0) + place("Side", 90.0, lane=-2, speed=10.0)
    anything = by_ego(
        """<TimeHeadwayCondition entityRef="Side" value="0" freespace="false" rule="greaterThan"/>"""
    )
    engine = run(
        scenario(tmp_path, event("Any", stop_ego(), anything), entities=("Ego", "Side"), init=behind),
        road,
        1.0,
    )
    assert started(engine, "Any") is None


def test_time_to_collision_with_freespace_and_closing_speed(tmp_path: Path, road: OpenDrive) -> None:
    init = place("Ego", 100.0, speed=30.0) + place("Lead", 200.0, speed=20.0)
    ttc = by_ego(
        """<TimeToCollisionCondition value="2" freespace="true" rule="lessThan" coordinateSystem="entity"
           relativeDistanceType="longitudinal"><TimeToCollisionConditionTarget><EntityRef entityRef="Lead"/>
           </TimeToCollisionConditionTarget></TimeToCollisionCondition>"""
    )
    engine = run(
        scenario(tmp_path, event("Brake", stop_ego(), ttc), entities=("Ego", "Lead"), init=init), road, 10.0
    )
    # gap 100 − 4.5 closing at 10 m/s: below 20 m after 7.55 s
    assert started(engine, "Brake") == pytest.approx(7.6, abs=0.051)


def test_time_to_collision_is_undefined_when_not_closing_in(tmp_path: Path, road: OpenDrive) -> None:
    init = place("Ego", 100.0, speed=20.0) + place("Lead", 150.0, speed=25.0)
    ttc = by_ego(
        """<TimeToCollisionCondition value="0" freespace="false" rule="greaterThan">
           <TimeToCollisionConditionTarget><EntityRef entityRef="Lead"/></TimeToCollisionConditionTarget>
           </TimeToCollisionCondition>"""
    )
    # (from 1 s on: velocities are measured over a step)
    engine = run(
        scenario(
            tmp_path, event("Any", stop_ego(), ttc + sim_time(1.0)), entities=("Ego", "Lead"), init=init
        ),
        road,
        3.0,
    )
    assert started(engine, "Any") is None  # moving apart: no time to collision, not an infinite one


def test_along_route_of_1_0_selects_road_coordinates(tmp_path: Path) -> None:
    headway = by_ego("""<TimeHeadwayCondition entityRef="Ego" value="1" freespace="false" alongRoute="true"
        rule="lessThan"/>""")
    path = scenario(tmp_path, event("E", stop_ego(), headway), header_minor=0)
    cond = load_scenario(path).stories[0].acts[0].groups[0].maneuvers[0].events[0].start_trigger
    assert cond is not None
    parsed = cond.groups[0][0].entity_condition
    assert parsed is not None
    assert (parsed.coordinate_system, parsed.distance_type) == ("road", "euclidianDistance")  # type: ignore[union-attr]


def test_bad_coordinate_system_names_the_element(tmp_path: Path) -> None:
    bad = by_ego("""<TimeHeadwayCondition entityRef="Ego" value="1" freespace="false" coordinateSystem="polar"
        rule="lessThan"/>""")
    with pytest.raises(BadInput, match="coordinateSystem='polar'") as err:
        load_scenario(scenario(tmp_path, event("E", stop_ego(), bad)))
    assert "TimeHeadwayCondition" in str(err.value)


# --- catalogs ---------------------------------------------------------------------------------------------


def test_missing_catalog_directory_is_named_with_its_declaration(tmp_path: Path) -> None:
    catalogs = """<CatalogLocations>
    <VehicleCatalog><Directory path="../nowhere/Vehicles"/></VehicleCatalog>
  </CatalogLocations>"""
    text = openscenario(
        catalogs=catalogs,  # the Directory on line 5
        road=road_network(HIGHWAY),
        entities=scenario_object(
            "Ego", '<CatalogReference catalogName="VehicleCatalog" entryName="car_white"/>'
        ),
    )
    path = write_scenario(tmp_path, text)
    with pytest.raises(BadInput) as err:
        load_scenario(path)
    message = str(err.value)
    assert "VehicleCatalog/car_white not found" in message
    assert "path='../nowhere/Vehicles' (line 5): no such directory" in message
    assert f"{path}:8" in message  # the CatalogReference's line


def test_catalog_directory_may_name_the_catalog_file(tmp_path: Path) -> None:
    (tmp_path / "cat").mkdir()
    (tmp_path / "cat" / "Cars.xosc").write_text(
        f'<?xml version="1.0"?><OpenSCENARIO>{file_header()}<Catalog name="Cars">{CAR}</Catalog></OpenSCENARIO>'
    )
    text = openscenario(
        catalogs='<CatalogLocations><VehicleCatalog><Directory path="cat/Cars.xosc"/></VehicleCatalog></CatalogLocations>',
        road=road_network(HIGHWAY),
        entities=scenario_object("Ego", '<CatalogReference catalogName="Cars" entryName="car"/>'),
    )
    scenario_ = load_scenario(write_scenario(tmp_path, text))
    assert scenario_.entities[0].box.length == 4.5


def test_warning_in_a_catalog_entry_names_the_catalog_file_and_line(tmp_path: Path) -> None:
    (tmp_path / "man").mkdir()
    (tmp_path / "man" / "Lights.xosc").write_text(
        f"""<?xml version="1.0"?>
<OpenSCENARIO>{file_header()}
<Catalog name="Lights">
  <Maneuver name="Blink">
    <Event name="On" priority="parallel"><Action name="OnAction"><PrivateAction><AppearanceAction>
      <LightStateAction><LightType><VehicleLight vehicleLightType="indicatorLeft"/></LightType>
      <LightState mode="on"/></LightStateAction></AppearanceAction></PrivateAction></Action>
      <StartTrigger><ConditionGroup><Condition name="t" delay="0" conditionEdge="none"><ByValueCondition>
        <SimulationTimeCondition value="1" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>
      </StartTrigger></Event>
  </Maneuver>
</Catalog></OpenSCENARIO>"""
    )
    text = openscenario(
        catalogs='<CatalogLocations><ManeuverCatalog><Directory path="man"/></ManeuverCatalog></CatalogLocations>',
        road=road_network(HIGHWAY),
        entities=scenario_object("Ego", CAR),
        init=place("Ego", 100.0),
        stories=story(
            act(maneuvers='<CatalogReference catalogName="Lights" entryName="Blink"/>', start=sim_time(0))
        ),
    )
    path = write_scenario(tmp_path, text)
    for _ in range(2):  # the second load uses the catalog parsed by the first: the same file and line
        warnings = load_scenario(path).warnings
        assert any(
            w.startswith(f"{tmp_path / 'man' / 'Lights.xosc'}:5: ") and "LightStateAction" in w
            for w in warnings
        ), warnings


def test_a_catalog_edited_between_loads_is_read_again(tmp_path: Path) -> None:
    """Catalogs are parsed once per content: an edit keeping the file's size and modification time is read
    at the next load all the same."""
    import os

    catalog = tmp_path / "cat" / "Cars.xosc"
    catalog.parent.mkdir()

    def write(length: str) -> None:
        car = CAR.replace('length="4.5"', f'length="{length}"')
        catalog.write_text(
            f'<?xml version="1.0"?><OpenSCENARIO>{file_header()}<Catalog name="Cars">{car}</Catalog></OpenSCENARIO>'
        )

    write("4.5")
    text = openscenario(
        catalogs='<CatalogLocations><VehicleCatalog><Directory path="cat"/></VehicleCatalog></CatalogLocations>',
        road=road_network(HIGHWAY),
        entities=scenario_object("Ego", '<CatalogReference catalogName="Cars" entryName="car"/>'),
    )
    path = write_scenario(tmp_path, text)
    assert load_scenario(path).entities[0].box.length == 4.5
    assert load_scenario(path).entities[0].box.length == 4.5
    before = catalog.stat()
    write("5.5")
    os.utime(catalog, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert catalog.stat().st_size == before.st_size
    assert load_scenario(path).entities[0].box.length == 5.5


# --- positions and trajectories seen by conditions --------------------------------------------------------


def test_relative_orientation_is_kept_along_the_lane(tmp_path: Path, road: OpenDrive) -> None:
    init = """<Private entityRef="Ego"><PrivateAction><TeleportAction><Position>
      <LanePosition roadId="1" laneId="-2" s="100" offset="0"><Orientation type="relative" h="1.2"/></LanePosition>
      </Position></TeleportAction></PrivateAction></Private>"""
    engine = run(scenario(tmp_path, "", init=init), road, 1.0)
    assert engine.bodies["Ego"].heading == pytest.approx(1.2, abs=1e-6)  # the road heads along +x here


def test_nurbs_control_point_times_sit_where_their_basis_function_peaks_on_esminis_sampling(
    tmp_path: Path, road: OpenDrive
) -> None:
    from simcore.scenario.paths import _basis

    points = [
        (100.0, -5.0, 0.0),
        (160.0, -5.0, 3.0),
        (220.0, 5.0, 6.0),
        (280.0, -5.0, 9.0),
        (340.0, -5.0, 12.0),
    ]
    knots = (0.0, 0.0, 0.0, 1 / 3, 2 / 3, 1.0, 1.0, 1.0)
    control = "".join(
        f"""<ControlPoint time="{t}" weight="1"><Position><WorldPosition x="{x}" y="{y}" z="0" h="0"/></Position>
        </ControlPoint>"""
        for x, y, t in points
    )
    knot_xml = "".join(f'<Knot value="{k}"/>' for k in knots)
    follow = f"""<PrivateAction><RoutingAction><FollowTrajectoryAction>
      <TrajectoryRef><Trajectory name="n" closed="false"><Shape><Nurbs order="3">{control}{knot_xml}
      </Nurbs></Shape></Trajectory></TrajectoryRef>
      <TimeReference><Timing domainAbsoluteRelative="relative" scale="1" offset="0"/></TimeReference>
      <TrajectoryFollowingMode followingMode="position"/></FollowTrajectoryAction></RoutingAction></PrivateAction>"""
    engine = run(scenario(tmp_path, event("Fly", follow, sim_time(0))), road, 3.0)
    # control point 1 (time 3) sits where its basis function peaks (near u = 2/9, not its Greville abscissa
    # 1/6), on esmini's coarse sampling of the curve: one sample a metre of the 242 m control polygon, the
    # peak read just ahead of each sample, so at sample 54 of 242
    u = 54 / 242
    b = [_basis(knots, 3, i, u) for i in range(len(points))]
    x = sum(w * p[0] for w, p in zip(b, points, strict=True))
    y = sum(w * p[1] for w, p in zip(b, points, strict=True))
    ego = engine.bodies["Ego"]
    assert (ego.x, ego.y) == (pytest.approx(x, abs=0.1), pytest.approx(y, abs=0.1))


def test_freespace_euclidean_relative_distance(tmp_path: Path, road: OpenDrive) -> None:
    init = place("Ego", 100.0, speed=30.0) + place("Lead", 200.0, speed=20.0)
    near = by_ego(
        """<RelativeDistanceCondition entityRef="Lead" relativeDistanceType="euclidianDistance" freespace="true"
           value="20" rule="lessThan"/>"""
    )
    far = by_ego(
        """<RelativeDistanceCondition entityRef="Lead" relativeDistanceType="euclidianDistance" freespace="true"
           value="50" rule="greaterThan"/>"""
    )
    events = event("Near", stop_ego(), near) + event("Far", signal_state("1", "x"), far)
    engine = run(scenario(tmp_path, events, entities=("Ego", "Lead"), init=init), road, 10.0)
    # between the boxes: 100 − 4.5 m closing at 10 m/s, below 20 m after 7.55 s
    assert started(engine, "Near") == pytest.approx(7.6, abs=0.051)
    assert started(engine, "Far") == pytest.approx(0.0)


def test_angle_conditions(tmp_path: Path, road: OpenDrive) -> None:
    turned = """<Private entityRef="Side"><PrivateAction><TeleportAction><Position>
      <LanePosition roadId="1" laneId="-1" s="150" offset="0"><Orientation type="relative" h="0.3"/></LanePosition>
      </Position></TeleportAction></PrivateAction></Private>"""
    init = place("Ego", 100.0, speed=0.0) + turned
    absolute = by_ego("""<AngleCondition angleType="heading" angle="0.02" angleTolerance="0.05"/>""")
    on_road = by_ego(
        """<AngleCondition angleType="heading" angle="0.3" angleTolerance="0.01" coordinateSystem="road"/>"""
    ).replace('entityRef="Ego"', 'entityRef="Side"')
    relative = by_ego(
        """<RelativeAngleCondition entityRef="Ego" angleType="heading" angle="0.3" angleTolerance="0.01"/>"""
    ).replace(
        '<EntityRef entityRef="Ego"/></TriggeringEntities>',
        '<EntityRef entityRef="Side"/></TriggeringEntities>',
    )
    off = by_ego("""<AngleCondition angleType="heading" angle="0.2" angleTolerance="0.05"/>""")
    events = (
        event("Abs", signal_state("a", "1"), absolute)
        + event("Road", signal_state("b", "1"), on_road)
        + event("Rel", signal_state("c", "1"), relative)
        + event("Off", signal_state("d", "1"), off)
    )
    engine = run(scenario(tmp_path, events, entities=("Ego", "Side"), init=init), road, 0.5)
    assert started(engine, "Abs") == pytest.approx(0.0)  # the road heads along +x: 0 is within 0.02 ± 0.05
    assert started(engine, "Road") == pytest.approx(0.0)
    assert started(engine, "Rel") == pytest.approx(0.0)
    assert started(engine, "Off") is None


def test_unknown_element_state_is_bad_input(tmp_path: Path) -> None:
    bad = """<Condition name="s" delay="0" conditionEdge="none"><ByValueCondition>
      <StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="E" state="finished"/>
      </ByValueCondition></Condition>"""
    with pytest.raises(BadInput, match="state='finished': expected one of startTransition") as err:
        load_scenario(scenario(tmp_path, event("E", stop_ego(), bad)))
    assert "StoryboardElementStateCondition" in str(err.value)


def test_speed_conditions_with_a_direction(tmp_path: Path, road: OpenDrive) -> None:
    change = """<PrivateAction><LateralAction><LaneChangeAction>
      <LaneChangeActionDynamics dynamicsShape="sinusoidal" dynamicsDimension="time" value="3"/>
      <LaneChangeTarget><AbsoluteTargetLane value="-1"/></LaneChangeTarget></LaneChangeAction></LateralAction>
      </PrivateAction>"""
    init = place("Ego", 100.0) + place("Other", 50.0, lane=-3)
    # in the other (straight-driving) entity's frame the lane change is a lateral speed; in the entity's own
    # frame (it turns toward where it goes) it is none
    sideways = by_ego(
        """<RelativeSpeedCondition entityRef="Other" value="1.5" rule="greaterThan" direction="lateral"/>"""
    )
    own = by_ego("""<SpeedCondition value="0.1" rule="greaterThan" direction="lateral"/>""")
    forward = by_ego("""<SpeedCondition value="19.9" rule="greaterThan" direction="longitudinal"/>""")
    events = (
        event("Change", change, sim_time(1.0))
        + event("Sideways", signal_state("a", "1"), sideways)
        + event("Own", signal_state("b", "1"), own)
        + event("Forward", signal_state("c", "1"), forward + sim_time(0.5))
    )
    engine = run(scenario(tmp_path, events, entities=("Ego", "Other"), init=init), road, 5.0)
    # 3.5 m over 3 s (sinusoidal): lateral speed 3.5·π/6·sin(π t/3), above 1.5 m/s from t ≈ 0.98 s of it
    start = started(engine, "Sideways")
    assert start is not None and 1.9 < start < 2.2
    assert started(engine, "Own") is None
    assert started(engine, "Forward") == pytest.approx(0.5)


def test_a_transition_counts_once_per_condition_however_late_it_is_evaluated(
    tmp_path: Path, road: OpenDrive
) -> None:
    def state(element: str, kind: str) -> str:
        return f"""<Condition name="s" delay="0" conditionEdge="none"><ByValueCondition>
          <StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="{element}"
            state="{kind}"/></ByValueCondition></Condition>"""

    repeat = event("Repeat", signal_state("r", "1"), state("Early", "startTransition")).replace(
        'maximumExecutionCount="1"', 'maximumExecutionCount="3"'
    )
    events = (
        event("Early", signal_state("e", "1"), sim_time(0.5))
        # the time condition does not hold before 2 s: the transition is looked at then (as esmini)
        + event("Late", signal_state("l", "1"), sim_time(2.0) + state("Early", "endTransition"))
        + repeat
    )
    engine = run(scenario(tmp_path, events), road, 3.0)
    assert started(engine, "Early") == pytest.approx(0.5, abs=0.051)
    assert started(engine, "Late") == pytest.approx(2.0, abs=0.051)
    assert sum("event Repeat: startTransition" in line for line in engine.log) == 1


def test_a_signal_missing_from_the_road_network_is_warned_about(tmp_path: Path, road: OpenDrive) -> None:
    green = """<Condition name="g" delay="0" conditionEdge="none"><ByValueCondition>
      <TrafficSignalCondition name="42" state="off;off;on"/></ByValueCondition></Condition>"""
    engine = run(scenario(tmp_path, event("Go", stop_ego(), green)), road, 0.1)
    assert any("TrafficSignalCondition: traffic signal '42' is not a <signal>" in w for w in engine.warnings)
    assert len([w for w in engine.warnings if "'42'" in w]) == 1


# --- collision ----------------------------------------------------------------------------------------------


def _bodies_world(bodies: dict[str, Any]) -> Any:
    """The least of an engine the geometric conditions read: bodies by name, no road, a Measure."""
    from dataclasses import dataclass, field

    from simcore.scenario.measure import Measure
    from simcore.scenario.motion import Body

    @dataclass
    class World:
        bodies: dict[str, Body]
        road: None = None
        step_index: int = 0
        measure: Measure = field(init=False)

        def __post_init__(self) -> None:
            self.measure = Measure(self)

        def body(self, name: str) -> Body:
            return self.bodies[name]

    return World(bodies)


def test_collision_is_the_overlap_of_the_footprints_near_and_far() -> None:
    """CollisionCondition holds when the footprints touch or overlap (within TOUCH_TOLERANCE), rotated or
    not; boxes apart (a millimetre up to far away) do not collide, whether or not their footprints are built."""
    import math

    from simcore.evaluation.metrics import TOUCH_TOLERANCE
    from simcore.scenario import conditions
    from simcore.scenario import model as m
    from simcore.scenario.motion import Body

    def car(name: str) -> m.Entity:
        return m.Entity(name, "vehicle", "car", m.Box(1.4, 0.0, 0.75, 4.5, 1.8, 1.5), m.Performance())

    def collides(dx: float, dy: float, heading: float = 0.0) -> bool:
        ego = Body(car("Ego"))
        other = Body(car("Other"), x=dx, y=dy, heading=heading)
        world = _bodies_world({"Ego": ego, "Other": other})
        return conditions.collision(m.CollisionCondition("Other"), world, ego)

    assert collides(4.5, 0.0)  # bumper to bumper: touching
    assert collides(4.5 + 0.5 * TOUCH_TOLERANCE, 0.0)
    assert not collides(4.5 + 1e-4, 0.0)  # a tenth of a millimetre apart
    assert not collides(4.5 + 2e-3, 0.0) and not collides(50.0, 3.0)
    assert collides(0.0, 1.8) and not collides(0.0, 1.8 + 1e-4)  # side by side
    # turned 90° with its box centred beside Ego's front (0.9 m either side along x): touching at x = 4.55
    assert collides(4.55 - 1e-3, -1.4, math.pi / 2) and not collides(4.55 + 2e-3, -1.4, math.pi / 2)


# --- relative distance --------------------------------------------------------------------------------------


def test_relative_distance_decided_by_bounds_agrees_with_the_measured_distance() -> None:
    """The bounds that spare measuring (boxes far apart, or centres closer than the value) give the answer
    the measured distance gives, for every rule, near and far, in front, beside and behind, turned or not."""
    import itertools
    import math

    from simcore.scenario import conditions
    from simcore.scenario import model as m
    from simcore.scenario.measure import LARGE
    from simcore.scenario.motion import Body

    def car(name: str, length: float = 4.5) -> m.Entity:
        return m.Entity(name, "vehicle", "car", m.Box(1.4, 0.2, 0.75, length, 1.8, 1.5), m.Performance())

    rules = ("greaterThan", "lessThan", "equalTo", "greaterOrEqual", "lessOrEqual", "notEqualTo")
    kinds = (("entity", "longitudinal"), ("entity", "lateral"), ("entity", "euclidianDistance"))
    checked = decided = 0
    for dx, dy, heading in itertools.product((-30.0, -6.0, 0.0, 3.0, 12.5, 40.0), (0.0, 3.5), (0.0, 0.4)):
        ego = Body(car("Ego"))
        other = Body(car("Other", 12.0), x=dx, y=dy, heading=heading)
        world = _bodies_world({"Ego": ego, "Other": other})
        for (system, kind), rule, value in itertools.product(kinds, rules, (0.0, 2.0, 8.0, 15.0, 60.0)):
            measured = world.measure.to_entity(ego, other, system, kind, True)
            expected = conditions.compare(rule, LARGE if measured is None else abs(measured), value)
            c = m.RelativeDistanceCondition("Other", kind, True, value, rule, system)  # type: ignore[arg-type]
            assert conditions.relative_distance(c, world, ego) == expected, (
                dx,
                dy,
                heading,
                kind,
                rule,
                value,
            )
            checked += 1
            centres = world.measure.box_distance_lower_bound(ego, other) + 0.5 * (
                math.hypot(4.5, 1.8) + math.hypot(12.0, 1.8)
            )
            decided += centres < value - 1e-6
    assert checked == 24 * 3 * 6 * 5 and decided > 100  # the bound decided many of them


def test_axis_gaps_are_the_gaps_of_the_projections_as_lists_of_them_give() -> None:
    """The unrolled projections give, to the bit, the gaps that min and max of lists of them give (NaN and
    -0.0 alike), on boxes near and far, turned or not, and degenerate."""
    import itertools
    import math
    import random

    from simcore.evaluation.metrics import Box, footprint
    from simcore.scenario.measure import SMALL, axis_gaps

    def reference(a: Box, b: Box) -> tuple[float, float]:
        out = []
        for ax, ay in a.axes:
            pa = [x * ax + y * ay for x, y in a.corners]
            pb = [x * ax + y * ay for x, y in b.corners]
            if max(pa) < min(pb) - SMALL:
                out.append(min(pb) - max(pa))
            elif min(pa) > max(pb) + SMALL:
                out.append(max(pb) - min(pa))
            else:
                out.append(0.0)
        return out[0], out[1]

    rng = random.Random(7)
    boxes = [footprint(0.0, 0.0, 0.0, 1.4, 0.0, 4.5, 1.8), footprint(0.0, 0.0, math.nan, 1.4, 0.0, 4.5, 1.8)]
    for _ in range(200):
        x, y = rng.uniform(-20, 20), rng.uniform(-6, 6)
        heading = rng.choice((0.0, -0.0, math.pi / 2, rng.uniform(-math.pi, math.pi)))
        boxes.append(footprint(x, y, heading, 1.4, rng.choice((0.0, 0.3)), rng.choice((0.0, 4.5)), 1.8))
    for a, b in itertools.product(boxes[:30], boxes):
        assert repr(axis_gaps(a, b)) == repr(reference(a, b))
