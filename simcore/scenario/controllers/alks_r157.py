"""esmini's ALKS_R157SM_Controller (ControllerALKS_R157SM.cpp): the UN R157 (ALKS) benchmark driver models
as esmini implements them, on the longitudinal domain. Ported by their semantics:

- property `model` picks one of `Regulation` (the regulation's performance model: reaction time 0.35 s,
  deceleration 6 m/s², detection range 46 m), `ReferenceDriver` (the regulation's careful, competent human
  driver: perception, reaction 0.75 s, braking at 0.774 g, an AEB at 0.85 g; range 100 m), `RSS` and `FSM`
  (the safety-distance models of the JRC); another value is bad input;
- `cruise` (default true: an ACC-like cruise at 2 m/s² toward the speed at activation and a simple
  car-following law behind a target), `fullStop` (brake to a standstill once critical), `alwaysTrigOnScenario`,
  and for the ReferenceDriver `cutInPerceptionDelayMode` (`Dist`, the default: 0.72 m of lateral motion
  past the trigger; `Time`: 0.4 s), `pedestrianRiskEvaluationTime` (0.4 s), `aebTTC` (1.5 s),
  `lateralTrigDistance` (a lateral-motion trigger in m instead of the 0.375 m lane-wandering one),
  `overlapTolerance` (0.1 m); `mode` override (the default: it moves its entity) or additive;
- each step (after every entity moved): find the object in focus — the closest object ahead (reference
  points 0 < ds ≤ the range along the road) in its own or a neighbour lane (pedestrians in any lane) that the
  model deems unsafe (in its lane, or cutting in); measure its freespace distances, relative speeds along and
  across the road, time to collision and time headway; then brake as the model reacts when critical, else
  cruise; its entity moves with the new speed.

Where esmini's roadmanager decides something CARLOS computes differently, this uses the closest CARLOS
equivalent: road deltas along the road network between reference points, freespace gaps from the boxes'
corners along the road's axes (signed: + ahead, + to the left), velocities from the last step's displacement
(0 before the first step)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Final

from simcore.errors import BadInput
from simcore.scenario.controllers.road_view import (
    LARGE,
    OVERLAP_PART,
    SMALL,
    RoadPose,
    freespace_road,
    overlapping_front,
    road_pose,
    sign,
)

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld

G: Final = 9.8  # esmini's Model::g (the deceleration limits use 9.81)

NONE, CUT_IN, CUT_OUT, DECELERATION = "None", "CutIn", "CutOut", "Deceleration"
CRITICAL, TARGET_IN_SIGHT, NO_TARGET = "CRITICAL", "TARGET_IN_SIGHT", "NO_TARGET"
INACTIVE, PERCEIVE, REACT, BRAKE_REF = "INACTIVE", "PERCEIVE", "REACT", "BRAKE_REF"


@dataclass
class ObjectInfo:
    """esmini's ObjectInfo: what the model knows of one object."""

    obj: Body | None = None
    cut_out_vehicle: Body | None = None
    dist_long: float = LARGE  # freespace along the road
    dist_lat: float = LARGE  # freespace across it (+: to the left in its driving direction)
    dv_s: float = 0.0  # own speed less the object's, along the road
    dv_t: float = 0.0  # across it, + when closing in
    ttc: float = LARGE
    thw: float = LARGE
    d_lane: int = 0  # lanes from its own to the object's (+: to the left; -1, 0, 1 considered)
    action: str = NONE


def _flag(value: str | None) -> bool | None:
    if value in ("true", "True"):
        return True
    if value in ("false", "False"):
        return False
    return None


