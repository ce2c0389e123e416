"""Synthetic OpenSCENARIO for the tests: the file header, a car, the road network, the Story and Storyboard
wrappers, and the few actions and conditions most scenarios start from. Each function returns XML text;
`openscenario` assembles a whole file and `write_scenario` writes one."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HIGHWAY = ROOT / "examples" / "maps" / "highway.xodr"


def file_header(minor: int | str = 2, description: str = "t") -> str:
    return (
        f'<FileHeader revMajor="1" revMinor="{minor}" date="2025-01-01T00:00:00" author="test"'
        f' description="{description}"/>'
    )


def vehicle(
    *,
    z: float = 0.75,
    width: float = 1.8,
    max_speed: float = 70,
    max_acceleration: float = 5,
    max_deceleration: float = 9,
    track_width: float | None = 1.6,
    parameters: str = "",
) -> str:
    """A Vehicle "car": a box 4.5 m long, `width` wide and 1.5 m high, its centre 1.4 m ahead of the
    reference point and `z` up; axles 2.8 m apart (none if `track_width` is None)."""
    axles = ""
    if track_width is not None:
        axles = f"""
    <Axles><FrontAxle maxSteering="0.5" wheelDiameter="0.6" trackWidth="{track_width}" positionX="2.8" positionZ="0.3"/>
      <RearAxle maxSteering="0" wheelDiameter="0.6" trackWidth="{track_width}" positionX="0" positionZ="0.3"/></Axles>"""
    return f"""
  <Vehicle name="car" vehicleCategory="car">{parameters}
    <BoundingBox><Center x="1.4" y="0" z="{z}"/><Dimensions width="{width}" length="4.5" height="1.5"/></BoundingBox>
    <Performance maxSpeed="{max_speed}" maxAcceleration="{max_acceleration}" maxDeceleration="{max_deceleration}"/>{axles}
    <Properties/>
  </Vehicle>"""


def scenario_object(name: str, body: str | None = None, controller: str = "") -> str:
    """A ScenarioObject: `body` (default: `vehicle()`; or a CatalogReference), then `controller`."""
    return f'<ScenarioObject name="{name}">{vehicle() if body is None else body}{controller}</ScenarioObject>'


def road_network(logic_file: str | Path | None = None, extra: str = "") -> str:
    if logic_file is None and not extra:
        return "<RoadNetwork/>"
    logic = "" if logic_file is None else f'<LogicFile filepath="{logic_file}"/>'
    return f"<RoadNetwork>{logic}{extra}</RoadNetwork>"


# --- actions and conditions -------------------------------------------------------------------------------


def sim_time(rule: str, value: float, edge: str = "none", delay: float = 0.0, *, name: str = "t") -> str:
    return f"""<Condition name="{name}" delay="{delay}" conditionEdge="{edge}"><ByValueCondition>
  <SimulationTimeCondition value="{value}" rule="{rule}"/></ByValueCondition></Condition>"""


def speed_action(shape: str, dimension: str, value: float, target: float) -> str:
    return f"""<PrivateAction><LongitudinalAction><SpeedAction>
  <SpeedActionDynamics dynamicsShape="{shape}" dynamicsDimension="{dimension}" value="{value}"/>
  <SpeedActionTarget><AbsoluteTargetSpeed value="{target}"/></SpeedActionTarget></SpeedAction></LongitudinalAction></PrivateAction>"""


def teleport_world(x: float, y: float = 0, h: float = 0) -> str:
    return (
        "<PrivateAction><TeleportAction><Position>"
        f'<WorldPosition x="{x}" y="{y}" h="{h}"/>'
        "</Position></TeleportAction></PrivateAction>"
    )


def teleport_lane(s: float, lane: int = -2) -> str:
    """To `s` along road 1, in the middle of lane `lane`."""
    return (
        "<PrivateAction><TeleportAction><Position>"
        f'<LanePosition roadId="1" laneId="{lane}" s="{s}" offset="0"/>'
        "</Position></TeleportAction></PrivateAction>"
    )


def private_actions(entity: str, *actions: str) -> str:
    """Init's Private element of `entity` with these PrivateActions."""
    return f'<Private entityRef="{entity}">{"".join(actions)}</Private>'


def place(name: str, s: float, lane: int = -2, speed: float = 20.0) -> str:
    """Init actions: `name` at `s` along road 1 in lane `lane`, at `speed` at once."""
    return f"""
<Private entityRef="{name}">
  {teleport_lane(s, lane)}
  {speed_action("step", "time", 0, speed)}
</Private>"""


def event(name: str, action: str, trigger: str, priority: str = "override", count: int = 1) -> str:
    """An event with the one action `action` (named `name`Action), started by the condition `trigger`."""
    return f"""<Event name="{name}" priority="{priority}" maximumExecutionCount="{count}">
  <Action name="{name}Action">{action}</Action>
  <StartTrigger><ConditionGroup>{trigger}</ConditionGroup></StartTrigger></Event>"""


# --- the storyboard and the file ----------------------------------------------------------------------------


def act(
    events: str = "",
    *,
    actor: str = "Ego",
    start: str | None = None,
    name: str = "A",
    group: str = "G",
    maneuver: str = "M",
    maneuvers: str | None = None,
) -> str:
    """An act with one maneuver group (run once) of `actor`: the maneuver `maneuver` with these events, or
    `maneuvers` as they are (e.g. a CatalogReference); started by the condition `start` (default: t ≥ 0)."""
    body = f'<Maneuver name="{maneuver}">{events}</Maneuver>' if maneuvers is None else maneuvers
    start = sim_time("greaterOrEqual", 0) if start is None else start
    return f"""<Act name="{name}">
      <ManeuverGroup name="{group}" maximumExecutionCount="1"><Actors selectTriggeringEntities="false"><EntityRef entityRef="{actor}"/></Actors>
        {body}
      </ManeuverGroup>
      <StartTrigger><ConditionGroup>{start}</ConditionGroup></StartTrigger>
    </Act>"""


def story(*acts: str, name: str = "S") -> str:
    return f'<Story name="{name}">{"".join(acts)}</Story>'


def openscenario(
    *,
    entities: str,
    init: str = "",
    stories: str = "",
    stop: str = "",
    road: str = "",
    parameters: str = "",
    catalogs: str = "",
    minor: int | str = 2,
    description: str = "t",
) -> str:
    """A whole OpenSCENARIO file (revision 1.`minor`). `entities`, `init` (Init's actions) and `stories` are
    XML; `stop` is the StopTrigger's condition group (none: an empty StopTrigger); `parameters`,
    `catalogs` and `road` are the whole ParameterDeclarations, CatalogLocations and RoadNetwork elements,
    each left out when empty."""
    trigger = (
        f"<StopTrigger><ConditionGroup>{stop}</ConditionGroup></StopTrigger>" if stop else "<StopTrigger/>"
    )
    declarations = "".join(f"\n  {part}" for part in (parameters, catalogs, road) if part)
    return f"""<?xml version="1.0"?>
<OpenSCENARIO>
  {file_header(minor, description)}{declarations}
  <Entities>{entities}</Entities>
  <Storyboard>
    <Init><Actions>{init}</Actions></Init>
    {stories}
    {trigger}
  </Storyboard>
</OpenSCENARIO>
"""


def write_scenario(directory: Path, text: str, name: str = "s.xosc") -> Path:
    path = directory / name
    path.write_text(text)
    return path
