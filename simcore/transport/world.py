"""Publishing the world state on the bus: DESIGN.md's topics, one publisher per topic."""

from __future__ import annotations

from simcore.transport import messages
from simcore.transport.bus import Bus, Publisher
from simcore.world.state import WorldFrame

STATUS_TOPIC = "/carlos/status"
STATUS_TYPE = "diagnostic_msgs/msg/DiagnosticStatus"


class WorldPublisher:
    """Publishes `/clock`, `/tf`, `/carlos/<entity>/odometry` and `/carlos/objects` for every frame, and the
    end-of-run status on `/carlos/status`."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self._publishers: dict[str, Publisher] = {}

    def _publisher(self, topic: str, typename: str) -> Publisher:
        publisher = self._publishers.get(topic)
        if publisher is None:
            publisher = self._publishers[topic] = self.bus.advertise(topic, typename)
        return publisher

    def publish(self, frame: WorldFrame) -> None:
        for topic, typename, msg in messages.frame_messages(frame):
            self._publisher(topic, typename).publish(msg, frame.time)

    def publish_status(self, frame: WorldFrame, state: str) -> None:
        self._publisher(STATUS_TOPIC, STATUS_TYPE).publish(messages.status(frame, state), frame.time)
