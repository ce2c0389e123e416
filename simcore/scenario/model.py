"""The OpenSCENARIO object model, after parameter resolution: plain typed data, no behaviour.

The parser (`xosc.py`) builds it; the engine (`engine.py`) runs it. New actions, conditions and positions
are added here as dataclasses, in the parser as one function each, and in the engine as one handler each.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

Rule = Literal["greaterThan", "lessThan", "equalTo", "greaterOrEqual", "lessOrEqual", "notEqualTo"]
Edge = Literal["rising", "falling", "risingOrFalling", "none"]
Shape = Literal["linear", "cubic", "sinusoidal", "step"]
Dimension = Literal["time", "distance", "rate"]


# --- entities ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Box:
    center_x: float
    center_y: float
    center_z: float
    length: float
    width: float
    height: float


@dataclass(frozen=True)
class Performance:
    max_speed: float = 70.0
    max_acceleration: float = 5.0
    max_deceleration: float = 9.0


@dataclass(frozen=True)
class Entity:
    name: str
    object_type: Literal["vehicle", "pedestrian", "miscObject"]
    category: str
    box: Box
    performance: Performance
    properties: dict[str, str] = field(default_factory=dict)
    controller: dict[str, str] = field(default_factory=dict)  # the assigned controller's properties

    @property
    def driver(self) -> str:
        """Who moves the entity: "scenario" (default) or "sumo" (`carlos.driver` controller property)."""
        return self.controller.get("carlos.driver", "scenario")


# --- positions -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Orientation:
    type: Literal["relative", "absolute"] = "absolute"
    h: float = 0.0
    p: float = 0.0
    r: float = 0.0


@dataclass(frozen=True)
class WorldPosition:
    x: float
    y: float
    z: float | None = None
    h: float | None = None
    p: float = 0.0
    r: float = 0.0


@dataclass(frozen=True)
class LanePosition:
    road_id: str
    lane_id: int
    s: float
    offset: float = 0.0
    orientation: Orientation | None = None


@dataclass(frozen=True)
class RoadPosition:
    road_id: str
    s: float
    t: float
    orientation: Orientation | None = None


@dataclass(frozen=True)
class RelativeLanePosition:
    entity: str
    d_lane: int
    ds: float
    offset: float = 0.0
    orientation: Orientation | None = None


@dataclass(frozen=True)
class RelativeRoadPosition:
    entity: str
    ds: float
    dt: float
    orientation: Orientation | None = None


@dataclass(frozen=True)
class RelativeWorldPosition:
    entity: str
    dx: float
    dy: float
    dz: float = 0.0
    orientation: Orientation | None = None


@dataclass(frozen=True)
class RelativeObjectPosition:
    entity: str
    dx: float
    dy: float
    dz: float = 0.0
    orientation: Orientation | None = None


Position = (
    WorldPosition
    | LanePosition
    | RoadPosition
    | RelativeLanePosition
    | RelativeRoadPosition
    | RelativeWorldPosition
    | RelativeObjectPosition
)


# --- actions -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TransitionDynamics:
    shape: Shape
    dimension: Dimension
    value: float


@dataclass(frozen=True)
class AbsoluteTargetSpeed:
    value: float


@dataclass(frozen=True)
class RelativeTargetSpeed:
    entity: str
    value: float
    value_type: Literal["delta", "factor"]
    continuous: bool


@dataclass(frozen=True)
class SpeedAction:
    dynamics: TransitionDynamics
    target: AbsoluteTargetSpeed | RelativeTargetSpeed
    domain = "longitudinal"


@dataclass(frozen=True)
class AbsoluteTargetLane:
    lane_id: int


@dataclass(frozen=True)
class RelativeTargetLane:
    entity: str
    value: int


@dataclass(frozen=True)
class LaneChangeAction:
    dynamics: TransitionDynamics
    target: AbsoluteTargetLane | RelativeTargetLane
    target_lane_offset: float = 0.0
    domain = "lateral"


@dataclass(frozen=True)
class TeleportAction:
    position: Position
    domain = "teleport"


PrivateAction = SpeedAction | LaneChangeAction | TeleportAction


# --- conditions ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SimulationTimeCondition:
    value: float
    rule: Rule


@dataclass(frozen=True)
class StoryboardElementStateCondition:
    element_type: str
    element_ref: str
    state: str  # startTransition, endTransition, stopTransition, skipTransition, completeState, runningState, standbyState


@dataclass(frozen=True)
class ParameterCondition:
    name: str
    value: str
    rule: Rule


@dataclass(frozen=True)
class RelativeDistanceCondition:
    entity: str
    distance_type: Literal["longitudinal", "lateral", "cartesianDistance", "euclidianDistance"]
    freespace: bool
    value: float
    rule: Rule


@dataclass(frozen=True)
class SpeedCondition:
    value: float
    rule: Rule


@dataclass(frozen=True)
class RelativeSpeedCondition:
    entity: str
    value: float
    rule: Rule


@dataclass(frozen=True)
class AccelerationCondition:
    value: float
    rule: Rule


@dataclass(frozen=True)
class TraveledDistanceCondition:
    value: float


@dataclass(frozen=True)
class ReachPositionCondition:
    position: Position
    tolerance: float


@dataclass(frozen=True)
class DistanceCondition:
    position: Position
    freespace: bool
    value: float
    rule: Rule


@dataclass(frozen=True)
class TimeHeadwayCondition:
    entity: str
    freespace: bool
    value: float
    rule: Rule


@dataclass(frozen=True)
class TimeToCollisionCondition:
    entity: str
    freespace: bool
    value: float
    rule: Rule


@dataclass(frozen=True)
class StandStillCondition:
    duration: float


@dataclass(frozen=True)
class CollisionCondition:
    entity: str | None  # None: with any entity


@dataclass(frozen=True)
class EndOfRoadCondition:
    duration: float


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
)
ValueCondition = SimulationTimeCondition | StoryboardElementStateCondition | ParameterCondition


@dataclass(frozen=True)
class Condition:
    name: str
    delay: float
    edge: Edge
    value_condition: ValueCondition | None = None
    entity_condition: EntityCondition | None = None
    triggering_entities: tuple[str, ...] = ()
    triggering_rule: Literal["any", "all"] = "any"


@dataclass(frozen=True)
class Trigger:
    """OR over condition groups, AND within a group. An empty trigger never fires."""

    groups: tuple[tuple[Condition, ...], ...]


# --- storyboard ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Action:
    name: str
    private: PrivateAction | None  # None for global actions not modelled yet


@dataclass(frozen=True)
class Event:
    name: str
    priority: Literal["override", "overwrite", "skip", "parallel"]
    maximum_execution_count: int
    actions: tuple[Action, ...]
    start_trigger: Trigger | None


@dataclass(frozen=True)
class Maneuver:
    name: str
    events: tuple[Event, ...]


@dataclass(frozen=True)
class ManeuverGroup:
    name: str
    maximum_execution_count: int
    actors: tuple[str, ...]
    select_triggering_entities: bool
    maneuvers: tuple[Maneuver, ...]


@dataclass(frozen=True)
class Act:
    name: str
    groups: tuple[ManeuverGroup, ...]
    start_trigger: Trigger | None
    stop_trigger: Trigger | None


@dataclass(frozen=True)
class Story:
    name: str
    acts: tuple[Act, ...]


@dataclass(frozen=True)
class InitAction:
    entity: str
    action: PrivateAction


@dataclass(frozen=True)
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
    #: unsupported elements that do not change motion: "file:line: element: what was ignored"
    warnings: tuple[str, ...] = ()
