"""Loopback TCP topics: the `Bus` between the separate processes of one pod (simcore, bridge, recorder).

Until the DDS transport exists (the bridge issue), the pod's roles exchange ROS 2 messages, CDR-encoded as
on DDS, over 127.0.0.1 through a hub:

- `LoopbackHub` (run by the `bridge` role, the first sidecar to start) accepts connections and relays every
  published message to each *other* connection with a matching subscription, in the order it received
  them (one TCP stream per client, so a subscriber sees one publisher's messages in publish order). A slow
  subscriber slows the publisher (TCP back-pressure): nothing is dropped.
- `LoopbackBus` (simcore, recorder) is a client implementing `simcore.transport.bus.Bus`. `subscribe`
  returns only after the hub acknowledged the subscription, so a role that subscribed and then reports
  ready cannot miss a message published after that. A client's own publications also reach its own
  matching subscriptions (as in ROS 2), without a round trip.

Wire format: frames of a 4-byte big-endian length and a body whose first byte is the kind:
- `P` publish: u16 topic length, topic (UTF-8), u16 type length, type, f64 time (s), CDR bytes to the end;
- `S` subscribe: u32 request id, u16 pattern length, pattern (shell-style glob, as `Bus.subscribe`);
- `A` acknowledge: u32 request id;
- `C` count request: u32 request id, u16 topic length, topic: how many *other* clients subscribed to
  exactly this topic name (glob patterns do not count; the closed loop's lockstep start waits for the
  system under test this way); `N` its answer: u32 request id, u32 count.
"""

from __future__ import annotations

import contextlib
import fnmatch
import logging
import socket
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from simcore.transport.bus import Callback, Message, Publisher

log = logging.getLogger("carlos.loopback")

DEFAULT_PORT = 7447
MAX_FRAME = 256 * 1024 * 1024
_LEN = struct.Struct("!I")
_U16 = struct.Struct("!H")
_U32 = struct.Struct("!I")
_F64 = struct.Struct("!d")


class LoopbackError(ConnectionError):
    """The hub is unreachable, or a peer broke the protocol."""


def encode_publish(topic: str, typename: str, time_s: float, data: bytes) -> bytes:
    t = topic.encode()
    n = typename.encode()
    body_len = 1 + 2 + len(t) + 2 + len(n) + 8 + len(data)
    return b"".join(
        (_LEN.pack(body_len), b"P", _U16.pack(len(t)), t, _U16.pack(len(n)), n, _F64.pack(time_s), data)
    )


def decode_publish(body: bytes | memoryview) -> Message:
    view = memoryview(body)
    (tlen,) = _U16.unpack_from(view, 1)
    topic = bytes(view[3 : 3 + tlen]).decode()
    pos = 3 + tlen
    (nlen,) = _U16.unpack_from(view, pos)
    typename = bytes(view[pos + 2 : pos + 2 + nlen]).decode()
    pos += 2 + nlen
    (time_s,) = _F64.unpack_from(view, pos)
    return Message(topic, typename, time_s, data=bytes(view[pos + 8 :]))


def _encode_subscribe(request: int, pattern: str) -> bytes:
    p = pattern.encode()
    body = b"S" + _U32.pack(request) + _U16.pack(len(p)) + p
    return _LEN.pack(len(body)) + body


def _encode_ack(request: int) -> bytes:
    body = b"A" + _U32.pack(request)
    return _LEN.pack(len(body)) + body


def _encode_count(request: int, topic: str) -> bytes:
    t = topic.encode()
    body = b"C" + _U32.pack(request) + _U16.pack(len(t)) + t
    return _LEN.pack(len(body)) + body


def _recv_exact(sock: socket.socket, n: int) -> bytes | None:
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        count = sock.recv_into(view[got:], n - got)
        if count == 0:
            return None
        got += count
    return bytes(buf)


def read_frame(sock: socket.socket) -> bytes | None:
    """One frame's body, or None at end of stream."""
    head = _recv_exact(sock, 4)
    if head is None:
        return None
    (length,) = _LEN.unpack(head)
    if length == 0 or length > MAX_FRAME:
        raise LoopbackError(f"bad frame length {length}")
    return _recv_exact(sock, length)


# --- hub -------------------------------------------------------------------------------------------------


@dataclass(eq=False)
class _Client:
    sock: socket.socket
    name: str
    patterns: list[str] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)
    alive: bool = True

    def send(self, frame: bytes) -> None:
        with self.lock:
            self.sock.sendall(frame)


