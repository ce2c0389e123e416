"""The scenario engine: runs a parsed OpenSCENARIO storyboard against the world, one fixed step at a time.

Per step (time t → t + dt): (1) triggers are evaluated on the state at t and storyboard elements change
state; (2) running actions set the motion of their actors; (3) scenario-driven entities move along their
lanes and are placed into SUMO; SUMO steps, moving the entities it drives; (4) the new frame is published.

The storyboard (`story`), triggers and conditions, the runtime of each action type (`action_registry`) and
position resolution (`positions`) live in their own modules; the engine is the `ScenarioWorld` they use.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Protocol

from simcore.errors import BadInput, SimulationError
from simcore.scenario import drivers, ghost, global_actions, positions
from simcore.scenario import model as m
from simcore.scenario.action_registry import make_runtime
from simcore.scenario.core_actions import LaneChangeRuntime
from simcore.scenario.measure import Measure
from simcore.scenario.motion import (
    UNPOSED,
    Body,
    EntityFacts,
    advance_on_road,
    align_trailer,
    lane_point,
    pull_trailer,
    update_pose_from_road,
    wrap_angle,
)
from simcore.scenario.runtime import Runtime
from simcore.scenario.signals import SignalControllers, unknown_signals
from simcore.scenario.story import StoryRun
from simcore.scenario.storyboard import State
from simcore.scenario.sumo_bridge import SumoBridge
from simcore.scenario.triggers import Triggers
from simcore.scenario.world import Pose
from simcore.world.native_calls import hypot
from simcore.world.state import BoundingBox, EntityState, LaneCoordinates, WorldFrame

if TYPE_CHECKING:
    from simcore.scenario import controllers
    from simcore.world.opendrive import OpenDrive
    from simcore.world.sumo import SumoWorld


class ExternalDriver(Protocol):
    """Moves the entities an external controller drives (`simcore.closedloop`): the pose and speed after
    `dt` from the current ones."""

    def move(
        self, entity: m.Entity, x: float, y: float, heading: float, speed: float, dt: float
    ) -> tuple[float, float, float, float]: ...

    def has_input(self, entity: str) -> bool:
        """Whether a command for `entity` has arrived (before the first one the entity is held as in
        esmini, so a run without a system under test is the reference player's run)."""
        ...


class ScenarioEngine:
    """Runs one scenario. `step()` advances one fixed step and returns the new frame."""

    def __init__(
        self,
        scenario: m.Scenario,
        *,
        road: OpenDrive | None,
        sumo: SumoWorld | None,
        step_seconds: float,
        ego: str | None = None,
        external: ExternalDriver | None = None,
        seed: int = 0,
    ) -> None:
        # esmini's FollowGhostController: a ghost entity runs the scenario's actions ahead (simcore.scenario.ghost)
        scenario, ghost_setup = ghost.setup(scenario)
        self.scenario = scenario
        self.external = external  # moves the entities whose external controller is active
        self.source = str(scenario.path)
        self.road = road
        self.sumo = SumoBridge(sumo, road) if sumo is not None else None
        self.dt = step_seconds
        self.time = 0.0
        self.step_index = 0
        self.log: list[str] = []
        self.warnings: list[str] = []
        self.ended_by: str | None = None
        self.bodies: dict[str, Body] = {e.name: Body(entity=e) for e in scenario.entities}
        #: the same bodies in the same order, as a list (iterated natively every step; a run's bodies never change)
        self._in_order: list[Body] = list(self.bodies.values())
        # per entity: [driver of its assigned controller, active longitudinally, active laterally]
        self.controllers: dict[str, list[Any]] = {
            e.name: [e.driver if e.driver == "external" else "scenario", False, False]
            for e in scenario.entities
        }
        self.ego = ego or _default_ego(scenario)
        if self.ego is not None and self.ego not in self.bodies:
            raise BadInput(f"ego entity {self.ego!r} is not in the scenario", field="spec.simulation.ego")
        for entity in scenario.entities:
            if entity.driver == "sumo" and sumo is None:
                raise BadInput(
                    f"entity {entity.name!r} is driven by SUMO but the scenario has no road network",
                    file=self.source,
                    field="RoadNetwork/LogicFile",
                )
        self._target_roads: dict[tuple[float, float, str], Any] = {}
        self.memo: dict[tuple[str, int], Any] = {}  # conditions' and positions' memory (ScenarioWorld)
        self.measure = Measure(self)
        self.triggers = Triggers(self)
        self.owner: Body | None = None  # the actor whose action runs now ("$owner")
        self.parameter_values: dict[str, Any] = dict(scenario.parameters)
        self.variables: dict[str, Any] = dict(scenario.variables)
        self.added_later = _added_later(scenario)
        # traffic signals: state shown by each signal (by the id or name the scenario uses), and the phase
        # cycle of each signal controller: name → (time its current cycle was anchored, phase index then)
        self.signal_control = SignalControllers(scenario.signal_controllers)
        self.signals = self.signal_control.signals
        self.signal_phases = self.signal_control.phases
        self.ended_in_move = False  # an action runtime finished while moving its entity this step
        # a FollowGhost controller (esmini) gives its ghost a head start: esmini reports every time shifted
        # back by it (the storyboard's time 0 is at -headstart on its time axis); `output_time_offset` is
        # that shift, for comparisons with such output (the storyboard itself runs on its own time)
        self.output_time_offset = -ghost_setup.headstart if ghost_setup is not None else 0.0
        self.ghosts = ghost.Ghosts(self, ghost_setup) if ghost_setup is not None else None
        self.seed = seed  # the run's seed (controllers that draw random numbers)
        # esmini's controllers of the registry (simcore.scenario.controllers: ALKS_R157SM, SloppyDriver) active now
        self.esmini_controllers: dict[str, controllers.EsminiController] = {}
        # the properties of each entity's controller assigned during the run (AssignControllerAction), and
        # the ACC/ALKS driver models (esmini's ACCController) active on the longitudinal domain now
        self.assigned_controller: dict[str, dict[str, str]] = {}
        # per entity: its controllers (name → properties, domains active on), `controller_actions.slots_of`
        self.controller_slots: dict[str, dict[str, tuple[dict[str, str], set[str]]]] = {}
        self.acc_drivers: dict[str, drivers.AccDriver] = {}
        # esmini's controllers that drive a vehicle model of their own (OffroadFollower), active now
        self.vehicle_drivers: dict[str, drivers.OffroadFollower] = {}
        # esmini's NaturalDriver controllers active on the longitudinal domain now (they move their entity)
        self.natural_drivers: dict[str, drivers.NaturalDriver] = {}
        # trailers: tow vehicle → the entity it tows (Trailer/TrailerRef, ConnectTrailerAction), and back
        self.trailer_of: dict[str, str] = {}
        for entity in scenario.entities:
            if entity.trailer is not None:
                if entity.trailer not in self.bodies or entity.trailer == entity.name:
                    raise BadInput(
                        f"entity {entity.name!r} tows {entity.trailer!r}, which is not another declared entity",
                        file=entity.source or self.source,
                        field="Vehicle/Trailer/TrailerRef",
                    )
                self.trailer_of[entity.name] = entity.trailer
        self.tow_of: dict[str, str] = {t: tow for tow, t in self.trailer_of.items()}
        self.story = StoryRun(scenario, self, self.triggers)
        self.root = self.story.root
        if road is not None:
            self.warnings.extend(unknown_signals(self.scenario, self.root, road, self.source))
        self.registry = self.story.registry
        self._states: dict[str, EntityState] = {}  # per-step cache of state_of (cleared when bodies move)
        self._frame: WorldFrame | None = None  # this step's frame, once built (forgotten when bodies move)
        self._init()
        if self.ghosts is not None:
            self.ghosts.start()

    # --- set-up ---------------------------------------------------------------------------------------

    def _init(self) -> None:
        # teleports first (other init actions may refer to positions of entities placed here), each after the
        # teleport of the entity its position refers to, wherever that is in Init (as esmini)
        ordered = _placement_order(self.scenario.init)
        self.init_runtimes: list[Runtime] = []
        for item in ordered:
            if not item.entity:
                global_actions.run(self, item.action)  # type: ignore[arg-type]
                continue
            runtime = make_runtime(self, self.bodies[item.entity], item.action)  # type: ignore[arg-type]
            if not runtime.start_in_init():
                # an Init action with duration (a trajectory, a distance to keep) runs from the first step
                self.init_runtimes.append(runtime)
        for runtime in self.init_runtimes:
            runtime.start()
        for driver in self.natural_drivers.values():
            # esmini's first frame steps the controllers activated in Init with a zero time step
            driver.step(0.0)
            self._start_lane_change(driver)
        for controller in list(self.esmini_controllers.values()):
            if getattr(controller, "steps_in_init", False) and not controller.actor.gone:
                controller.step(0.0)
        for body in self.bodies.values():
            if body.external and not self._has_input(body) and not body.gone:
                self._move_external(body, 0.0)  # that first frame rolls an interactive vehicle's speed down
        if self.trailer_of:
            self.align_trailers()
        for body in self.bodies.values():
            if not body.placed and body.name in self.added_later:
                body.gone = True
                body.placed = True
            if not body.placed and body.entity.controller:
                # an entity a controller of another tool populates (esmini's SUMO traffic): not in the world
                self.warnings.append(
                    f"{body.entity.source or self.source}: ScenarioObject[{body.name}]: no initial position and "
                    "driven by controller "
                    f"{body.entity.controller.get('name', '')!r}: it stays out of the world"
                )
                body.gone = True
                body.placed = True
            if not body.placed:
                # placed later by a TeleportAction (until then not in the world)
                self.warnings.append(
                    f"{body.entity.source or self.source}: ScenarioObject[{body.name}]: no initial position in "
                    "Storyboard/Init: "
                    "it is out of the world until an action places it"
                )
                body.gone = True
                body.placed = True
        if self.sumo is not None and not any(b.entity.driver == "sumo" for b in self.bodies.values()):
            # nothing reads SUMO back: no entity is SUMO-driven, so it is not stepped at all (placing every
            # scripted entity every step would cost two libsumo calls per entity for nothing)
            self.sumo = None
        if self.sumo is not None:
            self.sumo.add(self.bodies.values())
        self.story.begin()

    # --- positions ------------------------------------------------------------------------------------

    def body(self, name: str) -> Body:
        if name == "$owner" and self.owner is not None:  # esmini's name for the actor of the action
            return self.owner
        try:
            return self.bodies[name]
        except KeyError:
            raise BadInput(f"entity {name!r} is not declared in <Entities>", file=self.source) from None

    def place(self, body: Body, position: m.Position) -> None:
        """Teleport: pose from the position; road coordinates from the road network when on a road."""
        x, y, z, heading = self.resolve_position(position, body)
        self.moved()
        body.x, body.y, body.z, body.heading = x, y, z, heading
        body.posed = UNPOSED
        body.placed = True
        body.gone = False
        body.mover = None
        body.road_id = None
        if self.road is not None:
            # the road the position is on (a relative position resolved across roads says which: connecting
            # roads of a junction overlap)
            hint = getattr(position, "road_id", None) or self.memo.get(("road_hint", id(position)))
            rc = self.road.world_to_road(x, y, None, road_hint=hint)
            if rc is not None:
                body.road_id, body.lane_id, body.s = rc.road_id, rc.lane_id, rc.s
                body.offset = rc.offset
                body.direction = 1 if math.cos(heading - rc.heading) >= 0 else -1
                if isinstance(position, m.LanePosition) and 0.0 <= position.s <= self.road.road_length(
                    position.road_id
                ):
                    body.road_id, body.lane_id, body.s = position.road_id, position.lane_id, position.s
                    body.offset = position.offset
        # an orientation given relative to the road is kept while the entity moves along it (as esmini)
        body.heading_offset = 0.0
        orientation = getattr(position, "orientation", None)
        if body.road_id is not None and orientation is not None and orientation.type == "relative":
            lane_heading = heading
            if self.road is not None:
                lane_heading = self.road.road_to_world(body.road_id, body.s, 0.0).heading
            travel = lane_heading if body.direction > 0 else lane_heading + math.pi
            body.heading_offset = wrap_angle(heading - travel)
        if self.sumo is not None and self.step_index > 0:
            self.sumo.place(body)

    def align_trailers(self, tow: Body | None = None, *, pull: bool = False) -> None:
        """Place every trailer (of `tow`, else of every front tow vehicle) behind its tow vehicle, down the
        chain: straight behind, or with `pull` dragged by the hitch from where it was."""
        if tow is not None:
            fronts = [tow]
        else:
            fronts = [self.bodies[n] for n in self.trailer_of if n not in self.tow_of]
        for front in fronts:
            current = front
            for _ in range(len(self.trailer_of)):
                name = self.trailer_of.get(current.name)
                if name is None:
                    break
                trailer = self.bodies[name]
                if pull:
                    pull_trailer(current, trailer)
                else:
                    align_trailer(current, trailer)
                    if current.placed and not current.gone and not trailer.placed:
                        # a trailer without a position of its own is where its tow vehicle puts it
                        trailer.placed, trailer.gone = True, False
                self.track_road(trailer)
                current = trailer

    def track_road(self, body: Body, lock_lane: bool = False) -> None:
        """Road coordinates of a body moved freely (a trajectory): its lane, s and offset from x/y. With
        `lock_lane` the body follows that lane afterwards, in the direction it is heading."""
        self.moved()
        positions.track(self.road, body, lock_lane)

    def locate(self, body: Body) -> None:
        """Road coordinates (road, lane, s, offset, direction, z) of a body moved in world coordinates."""
        positions.locate(self.road, body)

    def resolve_position(self, position: m.Position, for_body: Body | None = None) -> Pose:
        """World (x, y, z, heading) of a position."""
        return positions.resolve(self, position, for_body)

    def plan_route(self, body: Body, targets: list[m.Position]) -> list[tuple[str, int]]:
        """The roads (id, direction) a body drives through to pass every target position in order."""
        return positions.plan_route(self, body, targets)

    def shift_along(self, body: Body, distance: float) -> None:
        """Move a body `distance` metres along its lane (or its heading off road) at once."""
        if abs(distance) < 1e-12:
            return
        if self.road is not None and body.road_id is not None and body.mover is None:
            if distance >= 0:
                advance_on_road(self.road, body, distance, self.time)
            else:
                body.direction = -body.direction
                advance_on_road(self.road, body, -distance, self.time)
                body.direction = -body.direction
                update_pose_from_road(self.road, body)
        else:
            body.x += distance * math.cos(body.heading)
            body.y += distance * math.sin(body.heading)
        self.moved()

    def distance_to(self, body: Body, target: tuple[float, float, float, float]) -> float:
        """Distance still to travel to a position: along the road when both are on the same road."""
        x, y, _, _ = target
        if self.road is not None and body.road_id is not None:
            key = (x, y, body.road_id)
            if key not in self._target_roads:  # targets are fixed: map each to the road once
                self._target_roads[key] = self.road.world_to_road(x, y, None, road_hint=body.road_id)
            rc = self._target_roads[key]
            if rc is not None and rc.road_id == body.road_id:
                return max((rc.s - body.s) * body.direction, 0.0)
        return hypot(x - body.x, y - body.y)

    # --- SUMO hooks -----------------------------------------------------------------------------------

    def sumo_set_speed(self, body: Body, speed: float) -> None:
        if self.sumo is not None:
            self.sumo.set_speed(body, speed)

    def sumo_change_lane(self, body: Body, lane_id: int, duration: float) -> None:
        if self.sumo is not None:
            self.sumo.change_lane(body, lane_id, duration)

    def step(self) -> WorldFrame:
        """Advance one step; returns the frame at the new time."""
        self.advance()
        return self.frame()

    def advance(self) -> None:
        """Advance one step without building the frame (headless runs that read the bodies directly)."""
        dt = self.dt
        ghosts = self.ghosts
        if ghosts is not None:
            ghosts.begin_step()
        if self.signal_control.cycles:
            self.signal_control.update(self.time)
        # the StopTrigger is evaluated at the end of every step, on the state just reached (so a run ends at
        # the first step where it holds, as esmini does); only the initial state is checked here
        if not (self.step_index == 0 and self._check_stop()):
            self.story.evaluate()
        for body in self._in_order:
            body.at_step_start = (body.speed, body.heading, body.x, body.y)
            body.lateral_velocity = 0.0  # lateral actions that are still running set it again
        if self.init_runtimes:
            for runtime in self.init_runtimes:
                if not runtime.done:
                    runtime.step(dt)
            self.init_runtimes = [r for r in self.init_runtimes if not r.done]
        self.story.step_actions(dt)
        self.moved()
        now = (self.step_index + 1) * dt  # no accumulated rounding: step k is at exactly k·dt
        sumo, tow_of = self.sumo, self.tow_of
        # entities an override-mode ACC moves itself, after the others (below)
        deferred: set[str] | tuple[()] = (
            {n for n, d in self.acc_drivers.items() if d.override and not d.virtual}
            if self.acc_drivers
            else ()
        )
        if ghosts is not None:
            deferred = ghosts.frozen().union(deferred)
        # entities an external controller steers (lateral only) while a driver model sets their speed: moved
        # after it (esmini steps the longitudinal controller first)
        steered = self._steered() if self.esmini_controllers or self.natural_drivers else ()
        if self.vehicle_drivers:
            deferred = set(self.vehicle_drivers).union(deferred)
        if self.natural_drivers:
            deferred = set(self.natural_drivers).union(deferred)
        if self.esmini_controllers:
            deferred = {n for n, c in self.esmini_controllers.items() if c.moves_itself}.union(deferred)
        for body in self._in_order:
            if body.gone:
                continue
            if body.external:
                if body.name in steered:
                    continue  # moved once its longitudinal controller has set the speed (below)
                self._move_external(body, dt)
                if sumo is not None:
                    sumo.place(body)
                continue
            if body.entity.driver == "sumo" or (tow_of and body.name in tow_of):
                continue  # SUMO moves it, or its tow vehicle drags it (below)
            if deferred and body.name in deferred:
                continue
            if not self._default_move(body, dt, now):
                continue
            if sumo is not None:
                sumo.place(body)
        if self.trailer_of:
            self.align_trailers(pull=True)
        if self.sumo is not None:
            self.sumo.step(self.bodies.values(), now, self.locate)
        if self.acc_drivers:
            self._step_drivers(self.acc_drivers.values(), dt, now)
        if self.natural_drivers:
            self._step_drivers(self.natural_drivers.values(), dt, now)
        if self.esmini_controllers:
            self._step_controllers(dt, now)
        for name in steered:
            self._move_external(self.bodies[name], dt)
            if sumo is not None:
                sumo.place(self.bodies[name])
            self.moved()
        if self.vehicle_drivers:
            for follower in list(self.vehicle_drivers.values()):
                if not follower.actor.gone and not follower.actor.external:
                    self.measure.clear()
                    follower.step(dt)
            self.moved()
        if ghosts is not None:
            ghosts.end_step(dt)
            self.moved()
        for body in self._in_order:  # (the bodies of the step's start: a run's bodies are made at its start)
            speed0, heading0, px, py = body.at_step_start
            speed = body.speed
            body.acceleration = (speed - speed0) / dt
            turn = body.heading - heading0
            body.yaw_rate = (turn if -math.pi <= turn < math.pi else wrap_angle(turn)) / dt
            # velocity from the displacement (as esmini derives it); a jump (teleport) from speed and heading
            vx, vy = (body.x - px) / dt, (body.y - py) / dt
            if vx * vx + vy * vy > (2.0 * abs(speed) + 1.0) ** 2:
                vx, vy = speed * math.cos(body.heading), speed * math.sin(body.heading)
            body.previous_velocity = (body.vx, body.vy)
            body.vx, body.vy = vx, vy
            if abs(speed) < 1e-3:
                if body.standstill_since is None:
                    body.standstill_since = now
            else:
                body.standstill_since = None
        if self.ended_in_move:
            # an action that moves its entity itself (a trajectory) ended while moving it: it ends in this
            # step, so conditions on its end see it at the next (as esmini)
            self.ended_in_move = False
            self.story.end_finished_actions()
        self.time = now
        self.step_index += 1
        self.moved()
        self._check_stop()

    def _check_stop(self) -> bool:
        if self.story.check_stop():
            self.ended_by = "stopTrigger"
            return True
        return False

    def _steered(self) -> list[str]:
        """Entities an external controller drives on the lateral domain only while a driver model of
        CARLOS' holds the longitudinal one."""
        out = []
        for name in (*self.natural_drivers, *self.esmini_controllers):
            body = self.bodies[name]
            control = self.controllers[name]
            if body.external and not control[1] and control[2] and not body.gone and name not in out:
                out.append(name)
        return out

    def run_alone(self, body: Body, dt: float, steps: int, sample: Callable[[int], None]) -> None:
        """esmini's ghost restart: `body` alone runs its actions and moves, `steps` steps of `dt`, the time
        going over the last head start again (every other entity stands); `sample(k)` after each."""
        start = self.time - steps * dt
        for k in range(steps):
            now = start + (k + 1) * dt
            body.lateral_velocity = 0.0
            runtimes = [r for r in self.init_runtimes if r.actor is body]
            for node in {id(n): n for n in self.story.running.values()}.values():
                runtimes.extend(r for r in node.runtime or () if r.actor is body)
            for runtime in runtimes:
                if not runtime.done:
                    self.owner = body
                    runtime.step(dt)
            self.moved()
            self._default_move(body, dt, now)
            self.moved()
            sample(k)

    def _default_move(self, body: Body, dt: float, now: float) -> bool:
        """Move one entity by its action mover, else along its road at its speed (the default controller);
        False when it stays where a teleport put it this step."""
        road = self.road
        extra = body.extra
        lateral_step = None
        if extra:
            if extra.pop("teleported", 0.0):
                extra.pop("move_speed", 0.0)
                return False
            speed = extra.pop("move_speed", body.speed)
            lateral_step = extra.pop("lateral_step", None)
        else:
            speed = body.speed
        distance = speed * dt
        mover = body.mover
        if mover is not None:
            mover.move(dt, now)
        else:
            if lateral_step is not None:
                # a sideways move of this step takes its length off the way along (esmini's lateral
                # distance action)
                distance = math.copysign(max(abs(distance) - lateral_step, 0.0), speed)
            elif body.lateral_velocity != 0.0:
                # the entity moves at its speed along its path: a lateral motion takes its share of it
                lateral = min(abs(body.lateral_velocity), abs(speed))
                distance = math.copysign(math.sqrt(speed * speed - lateral * lateral), speed) * dt
            if road is not None and body.road_id is not None:
                advance_on_road(road, body, distance, now)
            elif distance != 0.0:
                body.x += distance * math.cos(body.heading)
                body.y += distance * math.sin(body.heading)
            body.odometer += abs(distance)
        return True

    def _step_drivers(
        self, stepped: Iterable[drivers.AccDriver | drivers.NaturalDriver], dt: float, now: float
    ) -> None:
        """esmini steps these controllers after the default motion of every entity, each seeing the others
        where they are after this step. An ACC sets its entity's speed and, in override mode, moves it with
        it; a NaturalDriver sets the speed and moves it, and a lane change it decides starts from the next
        step (esmini injects it as an action)."""
        for driver in list(stepped):
            body = driver.actor
            # an external controller steering only (esmini's InteractiveController on the lateral domain) moves
            # the entity at the speed a longitudinal driver model sets
            if body.gone or (body.external and self.controllers[body.name][1]):
                continue
            self.measure.clear()
            driver.step(dt)
            if body.external:
                continue
            if isinstance(driver, drivers.NaturalDriver):
                self._move_body(body, dt, now)
                self._start_lane_change(driver)
            elif driver.override and not driver.virtual:
                self._move_body(body, dt, now)
        self.moved()

    def _step_controllers(self, dt: float, now: float) -> None:
        """The controllers of the registry, after the default motion of every entity (as esmini): each sets
        its entity's speed and, when it moves it, moves it with that speed."""
        for controller in list(self.esmini_controllers.values()):
            body = controller.actor
            if body.gone or (body.external and self.controllers[body.name][1]):
                continue
            self.measure.clear()
            controller.step(dt)
            if controller.moves_itself and not body.external:
                self._move_body(body, dt, now)
        self.moved()

    def _start_lane_change(self, driver: drivers.NaturalDriver) -> None:
        """The lane change a NaturalDriver decided: sinusoidal, over its laneChangeDuration, to its target
        lane; it overrides a lateral action running on the entity."""
        lane, driver.pending_lane = driver.pending_lane, None
        if lane is None:
            return
        body = driver.actor
        change = m.LaneChangeAction(
            dynamics=m.TransitionDynamics("sinusoidal", "time", driver.lane_change_duration),
            target=m.AbsoluteTargetLane(lane),
        )
        runtime = LaneChangeRuntime(self, body, change)
        self.story.stop_action_of(body.name, "lateral")
        self.init_runtimes = [
            r for r in self.init_runtimes if not (r.actor is body and r.domain == "lateral")
        ]
        runtime.start()
        self.log.append(f"t={self.time:.2f} {body.name}: NaturalDriver changes to lane {lane}")
        if not runtime.done:
            self.init_runtimes.append(runtime)  # stepped with the Init actions still running

    def _move_body(self, body: Body, dt: float, now: float) -> None:
        """One step of default motion of one body at its speed (as in `advance`)."""
        extra = body.extra
        if extra.pop("teleported", 0.0):
            extra.pop("move_speed", 0.0)
            return
        speed = extra.pop("move_speed", body.speed)
        distance = speed * dt
        if body.mover is not None:
            body.mover.move(dt, now)
        else:
            if body.lateral_velocity != 0.0:
                lateral = min(abs(body.lateral_velocity), abs(speed))
                distance = math.copysign(math.sqrt(speed * speed - lateral * lateral), speed) * dt
            if self.road is not None and body.road_id is not None:
                advance_on_road(self.road, body, distance, now)
            elif distance != 0.0:
                body.x += distance * math.cos(body.heading)
                body.y += distance * math.sin(body.heading)
            body.odometer += abs(distance)
        if self.sumo is not None:
            self.sumo.place(body)

    def drive_externally(self, name: str) -> None:
        """Make `name` externally driven from now on (`spec.control.entities`), as if its external
        controller had been assigned and activated on both domains."""
        body = self.bodies.get(name)
        if body is None:
            raise BadInput(
                f"entity {name!r} is not in the scenario (entities: {', '.join(self.bodies)})",
                field="spec.control.entities",
            )
        from simcore.scenario.controller_actions import slots_of

        for _, domains in slots_of(self, body).values():
            domains.clear()  # the system under test takes both domains
        slots_of(self, body)["carlos.driver=external"] = (
            {"name": "carlos.driver=external", "carlos.driver": "external"},
            {"longitudinal", "lateral"},
        )
        self.controllers[name] = ["external", True, True]
        body.external = True
        body.mover = None

    def _move_external(self, body: Body, dt: float) -> None:
        """An entity its external controller drives: moved by the control input; without one (no system
        under test attached, or none that sent a command yet) it stands still, as in esmini: `carlos run`
        and `carlos conformance` give the same trajectories for the same file."""
        external = self.external
        if external is None or not external.has_input(body.entity.name):
            assigned = self.assigned_controller.get(body.name, body.entity.controller)
            for properties, domains in self.controller_slots.get(body.name, {}).values():
                if domains and m.controller_type(properties) in m.EXTERNAL_CONTROLLERS:
                    assigned = properties  # the external controller active on the entity
            if m.controller_type(assigned) == "InteractiveController":
                self._coast(body, dt)
            else:
                body.speed = 0.0
            return
        x, y, heading, speed = external.move(body.entity, body.x, body.y, body.heading, body.speed, dt)
        body.odometer += hypot(x - body.x, y - body.y)
        body.x, body.y, body.heading, body.speed = x, y, heading, speed
        self.locate(body)

    def _has_input(self, body: Body) -> bool:
        return self.external is not None and self.external.has_input(body.entity.name)

    def _coast(self, body: Body, dt: float) -> None:
        """esmini's InteractiveController with no key pressed (a headless run): its vehicle model rolls on,
        the speed declining by 0.1 % a step and held within 1.2 × the default speed limit, wheels straight:
        along its heading when it steers too, along the road when it controls the speed only."""
        _, longitudinal, lateral = self.controllers[body.name]
        if longitudinal:  # on the lateral domain only, the speed stays the default controller's
            limit = drivers.speed_limit(self, body)
            body.speed = min(max(body.speed * (1.0 - 0.001), -1.2 * limit), 1.2 * limit)
        distance = body.speed * dt
        if lateral or self.road is None or body.road_id is None:
            body.x += distance * math.cos(body.heading)
            body.y += distance * math.sin(body.heading)
            body.odometer += abs(distance)
            self.locate(body)
        else:
            advance_on_road(self.road, body, distance, self.time)

    def moved(self) -> None:
        """Bodies moved: the per-step caches of their frame, their states and condition measurements are
        stale."""
        self._frame = None
        self._states.clear()
        self.measure.clear()

    def state_of(self, body: Body) -> EntityState:
        cached = self._states.get(body.name)
        if cached is None:
            cached = self._states[body.name] = self._state_of(body)
        return cached

    def _facts_of(self, body: Body) -> EntityFacts:
        """What a body's state takes from its entity and its driver (name, type, category, box, who drives
        it): built again only when the body's entity (an assigned controller) or its external driving
        changes; the published box stays the same object while the entity's box does."""
        e = body.entity
        known = body.facts
        box = e.box
        if known is not None and known.box is box:
            bbox = known.bbox
        else:
            bbox = BoundingBox(box.center_x, box.center_y, box.center_z, box.length, box.width, box.height)
        external = body.external
        fixed = body.facts = EntityFacts(
            e,
            box,
            external,
            body.name,
            e.object_type,
            e.category,
            bbox,
            "external" if external else e.driver,
        )
        return fixed

    def _state_of(self, body: Body) -> EntityState:
        fixed = body.facts
        if fixed is None or fixed.entity is not body.entity or fixed.external is not body.external:
            fixed = self._facts_of(body)
        lane = None
        road_id = body.road_id
        if road_id is not None:
            road = self.road
            if road is not None:
                s = body.s
                posed_on = body.ref_road  # the road of the last pose: no look-up when it is this one
                t, lane_id, offset = lane_point(
                    road,
                    road_id,
                    body.lane_id,
                    s,
                    body.offset,
                    posed_on if posed_on is not None and posed_on.id == road_id else None,
                )
                lane = LaneCoordinates(road_id, lane_id, s, t, offset)
        return EntityState(
            fixed.name,
            fixed.object_type,
            fixed.category,
            body.x,
            body.y,
            body.z,
            body.heading,
            body.pitch,
            body.roll,
            body.speed,
            body.acceleration,
            body.yaw_rate,
            fixed.bbox,
            lane,
            fixed.controlled_by,
        )

    def frame(self) -> WorldFrame:
        """Every entity in the world now (built once per step: `moved` forgets them). An entity out of the
        world (not placed yet, deleted) is in no frame — no topic, recording, sensor or metric sees it at a
        stale position — except the ego, which metrics measure from."""
        ego = self.ego
        if self.ghosts is None:
            last = self._frame
            if last is not None and last.step == self.step_index and last.time == self.time:
                return last  # asked again before anything moved: the same frame
            entities = []
            for b in self._in_order:
                if not b.gone or b.name == ego:
                    # (called directly: compiled, a native call, not a bound method's)
                    entities.append(self._state_of(b))
            last = self._frame = WorldFrame(self.step_index, self.time, tuple(entities), ego, (), ())
            return last
        ghost_names = self.ghosts.names
        # a ghost is no object of the world (esmini shows it as a shadow): published apart
        present = [b for b in self.bodies.values() if not b.gone or b.name == ego]
        entities = [self.state_of(b) for b in present if b.name not in ghost_names]
        ghosts = tuple([self.state_of(b) for b in present if b.name in ghost_names])
        return WorldFrame(self.step_index, self.time, tuple(entities), self.ego, (), ghosts)

    @property
    def started(self) -> bool:
        """The storyboard runs (Init is over)."""
        return self.root.state == State.RUNNING

    @property
    def ended(self) -> bool:
        return self.ended_by is not None


def _added_later(scenario: m.Scenario) -> set[str]:
    """Entities an AddEntityAction brings in (they may have no initial position)."""
    out: set[str] = set()
    for _, action in m.story_actions(scenario):
        if isinstance(action.global_action, m.AddEntityAction):
            out.add(action.global_action.entity)
    return out


def _placement_order(init: tuple[m.InitAction, ...] | list[m.InitAction]) -> list[m.InitAction]:
    """Init actions with the teleports first, a teleport relative to an entity after that entity's own
    teleport (in Init order otherwise; a cycle keeps the file's order)."""
    teleports = [i for i in init if isinstance(i.action, m.TeleportAction)]
    others = [i for i in init if not isinstance(i.action, m.TeleportAction)]
    placed_by_init = {i.entity for i in teleports}
    done: set[str] = set()
    ordered: list[m.InitAction] = []
    pending = list(teleports)
    while pending:
        ready = [
            i
            for i in pending
            if (ref := getattr(i.action.position, "entity", None)) is None  # type: ignore[union-attr]
            or ref in done
            or ref not in placed_by_init
            or ref == i.entity
        ]
        if not ready:
            ready = pending[:1]  # a cycle: the file's order decides (and the position fails to resolve)
        for item in ready:
            ordered.append(item)
            done.add(item.entity)
            pending.remove(item)
    return ordered + others


def _default_ego(scenario: m.Scenario) -> str | None:
    """The ego: Ego/ego/hero/Hero, else the first entity; None for a scenario without entities (it runs
    its storyboard all the same, as esmini does)."""
    names = [e.name for e in scenario.entities]
    for candidate in ("Ego", "ego", "hero", "Hero"):
        if candidate in names:
            return candidate
    return names[0] if names else None


__all__ = ["ScenarioEngine", "SimulationError", "update_pose_from_road"]
