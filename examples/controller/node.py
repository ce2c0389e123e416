"""A lane-holding cruise controller, written as a ROS 2-style node (topics in and out, nothing else).

In: `/carlos/<entity>/odometry` (nav_msgs/Odometry). Out: `/carlos/<entity>/control`
(ackermann_msgs/AckermannDriveStamped), one command per odometry message, stamped with the odometry's
stamp (what the simulator's lockstep mode waits for).

It holds the line the entity starts on (its first pose and heading) with a proportional steering law on
the lateral and heading errors, and drives at `speed` m/s, reached at `acceleration` m/s². It stops
answering after `stop_after` commands when that is set (to show what lockstep does when a node dies).

Constructed as `CruiseController(bus, entity="Ego", speed=20.0, …)`: the same class runs in-process
(`spec.systemUnderTest.module: examples.controller:CruiseController`) and as its own program
(`python -m examples.controller`, over the loopback topic hub of `carlos run --transport loopback`).
"""

from __future__ import annotations

import math
import threading
from typing import Any


class CruiseController:
    def __init__(
        self,
        bus: Any,
        entity: str = "Ego",
        speed: float = 20.0,
        acceleration: float = 2.0,
        steering_gain: float = 0.08,
        heading_gain: float = 1.0,
        stop_after: int | None = None,
    ) -> None:
        from simcore.transport.messages import TYPESTORE  # the message definitions (like a msgs package)

        self._types = TYPESTORE.types
        self.entity = entity
        self.speed = speed
        self.acceleration = acceleration
        self.steering_gain = steering_gain
        self.heading_gain = heading_gain
        self.stop_after = stop_after
        self.sent = 0
        self.line: tuple[float, float, float] | None = None  # x, y, heading of the line to hold
        self.ended = threading.Event()
        self.publisher = bus.advertise(
            f"/carlos/{entity}/control", "ackermann_msgs/msg/AckermannDriveStamped"
        )
        bus.subscribe("/carlos/status", self._on_status)
        bus.subscribe(f"/carlos/{entity}/odometry", self._on_odometry)

    def _on_status(self, message: Any) -> None:
        if message.obj().message in ("ended", "error"):
            self.ended.set()

    def _on_odometry(self, message: Any) -> None:
        if self.stop_after is not None and self.sent >= self.stop_after:
            return
        odom = message.obj()
        p, q = odom.pose.pose.position, odom.pose.pose.orientation
        heading = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        if self.line is None:
            self.line = (p.x, p.y, heading)
        x0, y0, h0 = self.line
        # signed distance to the left of the line, and the heading error
        lateral = -(p.x - x0) * math.sin(h0) + (p.y - y0) * math.cos(h0)
        heading_error = (heading - h0 + math.pi) % (2 * math.pi) - math.pi
        steering = -self.steering_gain * lateral - self.heading_gain * heading_error
        t = self._types
        command = t["ackermann_msgs/msg/AckermannDriveStamped"](
            header=t["std_msgs/msg/Header"](stamp=odom.header.stamp, frame_id=odom.child_frame_id),
            drive=t["ackermann_msgs/msg/AckermannDrive"](
                steering_angle=max(-0.5, min(0.5, steering)),
                steering_angle_velocity=0.0,
                speed=self.speed,
                acceleration=self.acceleration,
                jerk=0.0,
            ),
        )
        self.publisher.publish(command, message.time_s)
        self.sent += 1
