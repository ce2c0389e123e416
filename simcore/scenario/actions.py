"""Action runtimes beyond speed, lane change and teleport: trajectories, routes, distance keeping, lane offset,
speed profiles, synchronisation. Each sets the motion of its actor; the engine moves the actor."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario import paths
from simcore.scenario.motion import Body, shape_value, wrap_angle

if TYPE_CHECKING:
    from simcore.scenario.engine import ScenarioEngine


class Runtime:
    domain = "other"

    def __init__(self, engine: ScenarioEngine, actor: Body) -> None:
        self.engine = engine
        self.actor = actor
        self.done = False

    def start(self) -> None: ...

    def step(self, dt: float) -> None: ...


class NoMotionRuntime(Runtime):
    domain = "none"

    def start(self) -> None:
        self.done = True


# --- trajectories ------------------------------------------------------------------------------------------


class FollowTrajectoryRuntime(Runtime):
    """Moves the actor's reference point along the trajectory: at its own speed (no timing) or at the
    trajectory's times. At the end the actor goes back to following the road it is on."""

    domain = "lateral"

    def __init__(self, engine: ScenarioEngine, actor: Body, action: m.FollowTrajectoryAction) -> None:
        super().__init__(engine, actor)
        self.action = action
        self.path: paths.SampledPath | None = None
        self.s = 0.0
        self.t0 = 0.0

    def start(self) -> None:
        a = self.actor
        end = a.extra.get("trajectory_end_time")
        if end is not None and self.engine.time - end <= 2 * self.engine.dt + 1e-9:
            # chained trajectories: the next starts with the heading the previous one ended with (lane
            # following in between would have turned the entity back to the road's heading)
            a.heading = a.extra["trajectory_end_heading"]
        self.path = paths.sample(
            self.action.trajectory, self.engine.resolve_position, (a.x, a.y, a.z, a.heading)
        )
        self.t0 = self.engine.time
        self.s = min(max(self.action.initial_distance_offset, 0.0), self.path.length)
        timed = self.action.timing != "none" and self.path.t is not None
        self.timed = timed
        if timed:
            self.s = self.path.s_at_time(self._trajectory_time(self.engine.time))
        a.mover = self
        a.placed = True
        self._pose(self.s)

    def _trajectory_time(self, now: float) -> float:
        elapsed = now if self.action.timing == "absolute" else now - self.t0
        scale = self.action.scale if self.action.scale != 0 else 1.0
        return (elapsed - self.action.offset) / scale

    def _pose(self, s: float) -> None:
        assert self.path is not None
        x, y, z, h = self.path.at(s)
        a = self.actor
        a.x, a.y, a.heading = x, y, wrap_angle(h + (math.pi if a.speed < 0 and not self.timed else 0.0))
        if self.engine.road is not None:
            a.z = z if z != 0.0 else a.z
        self.engine.track_road(a)

    def move(self, dt: float, now: float) -> None:
        assert self.path is not None
        a = self.actor
        if self.timed:
            s_new = self.path.s_at_time(self._trajectory_time(now))
            a.speed = (s_new - self.s) / dt
            end = self.path.t is not None and self._trajectory_time(now) >= self.path.t[-1] - 1e-9
        else:
            s_new = self.s + abs(a.speed) * dt
            end = s_new >= self.path.length - 1e-9
        a.odometer += abs(s_new - self.s)
        self.s = min(s_new, self.path.length)
        self._pose(self.s)
        if end:
            if not self.timed:
                # what is left of this step's distance continues along the last heading
                over = s_new - self.path.length
                a.x += over * math.cos(a.heading)
                a.y += over * math.sin(a.heading)
            self.finish()

    def finish(self) -> None:
        a = self.actor
        a.extra["trajectory_end_time"] = self.engine.time + self.engine.dt
        a.extra["trajectory_end_heading"] = a.heading
        if a.mover is self:
            a.mover = None
        self.engine.track_road(a, lock_lane=True)
        if a.road_id is None and self.engine.road is None:
            # with no road to go on with, the entity stops where the trajectory ends (as esmini does)
            a.speed = 0.0
        self.done = True


# --- routes ------------------------------------------------------------------------------------------------


class AssignRouteRuntime(Runtime):
    domain = "route"

    def __init__(
        self, engine: ScenarioEngine, actor: Body, action: m.AssignRouteAction | m.AcquirePositionAction
    ) -> None:
        super().__init__(engine, actor)
        self.action = action

    def start(self) -> None:
        if isinstance(self.action, m.AssignRouteAction):
            targets = [w.position for w in self.action.route.waypoints]
        else:
            targets = [self.action.position]
        self.actor.route = self.engine.plan_route(self.actor, targets)
        self.done = True


# --- lateral -----------------------------------------------------------------------------------------------


