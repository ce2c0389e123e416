"""The OpenSCENARIO object model, after parameter resolution: plain typed data, no behaviour.

The parser (`xosc.py` and its `xosc_*` parts) builds it; the engine (`engine.py`) runs it. New actions,
conditions and positions are added here as frozen dataclasses (`@record`: simcore.scenario.record), in the
parser as one function each, and in the engine as one handler each.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import field
from functools import cached_property
from pathlib import Path
from typing import Literal

from simcore.scenario.record import record

Rule = Literal["greaterThan", "lessThan", "equalTo", "greaterOrEqual", "lessOrEqual", "notEqualTo"]
Edge = Literal["rising", "falling", "risingOrFalling", "none"]
Shape = Literal["linear", "cubic", "sinusoidal", "step"]
Dimension = Literal["time", "distance", "rate"]


# --- entities ------------------------------------------------------------------------------------------


@record
class Box:
    center_x: float
    center_y: float
    center_z: float
    length: float
    width: float
    height: float


@record
class Performance:
    max_speed: float = 70.0
    max_acceleration: float = 5.0
    max_deceleration: float = 9.0


@record
class Entity:
    name: str
    object_type: Literal["vehicle", "pedestrian", "miscObject"]
    category: str
    box: Box
    performance: Performance
    properties: dict[str, str] = field(default_factory=dict)
    controller: dict[str, str] = field(default_factory=dict)  # the assigned controller's properties
    # every ObjectController's properties, in file order (OpenSCENARIO 1.3 allows several; `controller` is the
    # last of them, the one an ActivateControllerAction without objectControllerRef activates, as esmini's)
    controllers: tuple[dict[str, str], ...] = ()
    wheelbase: float | None = None  # vehicles: FrontAxle.positionX − RearAxle.positionX, m
    max_steering: float | None = None  # vehicles: FrontAxle.maxSteering, rad
    source: str = ""  # "file:line" of its ScenarioObject (for messages)
    trailer_hitch: float | None = None  # vehicles: TrailerHitch dx (m ahead of the reference point)
    trailer_coupler: float | None = None  # trailers: TrailerCoupler dx
    trailer: str | None = None  # the entity towed from the start (Trailer/TrailerRef)

    @cached_property
    def driver(self) -> str:
        """Who moves the entity: "scenario" (default), "sumo" (`carlos.driver=sumo` controller property) or
        "external": the system under test through its control topic (`carlos.driver=external`, or the
        controllers other tools name for it: esmini's ExternalController and InteractiveController)."""
        driver = self.controller.get("carlos.driver")
        if driver is not None:
            return driver
        if controller_type(self.controller) in EXTERNAL_CONTROLLERS:
            return "external"
        return "scenario"


# controllers of other tools whose entity is moved from outside the scenario (a program, a person)
EXTERNAL_CONTROLLERS = frozenset({"ExternalController", "InteractiveController"})
# esmini's controllers of the registry (simcore.scenario.controllers), one module each: ALKS_R157SM (the UN R157
# driver models), SloppyDriver
REGISTERED_CONTROLLERS = frozenset(
    {"ALKS_R157SM_Controller", "SloppyDriverController", "FollowRouteController", "LoomingController"}
)
# esmini's driver controllers CARLOS runs with esmini's algorithm (simcore.scenario.actions.AccDriver): the
# ALKS controller is esmini's ACC controller under another name
ACC_CONTROLLERS = frozenset({"ACCController", "ALKSController"})
# controllers whose entities move as under the reference player: compared in conformance like scripted ones
# esmini's FollowGhostController (simcore.scenario.ghost): a ghost runs the actions ahead, the entity follows it
FOLLOW_GHOST_CONTROLLERS = frozenset({"FollowGhostController"})
# esmini's controllers with a vehicle model of their own CARLOS runs (simcore.scenario.drivers)
VEHICLE_CONTROLLERS = frozenset({"OffroadFollower"})
# esmini's NaturalDriver (simcore.scenario.drivers.NaturalDriver): IDM speed and lane changes of its own
NATURAL_DRIVER_CONTROLLERS = frozenset({"NaturalDriver"})
MODELLED_CONTROLLERS = (
    ACC_CONTROLLERS
    | FOLLOW_GHOST_CONTROLLERS
    | VEHICLE_CONTROLLERS
    | NATURAL_DRIVER_CONTROLLERS
    | REGISTERED_CONTROLLERS
    # esmini's ExternalController with no input holds its entity, as the engine does until a command arrives
    | {"", "DefaultController", "ExternalController"}
)


def partly_modelled(properties: dict[str, str]) -> bool:
    """A controller CARLOS runs only in part: esmini's LoomingController in override mode, which also steers
    its entity (CARLOS runs its speed)."""
    return controller_type(properties) == "LoomingController" and properties.get("mode") == "override"


# the key under which a controller's properties keep the name of the ObjectController that gives it
OBJECT_CONTROLLER = "carlos.objectController"


def controller_type(properties: dict[str, str]) -> str:
    """The kind of a controller: its `esminiController` property, else its name (as esmini decides)."""
    return properties.get("esminiController") or properties.get("name", "")


def property_number(text: str | None, default: float) -> float:
    """A controller property as a number: `default` when it is missing, empty or not a number (as esmini
    reads its controller properties)."""
    try:
        return float(text) if text is not None and text.strip() else default
    except ValueError:
        return default


# --- positions -----------------------------------------------------------------------------------------


@record
class Orientation:
    type: Literal["relative", "absolute"] = "absolute"
    h: float = 0.0
    p: float = 0.0
    r: float = 0.0


@record
class WorldPosition:
    x: float
    y: float
    z: float | None = None
    h: float | None = None
    p: float = 0.0
    r: float = 0.0


@record
class LanePosition:
    road_id: str
    lane_id: int
    s: float
    offset: float = 0.0
    orientation: Orientation | None = None
    source: str = field(default="", compare=False)  # "file:line" (for messages)


@record
class RoadPosition:
    road_id: str
    s: float
    t: float
    orientation: Orientation | None = None


@record
class RelativeLanePosition:
    entity: str
    d_lane: int
    ds: float  # along the road's s (`ds`), or along the lane in the entity's travel direction (`dsLane`)
    offset: float = 0.0
    orientation: Orientation | None = None
    along_lane: bool = False  # given as dsLane


@record
class RelativeRoadPosition:
    entity: str
    ds: float
    dt: float
    orientation: Orientation | None = None


@record
class RelativeWorldPosition:
    entity: str
    dx: float
    dy: float
    dz: float = 0.0
    orientation: Orientation | None = None


@record
class RelativeObjectPosition:
    entity: str
    dx: float
    dy: float
    dz: float = 0.0
    orientation: Orientation | None = None


@record
class RoutePosition:
    """A position along a route: `route` is resolved when used (the route of `entity` or an inline one)."""

    route: Route | None
    entity: str | None  # InRoutePosition/FromCurrentEntity: the entity's current position
    path_s: float | None = None  # PositionInRoadCoordinates/pathS
    t: float = 0.0
    lane_id: int | None = None  # PositionInLaneCoordinates
    lane_offset: float = 0.0
    orientation: Orientation | None = None


@record
class TrajectoryPosition:
    trajectory: Trajectory
    s: float
    t: float = 0.0
    orientation: Orientation | None = None


Position = (
    WorldPosition
    | LanePosition
    | RoadPosition
    | RelativeLanePosition
    | RelativeRoadPosition
    | RelativeWorldPosition
    | RelativeObjectPosition
    | RoutePosition
    | TrajectoryPosition
)


# --- routes and trajectories -------------------------------------------------------------------------------


@record
class Waypoint:
    position: Position
    strategy: str = "shortest"


@record
class Route:
    name: str
    closed: bool
    waypoints: tuple[Waypoint, ...]


@record
class Vertex:
    position: Position
    time: float | None = None


@record
class Polyline:
    vertices: tuple[Vertex, ...]


@record
class ClothoidSegment:
    curvature_start: float
    curvature_end: float
    length: float
    start: Position | None = None  # None: where the previous segment (or the entity) is
    h_offset: float = 0.0
    time_start: float | None = None
    time_end: float | None = None


@record
class Clothoid:
    segments: tuple[ClothoidSegment, ...]


@record
class ControlPoint:
    position: Position
    time: float | None = None
    weight: float = 1.0


@record
class Nurbs:
    order: int
    control_points: tuple[ControlPoint, ...]
    knots: tuple[float, ...]


TrajectoryShape = Polyline | Clothoid | Nurbs


@record
class Trajectory:
    name: str
    closed: bool
    shape: TrajectoryShape


# --- actions -------------------------------------------------------------------------------------------


@record
class TransitionDynamics:
    shape: Shape
    dimension: Dimension
    value: float


@record
class AbsoluteTargetSpeed:
    value: float


@record
class RelativeTargetSpeed:
    entity: str
    value: float
    value_type: Literal["delta", "factor"]
    continuous: bool


@record
class SpeedAction:
    dynamics: TransitionDynamics
    target: AbsoluteTargetSpeed | RelativeTargetSpeed
    domain = "longitudinal"


@record
class AbsoluteTargetLane:
    lane_id: int


@record
class RelativeTargetLane:
    entity: str
    value: int


@record
class LaneChangeAction:
    dynamics: TransitionDynamics
    target: AbsoluteTargetLane | RelativeTargetLane
    target_lane_offset: float = 0.0
    domain = "lateral"


@record
class TeleportAction:
    position: Position
    domain = "teleport"


@record
class LaneOffsetAction:
    shape: Shape
    max_lateral_acc: float | None
    offset: float  # target lane offset (m, + left of the lane centre in the travel direction)
    entity: str | None = None  # RelativeTargetLaneOffset: relative to this entity's offset
    continuous: bool = False
    domain = "lateral"


@record
class DynamicConstraints:
    max_acceleration: float | None = None
    max_deceleration: float | None = None
    max_speed: float | None = None
    max_acceleration_rate: float | None = None  # jerk limits, m/s³
    max_deceleration_rate: float | None = None


@record
class LongitudinalDistanceAction:
    entity: str
    distance: float | None
    time_gap: float | None
    freespace: bool
    continuous: bool
    displacement: str  # trailingReferencedEntity | leadingReferencedEntity | any
    constraints: DynamicConstraints | None
    coordinate_system: str = "entity"
    domain = "longitudinal"


@record
class LateralDistanceAction:
    entity: str
    distance: float
    freespace: bool
    continuous: bool
    displacement: str  # leftToReferencedEntity | rightToReferencedEntity | any
    constraints: DynamicConstraints | None
    coordinate_system: str = "entity"  # entity | road (1.1)
    domain = "lateral"


@record
class SpeedProfileEntry:
    speed: float
    time: float | None


@record
class SpeedProfileAction:
    entity: str | None  # speeds relative to this entity's speed when given
    following_mode: str  # position | follow
    entries: tuple[SpeedProfileEntry, ...]
    constraints: DynamicConstraints | None
    max_jerk: float | None = None
    domain = "longitudinal"


@record
class FollowTrajectoryAction:
    trajectory: Trajectory
    timing: Literal["none", "absolute", "relative"]
    scale: float = 1.0
    offset: float = 0.0
    initial_distance_offset: float = 0.0
    following_mode: str = "position"
    domain = "lateral"


@record
class AssignRouteAction:
    route: Route
    domain = "route"


@record
class AcquirePositionAction:
    position: Position
    domain = "route"


@record
class SynchronizeAction:
    master: str
    master_position: Position
    position: Position
    master_tolerance: float = 0.0
    tolerance: float = 0.0
    final_speed: float | None = None  # AbsoluteSpeed
    final_relative: tuple[str, float, str] | None = None  # (entity, value, delta|factor) steady state
    steady_distance: float | None = None  # final speed held over this distance before the target
    steady_time: float | None = None  # … or for this time
    domain = "longitudinal"


@record
class TrailerAction:
    """ConnectTrailerAction (trailer given) or DisconnectTrailerAction (trailer None), OpenSCENARIO 1.3."""

    trailer: str | None
    domain = "trailer"


@record
class NoMotionAction:
    """Recorded, no effect on motion: lights, visibility, appearance, controllers CARLOS does not model."""

    kind: str
    domain = "none"


@record
class ControllerAction:
    """Assign and/or (de)activate an entity's controller. `assign`: the driver of the controller assigned
    now ("external", "scenario"), None when nothing is assigned; `longitudinal`/`lateral`: True activates,
    False deactivates, None leaves that domain as it is. Only an external controller changes motion: while
    it is active on a domain, the entity moves by its control input (without one, it stands still)."""

    assign: str | None = None
    longitudinal: bool | None = None
    lateral: bool | None = None
    controller: tuple[tuple[str, str], ...] = ()  # the assigned controller's properties (with its "name")
    ref: str | None = None  # ActivateControllerAction objectControllerRef: the controller it activates
    domain = "none"


PrivateAction = (
    SpeedAction
    | LaneChangeAction
    | TeleportAction
    | LaneOffsetAction
    | LongitudinalDistanceAction
    | LateralDistanceAction
    | SpeedProfileAction
    | FollowTrajectoryAction
    | AssignRouteAction
    | AcquirePositionAction
    | SynchronizeAction
    | TrailerAction
    | NoMotionAction
    | ControllerAction
)


@record
class ParameterSetAction:
    name: str
    value: str
    variable: bool = False  # VariableSetAction


@record
class ParameterModifyAction:
    name: str
    rule: Literal["add", "multiply"]
    value: float
    variable: bool = False


@record
class AddEntityAction:
    entity: str
    position: Position


@record
class DeleteEntityAction:
    entity: str


@record
class TrafficSignalStateAction:
    """InfrastructureAction/TrafficSignalAction/TrafficSignalStateAction: a signal (by its OpenDRIVE id or
    name) shows `state` (e.g. "off;off;on", one entry per lamp) from now on."""

    name: str
    state: str


@record
class TrafficSignalControllerAction:
    """TrafficSignalControllerAction: the controller jumps to `phase` (its cycle goes on from there)."""

    controller: str
    phase: str


@record
class NoMotionGlobalAction:
    kind: str


GlobalAction = (
    ParameterSetAction
    | ParameterModifyAction
    | AddEntityAction
    | DeleteEntityAction
    | TrafficSignalStateAction
    | TrafficSignalControllerAction
    | NoMotionGlobalAction
)


# --- conditions ----------------------------------------------------------------------------------------


@record
class SimulationTimeCondition:
    value: float
    rule: Rule


@record
class StoryboardElementStateCondition:
    element_type: str
    element_ref: str
    state: str  # startTransition, endTransition, stopTransition, skipTransition, completeState, runningState, standbyState


@record
class ParameterCondition:
    name: str
    value: str
    rule: Rule


@record
class RelativeDistanceCondition:
    entity: str
    distance_type: Literal["longitudinal", "lateral", "cartesianDistance", "euclidianDistance"]
    freespace: bool
    value: float
    rule: Rule
    coordinate_system: str = "entity"  # entity | road | lane | trajectory


@record
class SpeedCondition:
    value: float
    rule: Rule
    direction: str | None = None  # 1.2+: longitudinal | lateral | vertical (None: the speed)


@record
class RelativeSpeedCondition:
    entity: str
    value: float
    rule: Rule
    direction: str | None = None  # 1.2+: in the reference entity's frame


@record
class AccelerationCondition:
    value: float
    rule: Rule


@record
class TraveledDistanceCondition:
    value: float


@record
class ReachPositionCondition:
    position: Position
    tolerance: float


@record
class DistanceCondition:
    position: Position
    freespace: bool
    value: float
    rule: Rule
    distance_type: str = "euclidianDistance"  # longitudinal | lateral | euclidianDistance (1.1+)
    coordinate_system: str = "entity"  # entity | road | lane | trajectory (1.1+)


@record
class TimeHeadwayCondition:
    entity: str
    freespace: bool
    value: float
    rule: Rule
    coordinate_system: str = "entity"  # entity | road | lane | trajectory
    distance_type: str = "euclidianDistance"  # longitudinal | lateral | euclidianDistance


@record
class TimeToCollisionCondition:
    entity: str
    freespace: bool
    value: float
    rule: Rule
    coordinate_system: str = "entity"
    position: Position | None = None  # to a position instead of an entity
    distance_type: str = "euclidianDistance"


@record
class StandStillCondition:
    duration: float


@record
class CollisionCondition:
    entity: str | None  # None: with any entity


@record
class EndOfRoadCondition:
    duration: float


@record
class VariableCondition:
    name: str
    value: str
    rule: Rule


@record
class RelativeClearanceCondition:
    entities: tuple[str, ...]
    free_space: bool  # distances between bounding boxes (else reference points)
    distance_forward: float
    distance_backward: float
    opposite_lanes: bool
    lanes: tuple[int, int] | None  # (from, to) relative lanes


@record
class OffroadCondition:
    duration: float


@record
class TrafficSignalCondition:
    """The signal (OpenDRIVE id or name) shows exactly `state`."""

    name: str
    state: str


@record
class TrafficSignalControllerCondition:
    """The traffic signal controller is in `phase`."""

    controller: str
    phase: str


@record
class AngleCondition:
    """The triggering entity's heading, pitch or roll is `angle` within `tolerance` (rad): absolute (in
    the world) by default, relative to the road's or the lane's direction in those coordinate systems."""

    angle_type: Literal["heading", "pitch", "roll"]
    angle: float
    tolerance: float
    coordinate_system: str = "entity"


@record
class RelativeAngleCondition:
    """The triggering entity's heading, pitch or roll less that of `entity` is `angle` within `tolerance`."""

    entity: str
    angle_type: Literal["heading", "pitch", "roll"]
    angle: float
    tolerance: float


@record
class UnsupportedCondition:
    """A condition CARLOS does not evaluate: always false (it is warned about at load)."""

    kind: str


EntityCondition = (
    RelativeDistanceCondition
    | SpeedCondition
    | RelativeSpeedCondition
    | AccelerationCondition
    | TraveledDistanceCondition
    | ReachPositionCondition
    | DistanceCondition
    | TimeHeadwayCondition
    | TimeToCollisionCondition
    | StandStillCondition
    | CollisionCondition
    | EndOfRoadCondition
    | RelativeClearanceCondition
    | OffroadCondition
    | AngleCondition
    | RelativeAngleCondition
    | UnsupportedCondition
)
ValueCondition = (
    SimulationTimeCondition
    | StoryboardElementStateCondition
    | ParameterCondition
    | VariableCondition
    | TrafficSignalCondition
    | TrafficSignalControllerCondition
    | UnsupportedCondition
)


@record
class Condition:
    name: str
    delay: float
    edge: Edge
    value_condition: ValueCondition | None = None
    entity_condition: EntityCondition | None = None
    triggering_entities: tuple[str, ...] = ()
    triggering_rule: Literal["any", "all"] = "any"


@record
class Trigger:
    """OR over condition groups, AND within a group. An empty trigger never fires."""

    groups: tuple[tuple[Condition, ...], ...]


# --- storyboard ----------------------------------------------------------------------------------------


@record
class Action:
    name: str
    private: PrivateAction | None
    global_action: GlobalAction | None = None


@record
class Event:
    name: str
    priority: Literal["override", "overwrite", "skip", "parallel"]
    maximum_execution_count: int
    actions: tuple[Action, ...]
    start_trigger: Trigger | None


@record
class Maneuver:
    name: str
    events: tuple[Event, ...]


@record
class ManeuverGroup:
    name: str
    maximum_execution_count: int
    actors: tuple[str, ...]
    select_triggering_entities: bool
    maneuvers: tuple[Maneuver, ...]


@record
class Act:
    name: str
    groups: tuple[ManeuverGroup, ...]
    start_trigger: Trigger | None
    stop_trigger: Trigger | None


@record
class Story:
    name: str
    acts: tuple[Act, ...]


@record
class SignalPhase:
    name: str
    duration: float
    states: tuple[tuple[str, str], ...]  # (traffic signal id, state)


@record
class SignalController:
    """RoadNetwork/TrafficSignals/TrafficSignalController: phases cycled from the start (after `delay`
    seconds, counted from the start of the `reference` controller when given)."""

    name: str
    delay: float
    reference: str | None
    phases: tuple[SignalPhase, ...]


@record
class InitAction:
    entity: str  # "" for a global action
    action: PrivateAction | GlobalAction


@record
class Scenario:
    path: Path
    version: str
    description: str
    road_file: Path | None
    entities: tuple[Entity, ...]
    init: tuple[InitAction, ...]
    stories: tuple[Story, ...]
    stop_trigger: Trigger | None
    parameters: dict[str, bool | int | float | str]
    variables: dict[str, bool | int | float | str] = field(default_factory=dict)
    signal_controllers: tuple[SignalController, ...] = ()
    #: unsupported elements that do not change motion: "file:line: element: what was ignored"
    warnings: tuple[str, ...] = ()


def story_actions(scenario: Scenario) -> Iterator[tuple[ManeuverGroup, Action]]:
    """Every action of every story, with the maneuver group it belongs to (its actors), in document order."""
    for story in scenario.stories:
        for act in story.acts:
            for group in act.groups:
                for maneuver in group.maneuvers:
                    for event in maneuver.events:
                        for action in event.actions:
                            yield group, action


def controller_kinds(scenario: Scenario) -> dict[str, set[str]]:
    """Entity name → the kinds of every controller it is given (ObjectController, AssignControllerAction in
    Init or in a story, to the group's actors); entities without one are left out. `carlos.driver` sumo or
    external counts as a kind of its own."""
    out: dict[str, set[str]] = {}

    def kind(properties: dict[str, str]) -> str:
        driver = properties.get("carlos.driver", "scenario")
        if partly_modelled(properties):
            return f"{controller_type(properties)} (override mode)"  # not among MODELLED_CONTROLLERS
        return f"carlos.driver={driver}" if driver != "scenario" else controller_type(properties)

    for entity in scenario.entities:
        for properties in entity.controllers or ((entity.controller,) if entity.controller else ()):
            out.setdefault(entity.name, set()).add(kind(properties))
    for item in scenario.init:
        if isinstance(item.action, ControllerAction) and item.action.controller:
            out.setdefault(item.entity, set()).add(kind(dict(item.action.controller)))
    for group, action in story_actions(scenario):
        private = action.private
        if isinstance(private, ControllerAction) and private.controller:
            for actor in group.actors:
                out.setdefault(actor, set()).add(kind(dict(private.controller)))
    return out
