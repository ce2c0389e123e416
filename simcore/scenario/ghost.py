"""esmini's FollowGhostController: a ghost entity runs the scenario's actions ahead in time and the real
entity follows the ghost's trail with a simple vehicle model.

Semantics as esmini implements them (ScenarioWorld::SetupGhost, ControllerFollowGhost, vehicle::Vehicle):

- the first entity given a FollowGhostController (ObjectController or an AssignControllerAction in Init) gets a
  ghost: a copy of it named ``<name>_ghost`` without a controller. It receives copies of the entity's Init
  actions (all but controller actions) and takes its place as actor in every maneuver group; the entity itself
  is only moved by its controller;
- the storyboard starts `headstartTime` (property, default 3 s) before time 0 of esmini's time axis: until
  then only the ghost moves (the other entities stand still and no controller runs). The simulation time
  conditions of act start triggers and of the events the ghost acts in are shifted back by the head start (on
  CARLOS's storyboard time, which starts at the head start's beginning, they keep their values); every other
  simulation time condition (the stop trigger, other events, act stop triggers) keeps its value on esmini's
  axis (on the storyboard's time it is later by the head start);
- in those triggers, speed, acceleration, traveled distance, reach position, collision, end of road, off road
  and standstill conditions on the entity are handed over to the ghost; an event the ghost acts in whose
  trigger has any other condition first teleports the ghost to the entity; after time 0 this restarts the
  ghost: a new trail at the entity's speed, and the head start run again by the ghost alone before the next
  step (esmini rewinds its clock for it while every other entity stands still);
- the ghost leaves a trail: its position, heading and speed whenever more than 0.2 s of esmini's simulation
  time passed since the last sample and it is not standing still (a sample more than 0.4 s old is repeated
  0.2 s before the new one), the trail's s being the length of the polyline;
- each step (after every entity moved) the controller finds a speed target and a steering target on the
  trail: in `followMode` position, the point closest to the entity (searching on from the last closest
  segment) and the points `max(minLookaheadSpeed, lookaheadSpeed·v)` and `max(minLookaheadSteering,
  lookaheadSteering·v)` further along the trail; in time mode (the default), the trail at esmini's time −
  headstart + max(minLookahead…, lookahead…). The target speed is the trail's (interpolated) speed there;
  the steering input the arcsine of the cross product of the heading and the unit vector to the steering
  target;
- the vehicle model (vehicle::Vehicle::DrivingControlTarget): acceleration 10·(target − v) within ±10 m/s²,
  speed within ±100 m/s; wheel angle = the steering input within ±60°/(1 + steeringSpeedInertia·v²);
  kinematic bicycle with the velocity at atan(0.15·tan(wheel angle)) from the heading and a heading rate of
  v·sin(that)/(0.15·length); the entity is put where the model is (its road position found from there).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from simcore.scenario import model as m
from simcore.scenario.drivers import Vehicle, put
from simcore.scenario.motion import UNPOSED
from simcore.world.native_calls import hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import GhostWorld


FOLLOW_GHOST: Final = "FollowGhostController"
SAMPLE_TIME: Final = 0.2  # s between trail samples (esmini's GHOST_TRAIL_SAMPLE_TIME)
SMALL: Final = 1e-10  # esmini's SMALL_NUMBER
MAX_ACCELERATION: Final = 10.0  # m/s² (the controller's vehicle model)
MAX_SPEED: Final = 100.0

# actions that move to the ghost (esmini: the event's actions of these types; CARLOS: the group's actors)
_GHOST_ACTIONS: Final = (
    m.SpeedAction,
    m.SpeedProfileAction,
    m.LaneChangeAction,
    m.LaneOffsetAction,
    m.SynchronizeAction,
    m.FollowTrajectoryAction,
    m.AssignRouteAction,
    m.TeleportAction,
)
# entity conditions on the entity handed over to the ghost
_HANDED_OVER: Final = (
    m.CollisionCondition,
    m.ReachPositionCondition,
    m.TraveledDistanceCondition,
    m.SpeedCondition,
    m.AccelerationCondition,
    m.EndOfRoadCondition,
    m.OffroadCondition,
    m.StandStillCondition,
)


@dataclass(frozen=True)
class GhostSetup:
    entity: str  # the entity that follows
    ghost: str  # its ghost
    headstart: float
    properties: tuple[tuple[str, str], ...]
    teleports: frozenset[int]  # ids of the TeleportActions that put the ghost on the entity (event starts)


def follow_ghost_properties(scenario: m.Scenario) -> tuple[str, dict[str, str]] | None:
    """The first entity a FollowGhostController is given to (esmini sets up one ghost only), and the
    controller's properties."""
    for entity in scenario.entities:
        if m.controller_type(entity.controller) == FOLLOW_GHOST:
            return entity.name, dict(entity.controller)
        for item in scenario.init:
            if (
                item.entity == entity.name
                and isinstance(item.action, m.ControllerAction)
                and item.action.controller
                and m.controller_type(dict(item.action.controller)) == FOLLOW_GHOST
            ):
                return entity.name, dict(item.action.controller)
    return None


