"""Live view: a Foxglove WebSocket server (foxglove-sdk) on 127.0.0.1 serving the run's topics as they are
published, paced to real time (or a multiple of it), for Foxglove Studio or any foxglove.sdk.v1 client.

It is a bus subscriber: every message is forwarded with its ROS 2 schema (`ros2msg`) and CDR encoding, so
Foxglove decodes point clouds, TF and ground-truth boxes natively. Pacing happens on `/clock`: the
publishing thread waits until wall time has caught up with simulated time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from simcore.transport.bus import Message


@dataclass
class LiveServer:
    """`speed` = simulated seconds per wall second (1.0 = real time; 0 = as fast as possible)."""

    host: str = "127.0.0.1"
    port: int = 8765
    speed: float = 1.0
    _server: Any = None
    _context: Any = None
    _channels: dict[str, Any] = field(default_factory=dict)
    _start_wall: float | None = None

    def start(self) -> LiveServer:
        import foxglove

        self._context = foxglove.Context()
        self._server = foxglove.start_server(
            name="carlos",
            host=self.host,
            port=self.port,
            context=self._context,
            capabilities=[foxglove.Capability.Time],
        )
        self.port = self._server.port
        return self

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def __call__(self, message: Message) -> None:
        channel = self._channels.get(message.topic)
        if channel is None:
            import foxglove

            from simcore.transport.messages import msgdef

            schema = foxglove.Schema(
                name=message.typename, encoding="ros2msg", data=msgdef(message.typename).encode()
            )
            channel = foxglove.Channel(
                message.topic, schema=schema, message_encoding="cdr", context=self._context
            )
            self._channels[message.topic] = channel
        log_time = round(message.time_s * 1e9)
        if message.topic == "/clock":
            self._pace(message.time_s)
            self._server.broadcast_time(log_time)
        channel.log(message.cdr(), log_time=log_time)

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
        if self._server is not None:
            self._server.stop()
            self._server = None