class LaneOffsetRuntime(Runtime):
    domain = "lateral"

    def __init__(self, engine: ScenarioEngine, actor: Body, action: m.LaneOffsetAction) -> None:
        super().__init__(engine, actor)
        self.action = action
        self.elapsed = 0.0

    def _target(self) -> float:
        value = self.action.offset * self.actor.direction
        if self.action.entity is not None:
            ref = self.engine.body(self.action.entity)
            value += ref.offset
        return value

    def start(self) -> None:
        self.offset0 = self.actor.offset
        self.offset1 = self._target()
        distance = abs(self.offset1 - self.offset0)
        acc = self.action.max_lateral_acc or 0.5
        shape = self.action.shape
        if shape == "step" or distance < 1e-9:
            self.duration = 0.0
        elif shape == "cubic":
            self.duration = math.sqrt(6.0 * distance / acc)
        elif shape == "sinusoidal":
            self.duration = math.pi * math.sqrt(distance / (2.0 * acc))
        else:  # linear: accelerate to the mean lateral speed within the first tenth
            self.duration = math.sqrt(distance / acc) * 2.0
        if self.duration <= 0:
            self.actor.offset = self.offset1
            self.done = not (self.action.continuous and self.action.entity is not None)

    def step(self, dt: float) -> None:
        if self.done:
            return
        if self.duration <= 0:
            self.actor.offset = self._target()
            return
        self.elapsed += dt
        p = self.elapsed / self.duration
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
    """Keeps a lateral distance (in road t) to another entity on the same road."""

    domain = "lateral"

    def __init__(self, engine: ScenarioEngine, actor: Body, action: m.LateralDistanceAction) -> None:
        super().__init__(engine, actor)
        self.action = action

    def step(self, dt: float) -> None:
        road = self.engine.road
        a, ref = self.actor, self.engine.body(self.action.entity)
        if road is None or a.road_id is None or ref.road_id != a.road_id:
            return
        t_ref = road.lane_center_t(ref.road_id, ref.lane_id, ref.s) + ref.offset
        t_me = road.lane_center_t(a.road_id, a.lane_id, a.s) + a.offset
        distance = self.action.distance
        if self.action.freespace:
            distance += (a.entity.box.width + ref.entity.box.width) / 2
        side = 1.0 if t_me >= t_ref else -1.0
        if self.action.displacement == "leftToReferencedEntity":
            side = float(a.direction)
        elif self.action.displacement == "rightToReferencedEntity":
            side = -float(a.direction)
        target = t_ref + side * distance
        wanted = target - t_me
        c = self.action.constraints
        if c is not None and c.max_speed is not None:
            limit = c.max_speed * dt
            wanted = max(-limit, min(limit, wanted))
        a.offset += wanted
        a.lateral_velocity = wanted / dt
        if not self.action.continuous and abs(target - t_me - wanted) < 0.01:
            self.done = True


# --- longitudinal ------------------------------------------------------------------------------------------


class LongitudinalDistanceRuntime(Runtime):
    domain = "longitudinal"

    def __init__(self, engine: ScenarioEngine, actor: Body, action: m.LongitudinalDistanceAction) -> None:
        super().__init__(engine, actor)
        self.action = action

    def _target_gap(self, ref: Body) -> float:
        if self.action.distance is not None:
            gap = self.action.distance
        else:
            gap = (self.action.time_gap or 0.0) * abs(ref.speed)
        return gap

    def start(self) -> None:
        self.step(0.0)

    def step(self, dt: float) -> None:
        a = self.actor
        ref = self.engine.body(self.action.entity)
        gap = self.engine.relative_distance(
            a, ref, "longitudinal", self.action.freespace, signed=True, system=self.action.coordinate_system
        )
        ahead = self.action.displacement != "leadingReferencedEntity"
        if self.action.displacement == "any":
            ahead = gap >= 0
        target = self._target_gap(ref) * (1 if ahead else -1)
        error = gap - target  # > 0: too far behind (trailing)
        c = self.action.constraints
        if c is None:
            # no dynamics given: the distance is kept exactly
            self.engine.shift_along(a, error)
            a.speed = ref.speed
            if not self.action.continuous:
                self.done = True
            return
        if dt <= 0:
            return
        # a critically damped follower limited by the constraints
        closing = ref.speed - a.speed
        accel = 4.0 * error + 4.0 * closing  # a spring (k = 4) with critical damping (2√k)
        if c.max_acceleration is not None:
            accel = min(accel, c.max_acceleration)
        if c.max_deceleration is not None:
            accel = max(accel, -c.max_deceleration)
        speed = a.speed + accel * dt
        if c.max_speed is not None:
            speed = min(speed, c.max_speed)
        a.speed = max(speed, 0.0)
        if not self.action.continuous and abs(error) < 0.1 and abs(closing) < 0.1:
            self.done = True


