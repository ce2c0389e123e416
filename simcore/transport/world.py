"""Publishing the world state on the bus: DESIGN.md's topics, one publisher per topic.

A message is built only for a topic someone consumes: on an in-process bus, a subscription that wants the
topic (`InProcessBus.wants`); on a transport to other processes (loopback, DDS) every topic, since its
consumers are elsewhere. With no consumer at all, `simcore.transport.messages` (rosbags' type store, a
noticeable import) is never imported.
"""

from __future__ import annotations

from collections.abc import Sized

from simcore.transport.bus import Bus, InProcessBus, Publisher
from simcore.world.state import WorldFrame

#: the consumers of a transport to other processes: never none
_ELSEWHERE: Sized = (True,)

STATUS_TOPIC = "/carlos/status"
STATUS_TYPE = "diagnostic_msgs/msg/DiagnosticStatus"


class WorldPublisher:
    """Publishes `/clock`, `/tf`, `/carlos/<entity>/odometry` and `/carlos/objects` for every frame, and the
    end-of-run status on `/carlos/status`, each topic only while it has a consumer."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self._publishers: dict[str, Publisher] = {}
        #: true while a world topic may have a consumer (read every step, so a plain attribute): an in-process
        #: bus's subscriptions as they grow, else always (the consumers of a transport are elsewhere)
        self.consumers: Sized = bus.subscriptions() if isinstance(bus, InProcessBus) else _ELSEWHERE

    def _publisher(self, topic: str, typename: str) -> Publisher:
        publisher = self._publishers.get(topic)
        if publisher is None:
            publisher = self._publishers[topic] = self.bus.advertise(topic, typename)
        return publisher

    def wants(self, topic: str) -> bool:
        bus = self.bus
        return bus.wants(topic) if isinstance(bus, InProcessBus) else True

    def has_consumers(self) -> bool:
        """Whether any world topic may have a consumer (else publishing a frame does nothing)."""
        return bool(self.consumers)

    def publish(self, frame: WorldFrame) -> None:
        if not self.consumers:
            return
        from simcore.transport import messages

        wants = self.wants
        for topic, typename, build, encode in messages.frame_builders(frame):
            if wants(topic):
                self._publisher(topic, typename).publish_lazily(build, encode, frame.time)

    def publish_status(self, frame: WorldFrame, state: str) -> None:
        if self.wants(STATUS_TOPIC):
            from simcore.transport.messages import status

            message = status(frame, state)
            self._publisher(STATUS_TOPIC, STATUS_TYPE).publish(message, frame.time)