class Model:
    """esmini's ControllerALKS_R157SM::Model: detection, cruise and the hooks each model fills in."""

    name = ""

    def __init__(
        self, world: ScenarioWorld, veh: Body, reaction_time: float, max_dec: float, max_range: float
    ):
        self.world = world
        self.veh = veh
        self.rt = reaction_time
        self.rt_counter = 0.0
        self.max_dec = max_dec
        self.max_range = max_range
        self.max_acc = 3.0
        self.max_acc_lat = 1.0
        self.set_speed = 0.0
        self.dt = 0.01
        self.acc = 0.0
        self.cruise_comfort_acc = 2.0
        self.cruise_comfort_dec = 2.0
        self.cruise_max_acc = 3.0
        self.cruise_max_dec = 4.0
        self.mode = NO_TARGET
        self.scenario_type = NONE
        self.cruise = True
        self.full_stop = False
        self.always_trig = False
        self.focus = ObjectInfo()
        self._own: RoadPose | None = None  # its road position this step

    # --- hooks ---------------------------------------------------------------------------------------

    def check_safety(self, info: ObjectInfo) -> bool:
        return False

    def check_critical(self) -> bool:
        return False

    def react_critical(self) -> float:
        raise NotImplementedError

    def min_dist(self) -> float:
        raise NotImplementedError

    def reset(self) -> None:
        pass

    def keeps_focus(self) -> bool:
        """Only re-measure the object in focus (no re-scan) this step."""
        return False

    # --- detection -----------------------------------------------------------------------------------

    def process(self, info: ObjectInfo) -> bool:
        """Measure one object (esmini's Process); False when it is not considered."""
        obj, veh, world = info.obj, self.veh, self.world
        if obj is None or obj is veh or obj.gone or not obj.placed:
            return False
        own = self._own
        if own is None:
            return False
        theirs = road_pose(world, obj)
        if theirs is None:
            return False
        delta = world.measure.road_delta_entity(veh, obj)
        if delta is None or abs(delta[0]) > self.max_range:
            return False
        # esmini's Position::Delta: the lane difference seen from its own side of the road (+: to the left)
        d_lane = int(-sign(own.lane_id) * (theirs.lane_id - own.lane_id))
        if d_lane == 2 and theirs.lane_id == 1 and own.lane_id == -1:
            d_lane = 1
        elif d_lane == -2 and theirs.lane_id == -1 and own.lane_id == 1:
            d_lane = -1
        if not (delta[0] > SMALL and (obj.entity.object_type == "pedestrian" or -2 < d_lane < 2)):
            return False
        info.d_lane = d_lane
        info.dist_long, info.dist_lat = freespace_road(veh, own, obj, theirs, delta)
        backwards = abs(own.h_relative) > math.pi / 2
        info.dv_s = (own.vel_s - theirs.vel_s) * (-1.0 if backwards else 1.0)
        info.dv_t = (own.vel_t - theirs.vel_t) * sign(theirs.t - own.t)
        # the time headway whatever the relative speed (esmini's player measures it so: a vehicle braking
        # ahead that is still no slower than its follower is within the headway of a deceleration scenario)
        info.thw = info.dist_long / own.vel_s if own.vel_s != 0.0 else LARGE
        info.ttc = info.dist_long / info.dv_s if info.dv_s > 0.0 else LARGE
        return True

    def detect(self) -> None:
        candidate = ObjectInfo()
        tmp = ObjectInfo()  # reused across objects, as esmini's (its action carries over)
        for body in self.world.bodies.values():
            tmp.obj = body
            if not self.process(tmp):
                continue
            if self.check_safety(tmp):
                continue
            cand_cut_out = (
                candidate.obj is not None
                and candidate.obj.entity.object_type == "vehicle"
                and candidate.action == CUT_OUT
            )
            if tmp.dist_long < candidate.dist_long or (tmp.d_lane == 0 and cand_cut_out):
                if (
                    tmp.obj is not None
                    and tmp.obj.entity.object_type == "vehicle"
                    and tmp.action == CUT_OUT
                    and candidate.obj is not None
                    and candidate.d_lane == 0
                ):
                    if tmp.ttc < candidate.ttc:  # cutting out, revealing another object in the lane
                        candidate = replace(tmp)
                elif tmp.d_lane == 0 and cand_cut_out:
                    if tmp.ttc < candidate.ttc:  # in the lane beyond one cutting out
                        cut_out = candidate.obj
                        candidate = replace(tmp, cut_out_vehicle=cut_out, action=CUT_OUT)
                else:
                    candidate = replace(tmp)
        if (
            candidate.obj is not None
            and candidate.action != NONE
            and (candidate.obj is not self.focus.obj or candidate.action != self.focus.action)
        ):
            self.scenario_type = candidate.action
        self.focus = candidate

    # --- stepping ------------------------------------------------------------------------------------

    def step(self, dt: float) -> float:
        """The new speed."""
        self.dt = dt
        self._own = road_pose(self.world, self.veh)
        if self.focus.obj is not None and self.keeps_focus():
            self.process(self.focus)
        else:
            self.detect()
        if self.check_critical():
            return self.react_critical()
        return self.cruise_speed()

    def cruise_speed(self) -> float:
        v = self.veh.speed
        focus = self.focus
        if self.cruise:
            if focus.obj is None:
                self.mode = NO_TARGET
                if abs(v - self.set_speed) < SMALL:
                    self.acc = 0.0
                else:
                    self.acc = -self.cruise_comfort_dec if v > self.set_speed else self.cruise_comfort_acc
                return min(max(v + self.acc * self.dt, 0.0), self.set_speed)
            if focus.dist_long > 0 and focus.ttc > focus.dv_s / 12.0 + 0.35:
                self.mode = TARGET_IN_SIGHT
                if abs(v) < SMALL:
                    self.acc = 0.0  # come to a stop: release the brake
                else:
                    self.acc = 2.0 * -focus.dv_s + 1.0 * (focus.dist_long - self.min_dist())
                    self.acc = min(max(self.acc, -self.cruise_max_dec), self.cruise_max_acc)
                return min(max(v + self.acc * self.dt, 0.0), self.set_speed)
        self.acc = 0.0
        return v


