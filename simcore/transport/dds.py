"""DDS topics (cyclonedds) with ROS 2's conventions: the `Bus` that real ROS 2 nodes see.

    from simcore.transport.dds import DdsBus
    bus = DdsBus()                       # domain from ROS_DOMAIN_ID (default 0), config from CYCLONEDDS_URI
    bus = DdsBus(42, config=loopback_config())   # or explicit: domain 42, loopback only
    odom = bus.advertise("/carlos/Ego/odometry", "nav_msgs/msg/Odometry")
    bus.subscribe("/carlos/Ego/control", on_control)   # shell-style glob, as every Bus
    bus.wait_for_subscribers("/carlos/Ego/odometry")   # optional: until a subscriber is there
    odom.publish(msg, time_s)
    bus.close()                          # waits (bounded) until the data was acknowledged

Any process can make one; each is its own DDS participant. Wire conventions, as rmw_cyclonedds_cpp:

- topic `/a/b` is the DDS topic `rt/a/b`; type `pkg/msg/T` is registered as `pkg::msg::dds_::T_`
  (simcore.transport.dds_types builds the IDL types from the type store, so every type of it works);
- QoS of writers: reliable, volatile, like ROS 2's default profile; `/tf_static` transient-local keep-last 1
  like tf2's static broadcaster. History: keep-all by default, `history=10` gives ROS 2's default profile
  exactly. History is not part of DDS' QoS matching, so ROS 2 subscribers match either way; the difference
  is what happens when a subscriber is slower than the publisher: with keep-last 10 cyclonedds drops the
  samples the subscriber has not acknowledged yet once 10 newer ones were written (bench/bridge.py lost 2
  of 101 point clouds that way), with keep-all the writer waits for it (back-pressure, up to 30 s per
  write), as the loopback hub does. A recorder must lose nothing, hence the default.
  Data representation XCDR1 (plain CDR, little endian).
- payload: the CDR bytes rosbags produces (`simcore.transport.messages.serialize`), which are ROS 2's own
  serialisation byte for byte, written as they are (a 65k-point PointCloud2 is one memcpy, never converted
  element by element); received payloads are handed over as bytes and deserialised only when a subscriber
  asks (`Message.obj()`). cyclonedds checks every sample against the IDL type on the way out and in.

What CARLOS adds on top, invisible to ROS 2 nodes (they ignore non-`rt/` topics and user data):

- Simulated time. A CARLOS writer stamps each sample's DDS source timestamp with the `time_s` given to
  `publish` (simulated seconds → ns) and marks itself in its USER_DATA (`carlos:simtime`); the receiving
  `DdsBus` hands that time on as `Message.time_s`, so a recorder in another process logs the same times as
  an in-process one. Samples of other writers (a ROS 2 node) get the latest `/clock` time this bus has
  published or delivered, or their source timestamp (wall clock) when it has seen no `/clock`.
- Glob subscriptions. `subscribe("*")` (the recorder, like `ros2 bag record -a`) watches the built-in
  DCPSPublication topic and creates a reader for every matching `rt/` topic as it appears (the reader
  adopts the publication's reliability and durability, as rosbag2 does). Readers keep all samples, so a
  callback slower than the publisher loses nothing on the reading side either. A topic whose type is not
  in the type store (a user's own message package) is skipped with one warning.
- Not losing the first messages. DDS delivers a volatile sample only to readers matched when it is
  written, and a glob subscriber creates its reader only after it discovered the writer. So every
  subscription is also announced as a reader of the (non-ROS) topic `carlos/bus/subscriptions` whose
  USER_DATA is the pattern; before the first sample of a topic, a writer waits (up to `match_timeout`)
  until it has matched a reader of every participant that announced a matching pattern, and of every
  participant with a reader of that topic of its own (a ROS 2 node's subscription: any reader without
  CARLOS' USER_DATA mark `carlos:bus`). `subscriber_count(topic)` counts those that subscribed by name
  (an announced exact name, or a node's reader), not glob subscribers: lockstep waits for them before the
  first frame (simcore.closedloop).
  `wait_for_subscribers(topic, n)` waits until `n` other participants announced one (the pod's simcore
  waits for the recorder this way before it starts).
- Own publications reach the bus' own matching subscriptions synchronously in `publish` (as on the
  loopback bus); readers ignore the own participant's writers (cyclonedds' IgnoreLocal), so nothing arrives
  twice.
- Ordering: one writer per topic and bus, so one topic's samples arrive in publish order. Across topics
  DDS gives no order; `flush()` (every writer's data acknowledged) before a final message, and `drain()` on
  the receiving side after it, make "everything before the final message" hold (simcore/pod.py does this
  around the end-of-run verdict).

Callbacks of remote messages run on the bus' receive thread, one at a time. Configuration: `config` (XML
or file URI, as CYCLONEDDS_URI) or else what a ROS 2 node with rmw_cyclonedds_cpp would use in this
environment (simcore.transport.dds_config: CYCLONEDDS_URI; localhost only with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST or ROS_LOCALHOST_ONLY=1; else cyclonedds' defaults, one interface
and multicast discovery). `loopback_config()` keeps a bus on 127.0.0.1 with unicast discovery (tests, one
pod's loopback).
Heavy import: cyclonedds is imported by this module only.
"""

