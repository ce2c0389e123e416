"""A TCP front for the live view that also admits `foxglove.websocket.v1` clients.

foxglove-sdk's server accepts only the WebSocket subprotocol `foxglove.sdk.v1`; Foxglove Studio before
2.x, Lichtblick and foxglove/ws-protocol clients ask for `foxglove.websocket.v1`, the same protocol under
its earlier name. The front listens on the public port, rewrites that name in the client's upgrade request
to the SDK's, and back in the server's answer (`Sec-WebSocket-Accept` depends only on the key), then
copies bytes both ways. Bounded: request and response heads of at most 64 KiB.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import threading
from typing import Any

OLD = b"foxglove.websocket.v1"
NEW = b"foxglove.sdk.v1"
MAX_HEAD = 64 * 1024
_PROTOCOL = re.compile(rb"^(sec-websocket-protocol:[ \t]*)(.*?)\r$", re.IGNORECASE | re.MULTILINE)


def rewrite_request(head: bytes) -> tuple[bytes, bool]:
    """(the request head for the SDK server, whether the client asked for the old name only) (pure)."""
    match = _PROTOCOL.search(head)
    if match is None:
        return head, False
    offered = [p.strip() for p in match.group(2).split(b",")]
    if NEW in offered or OLD not in offered:
        return head, False
    return head[: match.start(2)] + NEW + head[match.end(2) :], True


def rewrite_response(head: bytes) -> bytes:
    """The SDK server's answer with the subprotocol named as the client asked (pure)."""
    match = _PROTOCOL.search(head)
    if match is None or match.group(2).strip() != NEW:
        return head
    return head[: match.start(2)] + OLD + head[match.end(2) :]


async def _pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    with contextlib.suppress(ConnectionError, asyncio.IncompleteReadError, OSError):
        while chunk := await reader.read(65536):
            writer.write(chunk)
            await writer.drain()
    with contextlib.suppress(ConnectionError, OSError):
        writer.close()


class SubprotocolFront:
    """Listen on `host:port` (0: any free port, see `.port`) and forward to the server on `upstream_port`."""

    def __init__(self, host: str, port: int, upstream_port: int) -> None:
        self.host = host
        self.port = port
        self.upstream_port = upstream_port
        self._loop = asyncio.new_event_loop()
        self._server: asyncio.base_events.Server | None = None
        self._thread = threading.Thread(target=self._loop.run_forever, name="live-front", daemon=True)

    def start(self) -> SubprotocolFront:
        future = asyncio.run_coroutine_threadsafe(self._listen(), self._loop)
        self._thread.start()
        future.result(timeout=10)
        return self

    async def _listen(self) -> None:
        self._server = await asyncio.start_server(self._serve, self.host, self.port, limit=MAX_HEAD)
        self.port = self._server.sockets[0].getsockname()[1]

    async def _serve(self, client_reader: asyncio.StreamReader, client_writer: asyncio.StreamWriter) -> None:
        upstream_writer: Any = None
        try:
            request, translated = rewrite_request(await client_reader.readuntil(b"\r\n\r\n"))
            upstream_reader, upstream_writer = await asyncio.open_connection(
                "127.0.0.1", self.upstream_port, limit=MAX_HEAD
            )
            upstream_writer.write(request)
            await upstream_writer.drain()
            response = await upstream_reader.readuntil(b"\r\n\r\n")
            client_writer.write(rewrite_response(response) if translated else response)
            await client_writer.drain()
            await asyncio.gather(_pump(client_reader, upstream_writer), _pump(upstream_reader, client_writer))
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError, OSError):
            pass
        finally:
            for writer in (client_writer, upstream_writer):
                if writer is not None:
                    with contextlib.suppress(ConnectionError, OSError):
                        writer.close()

    def stop(self) -> None:
        async def close() -> None:
            if self._server is not None:
                self._server.close()
                for task in asyncio.all_tasks():
                    if task is not asyncio.current_task():
                        task.cancel()

        if self._thread.is_alive():
            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(close(), self._loop).result(timeout=5)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5)