class Regulation(Model):
    """The regulation's performance model (UN R157 5.2.3.3 following distance, cut-in when the front wheel is
    0.3 m inside the own lane, critical when TTC < dv/(2·6) + 0.35 + 0.1 s; then brakes at 6 m/s²)."""

    name = "Regulation"

    def __init__(self, world: ScenarioWorld, veh: Body) -> None:
        super().__init__(world, veh, 0.35, 6.0, 46.0)

    def min_dist(self) -> float:
        v = self.veh.speed
        # E/ECE/TRANS/505/Rev.3/Add.151 5.2.3.3
        slow = v * 3.6 < 10.0
        time_gap = 1.0 + (max(2.0, v) - 2.0) / 7.8 if slow else 1.0 + v * 3.6 / 100.0
        return max(v * time_gap, 2.0)

    def check_safety(self, info: ObjectInfo) -> bool:
        obj = info.obj
        if obj is None or info.dist_lat == LARGE:
            return True
        if info.d_lane == 0:
            info.action = DECELERATION
            return False
        theirs = road_pose(self.world, obj)
        road = self.world.road
        if theirs is not None and road is not None and info.dist_lat > -SMALL:
            lane_width = road.lane_width(theirs.road_id, theirs.lane_id, theirs.s)
            box = obj.entity.box
            # the front axle (the rear one at the reference point), else the front of the box
            vehicle = obj.entity.object_type == "vehicle"
            x = (obj.entity.wheelbase or 0.0) if vehicle else box.length / 2.0
            y = -sign(info.d_lane) * box.width / 2.0  # the side toward its own lane
            h = theirs.h_relative
            yr = x * math.sin(h) + y * math.cos(h)
            offset = (theirs.offset + yr) * -sign(info.d_lane)
            if offset > lane_width / 2.0 + 0.3:
                info.action = CUT_IN
                return False
        return True

    def check_critical(self) -> bool:
        focus = self.focus
        if focus.obj is None:
            self.mode = NO_TARGET
            return False
        if self.mode == CRITICAL and self.full_stop:
            return True
        closing = focus.dv_s > 0.0 and focus.dist_long > 0
        if closing and focus.ttc < focus.dv_s / (2 * self.max_dec) + self.rt + 0.1:
            self.mode = CRITICAL
            return True
        self.mode = TARGET_IN_SIGHT
        return False

    def react_critical(self) -> float:
        self.acc = -self.max_dec
        return max(0.0, self.veh.speed + self.acc * self.dt)


