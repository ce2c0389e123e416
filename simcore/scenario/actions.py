"""Action runtimes beyond speed, lane change and teleport: trajectories, routes, distance keeping, lane offset,
speed profiles, synchronisation. Each sets the motion of its actor; the engine moves the actor."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario import paths
from simcore.scenario.motion import UNPOSED, Body, lane_at_t, shape_value, wrap_angle
from simcore.scenario.runtime import Instant, Runtime
from simcore.world.native_calls import atan2, hypot

if TYPE_CHECKING:
    from simcore.scenario.action_world import ActionWorld
    from simcore.scenario.world import Pose
    from simcore.world.opendrive import OpenDrive

_BIG: Final = 1e10  # no limit (esmini's LARGE_NUMBER)
_EPS: Final = 1e-10


class NoMotionRuntime(Instant):
    domain = "none"

    def __init__(self, world: ActionWorld, actor: Body, action: m.NoMotionAction) -> None:
        super().__init__(world, actor)

    def start(self) -> None:
        self.done = True


# --- trajectories ------------------------------------------------------------------------------------------


class FollowTrajectoryRuntime(Runtime):
    """Moves the actor's reference point along the trajectory: at its own speed (no timing) or at the
    trajectory's times. At the end the actor goes back to following the road it is on."""

    domain = "lateral"

    def __init__(self, world: ActionWorld, actor: Body, action: m.FollowTrajectoryAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.path: paths.SampledPath | None = None
        self.s = 0.0
        self.t0 = 0.0
        self.t_start = 0.0  # trajectory time where a relative timing's clock starts
        self.step_speed: float | None = None
        self.backward_heading: float | None = None
        self.last_road: tuple[str, float] | None = None  # the road (and s) it was last on

    def start(self) -> None:
        a = self.actor
        end = a.extra.get("trajectory_end_time")
        if end is not None and self.world.time - end <= 2 * self.world.dt + 1e-9:
            # chained trajectories: the next starts with the heading the previous one ended with (lane
            # following in between would have turned the entity back to the road's heading)
            a.heading = a.extra["trajectory_end_heading"]
        self.path = paths.sample(
            self.action.trajectory, self.world.resolve_position, (a.x, a.y, a.z, a.heading)
        )
        if self.action.following_mode == "position":
            # timed vertices in position mode: each segment at its own constant speed; in follow mode the
            # speed changes linearly from vertex to vertex, from the speed the entity has now (as esmini)
            self.path.v = None
        elif self.path.v is not None:
            self.path.v = paths.vertex_speeds(self.path, abs(a.speed))
        self.t0 = self.world.time
        self.s = min(max(self.action.initial_distance_offset, 0.0), self.path.length)
        timed = self.action.timing != "none" and self.path.t is not None
        self.timed = timed
        if timed:
            self.t_start = self.path.time_at_s(self.s)
            self.s = self.path.s_at_time(self._trajectory_time(self.world.time))
        a.mover = self
        a.placed = True
        self._pose(self.s)
        self.backward_heading = None if timed else self._explicit_heading_against()
        if self.backward_heading is not None:
            a.heading = self.backward_heading

    def _explicit_heading_against(self) -> float | None:
        """The heading a polyline's first vertex gives explicitly (a WorldPosition's `h`) when it and the
        entity's speed make esmini drive the trajectory backwards from its start (a heading more than 90° off
        the trajectory's direction and a forward speed, or a heading along it and a reverse speed), which
        ends it at once (None otherwise)."""
        shape = self.action.trajectory.shape
        assert self.path is not None
        if not isinstance(shape, m.Polyline) or not shape.vertices or self.s > 0.0:
            return None
        first = shape.vertices[0].position
        if not isinstance(first, m.WorldPosition) or first.h is None:
            return None
        heading = self.world.resolve_position(first)[3]
        against = abs(wrap_angle(heading - self.path.at(0.0)[3])) > math.pi / 2 + _EPS
        # esmini's direction of motion along it: the speed's sign (0 counts as forward) times the heading's
        return heading if against == (self.actor.speed >= 0.0) else None

    def step(self, dt: float) -> None:
        # the entity moves along the trajectory at the speed it has when this action steps: a speed action
        # that steps after it (later in the storyboard) takes effect one step later (as esmini)
        self.step_speed = self.actor.speed

    def _trajectory_time(self, now: float) -> float:
        """The trajectory time at simulation time `now`, as esmini: absolute `now × scale + offset`;
        relative `t(initial s) + elapsed × scale + offset` (the clock starts at the time of the point the
        entity starts from, so a trajectory stamped from 4.2 s on starts moving at once)."""
        scale = self.action.scale if self.action.scale != 0 else 1.0
        if self.action.timing == "absolute":
            return now * scale + self.action.offset
        return self.t_start + (now - self.t0) * scale + self.action.offset

    def _pose(self, s: float) -> None:
        assert self.path is not None
        x, y, z, h = self.path.at(s)
        a = self.actor
        a.x, a.y, a.heading = x, y, wrap_angle(h + (math.pi if a.speed < 0 and not self.timed else 0.0))
        if self.world.road is not None:
            a.z = z if z != 0.0 else a.z
        self.world.track_road(a)
        if a.road_id is not None:
            self.last_road = (a.road_id, a.s)

    def move(self, dt: float, now: float) -> None:
        assert self.path is not None
        a = self.actor
        if self.backward_heading is not None:
            # driven backwards from its start: it ends at once where it starts, facing the heading given
            a.heading = self.backward_heading
            self.finish()
            return
        over_time = 0.0
        if self.timed:
            assert self.path.t is not None
            t_traj = self._trajectory_time(now)
            s_new = self.path.s_at_time(t_traj)
            end = t_traj >= self.path.t[-1] - 1e-9
            if t_traj < self.path.t[-1] + 1e-9:
                a.speed = (s_new - self.s) / dt
            else:
                # past the last vertex within this step: the speed it had is kept (not the part of the step
                # left to the end), and the time left over is driven on at it along the final heading (as
                # esmini)
                over_time = t_traj - self.path.t[-1]
        else:
            speed = a.speed if self.step_speed is None else self.step_speed
            self.step_speed = None
            s_new = self.s + abs(speed) * dt
            end = s_new >= self.path.length - 1e-9
        a.odometer += abs(s_new - self.s)
        self.s = min(s_new, self.path.length)
        self._pose(self.s)
        if end:
            # what is left of this step's distance continues the way the trajectory ends (backwards for an
            # entity reversing along it, whose heading is the opposite)
            over = over_time * a.speed if self.timed else s_new - self.path.length
            _, _, _, h_end = self.path.at(self.path.length)
            a.x += over * math.cos(h_end)
            a.y += over * math.sin(h_end)
            self.finish()

    def stop(self) -> None:
        # overridden (a speed action, another trajectory): the entity goes on along the road from where it is
        if self.actor.mover is self:
            self.finish()

    def finish(self) -> None:
        a = self.actor
        a.extra["trajectory_end_time"] = self.world.time + self.world.dt
        a.extra["trajectory_end_heading"] = a.heading
        if a.mover is self:
            a.mover = None
        self.world.track_road(a, lock_lane=True)
        road = self.world.road
        if a.road_id is None and road is not None and self.last_road is not None:
            # ended beside the lanes of the road it drove on: it goes on along that road at that distance
            # from it (as esmini)
            road_id, s_hint = self.last_road
            found = road.project_on(road_id, a.x, a.y, s_hint)
            if found is not None:
                a.road_id, a.s = road_id, found[0]
                a.lane_id, a.offset = lane_at_t(road, road_id, found[0], found[1])
                lane_heading = road.road_to_world(road_id, a.s, 0.0).heading
                a.direction = 1 if math.cos(a.heading - lane_heading) >= 0 else -1
                a.posed = UNPOSED
        if a.road_id is not None and road is not None:
            # it goes on along the lane keeping the heading it has relative to it (as esmini)
            lane_heading = road.road_to_world(a.road_id, a.s, 0.0).heading
            travel = lane_heading if a.direction > 0 else lane_heading + math.pi
            a.heading_offset = wrap_angle(a.heading - travel)
        if a.road_id is None and self.world.road is None:
            # with no road to go on with, the entity stops where the trajectory ends (as esmini does)
            a.speed = 0.0
        self.done = True
        self.world.ended_in_move = True


# --- routes ------------------------------------------------------------------------------------------------


class AssignRouteRuntime(Instant):
    """The roads the actor takes through the waypoints of a route, planned at once."""

    domain = "route"

    def __init__(self, world: ActionWorld, actor: Body, action: m.AssignRouteAction) -> None:
        super().__init__(world, actor)
        self.action = action

    def targets(self) -> list[m.Position]:
        return [w.position for w in self.action.route.waypoints]

    def strategies(self) -> list[str]:
        return [w.strategy for w in self.action.route.waypoints]

    def start(self) -> None:
        from simcore.scenario.controllers.follow_route import route_points

        targets = self.targets()
        self.actor.route = self.world.plan_route(self.actor, targets)
        # the waypoints as esmini keeps them for a FollowRouteController (resolved now)
        self.actor.route_points = route_points(self.world, targets)
        self.actor.route_strategies = self.strategies()
        self.done = True


class AcquirePositionRuntime(AssignRouteRuntime):
    """A route to one position; in Init it is planned with the actions that run from the first step."""

    def __init__(self, world: ActionWorld, actor: Body, action: m.AcquirePositionAction) -> None:
        Runtime.__init__(self, world, actor)
        self.position = action.position

    def targets(self) -> list[m.Position]:
        return [self.position]

    def strategies(self) -> list[str]:
        return ["shortest"]

    def start_in_init(self) -> bool:
        return False


# --- lateral -----------------------------------------------------------------------------------------------


class LaneOffsetRuntime(Runtime):
    domain = "lateral"

    def __init__(self, world: ActionWorld, actor: Body, action: m.LaneOffsetAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.elapsed = 0.0

    def _target(self) -> float:
        a = self.actor
        if self.action.entity is None:
            return self.action.offset * a.direction
        ref = self.world.body(self.action.entity)
        road = self.world.road
        if road is None or ref.road_id is None or a.road_id is None:
            return self.action.offset * a.direction + ref.offset
        # the other entity's road t plus the value (to its left when it drives toward +s), as an offset from
        # the centre of the actor's own lane (as esmini): a relative offset can move the actor across lanes
        t_target = road.lane_center_t(ref.road_id, ref.lane_id, ref.s) + ref.offset
        t_target += self.action.offset * (1 if ref.direction > 0 else -1)
        return t_target - road.lane_center_t(a.road_id, a.lane_id, a.s)

    def start(self) -> None:
        self.offset0 = self.actor.offset
        self.offset1 = self._target()
        distance = abs(self.offset1 - self.offset0)
        acc = self.action.max_lateral_acc or 0.5
        shape = self.action.shape
        if shape == "step" or distance < 1e-9:
            self.duration = 0.0
        elif shape == "sinusoidal":
            self.duration = math.pi * math.sqrt(distance / (2.0 * acc))
        else:
            # cubic: the peak lateral acceleration is maxLateralAcc; linear (infinite at its ends) takes the
            # cubic's duration (as esmini)
            self.duration = math.sqrt(6.0 * distance / acc)
        if self.duration <= 0:
            self.actor.offset = self.offset1
            self.done = not (self.action.continuous and self.action.entity is not None)

    def step(self, dt: float) -> None:
        if self.done:
            return
        if self.duration <= 0:
            self.actor.offset = self._target()
            return
        # esmini evaluates the transition before advancing it: the first step keeps the start offset, and
        # the target is reached one step after the duration
        p = self.elapsed / self.duration
        self.elapsed += dt
        new = self.offset0 + (self.offset1 - self.offset0) * shape_value(self.action.shape, p)
        # a lane offset shifts the path sideways: the speed along the road is kept (as esmini does)
        self.actor.offset = new
        if p >= 1.0 - 1e-9:
            self.actor.lateral_velocity = 0.0
            self.actor.offset = self.offset1
            if self.action.continuous and self.action.entity is not None:
                self.duration = 0.0  # keep following the other entity's offset
            else:
                self.done = True  # an absolute target reached ends the action, continuous or not (as esmini)


class LateralDistanceRuntime(Runtime):
    """Keeps a lateral distance to another entity on the same road: in road t (road coordinates) or across
    the actor's own heading (entity coordinates, the default). Without maxAcceleration the distance is taken
    at once, or in road coordinates at no more than maxSpeed; with maxAcceleration a spring (stiffness scaled
    by the limit; critically damped in road coordinates, overdamped in entity coordinates) pulls the entity
    there, damped on the lateral speed relative to the other entity's (its velocity across its own heading,
    as esmini's LateralDistanceAction takes it). The lateral speed stays below maxSpeed and the entity's own
    speed. The spring's first step moves nothing (as esmini, which steps it with the time elapsed since its
    start)."""

    domain = "lateral"
    SPRING = 0.4
    THRESHOLD = 0.01  # m: this close ends a non-continuous action

    def __init__(self, world: ActionWorld, actor: Body, action: m.LateralDistanceAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.velocity = 0.0  # lateral, in t per second
        self.first_step = -1

    def start(self) -> None:
        self.first_step = self.world.step_index

    def step(self, dt: float) -> None:
        road = self.world.road
        a, ref = self.actor, self.world.body(self.action.entity)
        if road is None or a.road_id is None or ref.road_id != a.road_id:
            return
        t_ref = road.lane_center_t(ref.road_id, ref.lane_id, ref.s) + ref.offset
        t_me = road.lane_center_t(a.road_id, a.lane_id, a.s) + a.offset
        road_system = self.action.coordinate_system == "road"
        c = self.action.constraints or m.DynamicConstraints()
        if not road_system:
            # in entity coordinates the distance is across the actor's own heading (as esmini): an actor
            # beside and behind a turning entity measures it along its own turned axis
            across = -math.sin(a.heading) * (a.x - ref.x) + math.cos(a.heading) * (a.y - ref.y)
            t_me = t_ref + across * a.direction
        distance = self.action.distance
        if self.action.freespace:
            distance += (a.entity.box.width + ref.entity.box.width) / 2
        side = 1.0 if t_me >= t_ref else -1.0
        if self.action.displacement == "leftToReferencedEntity":
            side = float(a.direction)
        elif self.action.displacement == "rightToReferencedEntity":
            side = -float(a.direction)
        target = t_ref + side * distance
        error = target - t_me
        if not self.action.continuous and abs(error) < self.THRESHOLD:
            self.done = True
        # in road coordinates maxSpeed alone limits the lateral speed; in entity coordinates (the default)
        # only maxAcceleration brings dynamics, else the distance is taken at once in the first step (as esmini)
        dynamic = c.max_acceleration is not None or (road_system and c.max_speed is not None)
        if self.world.step_index == self.first_step and dynamic:
            return
        max_speed = c.max_speed if c.max_speed is not None else _BIG
        if c.max_speed is not None or c.max_acceleration is not None:
            # moving with dynamics, the lateral speed takes a share of the entity's speed, never all of it
            # (as esmini; without dynamics it is put at the distance at once)
            max_speed = min(max_speed, abs(a.speed))
        if c.max_acceleration is not None:
            stiffness = c.max_acceleration * self.SPRING
            relative = self.velocity - self._reference_lateral_speed(road, ref)
            # damped on sqrt(stiffness) in road coordinates, on the limit itself in entity coordinates (an
            # overdamped spring there: esmini closes the distance slowly)
            damping = 2.0 * math.sqrt(stiffness if road_system else c.max_acceleration)
            acc = error * stiffness - relative * damping
            acc = min(max(acc, -c.max_acceleration), c.max_acceleration)
            self.velocity = min(max(self.velocity + acc * dt, -max_speed), max_speed)
            move = self.velocity * dt
        elif road_system:
            move = min(max(error, -max_speed * dt), max_speed * dt)
        else:
            move = error
        a.offset += move
        if road_system or c.max_acceleration is not None:
            a.lateral_velocity = move / dt
        else:
            # taken at once: the actor takes the other entity's heading relative to the road (as esmini),
            # not one of its own sideways motion, and the sideways move takes its length off the way along
            a.extra["lateral_step"] = abs(move)
            a.lateral_velocity = 0.0
            pose = road.road_to_world(ref.road_id, ref.s, 0.0)
            travel = pose.heading if ref.direction > 0 else pose.heading + math.pi
            a.heading_offset = wrap_angle(ref.heading - travel)
            # the rest of the step it drives along that heading: sideways too, relative to the road
            along = max(abs(a.speed) * dt - abs(move), 0.0)
            a.offset += a.direction * along * math.sin(a.heading_offset)

    @staticmethod
    def _reference_lateral_speed(road: OpenDrive, ref: Body) -> float:
        """The referenced entity's velocity across its own heading (+ to its left), as esmini takes it: the
        velocity of its last step's displacement seen from the heading it has now (a lateral action of its
        that stepped before this one has already turned it)."""
        heading = ref.heading
        if ref.lateral_velocity != 0.0 and ref.road_id is not None and abs(ref.speed) > 0.1:
            pose = road.road_to_world(ref.road_id, ref.s, road.lane_center_t(ref.road_id, ref.lane_id, ref.s))
            travel = pose.heading if ref.direction > 0 else pose.heading + math.pi
            drift = atan2(ref.lateral_velocity * ref.direction, abs(ref.speed))
            # esmini turns a lane-changing entity by the lateral rate at the start of the step: about the
            # mean of the heading it had and the one this step's lateral motion gives
            heading = ref.heading + 0.5 * wrap_angle(travel + drift + ref.heading_offset - ref.heading)
        return ref.vy * math.cos(heading) - ref.vx * math.sin(heading)


# --- longitudinal ------------------------------------------------------------------------------------------


class LongitudinalDistanceRuntime(Runtime):
    """Keeps a distance (or time gap) to another entity along the longitudinal axis. Without dynamic
    constraints the distance is kept exactly (the actor is moved to it and takes the other's speed); with
    them a critically damped spring pulls it there, its stiffness scaled by the acceleration limit, its
    acceleration limited and (with maxAcceleration/DecelerationRate) changing no faster than the jerk
    limits (as esmini does)."""

    domain = "longitudinal"
    SPRING = 0.4
    THRESHOLD = 0.1  # m: a distance this close ends a non-continuous action

    def __init__(self, world: ActionWorld, actor: Body, action: m.LongitudinalDistanceAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.acceleration = 0.0
        self.trailing = action.displacement != "leadingReferencedEntity"

    def _gap(self, ref: Body) -> float:
        a = self.action
        return self.world.measure.relative_distance(
            self.actor, ref, "longitudinal", a.freespace, signed=True, system=a.coordinate_system
        )

    def start(self) -> None:
        if self.action.displacement == "any":
            self.trailing = self._gap(self.world.body(self.action.entity)) >= 0.0

    def step(self, dt: float) -> None:
        a = self.actor
        ref = self.world.body(self.action.entity)
        gap = self._gap(ref)
        if self.action.distance is not None:
            wanted = abs(self.action.distance)
        else:
            wanted = abs((self.action.time_gap or 0.0) * ref.speed)
        error = gap - (wanted if self.trailing else -wanted)  # > 0: too far behind the wanted place
        if not self.action.continuous and abs(error) < self.THRESHOLD:
            self.done = True
        c = self.action.constraints or m.DynamicConstraints()
        # the limits given are bounded by the vehicle's performance (as esmini does); one of them missing is
        # the vehicle's (esmini would take it as unlimited, with absurd speeds as a result)
        perf = a.entity.performance
        given = c.max_acceleration is not None or c.max_deceleration is not None
        max_acc = min(c.max_acceleration, perf.max_acceleration) if c.max_acceleration is not None else _BIG
        max_dec = min(c.max_deceleration, perf.max_deceleration) if c.max_deceleration is not None else _BIG
        if given:
            max_acc = min(max_acc, perf.max_acceleration)
            max_dec = min(max_dec, perf.max_deceleration)
        if max_acc >= _BIG and max_dec >= _BIG:
            # no dynamics given: the distance is kept exactly
            self.world.shift_along(a, error)
            a.speed = ref.speed
            return
        stiffness = (max_acc if error < 0.0 else max_dec) * self.SPRING
        acc = error * stiffness - (a.speed - ref.speed) * 2.0 * math.sqrt(stiffness)
        if acc < 0.0:
            jerk = -(c.max_deceleration_rate if c.max_deceleration_rate is not None else _BIG)
            acc = max(acc, -max_dec)
            if acc < self.acceleration:
                acc = max(self.acceleration + jerk * dt, acc)
        else:
            jerk = c.max_acceleration_rate if c.max_acceleration_rate is not None else _BIG
            acc = min(acc, max_acc)
            if acc > self.acceleration:
                acc = min(self.acceleration + jerk * dt, acc)
        self.acceleration = acc
        speed = a.speed + acc * dt
        limit = c.max_speed if c.max_speed is not None else perf.max_speed
        a.speed = min(max(speed, -limit), limit)


class SpeedProfileRuntime(Runtime):
    """Speed over time through the entries' (time, speed) vertices. followingMode="position": straight lines
    between the vertices. "follow": the corners are rounded by phases of constant jerk within the dynamic
    constraints (maxAccelerationRate / maxDecelerationRate), each placed so the speed joins the next line
    tangentially; a single target is reached on time with jerk, constant acceleration, jerk (as esmini)."""

    domain = "longitudinal"

    def __init__(self, world: ActionWorld, actor: Body, action: m.SpeedProfileAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.elapsed = 0.0
        # (start time, speed, acceleration, jerk) of each phase, times from the action's start
        self.segments: list[tuple[float, float, float, float]] = []
        self.index = 0
        self.speed = 0.0

    def start(self) -> None:
        c = self.action.constraints or m.DynamicConstraints()
        self.max_acc = c.max_acceleration if c.max_acceleration is not None else _BIG
        self.max_dec = c.max_deceleration if c.max_deceleration is not None else _BIG
        self.jerk_up = c.max_acceleration_rate if c.max_acceleration_rate is not None else _BIG
        self.jerk_down = c.max_deceleration_rate if c.max_deceleration_rate is not None else _BIG
        self.max_speed = c.max_speed if c.max_speed is not None else _BIG
        self.follow = self.action.following_mode == "follow"
        vertices = self._vertices()
        a0 = self.actor.acceleration
        if len(vertices) == 1:
            self._add(vertices[0][0], vertices[0][1], 0.0, 0.0)
        elif self.follow and len(vertices) == 2:
            self._single_target(vertices, a0)
        else:
            self._multiple_targets(vertices, a0)
        self.speed = self.actor.speed

    def _vertices(self) -> list[list[float]]:
        """[time, speed, slope to the next vertex, intercept of that line] with redundant vertices merged."""
        entries = self.action.entries
        offset = self.world.body(self.action.entity).speed if self.action.entity else 0.0
        v_now = self.actor.speed
        first = entries[0]
        start = 0
        if first.time is not None and abs(first.time) <= _EPS and not self.follow:
            vertices = [[0.0, first.speed + offset, 0.0, 0.0]]
        else:
            vertices = [[0.0, v_now, 0.0, 0.0]]
            if first.time is not None and abs(first.time) <= _EPS:
                start = 1  # follow: the first entry at time 0 is where the entity is now
        time = 0.0
        last_index = len(entries) - 1
        for index in range(start, len(entries)):
            entry = entries[index]
            target = entry.speed + offset
            last = vertices[-1]
            if entry.time is None:
                # no time: reached at the constraints' acceleration (or deceleration)
                dv = target - last[1]
                if abs(dv) < _EPS:
                    continue
                acc = min(-_EPS, -self.max_dec) if dv < 0 else max(_EPS, self.max_acc)
                last[0] = time
                time += dv / acc
            else:
                time += entry.time
            span = time - last[0]
            if index < last_index and span < _EPS:
                vertices[-1] = [time, target, 0.0, 0.0]
                continue
            slope = (target - last[1]) / span
            limited = min(max(slope, -self.max_dec), self.max_acc)
            if limited != slope and abs(limited) > _EPS:
                # beyond the constraints: reached at the limit, later, and every later entry with it (as esmini)
                time = last[0] + (target - last[1]) / limited
                slope = limited
            last[2] = slope
            last[3] = last[1] - last[2] * last[0]
            previous_slope = vertices[-2][2] if index > 1 and len(vertices) > 1 else self.actor.acceleration
            if index > 1 and len(vertices) > 1 and abs(last[2] - previous_slope) < _EPS:
                # on the same line as the previous segment: the vertex between them is dropped
                before = vertices[-2]
                slope = (target - before[1]) / (time - before[0])
                vertices[-1] = [time, target, slope, target - slope * time]
                continue
            if index == last_index:
                vertices.append([time, target, 0.0, target])
            else:
                vertices.append([time, target, 0.0, 0.0])
        return vertices

    def _add(self, t: float, v: float, k: float, j: float) -> None:
        if self.follow and (
            abs(v) > self.max_speed + _EPS
            or not -self.max_dec - _EPS <= k <= self.max_acc + _EPS
            or not -self.jerk_down - _EPS <= j <= self.jerk_up + _EPS
        ):
            self.follow = False  # beyond the constraints: the rest is followed along straight lines
        self.segments.append((t, v, k, j))

    def _within(self, k: float) -> bool:
        return -self.max_dec < k < self.max_acc

    def _single_target(self, vertices: list[list[float]], k0: float) -> None:
        """Reach one speed at its time: jerk, constant acceleration when there is time for it, jerk back."""
        t0, v0, slope = vertices[0][0], vertices[0][1], vertices[0][2]
        t3, v3 = vertices[1][0], vertices[1][1]
        j0 = -self.jerk_down if slope - k0 < 0 else self.jerk_up
        j1 = self.jerk_up if slope < 0 else -self.jerk_down
        self._add(t0, v0, k0, j0)
        k1 = t2 = v2 = 0.0
        if abs(j1 - j0) < _EPS:
            if abs(t0 - t3) > _EPS and abs(j1 * (t0 - t3) - k0) > _EPS:
                t1 = (2 * j1 * (v0 + t0 * j1 * (t0 - t3) - v3) + k0**2 + 2 * k0 * j1 * (t3 - 2 * t0)) / (
                    2 * j1 * (j1 * (t0 - t3) - k0)
                )
                if t1 >= 0:
                    v1 = v0 + k0 * (t1 - t0) + 0.5 * j0 * (t1 - t0) ** 2
                    k1 = k0 + j0 * (t1 - t0)
                    t2 = k1 / j1 + t3
                    if t2 >= 0:
                        v2 = v1 + k1 * (t2 - t1)
                        if self._within(k1):
                            self._add(t1, v1, k1, 0.0)
        else:
            inner = 2 * v0 * (j1 - j0) + k0**2 + 2 * k0 * j1 * (t3 - t0) + j0 * j1 * (t0 - t3) ** 2
            factor = j0 * j1 * (inner + 2 * v3 * (j0 - j1))
            if factor < 0.0:
                # no time for a phase of constant acceleration: the target is reached later than asked
                root = math.sqrt(max(j1 * (j1 - j0) * (j0 * (2 * v3 - 2 * v0) + k0**2), 0.0))
                t2 = (root + (j0 - j1) * (t0 * j0 - k0)) / (j0 * (j0 - j1))
                v2 = v0 + k0 * (t2 - t0) + 0.5 * j0 * (t2 - t0) ** 2
                k1 = k0 + j0 * (t2 - t0)
                t3 = t2 - k1 / j1
            else:
                t1 = (-math.sqrt(factor) - j0 * (k0 + t3 * j1) + t0 * j0**2) / (j0 * (j0 - j1))
                v1 = v0 + k0 * (t1 - t0) + 0.5 * j0 * (t1 - t0) ** 2
                k1 = k0 + j0 * (t1 - t0)
                t2 = k1 / j1 + t3
                v2 = v1 + k1 * (t2 - t1)
                if self._within(k1):
                    self._add(t1, v1, k1, 0.0)
        if self._within(k1):
            self._add(t2, v2, k1, j1)
            self._add(t3, v3, 0.0, 0.0)
            return
        # the acceleration needed is beyond the constraints: limited, and the target is reached later
        k1 = min(max(k1, -self.max_dec), self.max_acc)
        t1 = t0 + (k1 - k0) / j0
        v1 = v0 + k0 * (t1 - t0) + 0.5 * j0 * (t1 - t0) ** 2
        t2 = (v3 - v1) / k1 + t1 + k1 / (2 * j1)
        v2 = v3 + k1**2 / (2 * j1)
        t3 = (v3 - v1) / k1 + t1 - k1 / (2 * j1)
        self._add(t1, v1, k1, 0.0)
        self._add(t2, v2, k1, j1)
        self._add(t3, v3, 0.0, 0.0)

    def _multiple_targets(self, vertices: list[list[float]], k0: float) -> None:
        if not self.follow:
            for t, v, k, _ in vertices:
                self._add(t, v, k, 0.0)
            return
        t0 = vertices[0][0]
        t3, v3 = t0, vertices[0][1]
        j = 0.0
        if abs(vertices[0][2]) > _EPS:
            # from the acceleration the entity has now to the first line's slope
            j = -self.jerk_down if vertices[0][2] - k0 < 0 else self.jerk_up
            self._add(t0, vertices[0][1], k0, j)
            t3 = t0 + (vertices[0][2] - k0) / j
        v3 = vertices[0][1] + k0 * (t3 - t0) + 0.5 * j * (t3 - t0) ** 2
        k1 = vertices[0][2]
        m1 = v3 - k1 * t3
        self._add(t3, v3, k1, 0.0)
        for index in range(len(vertices) - 1):
            if not self.follow:
                t, v, k, _ = vertices[index]
                self._add(t, v, k, 0.0)
                continue
            k0, m0, t0, v0 = k1, m1, t3, v3
            _, _, k1, m1 = vertices[index + 1]
            j = -self.jerk_down if k1 - k0 < 0 else self.jerk_up
            if abs(k0 - k1) >= _EPS:
                # the jerk phase that leaves line (k0, m0) and joins line (k1, m1) tangentially
                t1 = ((k0 - k1) ** 2 - 2 * j * (m0 - m1)) / (2 * j * (k0 - k1))
                if t1 < t0:
                    self.follow = False  # no room for it: straight lines from here
                    continue
                v1 = v0 + k0 * (t1 - t0)
                t3 = t1 + (k1 - k0) / j
                v3 = v1 + k0 * (t3 - t1) + 0.5 * j * (t3 - t1) ** 2
                self._add(t1, v1, k0, j)
            self._add(t3, v3, k1, 0.0)

    def step(self, dt: float) -> None:
        self.elapsed += dt
        time = self.elapsed
        segments = self.segments
        last_t, last_v = segments[-1][0], segments[-1][1]
        if time < last_t + 10 and not (time > last_t and abs(self.speed - last_v) < _EPS):
            while self.index < len(segments) - 1 and time > segments[self.index + 1][0] - _EPS:
                self.index += 1
            t, v, k, j = segments[self.index]
            tau = time - t
            self.speed = v + k * tau + 0.5 * j * tau * tau
            if abs(self.speed) < _EPS:
                self.speed = 0.0
        if self.index >= len(self.action.entries) - 1 and abs(self.speed - last_v) < 1e-6:
            self.speed = last_v
            self.done = True
        self.actor.speed = self.speed


class SynchronizeRuntime(Runtime):
    """Adapts the actor's speed so it reaches its target position when the master reaches its own (within the
    tolerances). Without a final speed: a constant acceleration to get there in time. With one, esmini's
    profile: first a phase of constant acceleration toward an apex speed (or a stop and wait when the
    target is too close), then a linear change to the final speed on arrival; an optional steady state
    keeps the final speed over the last distance (or time)."""

    domain = "longitudinal"
    MAX_DECELERATION = 8.0  # m/s², stopping at once when the target is far too close

    def __init__(self, world: ActionWorld, actor: Body, action: m.SynchronizeAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.mode = "none"  # none | nonlinear | linear | stopped | stop | waiting | steady
        self.convex = False
        self.last_dist = math.inf
        self.last_master_dist = math.inf
        self._projections: dict[tuple[int, float, float], tuple[float, float]] = {}

    def start(self) -> None:
        e = self.world
        self.target = e.resolve_position(self.action.position)
        self.master_target = e.resolve_position(self.action.master_position)
        self.master = e.body(self.action.master)
        final = self._final_speed()
        self.steady_distance: float | None = self.action.steady_distance
        if self.action.steady_time is not None and final is not None:
            self.steady_distance = self.action.steady_time * final

    def _final_speed(self) -> float | None:
        if self.action.final_speed is not None:
            return self.action.final_speed
        if self.action.final_relative is not None:
            _, value, kind = self.action.final_relative
            return self.master.speed + value if kind == "delta" else self.master.speed * value
        return None

    def step(self, dt: float) -> None:
        a, action = self.actor, self.action
        master_dist = self._distance(self.master, self.master_target)
        dist = self._distance(a, self.target)
        done = (
            dist < action.tolerance + _EPS
            or master_dist < action.master_tolerance + _EPS
            or dist > self.last_dist
            or master_dist > self.last_master_dist
        )
        self.last_dist, self.last_master_dist = dist, master_dist
        # measured to the edge of the tolerance areas
        dist = max(dist - action.tolerance, _EPS)
        master_dist = max(master_dist - action.master_tolerance, _EPS)
        master_time = _BIG
        master_speed = abs(self._speed_along_road(self.master))  # reversing toward it gets there too
        if master_speed > _EPS:
            master_time = master_dist / master_speed
            done = done or master_time < dt
        final = self._final_speed()
        if done:
            if final is not None:
                a.speed = final
            self.done = True
            return
        if final is None:
            # no final speed: constant acceleration to cover the distance in the master's time
            end_speed = 2 * dist / master_time - a.speed
            a.speed += (end_speed - a.speed) / master_time * dt
            return
        if self.steady_distance is not None and self.mode != "steady":
            time_to_steady = self.steady_distance / final if final > _EPS else _BIG
            if dist - self.steady_distance < _EPS or master_time - time_to_steady < _EPS:
                self.mode = "steady"
            else:
                dist -= self.steady_distance
                master_time -= time_to_steady
        if self.mode == "steady":
            a.speed = final
            return
        if master_time >= _BIG and self.mode != "stop":
            a.speed = 0.0  # the master stands still: wait for it (as esmini)
            return
        if self.mode == "waiting":
            if master_time >= _BIG:
                return
            self.mode = "none"
        if self.mode == "stop":
            a.speed -= self.MAX_DECELERATION * dt
            if a.speed < 0:
                a.speed = 0.0
                self.mode = "waiting"  # until the master moves
            return
        if self.mode == "stopped":
            if master_time < 2 * dist / final:
                self.mode = "linear"  # time to move again
            else:
                a.speed = 0.0
                return
        if self.mode == "linear":
            if master_time > _BIG - 1 or master_time < 0.001 or dist < 0.001:
                a.speed = 0.0
            else:
                a.speed = max(0.0, 2 * dist / master_time - max(0.0, final))
            return
        if (
            self.mode == "nonlinear"
            and master_time < _BIG
            and abs(a.speed - (2 * dist / master_time - final)) < 0.1
        ):
            self.mode = "linear"  # on the straight line to the final speed: follow it from the next step
            return
        if self.mode == "none":
            self.mode = "nonlinear"
            self.convex = (final + a.speed) / 2 < dist / master_time  # rush first, else linger first
        acc, apex = self._first_phase(dist, master_time, self._speed_along_road(a), final)
        if (not self.convex and acc > 0) or (self.convex and acc < 0):
            self.mode = "linear"  # past the apex: the speed is kept this step
            acc = 0.0
        if self.mode == "nonlinear" and apex < 0:
            # even stopping at once would be too far: decelerate to a stop, wait, then go
            v0 = a.speed
            t1 = 2 * v0 * dist / (v0 * v0 + final * final) if v0 * v0 + final * final > 0 else 0.0
            acc = -v0 / t1 if abs(t1) > _EPS else 0.0
            if t1 * v0 / 2 > dist / 2:
                acc = -self.MAX_DECELERATION
                self.mode = "stop"
            if v0 + acc * dt < 0:
                a.speed = 0.0
                self.mode = "stopped"
                return
        a.speed += acc * dt

    def _speed_along_road(self, body: Body) -> float:
        """The body's speed projected on its road's s axis (as esmini measures speeds here)."""
        road = self.world.road
        if road is None or body.road_id is None:
            return body.speed
        road_heading = road.road_to_world(body.road_id, body.s, 0.0).heading
        return math.copysign(abs(body.speed * math.cos(body.heading - road_heading)), body.speed)

    ON_PATH = 1.0  # m: a target this close to an entity's trajectory is measured along it

    def _distance(self, body: Body, target: Pose) -> float:
        """Distance still to go: for an entity on a trajectory, along the trajectory to the target's point
        on it (a crossing pedestrian's road s does not change), in a straight line to a target off it; else
        along the road (as esmini)."""
        mover = body.mover
        if isinstance(mover, FollowTrajectoryRuntime) and mover.path is not None:
            key = (id(mover), target[0], target[1])
            if key not in self._projections:  # targets are fixed: project each once per trajectory
                self._projections[key] = mover.path.project(target[0], target[1])
            s_target, off = self._projections[key]
            if off <= self.ON_PATH:
                return abs(s_target - mover.s)
            return hypot(target[0] - body.x, target[1] - body.y)
        road = self.world.road
        if road is not None and body.road_id is not None and body.speed < 0:
            # reversing toward a target behind: the distance either way along the road (esmini's |ds|)
            rc = road.world_to_road(target[0], target[1], None, road_hint=body.road_id)
            if rc is not None and rc.road_id == body.road_id:
                return abs(rc.s - body.s)
        return self.world.distance_to(body, target)

    @staticmethod
    def _first_phase(s: float, t: float, v0: float, v1: float) -> tuple[float, float]:
        """(acceleration, apex speed) of the first of two phases of constant acceleration that cover s in t,
        starting at v0 and ending at v1, the second phase being a straight line to v1."""
        if abs(v1 - v0) < _EPS:
            apex = (s - t / 2 * v0) / (t / 2)
            return (apex - v0) / (t / 2), apex
        radicand = 2 * s * s - 2 * (v1 + v0) * t * s + (v1 * v1 + v0 * v0) * t * t
        if radicand < 0:
            return 0.0, 0.0
        root = math.sqrt(2.0) * math.sqrt(radicand)
        for sign in (1.0, -1.0):
            x = -(sign * root + 2 * s - 2 * v1 * t) / (2 * (v1 - v0))
            apex = (2 * s - sign * root) / (2 * t)
            if 0 < x < t:
                return (apex - v0) / x, apex
        return 0.0, 0.0


class TrailerRuntime(Runtime):
    """ConnectTrailerAction: the actor tows the trailer from now on (a trailer it towed before is let go);
    DisconnectTrailerAction: the actor lets its trailer go, which stops there (as esmini)."""

    domain = "trailer"

    def __init__(self, world: ActionWorld, actor: Body, action: m.TrailerAction) -> None:
        super().__init__(world, actor)
        self.action = action

    def start(self) -> None:
        e, name = self.world, self.actor.name
        old = e.trailer_of.pop(name, None)
        if old is not None:
            e.tow_of.pop(old, None)
            e.body(old).speed = 0.0  # let go, a trailer has nothing to move it on
        trailer = self.action.trailer
        if trailer is not None:
            body = e.body(trailer)
            if body is self.actor:
                raise BadInput(f"ConnectTrailerAction: {name!r} cannot tow itself", file=e.source)
            previous_tow = e.tow_of.pop(trailer, None)
            if previous_tow is not None:
                e.trailer_of.pop(previous_tow, None)
            e.trailer_of[name] = trailer
            e.tow_of[trailer] = name
            body.mover = None
        self.done = True