from __future__ import annotations

import atexit
import contextlib
import fnmatch
import functools
import logging
import struct
import threading
import time
import uuid
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from cyclonedds._clayer import ddspy_take, ddspy_write_ts
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription
from cyclonedds.core import DDSException, GuardCondition, InstanceState, ReadCondition, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from simcore.transport.bus import Callback, Message, Publisher
from simcore.transport.dds_config import MAX_DOMAIN_ID, config_from_env, domain_id_from_env, loopback_config
from simcore.transport.dds_types import UnknownType, dds_typename, idl_type, ros_typename

log = logging.getLogger("carlos.dds")

#: ROS 2's prefix of topic names on DDS (rmw: `ros_topic_prefix`)
TOPIC_PREFIX = "rt"
#: the USER_DATA of CARLOS' writers: the source timestamp is simulated time
SIMTIME_MARK = b"carlos:simtime"
#: the USER_DATA of CARLOS' readers: not a node of its own (a glob subscriber's reader, e.g. the recorder's)
READER_MARK = b"carlos:bus"
#: the DDS topic of subscription announcements (no `rt/` prefix: not a ROS 2 topic)
ANNOUNCE_TOPIC = "carlos/bus/subscriptions"
#: topics whose writers are transient-local keep-last 1 (tf2's static broadcaster)
LATCHED_TOPICS = frozenset({"/tf_static"})
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any
_TAKE_BATCH = 64


class DdsError(ConnectionError):
    """The DDS participant could not be created, or a write failed."""


_domains: dict[int, tuple[str, Domain]] = {}
_domains_lock = threading.Lock()
_open_buses: weakref.WeakSet[DdsBus] = weakref.WeakSet()


@atexit.register
def _leave_dds() -> None:
    """Close the buses left open and delete the domains this process configured, while Python still runs.
    cyclonedds' own threads take the GIL to free a domain's types; a thread that does so while the
    interpreter finalizes is ended, and a domain deleted then (its last Python reference collected) waits
    for that thread forever: the process never exits."""
    for bus in list(_open_buses):
        bus.close()
    with _domains_lock:
        domains = [domain for _, domain in _domains.values()]
        _domains.clear()
    for domain in domains:
        domain.__del__()


def _configure(domain_id: int, config: str) -> None:
    """Create the process' domain `domain_id` with `config` (once; a later different config is an error:
    cyclonedds configures a domain when it is created)."""
    with _domains_lock:
        known = _domains.get(domain_id)
        if known is None:
            _domains[domain_id] = (config, Domain(domain_id, config))
        elif known[0] != config:
            raise DdsError(f"DDS domain {domain_id} already exists in this process with another config")


