"""Generated OpenSCENARIO for differential testing against the esmini player (`carlos conformance --against
esmini`, bench/differential.py, tests/test_differential.py).

One generator per feature type (an action, a condition or a position kind, named `action.X`, `condition.X`,
`position.X`); each draws its parameters from a seeded `random.Random` and returns a whole scenario on a road
the project ships (examples/maps: the straight three-lane motorway, the curved two-lane rural road). Every
scenario has two or three vehicles, one or more events exercising the feature, and a SimulationTime stop
trigger (conditions also end the scenario a fixed delay after they fire, so the end time checks when).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tests.xosc_fixtures import act, event, openscenario, scenario_object, sim_time, speed_action, story

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Road:
    name: str
    path: Path
    lanes: tuple[int, ...]  # driving lanes in the road's direction (negative ids)
    length: float
    straight: bool


HIGHWAY = Road("highway", ROOT / "examples" / "maps" / "highway.xodr", (-1, -2, -3), 2000.0, True)
RURAL = Road("rural", ROOT / "examples" / "maps" / "rural.xodr", (-1,), 1000.0, False)
ROADS = (HIGHWAY, RURAL)

Generator = Callable[[random.Random], str]
GENERATORS: dict[str, Generator] = {}


def feature(name: str) -> Callable[[Generator], Generator]:
    def register(fn: Generator) -> Generator:
        GENERATORS[name] = fn
        return fn

    return register


# --- building blocks -----------------------------------------------------------------------------------


def r1(x: float) -> float:
    return round(x, 1)


def r2(x: float) -> float:
    return round(x, 2)


def lane_position(s: float, lane: int, offset: float = 0.0, road: int = 1) -> str:
    return f'<Position><LanePosition roadId="{road}" laneId="{lane}" s="{r2(s)}" offset="{r2(offset)}"/></Position>'


def teleport(position: str) -> str:
    return f"<PrivateAction><TeleportAction>{position}</TeleportAction></PrivateAction>"


def private(entity: str, *actions: str) -> str:
    return f'<Private entityRef="{entity}">{"".join(actions)}</Private>'


def by_entity(entity: str, condition: str, name: str = "c", delay: float = 0.0, edge: str = "rising") -> str:
    return f"""<Condition name="{name}" delay="{delay}" conditionEdge="{edge}"><ByEntityCondition>
  <TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="{entity}"/></TriggeringEntities>
  <EntityCondition>{condition}</EntityCondition></ByEntityCondition></Condition>"""


def by_value(condition: str, name: str = "c", delay: float = 0.0, edge: str = "none") -> str:
    return f"""<Condition name="{name}" delay="{delay}" conditionEdge="{edge}"><ByValueCondition>
  {condition}</ByValueCondition></Condition>"""


def event_ended(event_name: str, delay: float, name: str = "ended") -> str:
    return by_value(
        f'<StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="{event_name}"'
        ' state="endTransition"/>',
        name=name,
        delay=delay,
        edge="none",
    )


def longitudinal(inner: str) -> str:
    return f"<PrivateAction><LongitudinalAction>{inner}</LongitudinalAction></PrivateAction>"


def lateral(inner: str) -> str:
    return f"<PrivateAction><LateralAction>{inner}</LateralAction></PrivateAction>"


def routing(inner: str) -> str:
    return f"<PrivateAction><RoutingAction>{inner}</RoutingAction></PrivateAction>"


def speed_to(target: float, shape: str = "step", dimension: str = "time", value: float = 0.0) -> str:
    return speed_action(shape, dimension, r2(value), r2(target))


@dataclass
class Setup:
    """Two (or three) vehicles on one road, placed by lane position with a speed."""

    road: Road
    ego_lane: int
    ego_s: float
    ego_speed: float
    target_lane: int
    target_s: float
    target_speed: float
    third: tuple[int, float, float] | None = None  # lane, s, speed of "Third"

    def entities(self) -> str:
        names = ["Ego", "Target"] + (["Third"] if self.third else [])
        return "".join(scenario_object(n) for n in names)

    def init(self, *extra: str) -> str:
        parts = [
            private("Ego", teleport(lane_position(self.ego_s, self.ego_lane)), speed_to(self.ego_speed)),
            private(
                "Target",
                teleport(lane_position(self.target_s, self.target_lane)),
                speed_to(self.target_speed),
            ),
        ]
        if self.third:
            lane, s, v = self.third
            parts.append(private("Third", teleport(lane_position(s, lane)), speed_to(v)))
        return "".join(parts) + "".join(extra)

    def file(
        self, stories: str, stop: str, *, init_extra: str = "", declarations: str = "", minor: int = 2
    ) -> str:
        return openscenario(
            entities=self.entities(),
            init=self.init(init_extra),
            stories=stories,
            stop=stop,
            road=f'<RoadNetwork><LogicFile filepath="{self.road.path}"/></RoadNetwork>',
            parameters=declarations,
            minor=minor,
        )


def setup(
    rng: random.Random, *, road: Road | None = None, same_lane: bool = False, ahead: bool = True
) -> Setup:
    road = road or rng.choice(ROADS)
    ego_lane = rng.choice(road.lanes)
    target_lane = ego_lane if same_lane or len(road.lanes) == 1 else rng.choice(road.lanes)
    ego_s = r1(rng.uniform(20, 150))
    gap = r1(rng.uniform(15, 60))
    target_s = ego_s + gap if ahead else max(5.0, ego_s - gap)
    return Setup(
        road, ego_lane, ego_s, r1(rng.uniform(8, 25)), target_lane, r1(target_s), r1(rng.uniform(8, 25))
    )


def stop_at(seconds: float) -> str:
    return sim_time("greaterThan", r1(seconds), name="stop")


def one_story(*events: str, actor: str = "Ego", start: str | None = None) -> str:
    return story(act("".join(events), actor=actor, start=start))


def two_stories(ego_events: str, target_events: str) -> str:
    return story(
        act(ego_events, actor="Ego", name="AE", group="GE", maneuver="ME"),
        act(target_events, actor="Target", name="AT", group="GT", maneuver="MT"),
    )


def at(t: float) -> str:
    return sim_time("greaterThan", r1(t), name="at")


# --- actions ---------------------------------------------------------------------------------------------


def _speed(shape: str, dimension: str) -> Generator:
    def generate(rng: random.Random) -> str:
        s = setup(rng)
        target = r1(rng.uniform(0, 30))
        delta = abs(target - s.ego_speed) or 1.0
        value = {
            "time": rng.uniform(1, 6),
            "rate": rng.uniform(1, 5),
            "distance": rng.uniform(0.5, 4) * delta * 3,
        }[dimension]
        ev = event("Speed", speed_to(target, shape, dimension, value), at(rng.uniform(0.5, 3)))
        return s.file(one_story(ev), stop_at(rng.uniform(8, 14)))

    return generate


for _shape in ("step", "linear", "cubic", "sinusoidal"):
    for _dimension in ("time", "rate", "distance") if _shape != "step" else ("time",):
        GENERATORS[f"action.SpeedAction.{_shape}.{_dimension}"] = _speed(_shape, _dimension)


@feature("action.SpeedAction.relative")
def _speed_relative(rng: random.Random) -> str:
    s = setup(rng)
    kind = rng.choice(["delta", "factor"])
    value = r2(rng.uniform(-4, 4)) if kind == "delta" else r2(rng.uniform(0.6, 1.4))
    continuous = rng.choice(["true", "false"])
    shape = rng.choice(["step", "linear"])
    dyn = f'<SpeedActionDynamics dynamicsShape="{shape}" dynamicsDimension="rate" value="{r1(rng.uniform(1, 4))}"/>'
    action = longitudinal(
        f'<SpeedAction>{dyn}<SpeedActionTarget><RelativeTargetSpeed entityRef="Target" value="{value}"'
        f' speedTargetValueType="{kind}" continuous="{continuous}"/></SpeedActionTarget></SpeedAction>'
    )
    ego = event("Rel", action, at(rng.uniform(0.5, 2)))
    target = event("TS", speed_to(r1(rng.uniform(5, 25)), "linear", "rate", r1(rng.uniform(1, 3))), at(3))
    return s.file(two_stories(ego, target), stop_at(rng.uniform(8, 12)))


@feature("action.TeleportAction")
def _teleport(rng: random.Random) -> str:
    s = setup(rng)
    dest = lane_position(rng.uniform(100, 400), rng.choice(s.road.lanes), rng.uniform(-0.5, 0.5))
    ev = event("Jump", teleport(dest), at(rng.uniform(0.5, 4)))
    return s.file(one_story(ev), stop_at(rng.uniform(6, 10)))


def _lane_change(relative: bool) -> Generator:
    def generate(rng: random.Random) -> str:
        s = setup(rng, road=rng.choice([HIGHWAY, HIGHWAY, RURAL]))
        shape = rng.choice(["sinusoidal", "linear", "cubic", "step"])
        dimension = rng.choice(["time", "distance"])
        value = r1(rng.uniform(2, 6) if dimension == "time" else rng.uniform(30, 120))
        lanes = [lane for lane in (s.road.lanes if s.road.straight else (-1, 1)) if lane != s.ego_lane]
        goal = rng.choice(lanes)
        if relative:
            delta = goal - s.target_lane
            if s.road.straight is False:
                delta = 1 if s.target_lane == -1 else -1
            target = f'<RelativeTargetLane entityRef="Target" value="{delta}"/>'
        else:
            target = f'<AbsoluteTargetLane value="{goal}"/>'
        offset = r2(rng.choice([0.0, 0.0, rng.uniform(-0.6, 0.6)]))
        action = lateral(
            f'<LaneChangeAction targetLaneOffset="{offset}"><LaneChangeActionDynamics dynamicsShape="{shape}"'
            f' value="{value}" dynamicsDimension="{dimension}"/><LaneChangeTarget>{target}</LaneChangeTarget>'
            "</LaneChangeAction>"
        )
        ev = event("LC", action, at(rng.uniform(0.5, 3)))
        return s.file(one_story(ev), stop_at(rng.uniform(9, 13)))

    return generate


GENERATORS["action.LaneChangeAction.absolute"] = _lane_change(False)
GENERATORS["action.LaneChangeAction.relative"] = _lane_change(True)


@feature("action.LaneOffsetAction")
def _lane_offset(rng: random.Random) -> str:
    s = setup(rng)
    shape = rng.choice(["sinusoidal", "linear", "cubic", "step"])
    if rng.random() < 0.7:
        target = f'<AbsoluteTargetLaneOffset value="{r2(rng.uniform(-1.2, 1.2))}"/>'
    else:
        target = f'<RelativeTargetLaneOffset entityRef="Target" value="{r2(rng.uniform(-1, 1))}"/>'
    action = lateral(
        f'<LaneOffsetAction continuous="false"><LaneOffsetActionDynamics maxLateralAcc="{r2(rng.uniform(0.3, 2))}"'
        f' dynamicsShape="{shape}"/><LaneOffsetTarget>{target}</LaneOffsetTarget></LaneOffsetAction>'
    )
    ev = event("LO", action, at(rng.uniform(0.5, 3)))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 12)))


def _trajectory_action(shape: str, timing: str) -> str:
    return routing(
        "<FollowTrajectoryAction><TrajectoryRef>"
        f'<Trajectory name="T" closed="false"><ParameterDeclarations/><Shape>{shape}</Shape></Trajectory>'
        f"</TrajectoryRef><TimeReference>{timing}</TimeReference>"
        '<TrajectoryFollowingMode followingMode="position"/></FollowTrajectoryAction>'
    )


def _vertices(rng: random.Random, s: Setup, count: int, t0: float, speed: float) -> list[tuple[float, str]]:
    """(time, Position) along the road ahead of Ego, with lateral wiggles."""
    out: list[tuple[float, str]] = []
    ds, t = 0.0, t0
    for _ in range(count):
        step = rng.uniform(10, 40)
        ds += step
        t += step / speed
        lane = rng.choice(s.road.lanes)
        out.append((t, lane_position(s.ego_s + s.ego_speed * t0 + ds, lane, rng.uniform(-0.8, 0.8))))
    return out


@feature("action.FollowTrajectoryAction.polyline")
def _polyline(rng: random.Random) -> str:
    s = setup(rng)
    timing = rng.choice(["none", "absolute", "relative"])
    t0 = r1(rng.uniform(0.5, 2))
    points = _vertices(rng, s, rng.randint(2, 5), t0, s.ego_speed)
    shape = "<Polyline>" + "".join(f'<Vertex time="{r2(t)}">{p}</Vertex>' for t, p in points) + "</Polyline>"
    if timing == "none":
        reference = "<None/>"
    else:
        offset = 0.0 if timing == "absolute" else -t0
        reference = f'<Timing domainAbsoluteRelative="{timing}" scale="1" offset="{r2(offset)}"/>'
    ev = event("Traj", _trajectory_action(shape, reference), at(t0))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 14)))


@feature("action.FollowTrajectoryAction.clothoid")
def _clothoid(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    t0 = r1(rng.uniform(0.5, 2))
    length = r1(rng.uniform(40, 120))
    start = lane_position(s.ego_s + s.ego_speed * t0, s.ego_lane)
    shape = (
        f'<Clothoid curvature="{r2(rng.uniform(-0.004, 0.004))}" curvaturePrime="{round(rng.uniform(-1e-4, 1e-4), 6)}"'
        f' length="{length}">{start}</Clothoid>'
    )
    ev = event("Traj", _trajectory_action(shape, "<None/>"), at(t0))
    return s.file(one_story(ev), stop_at(rng.uniform(6, 10)))


@feature("action.FollowTrajectoryAction.nurbs")
def _nurbs(rng: random.Random) -> str:
    s = setup(rng)
    t0 = r1(rng.uniform(0.5, 2))
    points = _vertices(rng, s, rng.randint(4, 6), t0, s.ego_speed)
    order = rng.choice([2, 3, 4])
    n = len(points)
    inner = max(0, n - order)
    knots = [0.0] * order + [float(i + 1) for i in range(inner)] + [float(inner + 1)] * order
    body = "".join(f'<ControlPoint time="{r2(t)}" weight="1">{p}</ControlPoint>' for t, p in points)
    body += "".join(f'<Knot value="{k}"/>' for k in knots)
    ev = event("Traj", _trajectory_action(f'<Nurbs order="{order}">{body}</Nurbs>', "<None/>"), at(t0))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 12)))


@feature("action.AssignRouteAction")
def _assign_route(rng: random.Random) -> str:
    s = setup(rng)
    strategy = rng.choice(["shortest", "fastest", "leastIntersections", "random"])
    wps = "".join(
        f'<Waypoint routeStrategy="{strategy}">{lane_position(s.ego_s + d, rng.choice(s.road.lanes))}</Waypoint>'
        for d in sorted(rng.uniform(30, 400) for _ in range(rng.randint(2, 3)))
    )
    action = routing(f'<AssignRouteAction><Route name="R" closed="false">{wps}</Route></AssignRouteAction>')
    ev = event("Route", action, at(rng.uniform(0.5, 2)))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 12)))


@feature("action.AcquirePositionAction")
def _acquire(rng: random.Random) -> str:
    s = setup(rng)
    dest = lane_position(s.ego_s + rng.uniform(80, 400), rng.choice(s.road.lanes))
    action = routing(f"<AcquirePositionAction>{dest}</AcquirePositionAction>")
    ev = event("Acq", action, at(rng.uniform(0.5, 2)))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 12)))


@feature("action.SynchronizeAction")
def _synchronize(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    lead = rng.uniform(150, 250)
    master = lane_position(s.target_s + lead, s.target_lane)
    mine = lane_position(s.target_s + lead + rng.uniform(-20, 20), s.ego_lane)
    final = (
        f'<FinalSpeed><AbsoluteSpeed value="{r1(rng.uniform(5, 25))}"/></FinalSpeed>'
        if rng.random() < 0.6
        else ""
    )
    action = (
        f'<PrivateAction><SynchronizeAction masterEntityRef="Target"><TargetPositionMaster>{master[10:-11]}'
        f"</TargetPositionMaster><TargetPosition>{mine[10:-11]}</TargetPosition>{final}</SynchronizeAction>"
        "</PrivateAction>"
    )
    ev = event("Sync", action, at(rng.uniform(0.2, 1)))
    return s.file(one_story(ev), stop_at(rng.uniform(10, 15)))


@feature("action.LongitudinalDistanceAction")
def _long_distance(rng: random.Random) -> str:
    s = setup(rng, same_lane=True)
    what = (
        f'distance="{r1(rng.uniform(10, 40))}"'
        if rng.random() < 0.5
        else f'timeGap="{r2(rng.uniform(0.8, 2.5))}"'
    )
    constraints = (
        f'<DynamicConstraints maxAcceleration="{r1(rng.uniform(2, 5))}" maxDeceleration="{r1(rng.uniform(4, 8))}"'
        ' maxSpeed="50"/>'
        if rng.random() < 0.5
        else ""
    )
    action = longitudinal(
        f'<LongitudinalDistanceAction entityRef="Target" {what} freespace="{rng.choice(["true", "false"])}"'
        f' continuous="{rng.choice(["true", "false"])}">{constraints}</LongitudinalDistanceAction>'
    )
    ego = event("LD", action, at(rng.uniform(0.5, 2)))
    target = event("TS", speed_to(r1(rng.uniform(8, 25)), "linear", "rate", 2), at(3))
    return s.file(two_stories(ego, target), stop_at(rng.uniform(8, 14)))


@feature("action.LateralDistanceAction")
def _lat_distance(rng: random.Random) -> str:
    s = setup(rng)
    s.target_s = s.ego_s + r1(rng.uniform(-5, 5))
    s.target_speed = s.ego_speed
    constraints = (
        f'<DynamicConstraints maxAcceleration="{r1(rng.uniform(0.5, 3))}" maxSpeed="{r1(rng.uniform(1, 4))}"/>'
        if rng.random() < 0.6
        else ""
    )
    action = lateral(
        f'<LateralDistanceAction entityRef="Target" distance="{r1(rng.uniform(2, 5))}"'
        f' freespace="{rng.choice(["true", "false"])}" continuous="{rng.choice(["true", "false"])}">'
        f"{constraints}</LateralDistanceAction>"
    )
    ev = event("Lat", action, at(rng.uniform(0.5, 2)))
    return s.file(one_story(ev), stop_at(rng.uniform(6, 10)))


@feature("action.SpeedProfileAction")
def _speed_profile(rng: random.Random) -> str:
    s = setup(rng)
    mode = rng.choice(["follow", "position"])
    entries = "".join(
        f'<SpeedProfileEntry speed="{r1(rng.uniform(3, 28))}" time="{r1(rng.uniform(1, 4))}"/>'
        for _ in range(rng.randint(1, 4))
    )
    constraints = f'<DynamicConstraints maxAcceleration="{r1(rng.uniform(2, 5))}" maxDeceleration="{r1(rng.uniform(3, 8))}"/>'
    action = longitudinal(
        f'<SpeedProfileAction followingMode="{mode}">{constraints}{entries}</SpeedProfileAction>'
    )
    ev = event("SP", action, at(rng.uniform(0.5, 2)))
    return s.file(one_story(ev), stop_at(rng.uniform(10, 16)))


def _global_event(name: str, action: str, trigger: str) -> str:
    return f"""<Event name="{name}" priority="override" maximumExecutionCount="1">
  <Action name="{name}Action"><GlobalAction>{action}</GlobalAction></Action>
  <StartTrigger><ConditionGroup>{trigger}</ConditionGroup></StartTrigger></Event>"""


@feature("action.DeleteEntityAction")
def _delete(rng: random.Random) -> str:
    s = setup(rng)
    ev = _global_event("Del", '<EntityAction entityRef="Target"><DeleteEntityAction/></EntityAction>', at(2))
    return s.file(one_story(ev), stop_at(rng.uniform(5, 9)))


@feature("action.AddEntityAction")
def _add(rng: random.Random) -> str:
    s = setup(rng)
    first = _global_event(
        "Del", '<EntityAction entityRef="Target"><DeleteEntityAction/></EntityAction>', at(1)
    )
    again = _global_event(
        "Add",
        '<EntityAction entityRef="Target"><AddEntityAction>'
        f"{lane_position(rng.uniform(100, 300), rng.choice(s.road.lanes))}</AddEntityAction></EntityAction>",
        at(rng.uniform(2, 4)),
    )
    return s.file(one_story(first, again), stop_at(rng.uniform(6, 9)))


@feature("action.VariableSetAction")
def _variable(rng: random.Random) -> str:
    s = setup(rng)
    value = rng.randint(1, 9)
    set_ev = _global_event(
        "Set",
        f'<VariableAction variableRef="v"><SetAction value="{value}"/></VariableAction>',
        at(rng.uniform(1, 4)),
    )
    react = event(
        "React",
        speed_to(r1(rng.uniform(0, 25)), "linear", "rate", 3),
        by_value(f'<VariableCondition variableRef="v" value="{value}" rule="equalTo"/>'),
    )
    declarations = '<VariableDeclarations><VariableDeclaration name="v" variableType="int" value="0"/></VariableDeclarations>'
    return s.file(one_story(set_ev, react), stop_at(rng.uniform(8, 12)), declarations=declarations)


@feature("action.ParameterSetAction")
def _parameter(rng: random.Random) -> str:
    s = setup(rng)
    value = rng.randint(1, 9)
    set_ev = _global_event(
        "Set",
        f'<ParameterAction parameterRef="p"><SetAction value="{value}"/></ParameterAction>',
        at(rng.uniform(1, 4)),
    )
    react = event(
        "React",
        speed_to(r1(rng.uniform(0, 25)), "linear", "rate", 3),
        by_value(f'<ParameterCondition parameterRef="p" value="{value}" rule="equalTo"/>'),
    )
    declarations = '<ParameterDeclarations><ParameterDeclaration name="p" parameterType="int" value="0"/></ParameterDeclarations>'
    return s.file(one_story(set_ev, react), stop_at(rng.uniform(8, 12)), declarations=declarations)


# --- conditions: Ego reacts (a speed change) when the condition holds; the run ends a fixed delay later ----


def _reacting(
    s: Setup, rng: random.Random, condition: str, *, ego_events: str = "", target_events: str = ""
) -> str:
    react = event("React", speed_to(r1(rng.uniform(0, 25)), "step"), condition)
    delay = r1(rng.uniform(0.5, 2))
    stop = f"{stop_at(rng.uniform(12, 18))}</ConditionGroup><ConditionGroup>{event_ended('React', delay)}"
    if target_events:
        stories = two_stories(ego_events + react, target_events)
    else:
        stories = one_story(ego_events, react)
    return s.file(stories, stop)


@feature("condition.SimulationTimeCondition")
def _c_time(rng: random.Random) -> str:
    s = setup(rng)
    rule = rng.choice(["greaterThan", "greaterOrEqual", "equalTo"])
    value = r2(rng.uniform(0.3, 5))
    return _reacting(s, rng, by_value(f'<SimulationTimeCondition value="{value}" rule="{rule}"/>'))


@feature("condition.StoryboardElementStateCondition")
def _c_state(rng: random.Random) -> str:
    s = setup(rng)
    first = event("First", speed_to(r1(rng.uniform(5, 25)), "linear", "time", r1(rng.uniform(1, 4))), at(1))
    state = rng.choice(["endTransition", "completeState", "startTransition", "runningState"])
    cond = by_value(
        f'<StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="First" state="{state}"/>',
        edge="none",
    )
    return _reacting(s, rng, cond, ego_events=first)


def _accelerate(rng: random.Random, s: Setup) -> str:
    return event("Acc", speed_to(r1(rng.uniform(20, 33)), "linear", "rate", r1(rng.uniform(1, 3))), at(0.5))


@feature("condition.SpeedCondition")
def _c_speed(rng: random.Random) -> str:
    s = setup(rng)
    s.ego_speed = r1(rng.uniform(5, 15))
    cond = by_entity("Ego", f'<SpeedCondition value="{r1(rng.uniform(16, 20))}" rule="greaterThan"/>')
    return _reacting(s, rng, cond, ego_events=_accelerate(rng, s))


@feature("condition.RelativeSpeedCondition")
def _c_relspeed(rng: random.Random) -> str:
    s = setup(rng)
    s.ego_speed = s.target_speed = r1(rng.uniform(5, 15))
    cond = by_entity(
        "Ego",
        f'<RelativeSpeedCondition entityRef="Target" value="{r1(rng.uniform(1, 5))}" rule="greaterThan"/>',
    )
    return _reacting(s, rng, cond, ego_events=_accelerate(rng, s))


@feature("condition.AccelerationCondition")
def _c_acc(rng: random.Random) -> str:
    s = setup(rng)
    s.ego_speed = 8.0
    acc = event("Acc", speed_to(30, "linear", "rate", r1(rng.uniform(2, 4))), at(rng.uniform(1, 3)))
    cond = by_entity(
        "Ego", f'<AccelerationCondition value="{r1(rng.uniform(0.5, 1.5))}" rule="greaterThan"/>'
    )
    return _reacting(s, rng, cond, ego_events=acc)


@feature("condition.TraveledDistanceCondition")
def _c_traveled(rng: random.Random) -> str:
    s = setup(rng)
    cond = by_entity("Ego", f'<TraveledDistanceCondition value="{r1(rng.uniform(10, 80))}"/>')
    return _reacting(s, rng, cond)


@feature("condition.ReachPositionCondition")
def _c_reach(rng: random.Random) -> str:
    s = setup(rng)
    where = lane_position(s.ego_s + rng.uniform(20, 80), s.ego_lane, rng.uniform(-0.5, 0.5))
    cond = by_entity(
        "Ego", f'<ReachPositionCondition tolerance="{r1(rng.uniform(1, 4))}">{where}</ReachPositionCondition>'
    )
    return _reacting(s, rng, cond)


@feature("condition.DistanceCondition")
def _c_distance(rng: random.Random) -> str:
    s = setup(rng)
    where = lane_position(s.ego_s + rng.uniform(60, 150), rng.choice(s.road.lanes))
    kind = rng.choice(["euclidianDistance", "longitudinal", "lateral"])
    system = rng.choice(["entity", "road"])
    value = r1(rng.uniform(10, 40)) if kind != "lateral" else r1(rng.uniform(1, 5))
    rule = "lessThan" if kind != "lateral" else rng.choice(["lessThan", "greaterThan"])
    cond = by_entity(
        "Ego",
        f'<DistanceCondition value="{value}" freespace="{rng.choice(["true", "false"])}" rule="{rule}"'
        f' relativeDistanceType="{kind}" coordinateSystem="{system}">{where}</DistanceCondition>',
    )
    return _reacting(s, rng, cond)


@feature("condition.RelativeDistanceCondition")
def _c_reldistance(rng: random.Random) -> str:
    s = setup(rng)
    s.ego_speed = r1(s.target_speed + rng.uniform(3, 8))
    kind = rng.choice(["euclidianDistance", "longitudinal"])
    system = rng.choice(["entity", "road"])
    cond = by_entity(
        "Ego",
        f'<RelativeDistanceCondition entityRef="Target" relativeDistanceType="{kind}" value="{r1(rng.uniform(8, 20))}"'
        f' freespace="{rng.choice(["true", "false"])}" rule="lessThan" coordinateSystem="{system}"/>',
    )
    return _reacting(s, rng, cond)


@feature("condition.TimeHeadwayCondition")
def _c_headway(rng: random.Random) -> str:
    s = setup(rng, same_lane=True)
    s.ego_speed = r1(s.target_speed + rng.uniform(3, 8))
    cond = by_entity(
        "Ego",
        f'<TimeHeadwayCondition entityRef="Target" value="{r2(rng.uniform(0.8, 2))}"'
        f' freespace="{rng.choice(["true", "false"])}" rule="lessThan" coordinateSystem="{rng.choice(["entity", "road"])}"'
        ' relativeDistanceType="longitudinal"/>',
    )
    return _reacting(s, rng, cond)


@feature("condition.TimeToCollisionCondition")
def _c_ttc(rng: random.Random) -> str:
    s = setup(rng, same_lane=True)
    s.ego_speed = r1(s.target_speed + rng.uniform(3, 8))
    cond = by_entity(
        "Ego",
        f'<TimeToCollisionCondition value="{r2(rng.uniform(2, 5))}" freespace="{rng.choice(["true", "false"])}"'
        f' rule="lessThan" coordinateSystem="{rng.choice(["entity", "road"])}" relativeDistanceType="longitudinal">'
        '<TimeToCollisionConditionTarget><EntityRef entityRef="Target"/></TimeToCollisionConditionTarget>'
        "</TimeToCollisionCondition>",
    )
    return _reacting(s, rng, cond)


@feature("condition.StandStillCondition")
def _c_standstill(rng: random.Random) -> str:
    s = setup(rng)
    brake = event("Brake", speed_to(0, "linear", "rate", r1(rng.uniform(3, 8))), at(rng.uniform(0.5, 2)))
    cond = by_entity("Ego", f'<StandStillCondition duration="{r1(rng.uniform(0, 2))}"/>')
    react = event("React", speed_to(r1(rng.uniform(5, 15)), "linear", "rate", 2), cond)
    stop = f"{stop_at(rng.uniform(14, 18))}</ConditionGroup><ConditionGroup>{event_ended('React', 1.0)}"
    return s.file(one_story(brake, react), stop)


@feature("condition.EndOfRoadCondition")
def _c_end_of_road(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    s.ego_s = r1(HIGHWAY.length - rng.uniform(60, 150))
    s.ego_speed = r1(rng.uniform(15, 25))
    s.target_s = r1(s.ego_s - 40)
    cond = by_entity("Ego", f'<EndOfRoadCondition duration="{r1(rng.uniform(0, 1))}"/>')
    return _reacting(s, rng, cond)


@feature("condition.CollisionCondition")
def _c_collision(rng: random.Random) -> str:
    s = setup(rng, same_lane=True)
    s.ego_speed = r1(s.target_speed + rng.uniform(4, 10))
    cond = by_entity("Ego", '<CollisionCondition><EntityRef entityRef="Target"/></CollisionCondition>')
    react = event("React", speed_to(0, "step"), cond)
    also = event("TStop", speed_to(0, "step"), cond.replace('name="c"', 'name="c2"'))
    stop = f"{stop_at(rng.uniform(14, 18))}</ConditionGroup><ConditionGroup>{event_ended('React', 1.0)}"
    return s.file(two_stories(react, also), stop)


@feature("condition.OffroadCondition")
def _c_offroad(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    leave = event(
        "Leave",
        lateral(
            '<LaneOffsetAction continuous="false"><LaneOffsetActionDynamics maxLateralAcc="1" dynamicsShape="linear"/>'
            '<LaneOffsetTarget><AbsoluteTargetLaneOffset value="-12"/></LaneOffsetTarget></LaneOffsetAction>'
        ),
        at(1),
    )
    cond = by_entity("Ego", f'<OffroadCondition duration="{r1(rng.uniform(0, 1))}"/>')
    return _reacting(s, rng, cond, ego_events=leave)


# --- positions: Target placed in Init by the position kind, both then drive and change speed --------------


def _positioned(rng: random.Random, s: Setup, position: str) -> str:
    init = private("Ego", teleport(lane_position(s.ego_s, s.ego_lane)), speed_to(s.ego_speed))
    init += private("Target", teleport(f"<Position>{position}</Position>"), speed_to(s.target_speed))
    ev = event("Speed", speed_to(r1(rng.uniform(5, 25)), "linear", "rate", 2), at(rng.uniform(1, 3)))
    return openscenario(
        entities=scenario_object("Ego") + scenario_object("Target"),
        init=init,
        stories=two_stories(ev.replace('"Speed"', '"SpeedE"'), ev.replace('"Speed"', '"SpeedT"')),
        stop=stop_at(rng.uniform(5, 10)),
        road=f'<RoadNetwork><LogicFile filepath="{s.road.path}"/></RoadNetwork>',
    )


@feature("position.WorldPosition")
def _p_world(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    return _positioned(
        rng, s, f'<WorldPosition x="{r1(rng.uniform(50, 300))}" y="{r2(rng.uniform(-9, -1))}" h="0"/>'
    )


@feature("position.LanePosition")
def _p_lane(rng: random.Random) -> str:
    s = setup(rng)
    return _positioned(
        rng,
        s,
        f'<LanePosition roadId="1" laneId="{rng.choice(s.road.lanes)}" s="{r1(rng.uniform(50, 300))}"'
        f' offset="{r2(rng.uniform(-1, 1))}"/>',
    )


@feature("position.RoadPosition")
def _p_road(rng: random.Random) -> str:
    s = setup(rng)
    t = -r2(rng.uniform(1, 3.5 * len(s.road.lanes) - 0.5))
    return _positioned(rng, s, f'<RoadPosition roadId="1" s="{r1(rng.uniform(50, 300))}" t="{t}"/>')


@feature("position.RelativeLanePosition")
def _p_rel_lane(rng: random.Random) -> str:
    s = setup(rng)
    d_lane = rng.choice([lane - s.ego_lane for lane in s.road.lanes])
    return _positioned(
        rng,
        s,
        f'<RelativeLanePosition entityRef="Ego" dLane="{d_lane}" ds="{r1(rng.uniform(-10, 80))}"'
        f' offset="{r2(rng.uniform(-0.8, 0.8))}"/>',
    )


@feature("position.RelativeRoadPosition")
def _p_rel_road(rng: random.Random) -> str:
    s = setup(rng)
    return _positioned(
        rng,
        s,
        f'<RelativeRoadPosition entityRef="Ego" ds="{r1(rng.uniform(-10, 80))}" dt="{r2(rng.uniform(-3, 3))}"/>',
    )


@feature("position.RelativeWorldPosition")
def _p_rel_world(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    return _positioned(
        rng,
        s,
        f'<RelativeWorldPosition entityRef="Ego" dx="{r1(rng.uniform(10, 80))}" dy="{r2(rng.uniform(-3, 3))}"/>',
    )


@feature("position.RelativeObjectPosition")
def _p_rel_object(rng: random.Random) -> str:
    s = setup(rng)
    return _positioned(
        rng,
        s,
        f'<RelativeObjectPosition entityRef="Ego" dx="{r1(rng.uniform(10, 80))}" dy="{r2(rng.uniform(-3, 3))}"/>',
    )


@feature("position.RoutePosition")
def _p_route(rng: random.Random) -> str:
    s = setup(rng)
    wps = "".join(
        f'<Waypoint routeStrategy="shortest">{lane_position(d, s.road.lanes[0])}</Waypoint>'
        for d in (10.0, 500.0)
    )
    in_route = (
        f'<FromLaneCoordinates pathS="{r1(rng.uniform(30, 300))}" laneId="{rng.choice(s.road.lanes)}"'
        f' laneOffset="{r2(rng.uniform(-0.5, 0.5))}"/>'
    )
    return _positioned(
        rng,
        s,
        f'<RoutePosition><RouteRef><Route name="R" closed="false">{wps}</Route></RouteRef>'
        f"<InRoutePosition>{in_route}</InRoutePosition></RoutePosition>",
    )


# --- the suite ---------------------------------------------------------------------------------------------


def generate(
    directory: Path, per_type: int, seed: int = 1, types: list[str] | None = None
) -> dict[Path, str]:
    """Write `per_type` scenarios of every feature type (or of `types`) into `directory`; file → type."""
    directory.mkdir(parents=True, exist_ok=True)
    out: dict[Path, str] = {}
    for name in sorted(types or GENERATORS):
        for index in range(per_type):
            rng = random.Random(f"{seed}:{name}:{index}")
            path = directory / f"{name}.{index:03d}.xosc"
            path.write_text(GENERATORS[name](rng))
            out[path] = name
    return out


# --- loading: files other tools write that must load and run as esmini runs them ----------------------------


def _simple(
    rng: random.Random, names: tuple[str, ...] = ("Ego", "Target"), road: Road | None = None, **kwargs: str
) -> str:
    road = road or rng.choice(ROADS)
    init = kwargs.pop("init", None)
    if init is None:
        init = "".join(
            private(
                n,
                teleport(lane_position(rng.uniform(20, 200), rng.choice(road.lanes))),
                speed_to(r1(rng.uniform(5, 25))),
            )
            for n in names
        )
    return openscenario(
        entities="".join(scenario_object(n) for n in names),
        init=init,
        stories=kwargs.pop("stories", ""),
        stop=kwargs.pop("stop", stop_at(rng.uniform(3, 8))),
        road=f'<RoadNetwork><LogicFile filepath="{road.path}"/></RoadNetwork>',
        parameters=kwargs.pop("parameters", ""),
        minor=int(kwargs.pop("minor", "2")),
    )


@feature("loading.ParameterDeclaration.dollar_name")
def _l_dollar(rng: random.Random) -> str:
    speed = r1(rng.uniform(5, 25))
    declarations = f'<ParameterDeclarations><ParameterDeclaration name="$Speed" parameterType="double" value="{speed}"/></ParameterDeclarations>'
    ev = event(
        "S",
        longitudinal(
            '<SpeedAction><SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>'
            '<SpeedActionTarget><AbsoluteTargetSpeed value="$Speed"/></SpeedActionTarget></SpeedAction>'
        ),
        at(rng.uniform(0.5, 2)),
    )
    return _simple(rng, stories=one_story(ev), parameters=declarations)


@feature("loading.Vehicle.ParameterDeclarations")
def _l_vehicle_parameters(rng: random.Random) -> str:
    text = _simple(rng)
    return text.replace(
        '<Vehicle name="car" vehicleCategory="car">',
        '<Vehicle name="car" vehicleCategory="car"><ParameterDeclarations><ParameterDeclaration name="Top"'
        f' parameterType="double" value="{r1(rng.uniform(30, 60))}"/></ParameterDeclarations>',
    ).replace('maxSpeed="70"', 'maxSpeed="$Top"')


@feature("loading.entity_names")
def _l_names(rng: random.Random) -> str:
    names = ("Ego car", rng.choice(["car-2", "car_2", "Car.2"]), rng.choice(["car+3", "car 3", "car#3"]))
    ev = event("S", speed_to(r1(rng.uniform(0, 25)), "linear", "rate", 2), at(rng.uniform(0.5, 2)))
    return _simple(rng, names, stories=one_story(ev, actor=names[1]))


@feature("loading.empty_Action")
def _l_empty(rng: random.Random) -> str:
    empty = (
        '<Event name="E" priority="override"><Action name="A"/><StartTrigger><ConditionGroup>'
        f"{at(rng.uniform(0.5, 2))}</ConditionGroup></StartTrigger></Event>"
    )
    ev = event(
        "S",
        speed_to(r1(rng.uniform(0, 25)), "linear", "rate", 2),
        event_ended("E", 0.5).replace("endTransition", "completeState"),
    )
    return _simple(rng, stories=one_story(empty, ev))


@feature("loading.no_entities")
def _l_no_entities(rng: random.Random) -> str:
    return openscenario(
        entities="",
        init="",
        stop=stop_at(rng.uniform(1, 5)),
        road=f'<RoadNetwork><LogicFile filepath="{HIGHWAY.path}"/></RoadNetwork>',
    )


@feature("loading.Init_refers_to_later_entity")
def _l_init_order(rng: random.Random) -> str:
    road = rng.choice(ROADS)
    lane = rng.choice(road.lanes)
    init = private(
        "Ego",
        teleport(
            f'<Position><RelativeLanePosition entityRef="Target" dLane="0" ds="{r1(-rng.uniform(10, 40))}" offset="0"/></Position>'
        ),
        speed_to(r1(rng.uniform(5, 25))),
    ) + private(
        "Target", teleport(lane_position(rng.uniform(60, 200), lane)), speed_to(r1(rng.uniform(5, 25)))
    )
    return _simple(rng, road=road, init=init)


@feature("loading.AngleCondition.world")
def _l_angle_world(rng: random.Random) -> str:
    cond = by_entity(
        "Ego",
        f'<AngleCondition angleType="heading" angle="0" angleTolerance="{r2(rng.uniform(0.05, 0.3))}" coordinateSystem="world"/>',
    )
    ev = event("S", speed_to(r1(rng.uniform(0, 25)), "linear", "rate", 2), cond)
    return _simple(rng, stories=one_story(ev), minor="3")


@feature("loading.RandomRouteAction")
def _l_random_route(rng: random.Random) -> str:
    ev = event("R", routing("<RandomRouteAction/>"), at(rng.uniform(0.5, 2)))
    return _simple(rng, stories=one_story(ev), minor="3")


# --- controllers: entities another tool's controller drives, in a headless run ----------------------------


def _controlled(kind: str) -> Generator:
    def generate(rng: random.Random) -> str:
        text = _simple(rng)
        controller = (
            '<ObjectController><Controller name="C"><Properties>'
            f'<Property name="esminiController" value="{kind}"/></Properties></Controller></ObjectController>'
        )
        text = text.replace("</Vehicle></ScenarioObject>", "</Vehicle>" + controller + "</ScenarioObject>", 1)
        lateral, longitudinal = rng.choice([("true", "true"), ("false", "true")])
        activate = (
            f'<PrivateAction><ActivateControllerAction lateral="{lateral}" longitudinal="{longitudinal}"/>'
            "</PrivateAction>"
        )
        return text.replace("</Private>", activate + "</Private>", 1)

    return generate


for _kind in ("InteractiveController", "ExternalController"):
    GENERATORS[f"controller.{_kind}"] = _controlled(_kind)


@feature("controller.FollowGhostController")
def _follow_ghost(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    s.target_s = s.ego_s + 80
    mode = rng.choice(["time", "position"])
    properties = {
        "esminiController": "FollowGhostController",
        "headstartTime": str(r1(rng.uniform(1, 3))),
        "followMode": mode,
    }
    controller = (
        '<ObjectController><Controller name="G"><Properties>'
        + "".join(f'<Property name="{k}" value="{v}"/>' for k, v in properties.items())
        + "</Properties></Controller></ObjectController>"
    )
    activate = '<PrivateAction><ActivateControllerAction lateral="true" longitudinal="true"/></PrivateAction>'
    goal = rng.choice([lane for lane in HIGHWAY.lanes if lane != s.ego_lane])
    change = lateral(
        '<LaneChangeAction><LaneChangeActionDynamics dynamicsShape="sinusoidal" dynamicsDimension="time"'
        f' value="{r1(rng.uniform(3, 6))}"/><LaneChangeTarget><AbsoluteTargetLane value="{goal}"/>'
        "</LaneChangeTarget></LaneChangeAction>"
    )
    events = event("Speed", speed_to(r1(rng.uniform(10, 30)), "linear", "rate", 2), at(rng.uniform(1, 3)))
    events += event("LC", change, at(rng.uniform(4, 7)))
    text = s.file(one_story(events), stop_at(rng.uniform(12, 16)))
    text = text.replace("</Vehicle></ScenarioObject>", "</Vehicle>" + controller + "</ScenarioObject>", 1)
    return text.replace("</Private>", activate + "</Private>", 1)


# --- routes through a junction (a four-way crossing written with scenariogeneration, a dev dependency) --------


def crossing() -> Road:
    """Four 150 m roads (ids 0–3, one lane each way, their ends at the junction) and the connecting roads of
    a four-way junction, written once per machine into the temporary directory."""
    import os
    import tempfile

    path = Path(tempfile.gettempdir()) / "carlos-differential-crossing.xodr"
    if not path.is_file():
        import numpy as np
        from scenariogeneration import xodr

        roads = [xodr.create_road(xodr.Line(150), id=i, left_lanes=1, right_lanes=1) for i in range(4)]
        junction = xodr.CommonJunctionCreator(id=100, name="crossing", startnum=100)
        for i, angle in enumerate((0.0, np.pi / 2, np.pi, 3 * np.pi / 2)):
            junction.add_incoming_road_circular_geometry(
                road=roads[i], radius=15, angle=angle, road_connection="successor"
            )
        for a in range(4):
            for b in range(a + 1, 4):
                junction.add_connection(road_one_id=a, road_two_id=b)
        network = xodr.OpenDrive("crossing")
        for road in roads:
            network.add_road(road)
        network.add_junction_creator(junction)
        network.adjust_roads_and_lanes()
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        network.write_xml(str(partial))
        partial.replace(path)
    return Road("crossing", path, (-1,), 150.0, True)


def _through_junction(rng: random.Random, routing_action: str | None) -> str:
    road = crossing()
    start_road = rng.randrange(4)
    s0 = r1(rng.uniform(60, 120))
    speed = r1(rng.uniform(6, 14))
    init = private("Ego", teleport(lane_position(s0, -1, road=start_road)), speed_to(speed)) + private(
        "Target",
        teleport(lane_position(r1(rng.uniform(20, 60)), -1, road=(start_road + 2) % 4)),
        speed_to(speed),
    )
    events = ""
    if routing_action is not None:
        exit_road = rng.choice([r for r in range(4) if r != start_road])
        events = event("Route", routing_action.format(exit=exit_road, s=r1(rng.uniform(40, 120))), at(0.5))
    seconds = (150 - s0 + 30 + 40) / speed
    return openscenario(
        entities=scenario_object("Ego") + scenario_object("Target"),
        init=init,
        stories=one_story(events) if events else "",
        stop=stop_at(min(seconds, 20)),
        road=f'<RoadNetwork><LogicFile filepath="{road.path}"/></RoadNetwork>',
    )


@feature("route.junction_without_route")
def _r_default(rng: random.Random) -> str:
    return _through_junction(rng, None)


@feature("route.AssignRouteAction.junction")
def _r_assign(rng: random.Random) -> str:
    strategy = rng.choice(["shortest", "fastest", "leastIntersections", "random"])
    action = routing(
        '<AssignRouteAction><Route name="R" closed="false">'
        f'<Waypoint routeStrategy="{strategy}"><Position><LanePosition roadId="{{start}}" laneId="-1" s="140"/></Position></Waypoint>'
        f'<Waypoint routeStrategy="{strategy}"><Position><LanePosition roadId="{{exit}}" laneId="1" s="{{s}}"/></Position></Waypoint>'
        "</Route></AssignRouteAction>"
    )
    text = _through_junction(rng, action.replace("{start}", "START"))
    start = text.split('<LanePosition roadId="', 1)[1].split('"', 1)[0]
    return text.replace("START", start)


@feature("route.AcquirePositionAction.junction")
def _r_acquire(rng: random.Random) -> str:
    action = routing(
        '<AcquirePositionAction><Position><LanePosition roadId="{exit}" laneId="1" s="{s}"/></Position>'
        "</AcquirePositionAction>"
    )
    return _through_junction(rng, action)


def _on_crossing(rng: random.Random, target_position: str, ego_events: str = "") -> str:
    road = crossing()
    arm = rng.randrange(4)
    speed = r1(rng.uniform(5, 12))
    init = private("Ego", teleport(lane_position(r1(rng.uniform(90, 140)), -1, road=arm)), speed_to(speed))
    init += private(
        "Target", teleport(f"<Position>{target_position}</Position>"), speed_to(r1(rng.uniform(3, 10)))
    )
    return openscenario(
        entities=scenario_object("Ego") + scenario_object("Target"),
        init=init,
        stories=one_story(ego_events) if ego_events else "",
        stop=stop_at(rng.uniform(4, 9)),
        road=f'<RoadNetwork><LogicFile filepath="{road.path}"/></RoadNetwork>',
    )


@feature("position.RelativeLanePosition.past_road_end")
def _p_rel_lane_across(rng: random.Random) -> str:
    ds = r1(rng.uniform(20, 90))  # from s 90–140 of a 150 m arm: often beyond its end, into the junction
    return _on_crossing(rng, f'<RelativeLanePosition entityRef="Ego" dLane="0" ds="{ds}" offset="0"/>')


@feature("position.RelativeRoadPosition.past_road_end")
def _p_rel_road_across(rng: random.Random) -> str:
    ds = r1(rng.uniform(20, 90))
    return _on_crossing(rng, f'<RelativeRoadPosition entityRef="Ego" ds="{ds}" dt="-1.5"/>')


@feature("action.LaneChangeAction.across_junction")
def _lc_across(rng: random.Random) -> str:
    change = lateral(
        '<LaneChangeAction><LaneChangeActionDynamics dynamicsShape="sinusoidal" dynamicsDimension="time"'
        f' value="{r1(rng.uniform(2, 5))}"/><LaneChangeTarget><RelativeTargetLane entityRef="Ego" value="1"/>'
        "</LaneChangeTarget></LaneChangeAction>"
    )
    target = f'<LanePosition roadId="{rng.randrange(4)}" laneId="1" s="{r1(rng.uniform(20, 120))}"/>'
    return _on_crossing(rng, target, event("LC", change, at(rng.uniform(0.5, 3))))


@feature("action.LaneOffsetAction.across_junction")
def _lo_across(rng: random.Random) -> str:
    offset = lateral(
        '<LaneOffsetAction continuous="false"><LaneOffsetActionDynamics maxLateralAcc="1" dynamicsShape="cubic"/>'
        f'<LaneOffsetTarget><AbsoluteTargetLaneOffset value="{r2(rng.uniform(-1, 1))}"/></LaneOffsetTarget>'
        "</LaneOffsetAction>"
    )
    target = f'<LanePosition roadId="{rng.randrange(4)}" laneId="1" s="{r1(rng.uniform(20, 120))}"/>'
    return _on_crossing(rng, target, event("LO", offset, at(rng.uniform(0.5, 3))))


@feature("action.SynchronizeAction.trajectory_position")
def _sync_trajectory(rng: random.Random) -> str:
    s = setup(rng, road=HIGHWAY)
    lane_y = {-1: -1.75, -2: -5.25, -3: -8.75}
    x0 = r1(s.ego_s + rng.uniform(150, 250))
    trajectory = (
        '<TrajectoryRef><Trajectory name="T" closed="false"><Shape><Polyline>'
        f'<Vertex><Position><WorldPosition x="{x0 - 100}" y="{lane_y[s.ego_lane]}"/></Position></Vertex>'
        f'<Vertex><Position><WorldPosition x="{x0 + 100}" y="{lane_y[s.ego_lane]}"/></Position></Vertex>'
        "</Polyline></Shape></Trajectory></TrajectoryRef>"
    )
    master = lane_position(s.target_s + rng.uniform(150, 250), s.target_lane)
    action = (
        f'<PrivateAction><SynchronizeAction masterEntityRef="Target"><TargetPositionMaster>{master[10:-11]}'
        f'</TargetPositionMaster><TargetPosition><TrajectoryPosition s="100">{trajectory}</TrajectoryPosition>'
        f'</TargetPosition><FinalSpeed><AbsoluteSpeed value="{r1(rng.uniform(5, 25))}"/></FinalSpeed>'
        "</SynchronizeAction></PrivateAction>"
    )
    ev = event("Sync", action, at(rng.uniform(0.2, 1)))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 12)))


@feature("position.RoutePosition.obstacle")
def _p_route_obstacle(rng: random.Random) -> str:
    # a parked obstacle placed by a route position along Ego's route: which way does it face
    s = setup(rng)
    s.target_speed = 0.0
    wps = "".join(
        f'<Waypoint routeStrategy="shortest">{lane_position(d, s.ego_lane)}</Waypoint>'
        for d in (s.ego_s, s.ego_s + 300)
    )
    position = (
        f'<RoutePosition><RouteRef><Route name="R" closed="false">{wps}</Route></RouteRef>'
        f'<InRoutePosition><FromLaneCoordinates pathS="{r1(rng.uniform(60, 200))}" laneId="{s.ego_lane}"/>'
        "</InRoutePosition></RoutePosition>"
    )
    ev = event("Go", speed_to(r1(rng.uniform(3, 8)), "linear", "rate", 2), at(rng.uniform(1, 3)))
    init = private("Ego", teleport(lane_position(s.ego_s, s.ego_lane)), speed_to(s.ego_speed))
    init += private("Target", teleport(f"<Position>{position}</Position>"), speed_to(0))
    return openscenario(
        entities=scenario_object("Ego") + scenario_object("Target"),
        init=init,
        stories=two_stories("", ev),
        stop=stop_at(rng.uniform(5, 9)),
        road=f'<RoadNetwork><LogicFile filepath="{s.road.path}"/></RoadNetwork>',
    )


@feature("action.FollowTrajectoryAction.follow_mode")
def _traj_follow(rng: random.Random) -> str:
    s = setup(rng)
    t0 = r1(rng.uniform(0.5, 2))
    points = _vertices(rng, s, rng.randint(2, 5), t0, s.ego_speed)
    shape = "<Polyline>" + "".join(f'<Vertex time="{r2(t)}">{p}</Vertex>' for t, p in points) + "</Polyline>"
    timing = rng.choice(["<None/>", '<Timing domainAbsoluteRelative="absolute" scale="1" offset="0"/>'])
    action = _trajectory_action(shape, timing).replace('followingMode="position"', 'followingMode="follow"')
    ev = event("Traj", action, at(t0))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 14)))


@feature("action.FollowTrajectoryAction.initialDistanceOffset")
def _traj_offset(rng: random.Random) -> str:
    s = setup(rng)
    t0 = r1(rng.uniform(0.5, 2))
    points = _vertices(rng, s, rng.randint(3, 5), t0, s.ego_speed)
    shape = "<Polyline>" + "".join(f'<Vertex time="{r2(t)}">{p}</Vertex>' for t, p in points) + "</Polyline>"
    action = _trajectory_action(shape, "<None/>").replace(
        "<FollowTrajectoryAction>",
        f'<FollowTrajectoryAction initialDistanceOffset="{r1(rng.uniform(0, 25))}">',
    )
    ev = event("Traj", action, at(t0))
    return s.file(one_story(ev), stop_at(rng.uniform(8, 12)))


@feature("condition.ReachPositionCondition.orientation")
def _c_reach_orientation(rng: random.Random) -> str:
    s = setup(rng)
    h = r2(rng.uniform(-0.3, 0.3))
    where = lane_position(s.ego_s + rng.uniform(20, 80), s.ego_lane).replace(
        "/></Position>", f'><Orientation type="relative" h="{h}"/></LanePosition></Position>'
    )
    cond = by_entity(
        "Ego", f'<ReachPositionCondition tolerance="{r1(rng.uniform(1, 4))}">{where}</ReachPositionCondition>'
    )
    return _reacting(s, rng, cond)


@feature("loading.inline_Trailer")
def _l_inline_trailer(rng: random.Random) -> str:
    # OpenSCENARIO 1.3: a truck with its trailer defined inline; esmini creates the trailer as "<name>+"
    coupler = r1(rng.uniform(3, 8))
    trailer = (
        '<Trailer><Trailer name="box"><Vehicle name="box" vehicleCategory="trailer">'
        '<BoundingBox><Center x="0" y="0" z="1.5"/><Dimensions width="2.5" length="8" height="3"/></BoundingBox>'
        '<Performance maxSpeed="40" maxAcceleration="5" maxDeceleration="9"/>'
        '<Axles><FrontAxle maxSteering="0" wheelDiameter="0.8" trackWidth="2" positionX="0" positionZ="0.4"/>'
        '<RearAxle maxSteering="0" wheelDiameter="0.8" trackWidth="2" positionX="0" positionZ="0.4"/></Axles>'
        f'<Properties/><TrailerCoupler dx="{coupler}"/></Vehicle></Trailer></Trailer>'
    )
    ev = event("S", speed_to(r1(rng.uniform(5, 20)), "linear", "rate", 2), at(rng.uniform(0.5, 2)))
    text = _simple(rng, road=HIGHWAY, stories=one_story(ev), minor="3")
    hitch = f'<TrailerHitch dx="{r1(rng.uniform(-1.5, 0))}"/>'
    return text.replace("<Properties/>\n  </Vehicle>", f"<Properties/>{hitch}{trailer}\n  </Vehicle>", 1)