class _LateralTrigger:
    """esmini's ReferenceDriver::LateralDistTrigger: armed on an object moving toward its lane, it fires when
    the object's t has changed by more than the threshold since."""

    def __init__(self, threshold: float) -> None:
        self.threshold = threshold
        self.active = False
        self.obj: Body | None = None
        self.t0 = 0.0

    def reset(self) -> None:
        self.active, self.obj, self.t0 = False, None, 0.0

    def update(self, driver: ReferenceDriver, info: ObjectInfo) -> None:
        if info.obj is None or info.dv_t < SMALL:  # moving away laterally
            if self.active:
                self.reset()
            return
        if info.obj is not self.obj:
            self.obj, self.active = info.obj, True
            pose = road_pose(driver.world, info.obj)
            self.t0 = pose.t if pose is not None else 0.0
            self.armed(driver, pose)

    def armed(self, driver: ReferenceDriver, pose: RoadPose | None) -> None:
        pass

    def evaluate(self, driver: ReferenceDriver) -> bool:
        if not self.active or self.obj is None:
            return False
        pose = road_pose(driver.world, self.obj)
        return pose is not None and abs(pose.t - self.t0) > self.threshold


class _WanderingTrigger(_LateralTrigger):
    """esmini's WanderingTrigger: the lane wandering threshold (0.375 m) counted from the lane's centre on the
    side away from its own lane (a motorbike's from where it is)."""

    def armed(self, driver: ReferenceDriver, pose: RoadPose | None) -> None:
        self.threshold = driver.wandering_threshold
        own = driver._own
        if pose is None or own is None or self.obj is None:
            return
        motorbike = self.obj.entity.object_type == "vehicle" and self.obj.entity.category == "motorbike"
        if (pose.t > own.t and pose.offset > 0) or (pose.t < own.t and pose.offset < 0):
            self.threshold += abs(pose.offset)
        elif not motorbike:
            self.threshold = max(0.0, self.threshold - abs(pose.offset))