def dds_topic(topic: str) -> str:
    """ROS topic `/a/b` → DDS topic `rt/a/b`."""
    if not topic.startswith("/") or topic == "/":
        raise ValueError(f"not an absolute ROS 2 topic name: {topic!r}")
    return TOPIC_PREFIX + topic


def ros_topic(name: str) -> str | None:
    """DDS topic `rt/a/b` → `/a/b`; None for a DDS topic that is not a ROS 2 topic."""
    prefix = TOPIC_PREFIX + "/"
    return "/" + name[len(prefix) :] if name.startswith(prefix) and len(name) > len(prefix) else None


#: the encapsulation options' bits that give the number of padding bytes at the end of a payload
_PADDING_BITS = 0x03


def decode(data: bytes, typename: str) -> tuple[Any, bytes]:
    """A received CDR payload → (message, the payload without transport padding).

    DDS carries payloads in multiples of 4 bytes: a sample of 11 bytes arrives with one byte appended, of
    any value (rmw_cyclonedds_cpp writes encapsulation options 0 and lets cyclonedds pad; ROS 2's
    deserialisers ignore what follows the message, as rosbags' does up to 3 bytes). The exact length is
    where the deserialiser stops, so what a subscriber gets (and the recorder stores) is byte for byte what
    the publisher serialised. (A CARLOS writer says its padding in the options instead: `padded`.) Raises
    ValueError for a payload that is not a `typename`."""
    from rosbags.serde import SerdeError

    from simcore.transport.messages import TYPESTORE

    if len(data) < 4 or data[:2] != b"\x00\x01":
        raise ValueError("not a little-endian plain CDR payload")
    msgdef = TYPESTORE.get_msgdef(typename)
    try:
        msg, pos = msgdef.deserialize_cdr_le(memoryview(data)[4:], 0, msgdef.cls, TYPESTORE)
    except (SerdeError, struct.error, UnicodeDecodeError, ValueError, IndexError) as exc:
        raise ValueError(f"not a {typename}: {exc}") from None
    end = 4 + pos
    if end > len(data) or end + 3 < len(data):
        raise ValueError(f"not a {typename}: {len(data) - end} bytes left over")
    return msg, unpadded(data, len(data) - end)


def _with_padding_bits(data: bytes, pad: int, end: int) -> bytes:
    """`data[:end]` with `pad` in the padding bits of its encapsulation options (the header's last byte)."""
    return b"%c%c%c%c" % (data[0], data[1], data[2], (data[3] & ~_PADDING_BITS) | pad) + data[4:end]


def unpadded(data: bytes, pad: int) -> bytes:
    """A received CDR payload without its last `pad` bytes of transport padding, the padding bits of its
    encapsulation options cleared: the bytes the publisher serialised."""
    if not pad and not data[3] & _PADDING_BITS:
        return data
    return _with_padding_bits(data, 0, len(data) - pad)


def padded(data: bytes) -> bytes:
    """A CDR payload as CARLOS writes it to DDS: the number of bytes the transport pads it with (to a multiple
    of 4) in the two low bits of its encapsulation options (DDS-XTypes 1.3, 7.6.3.1.2). A cyclonedds reader
    then hands over the payload without the padding, so a CARLOS reader has the exact bytes without
    deserialising the message (`own_payload`). ROS 2's deserialisers ignore the options."""
    pad = -len(data) % 4
    if not pad or len(data) < 4:
        return data
    return _with_padding_bits(data, pad, len(data))


def own_payload(data: bytes) -> bytes:
    """A CARLOS writer's payload (`padded`) as received → the bytes it serialised: its padding bits cleared,
    and its padding taken off where the reader left it on (a length that is a multiple of 4)."""
    pad = data[3] & _PADDING_BITS
    return unpadded(data, pad if len(data) % 4 == 0 else 0)


@functools.cache
def _announcement_type() -> type[IdlStruct]:
    return make_idl_struct("Subscription_", "carlos::bus::Subscription_", {"pattern": str})