def headstart_of(properties: dict[str, str]) -> float:
    return m.property_number(properties.get("headstartTime"), 3.0)


def setup(scenario: m.Scenario) -> tuple[m.Scenario, GhostSetup | None]:
    """The scenario as esmini runs it with a ghost (see the module's doc), or unchanged without one."""
    found = follow_ghost_properties(scenario)
    if found is None:
        return scenario, None
    name, properties = found
    headstart = headstart_of(properties)
    original = next(e for e in scenario.entities if e.name == name)
    ghost_name = f"{name}_ghost"
    ghost = dataclasses.replace(original, name=ghost_name, controller={})
    init = list(scenario.init)
    init += [
        m.InitAction(ghost_name, item.action)
        for item in scenario.init
        if item.entity == name and not isinstance(item.action, m.ControllerAction)
    ]
    teleports: set[int] = set()

    def later(trigger: m.Trigger | None) -> m.Trigger | None:
        """A trigger esmini leaves on its time axis: its simulation times, on the storyboard's, are later."""
        return _shift_times(trigger, headstart) if headstart else trigger

    def hand_over(trigger: m.Trigger | None) -> tuple[m.Trigger | None, bool]:
        """The trigger of an act or of an event the ghost acts in, and whether esmini gives the event a
        teleport of the ghost to the entity (a condition it does not hand over)."""
        if trigger is None:
            return None, False
        teleport = False
        groups = []
        for group in trigger.groups:
            conditions = []
            for cond in group:
                if cond.entity_condition is not None:
                    if isinstance(cond.entity_condition, _HANDED_OVER):
                        entities = tuple(ghost_name if e == name else e for e in cond.triggering_entities)
                        teleport = teleport or any(e != ghost_name for e in entities)
                        cond = dataclasses.replace(cond, triggering_entities=entities)
                    else:
                        teleport = True
                elif not isinstance(cond.value_condition, m.SimulationTimeCondition):
                    teleport = True
                conditions.append(cond)
            groups.append(tuple(conditions))
        return dataclasses.replace(trigger, groups=tuple(groups)), teleport

    stories = []
    for story in scenario.stories:
        acts = []
        for act in story.acts:
            start, _ = hand_over(act.start_trigger)
            groups = []
            for group in act.groups:
                if name not in group.actors:
                    groups.append(_shift_group(group, headstart))
                    continue
                actors = tuple(ghost_name if a == name else a for a in group.actors)
                maneuvers = []
                for maneuver in group.maneuvers:
                    events = []
                    for event in maneuver.events:
                        if any(isinstance(a.private, _GHOST_ACTIONS) for a in event.actions):
                            trigger, teleport = hand_over(event.start_trigger)
                            actions = event.actions
                            if teleport:
                                jump = m.TeleportAction(
                                    m.RelativeObjectPosition(
                                        name, 0.0, 0.0, 0.0, m.Orientation("relative", 0.0, 0.0, 0.0)
                                    )
                                )
                                teleports.add(id(jump))
                                actions = (m.Action("AddedGhostTeleport", jump), *actions)
                            event = dataclasses.replace(event, start_trigger=trigger, actions=actions)
                        else:
                            event = dataclasses.replace(event, start_trigger=later(event.start_trigger))
                        events.append(event)
                    maneuvers.append(dataclasses.replace(maneuver, events=tuple(events)))
                groups.append(dataclasses.replace(group, actors=actors, maneuvers=tuple(maneuvers)))
            acts.append(
                dataclasses.replace(
                    act, groups=tuple(groups), start_trigger=start, stop_trigger=later(act.stop_trigger)
                )
            )
        stories.append(dataclasses.replace(story, acts=tuple(acts)))
    changed = dataclasses.replace(
        scenario,
        entities=(*scenario.entities, ghost),
        init=tuple(init),
        stories=tuple(stories),
        stop_trigger=later(scenario.stop_trigger),
    )
    return changed, GhostSetup(name, ghost_name, headstart, tuple(properties.items()), frozenset(teleports))


