"""Closed loop: the system under test drives entities through their control topic.

Which entities: those whose external controller is active (the scenario's ExternalController or
InteractiveController, or a controller with the property `carlos.driver = external`, activated by an
ActivateControllerAction), plus the entities `spec.control.entities` names (external from the start, with
the pose and speed the scenario's Init gives them). The scenario's motion actions on such an entity are
ignored while its controller is active: the control input alone moves it.

Commands arrive on `/carlos/<entity>/control` as
- `ackermann_msgs/msg/AckermannDriveStamped`: `drive.speed` (m/s, negative: reverse) reached with
  `drive.acceleration` (m/s², 0: the vehicle's maximum acceleration / deceleration), `drive.steering_angle`
  (rad, left positive) reached with `drive.steering_angle_velocity` (rad/s, 0: at once); `header.stamp`
  is the simulated time of the odometry it answers (0: "the latest");
- `geometry_msgs/msg/Twist`: `linear.x` (m/s, reached at once) and `angular.z` (yaw rate, rad/s).

Motion: a kinematic bicycle about the rear axle (OpenSCENARIO's reference point of a vehicle):
ẋ = v cos ψ, ẏ = v sin ψ, ψ̇ = v tan δ / L, with the wheelbase L and steering limit from the vehicle's
Axles (defaults 0.6 × length and 0.6 rad), speeds within its Performance. Each step integrates exactly for
the step's mean speed and steering (an arc).

Modes (`spec.control.mode`):
- `lockstep` (default): before every step the simulator waits until each externally driven entity got a
  command answering the frame just published (stamp ≥ its time, or for a Twist / unstamped command, one
  received after it). Results then do not depend on machine speed. No answer within `timeoutSeconds`
  fails the run (exit code 3) with a message naming the entity, the topic and the simulated time. Before
  the first frame the simulator waits (up to `startupTimeoutSeconds`) until a node subscribed to each
  entity's odometry topic by its name, where the transport can tell (in-process, loopback hub, DDS: a
  ROS 2 node's reader of the topic, or a CARLOS bus that subscribed to the exact name).
- `freeRunning`: the latest command holds until the next one; nothing waits (real-time use, `--live`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Literal

from simcore.errors import SimulationError
from simcore.scenario import model as m
from simcore.transport.bus import Bus, Message
from simcore.transport.messages import odometry_topic, ros_name

log = logging.getLogger("carlos.closedloop")

ACKERMANN = "ackermann_msgs/msg/AckermannDriveStamped"
TWIST = "geometry_msgs/msg/Twist"
_EPS = 1e-6


def control_topic(entity: str) -> str:
    return f"/carlos/{ros_name(entity)}/control"


# --- the model (pure) -------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Command:
    """One control input. `steering_angle` None: a Twist, which commands the yaw rate instead."""

    speed: float
    acceleration: float = 0.0  # m/s², magnitude; 0: the vehicle's limit
    steering_angle: float | None = 0.0
    steering_rate: float = 0.0  # rad/s, magnitude; 0: at once
    yaw_rate: float = 0.0  # Twist only
    stamp: float | None = None  # simulated time it answers; None: unstamped
    sequence: int = 0  # frames published before it arrived


@dataclass(frozen=True, slots=True)
class Vehicle:
    wheelbase: float
    max_steering: float
    max_speed: float
    max_acceleration: float
    max_deceleration: float

    @classmethod
    def of(cls, entity: m.Entity) -> Vehicle:
        perf = entity.performance
        return cls(
            wheelbase=entity.wheelbase or max(0.6 * entity.box.length, 0.5),
            max_steering=entity.max_steering or 0.6,
            max_speed=perf.max_speed,
            max_acceleration=perf.max_acceleration,
            max_deceleration=perf.max_deceleration,
        )


@dataclass(frozen=True, slots=True)
class BicycleState:
    x: float
    y: float
    heading: float
    speed: float
    steering: float = 0.0


def _approach(value: float, target: float, rate: float, dt: float) -> float:
    if rate <= 0:
        return target
    step = rate * dt
    return target if abs(target - value) <= step else value + math.copysign(step, target - value)


def bicycle_step(state: BicycleState, command: Command, vehicle: Vehicle, dt: float) -> BicycleState:
    """The state `dt` seconds later under `command` (kinematic bicycle about the rear axle)."""
    target = max(-vehicle.max_speed, min(vehicle.max_speed, command.speed))
    speeding_up = abs(target) > abs(state.speed) and target * state.speed >= 0
    limit = vehicle.max_acceleration if speeding_up else vehicle.max_deceleration
    rate = min(command.acceleration, limit) if command.acceleration > 0 else limit
    speed = _approach(state.speed, target, rate, dt)
    mean_speed = (state.speed + speed) / 2
    if command.steering_angle is None:  # a Twist: the yaw rate is commanded
        steering = state.steering
        yaw_rate = command.yaw_rate
    else:
        goal = max(-vehicle.max_steering, min(vehicle.max_steering, command.steering_angle))
        steering = _approach(state.steering, goal, command.steering_rate, dt)
        yaw_rate = mean_speed * math.tan((state.steering + steering) / 2) / vehicle.wheelbase
    turn = yaw_rate * dt
    distance = mean_speed * dt
    if abs(turn) < 1e-9:
        dx, dy = distance * math.cos(state.heading), distance * math.sin(state.heading)
    else:  # along the arc: chord of length 2 r sin(turn / 2) in the mean direction
        chord = distance * math.sin(turn / 2) / (turn / 2)
        direction = state.heading + turn / 2
        dx, dy = chord * math.cos(direction), chord * math.sin(direction)
    heading = (state.heading + turn + math.pi) % (2 * math.pi) - math.pi
    return BicycleState(state.x + dx, state.y + dy, heading, speed, steering)


def command_from(message: Message, sequence: int) -> Command:
    """A Command from an AckermannDriveStamped or Twist message (ValueError for anything else)."""
    msg = message.obj()
    if message.typename == ACKERMANN:
        drive = msg.drive
        values = (drive.speed, drive.acceleration, drive.steering_angle, drive.steering_angle_velocity)
        if not all(math.isfinite(float(v)) for v in values):
            raise ValueError("a field is not finite")
        stamp_ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        return Command(
            speed=float(drive.speed),
            acceleration=abs(float(drive.acceleration)),
            steering_angle=float(drive.steering_angle),
            steering_rate=abs(float(drive.steering_angle_velocity)),
            stamp=stamp_ns / 1e9 if stamp_ns > 0 else None,
            sequence=sequence,
        )
    if message.typename == TWIST:
        speed, yaw_rate = float(msg.linear.x), float(msg.angular.z)
        if not (math.isfinite(speed) and math.isfinite(yaw_rate)):
            raise ValueError("a field is not finite")
        return Command(speed=speed, steering_angle=None, yaw_rate=yaw_rate, sequence=sequence)
    raise ValueError(f"type {message.typename}: send {ACKERMANN} or {TWIST}")


# --- the adapter: bus in, engine out --------------------------------------------------------------------


class ClosedLoop:
    """Collects the commands from the bus (any thread) and moves the externally driven entities
    (`simcore.scenario.engine.ExternalDriver`); in lockstep, `wait(…)` blocks until they answered."""

    def __init__(
        self,
        bus: Bus,
        *,
        mode: Literal["lockstep", "freeRunning"] = "lockstep",
        timeout_s: float = 10.0,
        startup_timeout_s: float = 60.0,
    ) -> None:
        self.bus = bus
        self.mode = mode
        self.timeout_s = timeout_s
        self.startup_timeout_s = startup_timeout_s
        self._lock = threading.Condition()
        self._commands: dict[str, Command] = {}  # ROS name → latest command
        self._sequence = 0  # frames published so far
        self._states: dict[str, BicycleState] = {}
        self._vehicles: dict[str, Vehicle] = {}
        self.rejected: dict[str, str] = {}  # ROS name → why its last bad command was dropped
        self.commands_received = 0
        bus.subscribe("/carlos/*/control", self._on_message)

    # bus side (any thread)
    def _on_message(self, message: Message) -> None:
        name = message.topic.split("/")[2]
        with self._lock:
            sequence = self._sequence
        try:
            command = command_from(message, sequence)
        except Exception as exc:  # a malformed command from the system under test: dropped, reported
            with self._lock:
                if name not in self.rejected:
                    log.warning("%s: command dropped: %s", message.topic, exc)
                self.rejected[name] = str(exc)
            return
        with self._lock:
            self._commands[name] = command
            self.commands_received += 1
            self._lock.notify_all()

    # simulator side
    def published(self, frame_time: float) -> None:
        """The frame at `frame_time` has been published: commands from now on answer it."""
        with self._lock:
            self._sequence += 1
            self.frame_time = frame_time

    def _answered(self, name: str, frame_time: float) -> bool:
        command = self._commands.get(name)
        if command is None:
            return False
        if command.stamp is not None:
            return command.stamp >= frame_time - _EPS
        return command.sequence >= self._sequence

    def wait_for_nodes(self, entities: Iterable[str]) -> None:
        """Lockstep start: wait until a node subscribed to each entity's odometry by its name (where the
        transport can tell), so it sees the first frame."""
        count = getattr(self.bus, "subscriber_count", None)
        if self.mode != "lockstep" or count is None:
            return
        deadline = time.monotonic() + self.startup_timeout_s
        for entity in entities:
            topic = odometry_topic(entity)
            while count(topic) < 1:
                if time.monotonic() > deadline:
                    raise SimulationError(
                        f"closed loop (lockstep): no node subscribed to {topic} within "
                        f"{self.startup_timeout_s:g} s (spec.control.startupTimeoutSeconds): start the system "
                        "under test, or check that it subscribes to that topic by name"
                    )
                time.sleep(0.01)

    def wait(self, entities: Iterable[str], frame_time: float) -> None:
        """Lockstep: block until every one of `entities` got a command answering the frame at
        `frame_time` (raises SimulationError after the timeout)."""
        if self.mode != "lockstep":
            return
        names = [ros_name(e) for e in entities]
        deadline = time.monotonic() + self.timeout_s
        with self._lock:
            for name in names:
                while not self._answered(name, frame_time):
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        why = (
                            f" (its last command was dropped: {self.rejected[name]})"
                            if name in self.rejected
                            else ""
                        )
                        raise SimulationError(
                            f"closed loop (lockstep): no command on /carlos/{name}/control answering "
                            f"t={frame_time:.2f} s within {self.timeout_s:g} s (spec.control.timeoutSeconds){why}: "
                            "the system under test stopped, crashed or is too slow"
                        )
                    self._lock.wait(remaining)

    def has_input(self, entity: str) -> bool:
        """`ExternalDriver`: whether a command for `entity` arrived (until then the engine holds it, as
        esmini holds an ExternalController's entity that gets no input)."""
        with self._lock:
            return ros_name(entity) in self._commands

    def move(
        self, entity: m.Entity, x: float, y: float, heading: float, speed: float, dt: float
    ) -> tuple[float, float, float, float]:
        """`ExternalDriver`: one step of the entity under its latest command (the engine moves it here
        only once a command arrived: `has_input`)."""
        name = ros_name(entity.name)
        vehicle = self._vehicles.get(name)
        if vehicle is None:
            vehicle = self._vehicles[name] = Vehicle.of(entity)
        state = self._states.get(name)
        if state is None or abs(state.x - x) > _EPS or abs(state.y - y) > _EPS:
            # first step, or the scenario teleported it: continue from where it is
            state = BicycleState(x, y, heading, speed, state.steering if state is not None else 0.0)
        with self._lock:
            command = self._commands.get(name, Command(speed=0.0))
        state = bicycle_step(replace(state, heading=heading, speed=speed), command, vehicle, dt)
        self._states[name] = state
        return state.x, state.y, state.heading, state.speed