class LoopbackHub:
    """The relay: accepts clients on `host:port` and forwards publications to matching subscribers."""

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT) -> None:
        self._server = socket.create_server((host, port), reuse_port=False)
        self.host, self.port = self._server.getsockname()[:2]
        self._clients: list[_Client] = []
        self._lock = threading.Lock()
        self._routes: dict[str, list[_Client]] = {}
        self._closed = threading.Event()
        self._threads: list[threading.Thread] = []
        self.relayed = 0

    def start(self) -> LoopbackHub:
        thread = threading.Thread(target=self._accept, name="loopback-hub", daemon=True)
        thread.start()
        self._threads.append(thread)
        return self

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                sock, peer = self._server.accept()
            except OSError:
                return
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = _Client(sock, f"{peer[0]}:{peer[1]}")
            with self._lock:
                self._clients.append(client)
            thread = threading.Thread(
                target=self._serve, args=(client,), name=f"hub-{client.name}", daemon=True
            )
            thread.start()

    def _route(self, sender: _Client, topic: str) -> list[_Client]:
        key = topic
        with self._lock:
            routes = self._routes.get(key)
            if routes is None:
                routes = [
                    c
                    for c in self._clients
                    if c.alive and any(fnmatch.fnmatchcase(topic, p) for p in c.patterns)
                ]
                self._routes[key] = routes
        return [c for c in routes if c is not sender]

    def _serve(self, client: _Client) -> None:
        sock = client.sock
        try:
            while True:
                body = read_frame(sock)
                if body is None:
                    return
                kind = body[:1]
                if kind == b"P":
                    (tlen,) = _U16.unpack_from(body, 1)
                    topic = body[3 : 3 + tlen].decode()
                    frame = _LEN.pack(len(body)) + body
                    for target in self._route(client, topic):
                        try:
                            target.send(frame)
                        except OSError:
                            self._drop(target)
                    self.relayed += 1
                elif kind == b"S":
                    (request,) = _U32.unpack_from(body, 1)
                    (plen,) = _U16.unpack_from(body, 5)
                    pattern = body[7 : 7 + plen].decode()
                    with self._lock:
                        client.patterns.append(pattern)
                        self._routes.clear()
                    client.send(_encode_ack(request))
                elif kind == b"C":
                    (request,) = _U32.unpack_from(body, 1)
                    (tlen,) = _U16.unpack_from(body, 5)
                    topic = body[7 : 7 + tlen].decode()
                    with self._lock:
                        count = sum(
                            1 for c in self._clients if c is not client and c.alive and topic in c.patterns
                        )
                    reply = b"N" + _U32.pack(request) + _U32.pack(count)
                    client.send(_LEN.pack(len(reply)) + reply)
                else:
                    raise LoopbackError(f"unknown frame kind {kind!r} from {client.name}")
        except (OSError, LoopbackError, struct.error, UnicodeDecodeError) as exc:
            if not self._closed.is_set():
                log.warning("loopback hub: client %s: %s", client.name, exc)
        finally:
            self._drop(client)

    def _drop(self, client: _Client) -> None:
        with self._lock:
            if client in self._clients:
                self._clients.remove(client)
            client.alive = False
            self._routes.clear()
        with contextlib.suppress(OSError):
            client.sock.close()

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._clients)

    def close(self) -> None:
        self._closed.set()
        with contextlib.suppress(OSError):
            self._server.close()
        with self._lock:
            clients = list(self._clients)
        for client in clients:
            with contextlib.suppress(OSError):
                client.sock.shutdown(socket.SHUT_RDWR)
            self._drop(client)


# --- client ----------------------------------------------------------------------------------------------


@dataclass
class _LoopbackPublisher:
    bus: LoopbackBus
    topic: str
    typename: str

    def publish(self, msg: Any, time_s: float) -> None:
        self.bus.publish_message(Message(self.topic, self.typename, time_s, msg=msg))

    def publish_lazily(
        self, build: Callable[[], Any], encode: Callable[[], bytes] | None, time_s: float
    ) -> None:
        self.bus.publish_message(Message(self.topic, self.typename, time_s, build=build, encode=encode))