class ReferenceDriver(Model):
    """The regulation's reference driver: perceives a cut-in (lateral motion past the wandering threshold, then
    0.72 m or 0.4 s more), a cut-out or a deceleration (< -5 m/s²) of the vehicle ahead (0.4 s), reacts after
    0.75 s when the time to collision (cut-in) or headway (others) is under 2 s, lifting off at 0.4 m/s², then
    brakes with a jerk of 0.774 g / 0.6 s up to 0.774 g; its AEB brakes at up to 0.85 g once the time to
    collision is under `aebTTC` with the object covering its front."""

    name = "ReferenceDriver"

    def __init__(self, world: ScenarioWorld, veh: Body, properties: dict[str, str]) -> None:
        super().__init__(world, veh, 0.75, 0.774 * 9.81, 100.0)
        p = properties.get
        self.c_lane_offset = 0.0
        self.release_deceleration = 0.4
        self.critical_ttc = 2.0
        self.critical_thw = 2.0
        self.phase = INACTIVE
        self.timer = 0.0
        self.time_mode = p("cutInPerceptionDelayMode") == "Time"
        self.perception_dist = 0.72
        self.perception_time = 0.4
        self.wandering_threshold = 0.375
        self.overlap_tolerance = _number(p("overlapTolerance"), 0.1)
        self.pedestrian_risk_time = _number(p("pedestrianRiskEvaluationTime"), 0.4)
        self.perception_t = 0.0
        self.aeb_ttc = _number(p("aebTTC"), 1.5)
        self.aeb_active = False
        trig = p("lateralTrigDistance")
        self.trigger: _LateralTrigger = (
            _LateralTrigger(_number(trig, 0.0))
            if trig is not None
            else _WanderingTrigger(self.wandering_threshold)
        )

    def keeps_focus(self) -> bool:
        return self.phase != INACTIVE and self.full_stop

    def reset(self) -> None:
        self.phase = INACTIVE
        self.scenario_type = NONE

    def min_dist(self) -> float:
        return 2.0 + self.veh.speed * 2.0

    def _t(self, body: Body | None) -> float:
        pose = road_pose(self.world, body) if body is not None else None
        return pose.t if pose is not None else 0.0

    def check_safety(self, info: ObjectInfo) -> bool:
        obj = info.obj
        if obj is None or info.dist_lat == LARGE:
            return True
        pose = road_pose(self.world, obj)
        offset = pose.offset if pose is not None else 0.0
        self.c_lane_offset = offset + obj.entity.box.center_x * math.sin(obj.heading)
        self.trigger.update(self, info)
        if obj.entity.object_type == "pedestrian":
            if info.dv_t > SMALL:
                info.action = CUT_IN  # moving laterally toward it
                return False
        elif info.d_lane == 0:
            acc_s = pose.acc_s if pose is not None else 0.0
            lane = pose.lane_id if pose is not None else obj.lane_id
            if abs(self.c_lane_offset) > self.wandering_threshold and info.dv_t < -SMALL:
                info.action = CUT_OUT
            elif -sign(lane) * acc_s < -5.0 + SMALL:
                info.action = DECELERATION
            return False
        else:
            if self.trigger.evaluate(self):
                info.action = CUT_IN
                return False
            if info.action == CUT_IN:
                info.action = NONE
        return True

    # perception
    def _perceive_cut_in(self) -> bool:
        focus = self.focus
        pedestrian = focus.obj is not None and focus.obj.entity.object_type == "pedestrian"
        if self.phase == INACTIVE:
            if pedestrian and focus.dv_s > SMALL:
                self.timer = self.pedestrian_risk_time
                self.phase = PERCEIVE
            elif self.trigger.evaluate(self):
                self.perception_t = self._t(focus.obj)
                if self.time_mode:
                    self.timer = self.perception_time
                else:
                    self.perception_dist = 0.72
                self.phase = PERCEIVE
        elif self.phase == PERCEIVE:
            if pedestrian:
                if focus.dv_s > SMALL:
                    self.timer -= self.dt
                    if self.timer < SMALL:
                        self.phase = REACT
            elif not self.time_mode:
                if focus.obj is not None:
                    t, own = self._t(focus.obj), self._t(self.veh)
                    if (t > own and t < self.perception_t - self.perception_dist) or (
                        t < own and t > self.perception_t + self.perception_dist
                    ):
                        self.phase = REACT
            else:
                self.timer -= self.dt
                if self.timer < SMALL:
                    self.phase = REACT
            if self.phase == REACT:
                self.timer = self.rt
                return True
        return False

    def _perceive_cut_out(self) -> bool:
        if self.phase == INACTIVE:
            if self.focus.dv_s > SMALL:
                self.phase = PERCEIVE
                self.timer = self.perception_time
        elif self.phase == PERCEIVE:
            self.timer -= self.dt
            return self.timer < SMALL
        return False

    def _perceive_deceleration(self) -> bool:
        if self.phase == INACTIVE:
            obj = self.focus.obj
            pose = road_pose(self.world, obj) if obj is not None else None
            if pose is not None and pose.acc_s < -5.0:
                self.phase = PERCEIVE
                self.timer = self.perception_time
        elif self.phase == PERCEIVE:
            self.timer -= self.dt
            return self.timer < SMALL
        return False

    def _perceived(self) -> bool:
        if self.scenario_type == CUT_IN:
            return self._perceive_cut_in()
        if self.scenario_type == CUT_OUT:
            return self._perceive_cut_out()
        if self.scenario_type == DECELERATION:
            return self._perceive_deceleration()
        return False

    def _critical_condition(self) -> None:
        if self.scenario_type not in (CUT_IN, CUT_OUT, DECELERATION):
            return
        focus = self.focus
        measure = (
            focus.ttc < self.critical_ttc if self.scenario_type == CUT_IN else focus.thw < self.critical_thw
        )
        if self.always_trig or measure:
            if self.phase == REACT and self.timer < SMALL:
                self.mode = CRITICAL
        elif self.phase == REACT:
            self.reset()  # not a critical scenario
        elif self.mode == CRITICAL and focus.dist_long > self.min_dist():
            self.mode = TARGET_IN_SIGHT if focus.obj is not None else NO_TARGET
            if focus.dv_s < SMALL:
                self.reset()  # gap increasing

    def check_critical(self) -> bool:
        if self.phase in (INACTIVE, PERCEIVE):
            if self._perceived():
                self.phase = REACT
                self.timer = self.rt
        elif self.phase == REACT:
            self.timer -= self.dt
        focus = self.focus
        if self.mode == NO_TARGET and focus.obj is not None:
            self.mode = TARGET_IN_SIGHT
        if self.full_stop and self.mode == CRITICAL:
            if self.veh.speed < SMALL:  # out of critical mode only at a standstill
                self.reset()
                self.mode = TARGET_IN_SIGHT if focus.obj is not None else NO_TARGET
        elif focus.obj is None:
            self.reset()
            self.mode = NO_TARGET
        elif (self.veh.speed > SMALL and focus.dist_long > 0) or self.full_stop:
            self._critical_condition()
        if (
            not self.aeb_active
            and focus.obj is not None
            and focus.ttc < self.aeb_ttc
            and overlapping_front(self.veh, focus.obj, self.overlap_tolerance) > OVERLAP_PART
        ):
            self.aeb_active = True
        return self.mode == CRITICAL or self.aeb_active

    def react_critical(self) -> float:
        if self.phase == REACT and self.timer < SMALL:
            self.phase = BRAKE_REF
        if (self.phase == BRAKE_REF or self.aeb_active) and self.veh.speed < SMALL:
            self.phase = INACTIVE
            self.aeb_active = False
            self.timer = 0.0
        if self.phase == REACT:
            self.acc = min(-self.release_deceleration, self.acc)  # foot off the accelerator
        elif self.phase == BRAKE_REF:
            self.acc -= self.dt * 0.774 * G / 0.6
        if self.aeb_active:
            self.acc -= self.dt * 0.85 * G / 0.6
        self.acc = max(self.acc, -0.85 * G) if self.aeb_active else max(self.acc, -0.774 * G)
        return max(0.0, self.veh.speed + self.acc * self.dt)