def _shift_group(group: m.ManeuverGroup, headstart: float) -> m.ManeuverGroup:
    if not headstart:
        return group
    maneuvers = tuple(
        dataclasses.replace(
            maneuver,
            events=tuple(
                dataclasses.replace(e, start_trigger=_shift_times(e.start_trigger, headstart))
                for e in maneuver.events
            ),
        )
        for maneuver in group.maneuvers
    )
    return dataclasses.replace(group, maneuvers=maneuvers)


def _shift_times(trigger: m.Trigger | None, by: float) -> m.Trigger | None:
    if trigger is None:
        return None
    groups = tuple(
        tuple(
            dataclasses.replace(
                c, value_condition=dataclasses.replace(c.value_condition, value=c.value_condition.value + by)
            )
            if isinstance(c.value_condition, m.SimulationTimeCondition)
            else c
            for c in group
        )
        for group in trigger.groups
    )
    return dataclasses.replace(trigger, groups=groups)


class Trail:
    """A ghost's trail: a polyline of samples (x, y, heading, time, speed) with its length s at each."""

    def __init__(self) -> None:
        self.x: list[float] = []
        self.y: list[float] = []
        self.time: list[float] = []
        self.speed: list[float] = []
        self.s: list[float] = []

    def __len__(self) -> int:
        return len(self.x)

    def add(self, x: float, y: float, time: float, speed: float) -> None:
        s = 0.0
        if self.x:
            s = self.s[-1] + hypot(x - self.x[-1], y - self.y[-1])
        self.x.append(x)
        self.y.append(y)
        self.time.append(time)
        self.speed.append(speed)
        self.s.append(s)

    def sample(self, x: float, y: float, time: float, speed: float) -> None:
        """The sample esmini takes after a step (see the module's doc)."""
        n = len(self.x)
        if n and not time - self.time[-1] > SAMPLE_TIME:
            return
        if n and not (abs(self.speed[-1]) > SMALL or abs(speed) > SMALL):
            return  # standing still
        if n and time - self.time[-1] > 2 * SAMPLE_TIME:
            self.add(self.x[-1], self.y[-1], time - SAMPLE_TIME, self.speed[-1])
        self.add(x, y, time, speed)

    def segment_point(self, i: int, local_s: float) -> tuple[float, float, float, float]:
        """(x, y, speed, s) at `local_s` along segment i (the last vertex from the last index on)."""
        if i >= len(self.x) - 1:
            return self.x[i], self.y[i], self.speed[i], self.s[i]
        length = max(self.s[i + 1] - self.s[i], SMALL)
        a = min(max(local_s, 0.0), length) / length
        b = 1.0 - a
        return (
            b * self.x[i] + a * self.x[i + 1],
            b * self.y[i] + a * self.y[i + 1],
            b * self.speed[i] + a * self.speed[i + 1],
            b * self.s[i] + a * self.s[i + 1],
        )

    def closest(self, px: float, py: float, start: int) -> tuple[int, float] | None:
        """(segment index, s) of the point of the trail closest to (px, py), searched from segment
        `start` on (from 0 when the trail is shorter); None without a segment."""
        n = len(self.x)
        if start > n - 1:
            start = 0
        best, best_i, best_local = math.inf, start, 0.0
        for i in range(start, n - 1):
            x0, y0 = self.x[i], self.y[i]
            dx, dy = self.x[i + 1] - x0, self.y[i + 1] - y0
            length2 = dx * dx + dy * dy
            if length2 < SMALL * SMALL:
                dist, local = hypot(px - x0, py - y0), 0.0
            else:
                f = ((px - x0) * dx + (py - y0) * dy) / length2
                qx, qy = x0 + f * dx, y0 + f * dy
                dist = hypot(px - qx, py - qy)
                seg = self.s[i + 1] - self.s[i]
                if f < 0.0:
                    along = f * math.sqrt(length2)  # distance before the segment's start
                    dist, local = hypot(dist, along), 0.0
                elif f > 1.0:
                    along = (f - 1.0) * math.sqrt(length2)
                    dist, local = hypot(dist, along), seg
                else:
                    local = f * seg
            if dist < best:
                best, best_i, best_local = dist, i, local
        if best == math.inf:
            return None
        return best_i, self.segment_point(best_i, best_local)[3]

    def at_s(self, s: float, start: int) -> tuple[float, float, float]:
        """(x, y, speed) at s along the trail (its last sample past its end), searched from `start`."""
        n = len(self.x)
        if s > self.s[-1]:
            return self.x[-1], self.y[-1], self.speed[-1]
        i = min(max(start, 0), n - 1)
        while i < n - 1 and self.s[i + 1] <= s:
            i += 1
        x, y, speed, _ = self.segment_point(i, s - self.s[i])
        return x, y, speed

    def at_time(self, time: float) -> tuple[float, float, float]:
        """(x, y, speed) at a time of the trail (its first/last sample before/after it)."""
        n = len(self.time)
        if time <= self.time[0]:
            return self.x[0], self.y[0], self.speed[0]
        if time >= self.time[-1]:
            return self.x[-1], self.y[-1], self.speed[-1]
        lo, hi = 0, n - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if self.time[mid] <= time:
                lo = mid
            else:
                hi = mid
        span = self.time[hi] - self.time[lo]
        a = (time - self.time[lo]) / span if span > SMALL else 0.0
        b = 1.0 - a
        return (
            b * self.x[lo] + a * self.x[hi],
            b * self.y[lo] + a * self.y[hi],
            b * self.speed[lo] + a * self.speed[hi],
        )