def _writer_qos(topic: str, depth: int | None) -> Qos:
    latched = topic in LATCHED_TOPICS
    history = Policy.History.KeepAll if depth is None else Policy.History.KeepLast(depth)
    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(seconds=30)),
        Policy.History.KeepLast(1) if latched else history,
        Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile,
        Policy.DataRepresentation(use_cdrv0_representation=True),
        Policy.Userdata(data=SIMTIME_MARK),
    )


def _reader_qos(reliable: bool, transient_local: bool) -> Qos:
    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(seconds=30))
        if reliable
        else Policy.Reliability.BestEffort,
        Policy.History.KeepAll,
        Policy.Durability.TransientLocal if transient_local else Policy.Durability.Volatile,
        Policy.DataRepresentation(use_cdrv0_representation=True),
        Policy.IgnoreLocal.Participant,
        Policy.Userdata(data=READER_MARK),
    )


@dataclass(eq=False)
class _Writer:
    topic: str
    typename: str
    writer: DataWriter[Any]
    matched: bool = False  # waited for the announced subscribers once


@dataclass(eq=False)
class _Reader:
    topic: str
    typename: str
    reader: DataReader[Any]
    condition: ReadCondition


@dataclass
class _DdsPublisher:
    bus: DdsBus
    topic: str
    typename: str

    def publish(self, msg: Any, time_s: float) -> None:
        self.bus.publish_message(Message(self.topic, self.typename, time_s, msg=msg))

    def publish_lazily(
        self, build: Callable[[], Any], encode: Callable[[], bytes] | None, time_s: float
    ) -> None:
        self.bus.publish_message(Message(self.topic, self.typename, time_s, build=build, encode=encode))


@dataclass
class _Announcements:
    """Subscription patterns announced by other participants: endpoint key → (participant key, pattern)."""

    by_key: dict[uuid.UUID, tuple[uuid.UUID, str]] = field(default_factory=dict)

    def participants(self, topic: str) -> set[uuid.UUID]:
        return {p for p, pattern in self.by_key.values() if fnmatch.fnmatchcase(topic, pattern)}

    def by_name(self, topic: str) -> set[uuid.UUID]:
        return {p for p, pattern in self.by_key.values() if pattern == topic}


@dataclass
class _NodeReaders:
    """DDS readers of ROS 2 topics that other participants created themselves (ROS 2 nodes, not CARLOS'
    glob readers): endpoint key → (participant key, ROS topic)."""

    by_key: dict[uuid.UUID, tuple[uuid.UUID, str]] = field(default_factory=dict)

    def participants(self, topic: str) -> set[uuid.UUID]:
        return {p for p, t in self.by_key.values() if t == topic}