class RSS(Model):
    """The RSS model: a cut-in within the RSS lateral safe distance, critical under the RSS longitudinal
    safe distance; brakes after the reaction time with a jerk of 12.65 m/s³."""

    name = "RSS"

    def __init__(self, world: ScenarioWorld, veh: Body) -> None:
        super().__init__(world, veh, 0.75, 0.774 * 9.81, 100.0)
        self.min_jerk = 12.65
        self.mu = 0.3

    def check_safety(self, info: ObjectInfo) -> bool:
        obj = info.obj
        if obj is None or info.dist_lat == LARGE:
            return True
        if info.dist_lat < SMALL or info.d_lane == 0:
            info.action = DECELERATION
            return False
        pose = road_pose(self.world, obj)
        lat = abs(pose.vel_t) if pose is not None else 0.0
        rt, a_lat = self.rt, self.max_acc_lat
        safe = self.mu + abs((2.0 * lat + a_lat * rt) * rt / 2.0) + (lat + a_lat * rt) ** 2 / (2 * a_lat)
        if abs(info.dist_lat) < safe:
            info.action = CUT_IN
            return False
        return True

    def check_critical(self) -> bool:
        focus = self.focus
        if focus.obj is None:
            self.mode = NO_TARGET
            return False
        if focus.dv_s > 0.0 and focus.dist_long > 0:
            v, rt = self.veh.speed, self.rt
            safe = (
                v * rt
                + self.max_acc * rt**2 / 2.0
                + (v + rt * self.max_acc) ** 2 / (2 * self.max_dec)
                - focus.obj.speed**2 / (2 * self.max_dec)
            )
            if focus.dist_long < safe:
                if self.mode != CRITICAL:
                    self.rt_counter = self.rt
                self.mode = CRITICAL
                return True
        self.mode = TARGET_IN_SIGHT
        return False

    def react_critical(self) -> float:
        if self.rt_counter > 0:
            self.acc = min(self.acc, 0.0)  # release the accelerator
            self.rt_counter -= self.dt
            return self.veh.speed + self.acc * self.dt
        self.acc = min(self.acc - self.min_jerk * self.dt, self.max_dec)
        return max(self.veh.speed + self.acc * self.dt, 0.0)

    def min_dist(self) -> float:
        v, rt, a, b = self.veh.speed, self.rt, self.max_acc, self.max_dec
        return (
            v * rt * rt
            + a * rt**2 / 2
            + (v + rt * a) ** 2 / (2 * b)
            - max(v - rt * a * b, 0.0) ** 2 / (2 * b)
            + 1.0 / 2 * b * rt**2
        )