class GhostFollower:
    """The controller of the entity that follows its ghost's trail (see the module's doc)."""

    def __init__(self, actor: Body, properties: dict[str, str], headstart: float) -> None:
        self.actor = actor
        self.headstart = headstart
        self.position_mode = properties.get("followMode", "time").strip() == "position"
        self.lookahead_speed = m.property_number(properties.get("lookaheadSpeed"), 0.1)
        self.min_lookahead_speed = m.property_number(properties.get("minLookaheadSpeed"), 0.1)
        self.lookahead_steering = m.property_number(properties.get("lookaheadSteering"), 1.0)
        self.min_lookahead_steering = m.property_number(properties.get("minLookaheadSteering"), 1.0)
        # the vehicle model (esmini keeps its state apart from the entity's)
        self.vehicle = Vehicle(actor)
        self.vehicle.max_acc = MAX_ACCELERATION
        self.vehicle.max_speed = MAX_SPEED
        self.vehicle.steering_scale = m.property_number(properties.get("steeringSpeedInertia"), 0.01)
        self.follow_index = 0
        self.closest_s = 0.0
        self.target: tuple[float, float] = (actor.x, actor.y)  # the steering target last used

    def step(self, dt: float, trail: Trail, time: float) -> None:
        a = self.actor
        px, py = a.x, a.y
        target: tuple[float, float, float] | None = None
        if len(trail):
            if self.position_mode:
                found = trail.closest(px, py, self.follow_index)
                if found is not None:
                    self.follow_index, self.closest_s = found
                v = a.speed
                speed_point = trail.at_s(
                    self.closest_s + max(self.min_lookahead_speed, self.lookahead_speed * v),
                    self.follow_index,
                )
                steer_point = trail.at_s(
                    self.closest_s + max(self.min_lookahead_steering, self.lookahead_steering * v),
                    self.follow_index,
                )
            else:
                base = time - self.headstart
                speed_point = trail.at_time(base + max(self.min_lookahead_speed, self.lookahead_speed))
                steer_point = trail.at_time(base + max(self.min_lookahead_steering, self.lookahead_steering))
            target = (steer_point[0], steer_point[1], speed_point[2])
        if target is None:
            target = (px, py, 0.0)
        tx, ty, target_speed = target
        self.target = (tx, ty)
        dx, dy = tx - px, ty - py
        length = hypot(dx, dy)
        if length > SMALL:
            dx, dy = dx / length, dy / length
        else:
            dx, dy = 0.0, 0.0
        cross = math.cos(a.heading) * dy - math.sin(a.heading) * dx
        steering = math.asin(min(max(cross, -1.0), 1.0))
        self.vehicle.control_target(dt, target_speed, steering)


