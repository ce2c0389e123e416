"""Live view: a Foxglove WebSocket server (foxglove-sdk) on 127.0.0.1 serving the run's topics as they are
published, paced to real time (or a multiple of it), for Foxglove Studio or any foxglove.sdk.v1 client, and
for foxglove.websocket.v1 clients (older Foxglove Studio, Lichtblick) through `simcore.live_front`.

It is a bus subscriber: every message is forwarded with its ROS 2 schema (`ros2msg`) and CDR encoding, so
Foxglove decodes point clouds and TF natively. Neither Foxglove nor a stock RViz draws
vision_msgs/Detection3DArray, so every Detection3DArray topic (ground truth, a detector's output) is also
served as `<topic>/markers` (visualization_msgs/MarkerArray, one CUBE per box), for the live view only: the
recording keeps the lean Detection3DArray. Pacing happens on `/clock`: the publishing thread waits until
wall time has caught up with simulated time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from simcore.transport.bus import Message

DETECTIONS = "vision_msgs/msg/Detection3DArray"
MARKERS = "visualization_msgs/msg/MarkerArray"
#: colour of the boxes of a markers topic: ground truth green, anything else (a system under test) orange
_TRUTH_COLOUR = (0.2, 0.8, 0.3, 0.6)
_OTHER_COLOUR = (1.0, 0.55, 0.0, 0.6)


def markers(detections: Any, topic: str) -> Any:
    """visualization_msgs/MarkerArray with one CUBE per Detection3D (pose and size of its box), replacing
    the previous frame's boxes (DELETEALL first)."""
    import numpy as np

    from simcore.transport.messages import TYPESTORE

    types = TYPESTORE.types
    no_bytes = np.zeros(0, dtype=np.uint8)
    marker_t: Any
    marker_t, array_t = types["visualization_msgs/msg/Marker"], types[MARKERS]
    colour_t, duration_t = types["std_msgs/msg/ColorRGBA"], types["builtin_interfaces/msg/Duration"]
    vector_t = types["geometry_msgs/msg/Vector3"]
    r, g, b, a = _TRUTH_COLOUR if topic == "/carlos/objects" else _OTHER_COLOUR
    header = detections.header

    def marker(index: int, action: int, pose: Any = None, size: Any = None, text: str = "") -> Any:
        template = detections.detections[0].bbox if detections.detections else None
        return marker_t(
            header=header,
            ns=topic,
            id=index,
            type=marker_t.CUBE,
            action=action,
            pose=pose
            if pose is not None
            else (template.center if template is not None else _identity_pose()),
            scale=size if size is not None else vector_t(x=1.0, y=1.0, z=1.0),
            color=colour_t(r=r, g=g, b=b, a=a),
            lifetime=duration_t(sec=0, nanosec=0),
            frame_locked=False,
            points=[],
            colors=[],
            texture_resource="",
            texture=types["sensor_msgs/msg/CompressedImage"](header=header, format="", data=no_bytes),
            uv_coordinates=[],
            text=text,
            mesh_resource="",
            mesh_file=types["visualization_msgs/msg/MeshFile"](filename="", data=no_bytes),
            mesh_use_embedded_materials=False,
        )

    items = [marker(0, marker_t.DELETEALL)]
    for index, detection in enumerate(detections.detections, start=1):
        items.append(marker(index, marker_t.ADD, detection.bbox.center, detection.bbox.size, detection.id))
    return array_t(markers=items)


def _identity_pose() -> Any:
    from simcore.transport.messages import TYPESTORE

    types = TYPESTORE.types
    return types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
        orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )


@dataclass
class LiveServer:
    """`speed` = simulated seconds per wall second (1.0 = real time; 0 = as fast as possible)."""

    host: str = "127.0.0.1"
    port: int = 8765
    speed: float = 1.0
    _server: Any = None
    _front: Any = None
    _context: Any = None
    _channels: dict[str, Any] = field(default_factory=dict)
    _start_wall: float | None = None

    def start(self) -> LiveServer:
        import foxglove

        from simcore.live_front import SubprotocolFront

        self._context = foxglove.Context()
        self._server = foxglove.start_server(
            name="carlos",
            host="127.0.0.1",
            port=0,
            context=self._context,
            capabilities=[foxglove.Capability.Time],
        )
        try:
            self._front = SubprotocolFront(self.host, self.port, self._server.port).start()
        except BaseException:
            self._server.stop()
            raise
        self.port = self._front.port
        return self

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def _channel(self, topic: str, typename: str) -> Any:
        channel = self._channels.get(topic)
        if channel is None:
            import foxglove

            from simcore.transport.messages import msgdef

            schema = foxglove.Schema(name=typename, encoding="ros2msg", data=msgdef(typename).encode())
            channel = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._context)
            self._channels[topic] = channel
        return channel

    def __call__(self, message: Message) -> None:
        log_time = round(message.time_s * 1e9)
        if message.topic == "/clock":
            self._pace(message.time_s)
            self._server.broadcast_time(log_time)
        self._channel(message.topic, message.typename).log(message.cdr(), log_time=log_time)
        if message.typename == DETECTIONS:
            from simcore.transport.messages import serialize

            boxes = markers(message.obj(), message.topic)
            self._channel(f"{message.topic}/markers", MARKERS).log(serialize(boxes), log_time=log_time)

    def _pace(self, sim_time: float) -> None:
        now = time.monotonic()
        if self._start_wall is None:
            self._start_wall = now - (sim_time / self.speed if self.speed > 0 else 0.0)
            return
        if self.speed <= 0:
            return
        wait = self._start_wall + sim_time / self.speed - now
        if wait > 0:
            time.sleep(wait)

    def stop(self) -> None:
        if self._front is not None:
            self._front.stop()
            self._front = None
        if self._server is not None:
            self._server.stop()
            self._server = None
