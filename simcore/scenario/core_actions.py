"""Speed, lane change and teleport: the runtimes of the private actions nearly every scenario uses."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario.motion import (
    Body,
    lane_shift,
    shape_peak_rate_factor,
    shape_slope,
    shape_value,
    wrap_angle,
)
from simcore.scenario.runtime import Instant, Runtime

if TYPE_CHECKING:
    from simcore.scenario.action_world import ActionWorld


class SpeedRuntime(Runtime):
    domain = "longitudinal"

    def __init__(self, world: ActionWorld, actor: Body, action: m.SpeedAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.v0 = 0.0
        self.elapsed = 0.0
        self.duration = 0.0
        self.rate = 0.0  # the rate of a rate-dimension transition, within the vehicle's performance
        # what the (immutable) action says, read at every step: a fixed target speed, a target that is
        # followed continuously, followed at once (step shape), and a rate to a moving target
        target = action.target
        self._fixed = target.value if isinstance(target, m.AbsoluteTargetSpeed) else None
        self._follows = isinstance(target, m.RelativeTargetSpeed) and target.continuous
        self._follows_at_once = action.dynamics.shape == "step" and self._follows
        self._moving_rate = action.dynamics.dimension == "rate" and isinstance(target, m.RelativeTargetSpeed)

    def target(self) -> float:
        fixed = self._fixed
        if fixed is not None:
            return fixed
        target = self.action.target
        assert isinstance(target, m.RelativeTargetSpeed)
        reference = self.world.body(target.entity).speed
        return reference + target.value if target.value_type == "delta" else reference * target.value

    def start(self) -> None:
        self.v0 = self.actor.speed
        dyn = self.action.dynamics
        target = self.target()
        dv = abs(target - self.v0)
        if dyn.dimension == "rate":
            # the rate is bounded by the vehicle's performance (as esmini does)
            perf = self.actor.entity.performance
            limit = perf.max_acceleration if target >= self.v0 else perf.max_deceleration
            rate = min(dyn.value, limit) if limit > 0 else dyn.value
            self.rate = rate
            self.duration = dv / rate * shape_peak_rate_factor(dyn.shape) if rate > 0 else 0.0
        elif dyn.dimension == "distance":
            # every shape is symmetric, so the mean speed over the transition is (v0 + v1) / 2: the
            # transition covers `value` metres in this time (as esmini does)
            mean = (abs(self.v0) + abs(target)) / 2
            self.duration = dyn.value / mean if mean > 1e-9 else 0.0
        else:
            self.duration = dyn.value
        if dyn.dimension != "rate" and dyn.shape != "step" and self.duration > 0 and dv > 0:
            # the shape's peak acceleration stays within the vehicle's performance: the transition is
            # stretched when it would exceed it (as esmini does)
            perf = self.actor.entity.performance
            limit = perf.max_acceleration if target >= self.v0 else perf.max_deceleration
            peak = dv / self.duration * shape_peak_rate_factor(dyn.shape)
            if limit > 0 and peak > limit:
                self.duration = dv * shape_peak_rate_factor(dyn.shape) / limit
        if self.actor.entity.driver == "sumo":
            # the SUMO driver reaches the desired speed with its own dynamics
            self.world.sumo_set_speed(self.actor, self.target())
            self.done = not self._follows
            return
        if dyn.shape == "step" or self.duration <= 0:
            self._set(self.target())
            self.done = not self._follows

    def _set(self, speed: float, dt: float | None = None) -> None:
        if dt:
            # the vehicle's performance bounds the acceleration (as esmini does)
            perf = self.actor.entity.performance
            v = self.actor.speed
            speed = min(max(speed, v - perf.max_deceleration * dt), v + perf.max_acceleration * dt)
        self.actor.speed = speed

    def step(self, dt: float) -> None:
        if self.actor.entity.driver == "sumo":
            self.world.sumo_set_speed(self.actor, self.target())
            return
        if self.done or self._follows_at_once:
            # following a moving target: within the vehicle's performance (as esmini does)
            self._set(self.target(), dt)
            return
        self.elapsed += dt
        dyn = self.action.dynamics
        target = self.target()
        if self._moving_rate and self.rate > 0:
            # a moving target changes how long the transition at this rate lasts, not the rate (as esmini)
            self.duration = abs(target - self.v0) / self.rate * shape_peak_rate_factor(dyn.shape)
        progress = self.elapsed / max(self.duration, 1e-9)
        self._set(self.v0 + (target - self.v0) * shape_value(dyn.shape, progress), dt)
        if progress >= 1.0 - 1e-9:
            self._set(target, dt)
            # bounded by the vehicle's performance, the target may be reached later than the shape says
            self.done = not self._follows and abs(self.actor.speed - target) < 1e-9

    def start_in_init(self) -> bool:
        """In Init, a step (or zero-time) change to a fixed target is the initial speed: reached at once; with a
        transition shape the speed changes over time from the start, as in a story."""
        dyn = self.action.dynamics
        if isinstance(self.action.target, m.RelativeTargetSpeed):
            # relative to another entity: esmini starts every Init action before it steps them, so the other
            # entity's Init speed counts wherever it stands in Init
            return False
        if dyn.shape == "step" or dyn.value == 0:
            self.actor.speed = self.target()
            return True
        return False


class LaneChangeRuntime(Runtime):
    domain = "lateral"

    def __init__(self, world: ActionWorld, actor: Body, action: m.LaneChangeAction) -> None:
        super().__init__(world, actor)
        self.action = action
        self.elapsed = 0.0
        self.start_odometer = 0.0
        self.offset0 = 0.0
        self.offset1 = 0.0

    def start(self) -> None:
        actor = self.actor
        road = self.world.road
        if road is None or actor.road_id is None:
            raise BadInput(
                f"LaneChangeAction on {actor.name!r}, which is not on a road", file=self.world.source
            )
        target = self.action.target
        try:
            if isinstance(target, m.AbsoluteTargetLane):
                lane = target.lane_id
                if lane not in road.lane_ids(actor.road_id, actor.s):
                    raise ValueError(f"lane {lane} does not exist on road {actor.road_id} at s={actor.s:.1f}")
            else:
                reference = self.world.body(target.entity)
                base = reference.lane_id if reference.road_id == actor.road_id else actor.lane_id
                lane = lane_shift(road, actor.road_id, actor.s, base, target.value, reference.direction)
        except ValueError as exc:
            lanes = road.lane_ids(actor.road_id, actor.s)
            if isinstance(target, m.AbsoluteTargetLane):
                if not lanes or lanes[0] <= target.lane_id <= lanes[-1]:
                    raise BadInput(
                        f"LaneChangeAction on {actor.name!r}: {exc}", file=self.world.source
                    ) from None
                to_left = target.lane_id > lanes[-1]
            else:
                to_left = (target.value > 0) == (self.world.body(target.entity).direction > 0)
            self._to_missing_lane(str(exc), to_left)
            return
        actor.heading_offset = 0.0  # esmini aligns the entity with the road when a lane change starts
        t_now = road.lane_center_t(actor.road_id, actor.lane_id, actor.s) + actor.offset
        centre = road.lane_center_t(actor.road_id, lane, actor.s)
        actor.lane_id = lane
        actor.offset = t_now - centre
        self.offset0 = actor.offset
        self.offset1 = self.action.target_lane_offset * actor.direction
        self.start_odometer = actor.odometer
        self.target_lane = lane
        if actor.entity.driver == "sumo":
            self.world.sumo_change_lane(actor, lane, self.action.dynamics.value)
            self.done = True
            return
        if self.action.dynamics.shape == "step" or self.action.dynamics.value <= 0:
            actor.offset = self.offset1
            self.done = True

    def stop(self) -> None:
        # stopped midway (another lateral action, an overriding event): the entity keeps its offset and the
        # heading it has relative to the road (as esmini)
        a, road = self.actor, self.world.road
        if road is not None and a.road_id is not None:
            lane_heading = road.road_to_world(a.road_id, a.s, 0.0).heading
            travel = lane_heading if a.direction > 0 else lane_heading + math.pi
            a.heading_offset = wrap_angle(a.heading - travel)
        a.lateral_velocity = 0.0

    def _to_missing_lane(self, why: str, to_left: bool) -> None:
        """A target lane beyond the road's last lane (to the left of it with `to_left`): esmini runs on. It
        measures the offset from the road's outer edge on that side (the centre of a lane of no width), puts
        the entity at that offset in the lane it is in (a jump sideways) and then changes to the target offset
        in its own lane."""
        actor, road = self.actor, self.world.road
        assert road is not None and actor.road_id is not None
        lanes = road.lane_ids(actor.road_id, actor.s)
        outer = lanes[-1] if to_left else lanes[0]
        centre = road.lane_center_t(actor.road_id, outer, actor.s)
        half = 0.5 * road.lane_width(actor.road_id, outer, actor.s)
        edge = max(centre + half, centre - half) if to_left else min(centre + half, centre - half)
        t_now = road.lane_center_t(actor.road_id, actor.lane_id, actor.s) + actor.offset
        actor.offset += t_now - edge  # from the lane's centre: the offset it had from the edge
        self.offset0 = actor.offset
        self.offset1 = self.action.target_lane_offset * actor.direction
        self.start_odometer = actor.odometer
        self.target_lane = actor.lane_id
        warning = f"{self.world.source}: LaneChangeAction on {actor.name!r}: {why}: it runs on in its lane (as esmini)"
        if warning not in self.world.warnings:
            self.world.warnings.append(warning)
        if self.action.dynamics.shape == "step" or self.action.dynamics.value <= 0:
            actor.offset = self.offset1
            self.done = True

    def step(self, dt: float) -> None:
        if self.done:
            return
        # the lane change moves the entity at the speed it has now: a speed action stepped after it in the
        # storyboard's order changes the speed from the next step on (as esmini); esmini's lane change moves
        # its entity itself, also in a step it was teleported in
        self.actor.extra["move_speed"] = self.actor.speed
        self.actor.extra.pop("teleported", None)
        dyn = self.action.dynamics
        before = self.elapsed
        self.elapsed += dt
        span = self.offset1 - self.offset0
        if dyn.dimension == "distance":
            travelled = self.actor.odometer - self.start_odometer
            progress = (travelled + abs(self.actor.speed) * dt) / dyn.value
            # lateral per metre along the road at the start of the step, as a velocity at the entity's speed
            rate = span * shape_slope(dyn.shape, travelled / dyn.value) / dyn.value * abs(self.actor.speed)
        else:
            if dyn.dimension == "rate":  # lateral rate in m/s: duration from the lateral distance
                duration = abs(span) / dyn.value * shape_peak_rate_factor(dyn.shape)
            else:
                duration = dyn.value
            duration = max(duration, 1e-9)
            progress = self.elapsed / duration
            rate = span * shape_slope(dyn.shape, before / duration) / duration
        new_offset = self.offset0 + span * shape_value(dyn.shape, progress)
        # esmini takes the heading, and the share of the speed the lateral motion takes, from the transition's
        # rate at the start of the step (before it advances the transition)
        self.actor.lateral_velocity = rate if dyn.shape != "step" else (new_offset - self.actor.offset) / dt
        self.actor.offset = new_offset
        if progress >= 1.0 - 1e-9:
            self.actor.offset = self.offset1
            self.actor.lateral_velocity = 0.0
            self.done = True


class TeleportRuntime(Instant):
    domain = "teleport"

    def __init__(self, world: ActionWorld, actor: Body, action: m.TeleportAction) -> None:
        super().__init__(world, actor)
        self.action = action

    def start(self) -> None:
        self.done = True
        ghosts = self.world.ghosts
        if ghosts is not None and id(self.action) in ghosts.setup.teleports:
            ghosts.teleport(self.actor)  # the ghost put on its entity (esmini's AddedGhostTeleport)
            return
        if self.actor.name in self.world.tow_of:
            return  # a towed trailer goes where its tow vehicle takes it (as esmini)
        self.world.place(self.actor, self.action.position)
        if self.actor.name in self.world.trailer_of:
            self.world.align_trailers(self.actor)
        if self.world.started:
            # teleported during the run: it stays where it was put for the rest of this step (as esmini)
            self.actor.extra["teleported"] = 1.0
        self.done = True