class FSM(Model):
    """The JRC fuzzy safety model: proactive (PFS) and critical (CFS) fuzzy safety in [0, 1]; critical when
    either is positive; brakes between 4 and 6 m/s² with a jerk of 12.65 m/s³ after the reaction time."""

    name = "FSM"

    def __init__(self, world: ScenarioWorld, veh: Body) -> None:
        super().__init__(world, veh, 0.75, 0.774 * 9.81, 46.0)
        self.min_jerk = 12.65
        self.br_min, self.br_max, self.bl = 4.0, 6.0, 7.0
        self.margin_dist, self.margin_safe_dist = 2.0, 2.0
        self.cfs = self.pfs = 0.0

    def min_dist(self) -> float:
        lead = self.focus.obj.speed if self.focus.obj is not None else 0.0
        v = self.veh.speed
        return (
            self.margin_dist
            + v * self.rt
            + v * v / (2 * self.br_min)
            - lead * lead / (2 * self.bl)
            + self.margin_safe_dist
        )

    def pfs_of(self, dist: float, rear: float, lead: float) -> float:
        dist -= self.margin_dist
        rt = self.rt
        dsafe = rear * rt + rear**2 / (2 * self.br_min) - lead**2 / (2 * self.bl) + self.margin_safe_dist
        if dist > dsafe:
            return 0.0
        dunsafe = rear * rt + rear**2 / (2 * self.br_max) - lead**2 / (2 * self.bl)
        if dist < dunsafe:
            return 1.0
        return (dist - dsafe) / (dunsafe - dsafe)

    def cfs_of(self, dist: float, rear: float, lead: float, acc: float) -> float:
        rt = self.rt
        ar = max(acc, -self.br_min)
        u_new = rear + rt * ar
        if rear <= lead:
            return 0.0
        if u_new < lead:
            dsafe = (rear - lead) ** 2 / abs(acc * 2) if acc != 0 else LARGE
            return 1.0 if dist < dsafe else 0.0
        dsafe = (rear + ar * rt / 2 - lead) * rt + (rear + ar * rt - lead) ** 2 / (self.br_min * 2)
        if dist > dsafe:
            return 0.0
        dunsafe = (rear + ar * rt / 2 - lead) * rt + (rear + ar * rt - lead) ** 2 / (self.br_max * 2)
        if dist < dunsafe:
            return 1.0
        return (dist - dsafe) / (dunsafe - dsafe)

    def check_safety(self, info: ObjectInfo) -> bool:
        obj = info.obj
        if obj is None or info.dist_lat == LARGE:
            return True
        if info.d_lane == 0:
            info.action = DECELERATION
            return False
        if info.dist_lat > -SMALL:
            pose = road_pose(self.world, obj)
            cut_in_speed = -sign(info.d_lane) * (pose.vel_t if pose is not None else 0.0)
            if cut_in_speed > 0:
                headway_lat = abs(info.dist_lat) / cut_in_speed
                headway_long = abs(info.dist_long) / max(SMALL, self.veh.speed - obj.speed)
                if headway_lat > headway_long + 0.1:
                    return True
            else:
                return True
        info.action = CUT_IN
        return False

    def check_critical(self) -> bool:
        focus = self.focus
        if focus.obj is None:
            self.mode = NO_TARGET
            return False
        if self.dt > SMALL and focus.dv_s > 0.0 and focus.dist_long > 0:
            own = self._own
            v = self.veh.speed
            self.cfs = self.cfs_of(focus.dist_long, v, focus.obj.speed, own.acc_s if own is not None else 0.0)
            self.pfs = self.pfs_of(focus.dist_long, v, focus.obj.speed)
            if self.cfs + self.pfs < SMALL:
                self.mode = TARGET_IN_SIGHT
                return False
            if self.mode != CRITICAL:
                self.rt_counter = self.rt
            self.mode = CRITICAL
            return True
        self.mode = TARGET_IN_SIGHT
        return False

    def react_critical(self) -> float:
        if self.rt_counter > 0.0:
            self.acc = min(self.acc, 0.0)
            self.rt_counter -= self.dt
            return self.veh.speed + self.acc * self.dt
        if self.cfs > SMALL:
            acc = self.cfs * (self.br_max - self.br_min) + self.br_min
        else:
            acc = self.pfs * self.br_min
        self.acc = max(max(self.acc - self.min_jerk * self.dt, -self.max_dec), -acc)
        return max(self.veh.speed + self.acc * self.dt, 0.0)


