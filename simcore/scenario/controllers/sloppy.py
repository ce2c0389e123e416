"""esmini's SloppyDriverController (ControllerSloppyDriver.cpp): a driver who varies its speed around the one
the scenario sets and wanders across its lane, `sloppiness` (default 0.5, recommended 0…1) saying how much.
Its semantics as esmini implements them:

- longitudinal: every 3 s × U(0.5, 1.5) a new target factor 1 + sloppiness × U(-0.35, 0.35) is drawn; the
  speed blends linearly over that period from the previous target (reference × the previous factor) to
  reference × the new factor, never below 0. The reference speed is the entity's speed at activation, and
  any speed someone else sets later (a speed action);
- lateral: every 1.5 s × U(0.5, 1.5) a new lateral target 5 × sloppiness × min(sloppiness, 1) × U(0.5, 1.5)
  m is drawn, blended linearly from the previous; the heading turns by (−0.02 × (t + fuzz) − 0.05 ×
  heading error) × v × dt (t counted from where it was at activation, the heading error its heading relative
  to the road in override mode, else the heading it built up), and it moves across the road by
  v × dt × sin(heading); only while moving forward;
- `mode`: override (the default) or additive: either way the entity moves at the speed it drives.

The random numbers are drawn from the run's seed (the same seed gives the same run); they are not esmini's
random sequence, so a sloppy entity agrees with esmini's in its character, not sample by sample."""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING, Final

from simcore.scenario.motion import update_pose_from_road, wrap_angle

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld

SMALL: Final = 1e-10


class _Timer:
    """esmini's SE_SimulationTimer: started at a time for a duration."""

    def __init__(self, start: float, duration: float) -> None:
        self.start, self.duration = start, duration

    def elapsed(self, now: float) -> float:
        return now - self.start

    def expired(self, now: float) -> bool:
        return self.elapsed(now) >= self.duration


class SloppyDriver:
    """esmini's SloppyDriverController on one entity (see the module's doc)."""

    def __init__(
        self,
        world: ScenarioWorld,
        actor: Body,
        properties: dict[str, str],
        domains: frozenset[str],
        rng: random.Random,
    ) -> None:
        self.world = world
        self.actor = actor
        self.domains = domains
        self.rng = rng
        try:
            self.sloppiness = float(properties.get("sloppiness", "0.5"))
        except ValueError:
            self.sloppiness = 0.5
        self.override = properties.get("mode", "override") != "additive"
        # it moves along the road at the speed it drives (in additive mode too: esmini adds the difference
        # to the default motion's step)
        self.moves_itself = "longitudinal" in domains
        self.time = 0.0
        self.speed_timer = _Timer(0.0, 3.0)
        self.target_factor = 1.0
        self.current_speed = self.init_speed = self.reference_speed = actor.speed
        self.lateral_timer = _Timer(0.0, 1.5)
        self.fuzz_target = self.fuzz0 = 0.0
        self.current_t = 0.0
        self.current_h = self._h_relative()

    def _h_relative(self) -> float:
        """The heading relative to the road's driving direction, in [0, 2π) as esmini's GetHRelative."""
        a, road = self.actor, self.world.road
        if road is None or a.road_id is None:
            return 0.0
        h_road = road.road(a.road_id).reference_xyh(min(max(a.s, 0.0), road.road_length(a.road_id)))[2]
        return (a.heading - h_road) % (2 * math.pi)

    def step(self, dt: float) -> None:
        a, rng, s = self.actor, self.rng, self.sloppiness
        self.time += dt
        if abs(a.speed - self.current_speed) > 1e-3:
            self.reference_speed = a.speed  # set by someone else: the new reference
        self.current_speed = a.speed
        if "longitudinal" in self.domains:
            if self.speed_timer.expired(self.time):
                self.speed_timer = _Timer(self.time, 3.0 * rng.uniform(0.5, 1.5))
                self.init_speed = self.reference_speed * self.target_factor
                self.target_factor = 1.0 + s * rng.uniform(-0.35, 0.35)
            weight = self.speed_timer.elapsed(self.time) / self.speed_timer.duration
            blended = self.init_speed * (1 - weight) + self.target_factor * self.reference_speed * weight
            self.current_speed = max(blended, 0.0)
        if "lateral" in self.domains:
            self._wander(dt)
        a.speed = self.current_speed

    def _wander(self, dt: float) -> None:
        a, road, s = self.actor, self.world.road, self.sloppiness
        if self.lateral_timer.expired(self.time):
            self.fuzz0 = self.fuzz_target
            self.fuzz_target = 5.0 * s * min(s, 1.0) * self.rng.uniform(0.5, 1.5)
            self.lateral_timer = _Timer(self.time, 1.5 * self.rng.uniform(0.5, 1.5))
        h_error = self._h_relative() if self.override else self.current_h
        if h_error > math.pi:
            h_error -= 2 * math.pi
        fuzz = self.fuzz0 + (self.fuzz_target - self.fuzz0) * (
            self.lateral_timer.elapsed(self.time) / self.lateral_timer.duration
        )
        lat_error = self.current_t + fuzz
        speed = a.speed  # the speed it moved with this step
        dh = (-0.02 * lat_error - 0.05 * h_error) * dt * speed
        dt_lateral = speed * dt * math.sin(self.current_h + dh)
        if speed > SMALL and road is not None and a.road_id is not None:
            a.offset += dt_lateral
            a.heading_offset = wrap_angle(a.heading_offset + dh)
            update_pose_from_road(road, a)
            self.current_t += dt_lateral
            self.current_h += dh