class LoopbackBus:
    """A `Bus` client of a `LoopbackHub`. Callbacks of remote messages run on the bus' reader thread."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        connect_timeout: float = 30.0,
        on_disconnect: Callable[[], None] | None = None,
    ) -> None:
        deadline = time.monotonic() + connect_timeout
        while True:
            try:
                self._sock = socket.create_connection((host, port), timeout=5.0)
                break
            except OSError as exc:
                if time.monotonic() >= deadline:
                    raise LoopbackError(f"no loopback topic hub at {host}:{port}: {exc}") from exc
                time.sleep(0.05)
        self._sock.settimeout(None)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._send_lock = threading.Lock()
        self._subscriptions: list[tuple[str, Callback]] = []
        self._routes: dict[str, list[Callback]] = {}
        self._acks: dict[int, threading.Event] = {}
        self._counts: dict[int, int] = {}
        self._next_request = 0
        self.topics: dict[str, str] = {}
        self._closed = False
        self._on_disconnect = on_disconnect
        self.disconnected = threading.Event()
        self.error: BaseException | None = None
        self.last_receive = time.monotonic()  # when the reader last got a frame (drain on shutdown)
        self._reader = threading.Thread(target=self._read, name="loopback-reader", daemon=True)
        self._reader.start()

    # Bus protocol
    def advertise(self, topic: str, typename: str) -> Publisher:
        known = self.topics.setdefault(topic, typename)
        if known != typename:
            raise ValueError(f"topic {topic} is advertised as {known}, not {typename}")
        return _LoopbackPublisher(self, topic, typename)

    def subscribe(self, pattern: str, callback: Callback, *, timeout: float = 30.0) -> None:
        """Subscribe; returns once the hub has the subscription (raises LoopbackError otherwise)."""
        with self._send_lock:
            self._next_request += 1
            request = self._next_request
            event = self._acks[request] = threading.Event()
            self._subscriptions.append((pattern, callback))
            self._routes.clear()
            self._sock.sendall(_encode_subscribe(request, pattern))
        if not event.wait(timeout):
            raise LoopbackError(f"the topic hub did not acknowledge the subscription {pattern!r}")

    def subscriber_count(self, topic: str, *, timeout: float = 10.0) -> int:
        """How many other clients of the hub subscribed to `topic` by its exact name."""
        with self._send_lock:
            self._next_request += 1
            request = self._next_request
            event = self._acks[request] = threading.Event()
            self._sock.sendall(_encode_count(request, topic))
        if not event.wait(timeout):
            raise LoopbackError(f"the topic hub did not answer a subscriber count for {topic!r}")
        return self._counts.pop(request)

    def publish_message(self, message: Message) -> None:
        frame = encode_publish(message.topic, message.typename, message.time_s, message.cdr())
        with self._send_lock:
            self._sock.sendall(frame)
        self._dispatch(message)

    def drain(self, quiet: float = 0.3, limit: float = 5.0) -> None:
        """Wait until nothing arrived for `quiet` seconds (or `limit` passed, or the hub is gone): what
        was already sent to this client is then dispatched. The quiet time counts from this call at the
        earliest: frames queued for a reader that has not run since its last frame are not given up."""
        start = time.monotonic()
        deadline = start + limit
        while time.monotonic() < deadline and not self.disconnected.is_set():
            idle = time.monotonic() - max(self.last_receive, start)
            if idle >= quiet:
                return
            time.sleep(quiet - idle)

    def close(self) -> None:
        """Send everything (the kernel delivers what was written before the FIN), then disconnect."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_WR)
        self._reader.join(timeout=5.0)
        with contextlib.suppress(OSError):
            self._sock.close()

    # internals
    def _dispatch(self, message: Message) -> None:
        route = self._routes.get(message.topic)
        if route is None:
            route = [cb for p, cb in list(self._subscriptions) if fnmatch.fnmatchcase(message.topic, p)]
            self._routes[message.topic] = route
        for callback in route:
            callback(message)

    def _read(self) -> None:
        try:
            while True:
                body = read_frame(self._sock)
                if body is None:
                    return
                self.last_receive = time.monotonic()
                kind = body[:1]
                if kind == b"P":
                    self._dispatch(decode_publish(body))
                elif kind == b"A":
                    (request,) = _U32.unpack_from(body, 1)
                    event = self._acks.pop(request, None)
                    if event is not None:
                        event.set()
                elif kind == b"N":
                    request, count = struct.unpack_from("!II", body, 1)
                    self._counts[request] = count
                    event = self._acks.pop(request, None)
                    if event is not None:
                        event.set()
                else:
                    raise LoopbackError(f"unknown frame kind {kind!r} from the hub")
        except BaseException as exc:  # a failing callback or a broken stream ends the reader
            if not self._closed:
                self.error = exc
                log.error("loopback bus: %s", exc)
        finally:
            self.disconnected.set()
            if self._on_disconnect is not None:
                self._on_disconnect()