def _number(text: str | None, default: float) -> float:
    try:
        return float(text) if text is not None and text.strip() else default
    except ValueError:
        return default


MODELS: Final = ("Regulation", "ReferenceDriver", "RSS", "FSM")


class AlksR157Controller:
    """esmini's ALKS_R157SM_Controller on one entity (see the module's doc). Longitudinal: it sets the speed
    each step after every entity moved; in override mode (the default) it moves its entity with it."""

    domains = frozenset({"longitudinal"})

    def __init__(self, world: ScenarioWorld, actor: Body, properties: dict[str, str]) -> None:
        self.world = world
        self.actor = actor
        self.override = properties.get("mode", "override") != "additive"
        self.moves_itself = self.override  # additive: the speed it sets moves the entity from the next step
        kind = properties.get("model", "")
        model: Model
        if kind == "Regulation":
            model = Regulation(world, actor)
        elif kind == "ReferenceDriver":
            model = ReferenceDriver(world, actor, properties)
        elif kind == "RSS":
            model = RSS(world, actor)
        elif kind == "FSM":
            model = FSM(world, actor)
        else:
            raise BadInput(
                f"ALKS_R157SM_Controller of {actor.name!r}: unknown model {kind!r}: use one of {', '.join(MODELS)}",
                file=actor.entity.source or None,
                field="Controller/Properties/Property[model]",
            )
        if "fullStop" in properties:
            model.full_stop = properties["fullStop"] == "true"
        always = properties.get("alwaysTrigOnScenario")
        if always is not None:
            model.always_trig = always == "true"
        cruise = _flag(properties.get("cruise"))
        if cruise is not None:
            model.cruise = cruise
        model.set_speed = actor.speed  # activation: the speed now is the set speed
        self.model = model

    def step(self, dt: float) -> None:
        self.actor.speed = self.model.step(dt)