class DdsBus:
    """A `Bus` on a DDS domain (see the module docstring). Thread-safe: publish from any thread."""

    def __init__(
        self,
        domain_id: int | None = None,
        *,
        config: str | None = None,
        match_timeout: float = 10.0,
        history: int | None = None,
    ) -> None:
        self.domain_id = domain_id_from_env() if domain_id is None else domain_id
        if not 0 <= self.domain_id <= MAX_DOMAIN_ID:
            raise ValueError(f"domain id {self.domain_id} is outside 0..{MAX_DOMAIN_ID}")
        self.match_timeout = match_timeout
        if history is not None and history < 1:
            raise ValueError(f"history depth {history} is not positive")
        self.history = history
        if config is None:
            config = config_from_env()
        try:
            if config is not None:
                _configure(self.domain_id, config)
            self.participant = DomainParticipant(self.domain_id)
        except DDSException as exc:
            raise DdsError(
                f"cannot join DDS domain {self.domain_id} (check CYCLONEDDS_URI / the config): {exc}"
            ) from None
        self.guid: uuid.UUID = self.participant.guid
        self._lock = threading.RLock()
        self._topics: dict[str, Topic[Any]] = {}
        self._writers: dict[str, _Writer] = {}
        self._readers: dict[str, _Reader] = {}
        self._subscriptions: list[tuple[str, Callback]] = []
        self._routes: dict[str, list[Callback]] = {}
        self._announcers: list[DataReader[Any]] = []
        self._announced = _Announcements()
        self._node_readers = _NodeReaders()
        self._known_publications: dict[uuid.UUID, Any] = {}
        #: every ROS 2 topic other participants published since this bus started: topic → type
        self.discovered: dict[str, str] = {}
        self._changed = threading.Condition(self._lock)
        self._simtime_writers: dict[int, bool] = {}
        self._unknown_types: set[str] = set()
        self._bad_topics: set[str] = set()
        self._last_clock: float | None = None
        self.topics: dict[str, str] = {}  # advertised topic → type
        self.received = 0
        self.error: BaseException | None = None
        self._closed = False
        self._pass = 0  # receive passes started (drain)
        self._idle_pass = 0  # the last pass that took nothing
        self._announce_topic = Topic(self.participant, ANNOUNCE_TOPIC, _announcement_type())
        self._publications = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
        self._subscriptions_seen = BuiltinDataReader(self.participant, BuiltinTopicDcpsSubscription)
        self._wake = GuardCondition(self.participant)
        from cyclonedds.core import WaitSet

        self._waitset = WaitSet(self.participant)
        self._waitset.attach(self._wake)
        for builtin in (self._publications, self._subscriptions_seen):
            self._waitset.attach(ReadCondition(builtin, _ANY))
        self._thread = threading.Thread(target=self._run, name=f"dds-{self.domain_id}", daemon=True)
        self._thread.start()
        _open_buses.add(self)

    # --- Bus protocol -----------------------------------------------------------------------------------

    def advertise(self, topic: str, typename: str) -> Publisher:
        with self._lock:
            known = self.topics.setdefault(topic, typename)
            if known != typename:
                raise ValueError(f"topic {topic} is advertised as {known}, not {typename}")
            if topic not in self._writers:
                try:
                    qos = _writer_qos(topic, self.history)
                    writer = DataWriter(self.participant, self._topic(topic, typename), qos)
                except DDSException as exc:
                    raise DdsError(f"cannot create the DDS writer of {topic} ({typename}): {exc}") from None
                self._writers[topic] = _Writer(topic, typename, writer)
        return _DdsPublisher(self, topic, typename)

    def subscribe(self, pattern: str, callback: Callback, *, typename: str | None = None) -> None:
        """Receive every message whose topic matches `pattern` (shell-style glob), from other participants
        as they appear and from this bus' own publications. With `typename` (and a pattern without glob
        characters) the reader is created at once instead of on discovery of a writer."""
        with self._lock:
            self._subscriptions.append((pattern, callback))
            self._routes.clear()
            announcer = DataReader(
                self.participant,
                self._announce_topic,
                Qos(Policy.Reliability.Reliable(max_blocking_time=0), Policy.Userdata(data=pattern.encode())),
            )
            self._announcers.append(announcer)
            if typename is not None:
                self._ensure_reader(
                    pattern, typename, reliable=True, transient_local=pattern in LATCHED_TOPICS
                )
            for endpoint in list(self._known_publications.values()):  # topics already discovered
                self._on_publication(endpoint)
        self._wake.set(True)

    def publish_message(self, message: Message) -> None:
        """Publish a message (object or CDR bytes) on its topic (advertised before, or now)."""
        writer = self._writers.get(message.topic)
        if writer is None:
            self.advertise(message.topic, message.typename)
            writer = self._writers[message.topic]
        if not writer.matched:
            self._await_announced(writer)
        data = message.cdr()
        if message.topic == "/clock":
            self._last_clock = message.time_s  # the time of the commands of ROS 2 nodes that answer it
        stamp = max(0, round(message.time_s * 1e9))
        ret = ddspy_write_ts(writer.writer._ref, padded(data), stamp)
        if ret < 0:
            raise DdsError(f"DDS write on {message.topic} failed ({DDSException(ret, '')!s})")
        self._dispatch(message)

    def close(self) -> None:
        """Wait (up to 5 s) until every writer's data is acknowledged, then leave the domain."""
        if self._closed:
            return
        self.flush(5.0)
        self._closed = True
        self._wake.set(True)
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        with self._lock:
            self._readers.clear()
            self._writers.clear()
            self._topics.clear()
            self._announcers.clear()
        self.participant.__del__()  # deletes the participant and everything in it
        _open_buses.discard(self)

    # --- extras ----------------------------------------------------------------------------------------

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until every reliable reader matched by this bus' writers acknowledged all data written so far
        (False on timeout)."""
        deadline = time.monotonic() + timeout
        with self._lock:
            writers = list(self._writers.values())
        ok = True
        for writer in writers:
            left = max(0.0, deadline - time.monotonic())
            # the C call: cyclonedds' DataWriter.wait_for_acks fails on its own timeout code (11.0.1)
            ret = writer.writer._wait_for_acks(writer.writer._ref, duration(seconds=left))
            ok = ret == 0 and ok
        return ok

    def drain(self, timeout: float = 5.0) -> bool:
        """Wait until the receive thread has dispatched everything that had arrived before this call (a full
        receive pass that found nothing more). False on timeout or when the bus is closed."""
        with self._changed:
            first = self._pass + 1  # passes from this number on start after this call
            self._wake.set(True)
            return (
                self._changed.wait_for(lambda: self._closed or self._idle_pass >= first, timeout=timeout)
                and not self._closed
            )

    def wait_for_subscribers(self, topic: str, count: int = 1, timeout: float = 30.0) -> bool:
        """Wait until `count` other participants announced a subscription matching `topic`."""
        with self._changed:
            return self._changed.wait_for(
                lambda: len(self._announced.participants(topic)) >= count, timeout=timeout
            )

    def subscriber_count(self, topic: str) -> int:
        """How many other participants subscribed to `topic` by its exact name: a CARLOS bus that announced
        the name (not a glob such as the recorder's "*"), or any other DDS participant (a ROS 2 node) with a
        reader of the topic. What lockstep waits for before the first frame."""
        with self._lock:
            return len(self._announced.by_name(topic) | self._node_readers.participants(topic))

    def publishers(self, topic: str) -> set[uuid.UUID]:
        """The participants (other than this one) that currently have a writer of `topic`."""
        with self._lock:
            return {
                e.participant_key
                for e in self._known_publications.values()
                if ros_topic(e.topic_name) == topic and e.participant_key != self.guid
            }

    def subscribers(self, topic: str) -> set[uuid.UUID]:
        """The participants (other than this one) that announced a subscription matching `topic`."""
        with self._lock:
            return self._announced.participants(topic)

    def graph(self) -> dict[str, str]:
        """The ROS 2 topics published on the domain as this bus knows them: topic → `pkg/msg/Type` (other
        participants' writers, discovered through DCPSPublication, and this bus' own)."""
        with self._lock:
            out = dict(self.topics)
            for endpoint in self._known_publications.values():
                topic = ros_topic(endpoint.topic_name)
                typename = ros_typename(endpoint.type_name)
                if topic is not None and typename is not None:
                    out.setdefault(topic, typename)
        return out

    # --- internals ---------------------------------------------------------------------------------------

    def _topic(self, topic: str, typename: str) -> Topic[Any]:
        existing = self._topics.get(topic)
        if existing is None:
            try:
                existing = self._topics[topic] = Topic(self.participant, dds_topic(topic), idl_type(typename))
            except DDSException as exc:
                raise DdsError(f"cannot create the DDS topic of {topic} ({typename}): {exc}") from None
        return existing

    @staticmethod
    def _matched_participants(writer: DataWriter[Any]) -> set[uuid.UUID]:
        """The participants of the readers matched with `writer` (empty when a reader matched in the middle of
        the query: the callers ask again)."""
        out: set[uuid.UUID] = set()
        try:
            handles = writer.get_matched_subscriptions()
        except IndexError:
            # cyclonedds-python counts the matches, allocates, then fills: a reader matching in between
            # makes the fill return more than it allocated (IndexError "invalid index")
            return out
        for handle in handles:
            with contextlib.suppress(DDSException):
                data = writer.get_matched_subscription_data(handle)
                if data is not None:
                    out.add(data.participant_key)
        return out

    def _await_announced(self, writer: _Writer) -> None:
        deadline = time.monotonic() + self.match_timeout
        while True:
            with self._lock:
                expected = self._announced.participants(writer.topic) | self._node_readers.participants(
                    writer.topic
                )
            missing = expected - self._matched_participants(writer.writer)
            if not missing:
                break
            if time.monotonic() >= deadline:
                log.warning(
                    "dds: %s: %d announced subscriber(s) did not match within %.1f s; publishing anyway",
                    writer.topic,
                    len(missing),
                    self.match_timeout,
                )
                break
            time.sleep(0.002)
        writer.matched = True

    def _ensure_reader(self, topic: str, typename: str, *, reliable: bool, transient_local: bool) -> None:
        if topic in self._readers or self._closed:
            return
        try:
            reader = DataReader(
                self.participant, self._topic(topic, typename), _reader_qos(reliable, transient_local)
            )
        except UnknownType as exc:
            if typename not in self._unknown_types:
                self._unknown_types.add(typename)
                log.warning("dds: not subscribing to %s: %s", topic, exc)
            return
        condition = ReadCondition(reader, _ANY)
        self._readers[topic] = _Reader(topic, typename, reader, condition)
        self._waitset.attach(condition)

    def _wanted(self, topic: str) -> bool:
        return any(fnmatch.fnmatchcase(topic, pattern) for pattern, _ in self._subscriptions)

    def _on_publication(self, endpoint: Any) -> None:
        if endpoint.participant_key == self.guid:
            return
        topic = ros_topic(endpoint.topic_name)
        if topic is None or topic in self._readers or not self._wanted(topic):
            return
        typename = ros_typename(endpoint.type_name)
        if typename is None:
            return
        qos = endpoint.qos
        reliable = isinstance(qos[Policy.Reliability], Policy.Reliability.Reliable) if qos else True
        durable = bool(qos) and qos[Policy.Durability] == Policy.Durability.TransientLocal
        try:
            self._ensure_reader(topic, typename, reliable=reliable, transient_local=durable)
        except DdsError as exc:
            log.warning("dds: %s", exc)

    def _note(self, endpoint: Any) -> None:
        if endpoint.participant_key == self.guid:
            return
        topic = ros_topic(endpoint.topic_name)
        typename = ros_typename(endpoint.type_name)
        if topic is not None and typename is not None:
            self.discovered.setdefault(topic, typename)

    def _on_subscription(self, endpoint: Any, alive: bool) -> None:
        if endpoint.participant_key == self.guid:
            return
        if not alive:
            self._announced.by_key.pop(endpoint.key, None)
            self._node_readers.by_key.pop(endpoint.key, None)
            return
        qos = endpoint.qos
        data = qos[Policy.Userdata].data if qos and Policy.Userdata in qos else b""
        if endpoint.topic_name != ANNOUNCE_TOPIC:
            topic = ros_topic(endpoint.topic_name)
            if topic is not None and data != READER_MARK:
                self._node_readers.by_key[endpoint.key] = (endpoint.participant_key, topic)
            return
        with contextlib.suppress(UnicodeDecodeError):
            self._announced.by_key[endpoint.key] = (endpoint.participant_key, data.decode())

    def _discover(self) -> int:
        count = 0
        for endpoint in self._publications.take(N=_TAKE_BATCH):
            count += 1
            info = getattr(endpoint, "sample_info", None)
            with self._lock:
                if info is None or info.instance_state == InstanceState.Alive:
                    self._known_publications[endpoint.key] = endpoint
                    self._note(endpoint)
                    self._on_publication(endpoint)
                else:
                    self._known_publications.pop(endpoint.key, None)
        for endpoint in self._subscriptions_seen.take(N=_TAKE_BATCH):
            count += 1
            info = getattr(endpoint, "sample_info", None)
            alive = info is None or info.instance_state == InstanceState.Alive
            with self._changed:
                self._on_subscription(endpoint, alive)
                self._changed.notify_all()
        return count

    def _simtime(self, reader: _Reader, handle: int) -> bool:
        known = self._simtime_writers.get(handle)
        if known is None:
            try:
                data = reader.reader.get_matched_publication_data(handle)
            except DDSException:
                data = None
            if data is None:
                return False  # not known (yet): this sample gets the fallback time, the next ones ask again
            qos: Any = data.qos
            known = qos is not None and Policy.Userdata in qos and qos[Policy.Userdata].data == SIMTIME_MARK
            self._simtime_writers[handle] = known
        return known

    def _receive(self, reader: _Reader) -> int:
        samples = ddspy_take(reader.reader._ref, _ANY, _TAKE_BATCH)
        if isinstance(samples, int):
            raise DdsError(f"DDS take on {reader.topic} failed ({samples})")
        count = 0
        for data, info in samples:
            if not info.valid_data:
                continue
            count += 1
            own = self._simtime(reader, info.publication_handle)
            if own:
                time_s = info.source_timestamp / 1e9
                if reader.topic == "/clock":
                    self._last_clock = time_s
            elif self._last_clock is not None:
                time_s = self._last_clock
            else:
                time_s = info.source_timestamp / 1e9
            if own and len(data) >= 4 and data[:2] == b"\x00\x01":
                # a CARLOS writer's payload says its padding (`padded`): the message is made only for a
                # subscriber that wants the object (a recorder wants the bytes only)
                message = Message(reader.topic, reader.typename, time_s, data=own_payload(data))
            else:  # any other writer's: the exact length is where the deserialiser stops
                try:
                    msg, exact = decode(data, reader.typename)
                except ValueError as exc:
                    if reader.topic not in self._bad_topics:
                        self._bad_topics.add(reader.topic)
                        log.warning("dds: dropping undecodable samples on %s: %s", reader.topic, exc)
                    continue
                message = Message(reader.topic, reader.typename, time_s, msg=msg, data=exact)
            self._dispatch(message)
        self.received += count
        return count

    def _dispatch(self, message: Message) -> None:
        route = self._routes.get(message.topic)
        if route is None:
            with self._lock:
                route = [cb for p, cb in self._subscriptions if fnmatch.fnmatchcase(message.topic, p)]
                self._routes[message.topic] = route
        for callback in route:
            callback(message)

    def _run(self) -> None:
        try:
            while not self._closed:
                self._waitset.wait(duration(milliseconds=100))
                self._wake.set(False)
                with self._changed:
                    self._pass += 1
                    number = self._pass
                taken = self._discover()
                with self._lock:
                    readers = list(self._readers.values())
                for reader in readers:
                    while True:
                        count = self._receive(reader)
                        taken += count
                        if count < _TAKE_BATCH:
                            break
                with self._changed:
                    if taken == 0:
                        self._idle_pass = number
                    self._changed.notify_all()
        except BaseException as exc:  # a failing callback ends the receive thread; the owner sees .error
            if not self._closed:
                self.error = exc
                log.error("dds bus: %s: %s", type(exc).__name__, exc)
        finally:
            with self._changed:
                self._changed.notify_all()

    def __enter__(self) -> DdsBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = [
    "ANNOUNCE_TOPIC",
    "LATCHED_TOPICS",
    "READER_MARK",
    "SIMTIME_MARK",
    "DdsBus",
    "DdsError",
    "dds_topic",
    "dds_typename",
    "domain_id_from_env",
    "loopback_config",
    "ros_topic",
]