class SpeedProfileRuntime(Runtime):
    domain = "longitudinal"

    def __init__(self, engine: ScenarioEngine, actor: Body, action: m.SpeedProfileAction) -> None:
        super().__init__(engine, actor)
        self.action = action
        self.elapsed = 0.0
        self.knots: list[tuple[float, float]] = []

    def start(self) -> None:
        v = self.actor.speed
        t = 0.0
        self.knots = [(0.0, v)]
        base = self.engine.body(self.action.entity).speed if self.action.entity else 0.0
        c = self.action.constraints
        for entry in self.action.entries:
            target = base + entry.speed
            if entry.time is not None:
                duration = entry.time
            else:
                rate = None
                if c is not None:
                    rate = c.max_acceleration if target >= v else c.max_deceleration
                duration = abs(target - v) / rate if rate else 0.0
            t += max(duration, 0.0)
            self.knots.append((t, target))
            v = target

    def step(self, dt: float) -> None:
        self.elapsed += dt
        for (t0, v0), (t1, v1) in zip(self.knots, self.knots[1:], strict=False):
            if self.elapsed <= t1:
                f = (self.elapsed - t0) / (t1 - t0) if t1 > t0 else 1.0
                self.actor.speed = v0 + f * (v1 - v0)
                return
        self.actor.speed = self.knots[-1][1]
        self.done = True


class SynchronizeRuntime(Runtime):
    """Adapts the actor's speed so it reaches its target position when the master reaches its own; with a
    final speed, along a quadratic speed profile that ends at that speed."""

    domain = "longitudinal"

    def __init__(self, engine: ScenarioEngine, actor: Body, action: m.SynchronizeAction) -> None:
        super().__init__(engine, actor)
        self.action = action
        self.master_previous = math.inf

    def start(self) -> None:
        e = self.engine
        self.target = e.resolve_position(self.action.position)
        self.master_target = e.resolve_position(self.action.master_position)
        self.master = e.body(self.action.master)

    def _final_speed(self) -> float | None:
        if self.action.final_speed is not None:
            return self.action.final_speed
        if self.action.final_relative is not None:
            _, value, kind = self.action.final_relative
            return self.master.speed + value if kind == "delta" else self.master.speed * value
        return None

    def step(self, dt: float) -> None:
        e = self.engine
        a = self.actor
        d_master = e.distance_to(self.master, self.master_target)
        d_me = e.distance_to(a, self.target)
        final = self._final_speed()
        reached = d_master <= max(self.action.master_tolerance, abs(self.master.speed) * dt * 0.5, 0.05)
        if reached or d_master > self.master_previous + 1e-6:
            if final is not None:
                a.speed = final
            self.done = True
            return
        self.master_previous = d_master
        if self.master.speed <= 1e-3:
            return
        remaining = d_master / self.master.speed
        if remaining <= dt:
            if final is not None:
                a.speed = final
            return
        if final is None:
            a.speed = max(d_me / remaining, 0.0)
            return
        v0, T, d = a.speed, remaining, d_me
        # a steady state: the final speed is reached this far (or this long) before the target
        if self.action.steady_distance is not None and final > 1e-6:
            d -= self.action.steady_distance
            T -= self.action.steady_distance / final
        elif self.action.steady_time is not None:
            d -= final * self.action.steady_time
            T -= self.action.steady_time
        if dt >= T or d <= 0:
            a.speed = final
            return
        c = 6.0 * ((final - v0) * T / 2.0 - d + v0 * T) / T**3
        b = (final - v0 - c * T * T) / T
        a.speed = max(v0 + b * dt + c * dt * dt, 0.0)


def make(engine: ScenarioEngine, actor: Body, action: m.PrivateAction) -> Runtime | None:
    if isinstance(action, m.FollowTrajectoryAction):
        return FollowTrajectoryRuntime(engine, actor, action)
    if isinstance(action, m.AssignRouteAction | m.AcquirePositionAction):
        return AssignRouteRuntime(engine, actor, action)
    if isinstance(action, m.LaneOffsetAction):
        return LaneOffsetRuntime(engine, actor, action)
    if isinstance(action, m.LateralDistanceAction):
        return LateralDistanceRuntime(engine, actor, action)
    if isinstance(action, m.LongitudinalDistanceAction):
        return LongitudinalDistanceRuntime(engine, actor, action)
    if isinstance(action, m.SpeedProfileAction):
        return SpeedProfileRuntime(engine, actor, action)
    if isinstance(action, m.SynchronizeAction):
        return SynchronizeRuntime(engine, actor, action)
    if isinstance(action, m.NoMotionAction):
        return NoMotionRuntime(engine, actor)
    return None


__all__ = ["BadInput", "Runtime", "make"]