class Ghosts:
    """The ghost of a scenario run: its trail, esmini's clock (the head start's restart), the follower."""

    def __init__(self, world: GhostWorld, setup: GhostSetup) -> None:
        self.world = world
        self.setup = setup
        self.ghost = world.bodies[setup.ghost]
        self.entity = world.bodies[setup.entity]
        self.trail = Trail()
        # esmini's simulation time, accumulated as esmini does (its samples depend on its rounding)
        self.clock = 0.0 - setup.headstart
        self.restarting = setup.headstart > 0.0
        self.follower: GhostFollower | None = None
        self.names = frozenset({setup.ghost})
        self.restart = False  # the ghost was put back on its entity after time 0: its head start runs again
        self.rerun = False  # … before the next step

    def start(self) -> None:
        """The initial sample (esmini's first frame, before any step)."""
        g = self.ghost
        self.trail.sample(g.x, g.y, self.clock, g.speed)

    def activate(self, active: bool) -> None:
        e = self.world
        if active and self.follower is None:
            self.follower = GhostFollower(self.entity, dict(self.setup.properties), self.setup.headstart)
            e.log.append(f"t={e.time:.2f} {self.entity.name}: FollowGhost controller activated")
        elif not active and self.follower is not None:
            self.follower = None
            e.log.append(f"t={e.time:.2f} {self.entity.name}: FollowGhost controller deactivated")

    def frozen(self) -> set[str]:
        """The entities default motion leaves alone this step: the follower's (moved by it), and during the
        head start every entity but the ghost."""
        if self.restarting:
            return {name for name in self.world.bodies if name not in self.names}
        return {self.entity.name} if self.follower is not None else set()

    def begin_step(self) -> None:
        if self.restarting and self.clock > -SMALL:
            self.restarting = False
        g = self.ghost
        if self.rerun and not g.gone:
            # the restart's head start, before this step: the ghost alone, on esmini's clock rewound by it
            self.rerun = False
            dt = self.world.dt
            steps = round(self.setup.headstart / dt)
            first = self.clock - steps * dt

            def sample(k: int) -> None:
                self.trail.sample(g.x, g.y, first + (k + 1) * dt, g.speed)

            self.world.run_alone(g, dt, steps, sample)

    def end_step(self, dt: float) -> None:
        """After default motion: esmini's clock on, the follower steps, the ghost leaves its sample; after
        a restart the ghost runs its head start again alone (esmini rewinds its clock by the head start and
        runs the ghost only until it is back: the storyboard's time goes on from where it was)."""
        clock = self.clock + dt
        if -SMALL < clock < 0.0:
            clock = 0.0
        self.clock = clock
        follower = self.follower
        if follower is not None and not self.restarting and not self.entity.gone:
            follower.step(dt, self.trail, clock)
            put(self.world, self.entity, follower.vehicle)
        g = self.ghost
        if self.restart:
            self.restart, self.rerun = False, True  # its head start runs again before the next step
            return
        if not g.gone:
            self.trail.sample(g.x, g.y, clock, g.speed)

    def teleport(self, ghost: Body) -> None:
        """The ghost put on its entity when an event it acts in starts (esmini's AddedGhostTeleport); after
        time 0 this restarts it: its trail starts anew, at its entity's speed."""
        e = self.entity
        for attr in ("x", "y", "z", "heading", "road_id", "lane_id", "s", "offset", "direction"):
            setattr(ghost, attr, getattr(e, attr))
        ghost.heading_offset = e.heading_offset
        ghost.posed = UNPOSED
        if self.clock > SMALL:
            self.restart = True
            self.trail = Trail()
            ghost.speed = e.speed
            ghost.extra["teleported"] = 1.0  # it stays there this step
            self.world.log.append(f"t={self.world.time:.2f} {ghost.name}: restarts its head start")
