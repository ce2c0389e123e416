"""The topic bus: one interface for every way CARLOS' parts exchange ROS 2 messages.

- `InProcessBus`: the embedded executor's path; subscribers get the message objects, nothing is serialised
  unless a subscriber asks for CDR bytes (the recorder does).
- Other implementations (loopback sockets between the pod's roles, DDS via cyclonedds, rclpy in the
  `ros:jazzy` images) implement the same `Bus` protocol: `advertise` → `Publisher.publish`, `subscribe`.

Topic names and types are DESIGN.md's; messages are rosbags dataclasses of the jazzy type store
(`simcore.transport.messages.TYPESTORE`).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Sized
from dataclasses import dataclass, field
from typing import Any, Protocol


@dataclass(slots=True)
class Message:
    """One message on the bus. `msg` (the object) or `data` (CDR bytes) is set, or `build` (makes the object)
    with `encode` (makes its CDR bytes, the same as serialising the object, without it); `cdr()`/`obj()`
    give either, made or converted on first use."""

    topic: str
    typename: str
    time_s: float
    msg: Any = None
    data: bytes | None = None
    build: Callable[[], Any] | None = None
    encode: Callable[[], bytes] | None = None

    def cdr(self) -> bytes:
        if self.data is None:
            if self.encode is not None:
                self.data = self.encode()
            else:
                from simcore.transport.messages import serialize

                self.data = serialize(self.obj())
        return self.data

    def obj(self) -> Any:
        if self.msg is None:
            if self.build is not None:
                self.msg = self.build()
            else:
                from simcore.transport.messages import deserialize

                assert self.data is not None
                self.msg = deserialize(self.data, self.typename)
        return self.msg


Callback = Callable[[Message], None]


class Publisher(Protocol):
    topic: str
    typename: str

    def publish(self, msg: Any, time_s: float) -> None: ...

    def publish_lazily(
        self, build: Callable[[], Any], encode: Callable[[], bytes] | None, time_s: float
    ) -> None:
        """Publish the message `build()` makes, made only if a consumer wants the object; `encode()` (when
        given) makes its CDR bytes directly, for consumers that want only those (a recorder, a transport)."""
        ...


class Bus(Protocol):
    def advertise(self, topic: str, typename: str) -> Publisher: ...

    def subscribe(self, pattern: str, callback: Callback) -> None:
        """Receive every message whose topic matches `pattern` (shell-style glob)."""
        ...

    def close(self) -> None: ...


@dataclass
class _InProcessPublisher:
    bus: InProcessBus
    topic: str
    typename: str

    def publish(self, msg: Any, time_s: float) -> None:
        self.bus.dispatch(Message(self.topic, self.typename, time_s, msg=msg))

    def publish_lazily(
        self, build: Callable[[], Any], encode: Callable[[], bytes] | None, time_s: float
    ) -> None:
        self.bus.dispatch(Message(self.topic, self.typename, time_s, build=build, encode=encode))


@dataclass
class InProcessBus:
    """Synchronous in-process delivery, in subscription order. A subscription may narrow its pattern with
    `wants(topic)` (e.g. a recorder's topic filter); `wants`/`subscriptions` tell a publisher whether a
    message would reach anyone, so that nothing is built for no one."""

    _subscriptions: list[tuple[str, Callback, Callable[[str], bool] | None]] = field(default_factory=list)
    _routes: dict[str, list[Callback]] = field(default_factory=dict)
    topics: dict[str, str] = field(default_factory=dict)  # advertised topic → type

    def advertise(self, topic: str, typename: str) -> Publisher:
        known = self.topics.setdefault(topic, typename)
        if known != typename:
            raise ValueError(f"topic {topic} is advertised as {known}, not {typename}")
        return _InProcessPublisher(self, topic, typename)

    def subscribe(
        self, pattern: str, callback: Callback, *, wants: Callable[[str], bool] | None = None
    ) -> None:
        self._subscriptions.append((pattern, callback, wants))
        self._routes.clear()

    def subscriber_count(self, topic: str) -> int:
        """Subscriptions to `topic` by its name (glob patterns such as a recorder's `*` do not count)."""
        return sum(1 for pattern, _, _ in self._subscriptions if pattern == topic)

    def subscriptions(self) -> Sized:
        """The subscriptions, live (it grows with each `subscribe`): empty while nobody subscribed."""
        return self._subscriptions

    def wants(self, topic: str) -> bool:
        """Whether a message on `topic` reaches any subscriber."""
        return bool(self._route(topic))

    def _route(self, topic: str) -> list[Callback]:
        route = self._routes.get(topic)
        if route is None:
            route = [
                cb
                for pattern, cb, wants in self._subscriptions
                if fnmatch.fnmatchcase(topic, pattern) and (wants is None or wants(topic))
            ]
            self._routes[topic] = route
        return route

    def dispatch(self, message: Message) -> None:
        for callback in self._route(message.topic):
            callback(message)

    def close(self) -> None:
        self._subscriptions.clear()
        self._routes.clear()
