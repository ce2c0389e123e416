"""The scenario's side of SUMO: every entity in the world is a SUMO vehicle; scripted ones are placed where
the scenario moves them, SUMO-driven ones are read back after SUMO's step. Only used when some entity is
SUMO-driven (nothing reads SUMO back otherwise)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from simcore.world.native_calls import hypot

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.world.opendrive import OpenDrive
    from simcore.world.sumo import SumoWorld


class SumoBridge:
    def __init__(self, sumo: SumoWorld, road: OpenDrive | None) -> None:
        self.sumo = sumo
        self.road = road

    def add(self, bodies: Iterable[Body]) -> None:
        """The entities in the world become SUMO vehicles (scripted unless SUMO drives them)."""
        for body in bodies:
            if body.gone:
                continue
            e = body.entity
            self.sumo.add_vehicle(
                body.name,
                length=e.box.length,
                width=e.box.width,
                height=e.box.height,
                front_offset=e.box.center_x + e.box.length / 2,
                max_speed=e.performance.max_speed,
                max_accel=e.performance.max_acceleration,
                max_decel=e.performance.max_deceleration,
                x=body.x,
                y=body.y,
                heading=body.heading,
                speed=body.speed,
                scripted=e.driver != "sumo",
            )

    def place(self, body: Body) -> None:
        """SUMO's vehicle of `body` where the scenario put it."""
        if self.sumo.has(body.name):
            self.sumo.place(body.name, body.x, body.y, body.heading, body.speed)

    def set_speed(self, body: Body, speed: float) -> None:
        self.sumo.set_desired_speed(body.name, speed)

    def change_lane(self, body: Body, lane_id: int, duration: float) -> None:
        if self.road is None or body.road_id is None:
            return
        # SUMO lane index 0 is the rightmost driving lane in the travel direction
        side = [
            lane for lane in self.road.lane_ids(body.road_id, body.s, driving_only=True) if lane * lane_id > 0
        ]
        lanes = sorted(side, reverse=body.direction < 0)
        if lane_id in lanes:
            self.sumo.change_lane(body.name, lanes.index(lane_id), duration)

    def step(self, bodies: Iterable[Body], now: float, locate: Callable[[Body], None]) -> None:
        """SUMO steps; the SUMO-driven bodies take their new pose (one that left SUMO's network is gone, at
        the end of its road)."""
        self.sumo.step()
        for body in bodies:
            if body.entity.driver != "sumo" or body.gone or body.external:
                continue
            state = self.sumo.read(body.name)
            if state is None:
                body.gone = True
                body.speed = 0.0
                if body.end_of_road_since is None:
                    body.end_of_road_since = now
                continue
            x, y, body.heading, body.speed = state
            body.odometer += hypot(x - body.x, y - body.y)
            body.x, body.y = x, y
            locate(body)
