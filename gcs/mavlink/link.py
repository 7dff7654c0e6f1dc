"""One MAVLink link (TCP, UDP in/out or serial) with one reader that fans messages out.

A :class:`Link` owns one transport and pymavlink's codec. Bytes that arrive are parsed once;
every valid message goes to every listener (synchronous callbacks, e.g. telemetry reducers)
and to every matching subscription (its own queue), so no waiter can swallow another's reply.
Several vehicles may share a link; they are discovered by system id from their HEARTBEATs.
Around that the link keeps itself alive: a GCS HEARTBEAT at 1 Hz, stream-rate requests to each
vehicle it discovers, TIMESYNC pings for the round-trip time, reconnection with back-off, and
counters for everything it received, sent, dropped or rejected.

Example::

    async with Link.open("tcp:127.0.0.1:5760") as link:
        await link.wait_vehicle(1, timeout_s=5.0)
        with link.subscribe(types={"COMMAND_ACK"}, system_id=1) as sub:
            link.send(mavlink2.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
            ack = await sub.get(timeout_s=1.5)

Malformed input never reaches a subscriber: garbage bytes, CRC errors, bad or missing
signatures (when signing is on), frames of impossible length, messages from system id 0 and,
when ``system_ids`` is given, messages from any other system are counted and dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Collection, Mapping
from dataclasses import asdict, dataclass
from typing import Any

from gcs.errors import LinkClosed, LinkTimeout
from gcs.mavlink.dialect import MESSAGE_BY_NAME, mavlink2
from gcs.mavlink.endpoints import Endpoint, parse_connection
from gcs.mavlink.framing import FramingCodec
from gcs.mavlink.signing import SigningConfig, apply_signing
from gcs.mavlink.transports import Transport, open_transport

log = logging.getLogger(__name__)

Listener = Callable[[Any, float], None]

GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = mavlink2.MAV_COMP_ID_MISSIONPLANNER
HEARTBEAT_PERIOD_S = 1.0
TIMESYNC_PERIOD_S = 5.0
STREAM_REFRESH_S = 30.0
# A sequence jump larger than this is a restart or reordering, not loss.
MAX_SEQ_GAP = 128
# type, autopilot, base_mode, custom_mode, system_status, mavlink_version
_GCS_HEARTBEAT = (mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0,
                  mavlink2.MAV_STATE_ACTIVE, 3)  # fmt: skip


@dataclass(slots=True)
class LinkCounters:
    """What one link has seen; all counts since the link was created."""

    received: int = 0
    received_bytes: int = 0
    sent: int = 0
    sent_bytes: int = 0
    send_dropped: int = 0
    seq_lost: int = 0
    """Packets missing from a sender's sequence numbers (radio loss)."""
    seq_out_of_order: int = 0
    crc_errors: int = 0
    garbage_bytes: int = 0
    bad_signature: int = 0
    malformed: int = 0
    unknown_message: int = 0
    unknown_system: int = 0
    subscriber_overflow: int = 0
    listener_errors: int = 0
    connects: int = 0
    reconnects: int = 0
    connect_failures: int = 0
    rtt_s: float | None = None
    """Last TIMESYNC round-trip time."""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(slots=True)
class Peer:
    """A vehicle (autopilot component) heard on the link."""

    system_id: int
    component_id: int
    mav_type: int
    autopilot: int
    first_heartbeat_s: float
    last_heartbeat_s: float


class Subscription:
    """A queue of the messages that match ``types`` and ``system_id``; close it when done."""

    def __init__(
        self,
        link: Link,
        types: frozenset[str] | None,
        system_id: int | None,
        maxsize: int,
    ) -> None:
        self._link = link
        self.types = types
        self.system_id = system_id
        self._queue: asyncio.Queue[Any] = asyncio.Queue(maxsize)
        self.dropped = 0

    def matches(self, msg_type: str, system_id: int) -> bool:
        return (self.types is None or msg_type in self.types) and (
            self.system_id is None or self.system_id == system_id
        )

    def put(self, msg: Any) -> None:
        try:
            self._queue.put_nowait(msg)
        except asyncio.QueueFull:
            # Keep the newest: a slow consumer loses history, not the reply it waits for.
            self._queue.get_nowait()
            self._queue.put_nowait(msg)
            self.dropped += 1
            self._link.counters.subscriber_overflow += 1

    async def get(self, timeout_s: float | None = None) -> Any | None:
        """The next matching message, or None after ``timeout_s``."""
        if timeout_s is None:
            return await self._queue.get()
        if not self._queue.empty():
            return self._queue.get_nowait()
        if timeout_s <= 0:
            return None
        try:
            async with asyncio.timeout(timeout_s):
                return await self._queue.get()
        except TimeoutError:
            return None

    def get_nowait(self) -> Any | None:
        return None if self._queue.empty() else self._queue.get_nowait()

    def close(self) -> None:
        self._link._unsubscribe(self)

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __aiter__(self) -> Subscription:
        return self

    async def __anext__(self) -> Any:
        return await self._queue.get()


class Link:
    """A MAVLink connection to one or more vehicles; see the module docstring."""

    def __init__(
        self,
        connection: str | Endpoint,
        *,
        system_id: int = GCS_SYSTEM_ID,
        component_id: int = GCS_COMPONENT_ID,
        system_ids: Collection[int] | None = None,
        heartbeat_period_s: float | None = HEARTBEAT_PERIOD_S,
        timesync_period_s: float | None = TIMESYNC_PERIOD_S,
        stream_rate_hz: float | None = None,
        message_rates_hz: Mapping[str, float] | None = None,
        stream_refresh_s: float = STREAM_REFRESH_S,
        signing: SigningConfig | None = None,
        reconnect_min_s: float = 0.25,
        reconnect_max_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.endpoint = (
            connection if isinstance(connection, Endpoint) else parse_connection(connection)
        )
        if not 1 <= system_id <= 255:
            raise ValueError(f"link system_id {system_id} is outside 1..255")
        self.system_id = system_id
        self.component_id = component_id
        self.allowed_systems = None if system_ids is None else frozenset(system_ids)
        self.heartbeat_period_s = heartbeat_period_s
        self.timesync_period_s = timesync_period_s
        self.stream_rate_hz = stream_rate_hz
        self.message_rates_hz = dict(message_rates_hz or {})
        for name in self.message_rates_hz:
            if name not in MESSAGE_BY_NAME:
                raise ValueError(f"message_rates_hz: unknown MAVLink message {name!r}")
        self.stream_refresh_s = stream_refresh_s
        self.signing = signing
        self.reconnect_min_s = reconnect_min_s
        self.reconnect_max_s = reconnect_max_s
        self.clock = clock

        self.counters = LinkCounters()
        self.vehicles: dict[int, Peer] = {}
        self._packer = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._parser = self._new_parser()
        if signing is not None:
            apply_signing(self._packer, signing, outgoing=True)
        self._transport: Transport | None = None
        self._connected = asyncio.Event()
        self._closed = False
        self._subs: list[Subscription] = []
        self._listeners: list[Listener] = []
        self._vehicle_events: dict[int | None, asyncio.Event] = {}
        self._last_seq: dict[tuple[int, int], int] = {}
        self._stream_sent_s: dict[int, float] = {}
        self._timesync_sent_ns: dict[int, float] = {}
        self._tasks: list[asyncio.Task[None]] = []
        self.last_rx_s: float | None = None

    # -- lifecycle -----------------------------------------------------------------------

    @classmethod
    def open(cls, connection: str | Endpoint, **kwargs: Any) -> Link:
        """A link to use as ``async with``: started on entry (it connects in the background),
        closed on exit. Bad arguments raise here, before anything is opened."""
        return cls(connection, **kwargs)

    async def __aenter__(self) -> Link:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def start(self) -> None:
        if self._tasks:
            raise RuntimeError(f"link {self.endpoint} already started")
        self._tasks = [
            asyncio.create_task(self._run(), name=f"link {self.endpoint}"),
            asyncio.create_task(self._housekeeping(), name=f"link {self.endpoint} timers"),
        ]

    async def close(self) -> None:
        self._closed = True
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks = []
        self._drop_transport()

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    async def wait_connected(self, timeout_s: float = 5.0) -> None:
        try:
            async with asyncio.timeout(timeout_s):
                await self._connected.wait()
        except TimeoutError:
            raise LinkTimeout(
                f"link {self.endpoint}: not connected after {timeout_s:g} s"
            ) from None

    async def wait_vehicle(self, system_id: int | None = None, timeout_s: float = 5.0) -> Peer:
        """The vehicle ``system_id`` (None: the first one) once its HEARTBEAT has arrived."""
        if self._closed:
            raise LinkClosed(f"link {self.endpoint} is closed")
        peer = self._find_vehicle(system_id)
        if peer is not None:
            return peer
        event = self._vehicle_events.setdefault(system_id, asyncio.Event())
        try:
            async with asyncio.timeout(timeout_s):
                await event.wait()
        except TimeoutError:
            who = "any vehicle" if system_id is None else f"vehicle {system_id}"
            raise LinkTimeout(
                f"link {self.endpoint}: no HEARTBEAT from {who} within {timeout_s:g} s"
            ) from None
        peer = self._find_vehicle(system_id)
        assert peer is not None
        return peer

    def _find_vehicle(self, system_id: int | None) -> Peer | None:
        if system_id is None:
            return next(iter(self.vehicles.values()), None)
        return self.vehicles.get(system_id)

    # -- fan-out -------------------------------------------------------------------------

    def subscribe(
        self,
        types: Collection[str] | None = None,
        system_id: int | None = None,
        *,
        maxsize: int = 1000,
    ) -> Subscription:
        sub = Subscription(self, None if types is None else frozenset(types), system_id, maxsize)
        self._subs.append(sub)
        return sub

    def _unsubscribe(self, sub: Subscription) -> None:
        with contextlib.suppress(ValueError):
            self._subs.remove(sub)

    def add_listener(self, callback: Listener) -> Callable[[], None]:
        self._listeners.append(callback)

        def remove() -> None:
            with contextlib.suppress(ValueError):
                self._listeners.remove(callback)

        return remove

    # -- sending -------------------------------------------------------------------------

    def send(self, msg: Any) -> bool:
        """Pack ``msg`` with our ids and send it; False (counted) when it could not go out."""
        transport = self._transport
        if transport is None:
            self.counters.send_dropped += 1
            return False
        packer = self._packer
        data = msg.pack(packer)
        packer.seq = (packer.seq + 1) % 256  # pymavlink's pack() leaves this to send()
        target = getattr(msg, "target_system", 0)
        if transport.write(data, int(target) if isinstance(target, int) else 0):
            self.counters.sent += 1
            self.counters.sent_bytes += len(data)
            return True
        self.counters.send_dropped += 1
        return False

    def request_streams(self, system_id: int) -> None:
        """Ask vehicle ``system_id`` for the configured stream rates (fire and forget)."""
        self._stream_sent_s[system_id] = self.clock()
        if self.stream_rate_hz is not None:
            self.send(
                mavlink2.MAVLink_request_data_stream_message(
                    system_id, 0, mavlink2.MAV_DATA_STREAM_ALL, round(self.stream_rate_hz), 1
                )
            )
        by_name = MESSAGE_BY_NAME
        for name, rate_hz in self.message_rates_hz.items():
            interval_us = -1.0 if rate_hz <= 0 else 1e6 / rate_hz
            params = (by_name[name].id, interval_us, 0.0, 0.0, 0.0, 0.0, 0.0)
            cmd = mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL
            self.send(mavlink2.MAVLink_command_long_message(system_id, 0, cmd, 0, *params))

    # -- receiving -----------------------------------------------------------------------

    def _new_parser(self) -> Any:
        parser = FramingCodec(None, srcSystem=self.system_id, srcComponent=self.component_id)
        parser.robust_parsing = True
        if self.signing is not None:
            apply_signing(parser, self.signing, outgoing=False)
        return parser

    def feed(self, data: bytes, source: Any = None) -> None:
        """Parse received bytes and dispatch what they hold (the transports call this)."""
        now = self.clock()
        c = self.counters
        c.received_bytes += len(data)
        try:
            msgs = self._parser.parse_buffer(data)
        except Exception:  # pymavlink raises on some inputs even in robust mode
            log.debug("link %s: parser error", self.endpoint, exc_info=True)
            c.malformed += 1
            self._parser = self._new_parser()
            return
        if not msgs:
            return
        for msg in msgs:
            self._dispatch(msg, now, source)

    def _dispatch(self, msg: Any, now: float, source: Any) -> None:
        c = self.counters
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            self._count_bad(msg)
            return
        if mtype == "UNKNOWN" or mtype.startswith("UNKNOWN_"):
            c.unknown_message += 1
            self._track_unknown(msg)
            return
        sysid = msg.get_srcSystem()
        compid = msg.get_srcComponent()
        if sysid == 0:
            c.malformed += 1
            return
        if sysid == self.system_id and compid == self.component_id:
            return  # our own packets echoed back (UDP broadcast, loops)
        if self.allowed_systems is not None and sysid not in self.allowed_systems:
            c.unknown_system += 1
            return
        c.received += 1
        self.last_rx_s = now
        self._track_sequence(sysid, compid, msg.get_seq())
        if source is not None and self._transport is not None:
            self._transport.remember(sysid, source)
        if mtype == "HEARTBEAT":
            self._on_heartbeat(msg, sysid, compid, now)
        elif mtype == "TIMESYNC":
            self._on_timesync(msg, sysid, now)
        for listener in self._listeners:
            try:
                listener(msg, now)
            except Exception:
                c.listener_errors += 1
                log.exception("link %s: listener failed on %s", self.endpoint, mtype)
        for sub in self._subs:
            if sub.matches(mtype, sysid):
                sub.put(msg)

    def _count_bad(self, msg: Any) -> None:
        c = self.counters
        reason = str(getattr(msg, "reason", ""))
        if reason == "Bad prefix":
            c.garbage_bytes += len(msg.data)
        elif "CRC" in reason:
            c.crc_errors += 1
        elif "signature" in reason:
            c.bad_signature += 1
        else:
            c.malformed += 1

    def _track_unknown(self, msg: Any) -> None:
        """A message this dialect cannot decode (one of PX4's that ArduPilot's dialect lacks)
        still took its sender's next sequence number: kept in the sequence from its frame's
        header, so that it is counted unknown and not as a lost packet."""
        frame = msg.get_msgbuf()
        if len(frame) >= 7 and frame[0] == mavlink2.PROTOCOL_MARKER_V2:
            seq, sysid, compid = frame[4], frame[5], frame[6]
        elif len(frame) >= 5 and frame[0] == mavlink2.PROTOCOL_MARKER_V1:
            seq, sysid, compid = frame[2], frame[3], frame[4]
        else:
            return
        if sysid == 0 or (self.allowed_systems is not None and sysid not in self.allowed_systems):
            return
        self._track_sequence(sysid, compid, seq)

    def _track_sequence(self, sysid: int, compid: int, seq: int) -> None:
        key = (sysid, compid)
        last = self._last_seq.get(key)
        self._last_seq[key] = seq
        if last is None:
            return
        gap = (seq - last - 1) % 256
        if gap == 0:
            return
        if gap < MAX_SEQ_GAP:
            self.counters.seq_lost += gap
        else:
            self.counters.seq_out_of_order += 1

    def _on_heartbeat(self, msg: Any, sysid: int, compid: int, now: float) -> None:
        if msg.type == mavlink2.MAV_TYPE_GCS or msg.autopilot == mavlink2.MAV_AUTOPILOT_INVALID:
            return  # another GCS, or a peripheral: not a vehicle
        peer = self.vehicles.get(sysid)
        if peer is None:
            peer = Peer(sysid, compid, msg.type, msg.autopilot, now, now)
            self.vehicles[sysid] = peer
            log.info("link %s: vehicle %d discovered", self.endpoint, sysid)
            for key in (sysid, None):
                event = self._vehicle_events.pop(key, None)
                if event is not None:
                    event.set()
            self.request_streams(sysid)
            return
        if now - peer.last_heartbeat_s > 3 * HEARTBEAT_PERIOD_S + 2.0:
            self.request_streams(sysid)  # back after silence: it may have rebooted
        peer.last_heartbeat_s = now
        peer.mav_type = msg.type
        peer.autopilot = msg.autopilot

    def _on_timesync(self, msg: Any, sysid: int, now: float) -> None:
        if msg.tc1 == 0:
            # A request from the vehicle: answer with our time (ArduPilot/PX4 use it for lag).
            self.send(mavlink2.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1))
            return
        sent = self._timesync_sent_ns.pop(int(msg.ts1), None)
        if sent is not None:
            self.counters.rtt_s = max(0.0, now - sent)

    # -- background tasks ----------------------------------------------------------------

    async def _run(self) -> None:
        backoff_s = self.reconnect_min_s
        first = True
        while not self._closed:
            try:
                transport = await open_transport(self.endpoint, self)
            except OSError as exc:
                self.counters.connect_failures += 1
                why = f"connect failed ({exc}); retry in {backoff_s:.2f} s"
                log.info("link %s: %s", self.endpoint, why)
                await asyncio.sleep(backoff_s)
                backoff_s = min(self.reconnect_max_s, backoff_s * 2)
                continue
            backoff_s = self.reconnect_min_s
            self._parser = self._new_parser()
            self._last_seq.clear()
            self._transport = transport
            self.counters.connects += 1
            if not first:
                self.counters.reconnects += 1
            first = False
            self._connected.set()
            self._send_heartbeat()
            try:
                await transport.lost
            finally:
                self._connected.clear()
                self._drop_transport()
            if not self._closed:
                log.info("link %s: connection lost; reconnecting", self.endpoint)
                # Ask every vehicle for its streams again once the link is back.
                self._stream_sent_s.clear()
                await asyncio.sleep(backoff_s)

    def _drop_transport(self) -> None:
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close()

    def _send_heartbeat(self) -> None:
        self.send(mavlink2.MAVLink_heartbeat_message(*_GCS_HEARTBEAT))

    async def _housekeeping(self) -> None:
        period_s = self.heartbeat_period_s or 1.0
        last_timesync = -1e18
        while True:
            await asyncio.sleep(period_s)
            if not self.connected:
                continue
            now = self.clock()
            if self.heartbeat_period_s is not None:
                self._send_heartbeat()
            if self.timesync_period_s is not None and now - last_timesync >= (
                self.timesync_period_s
            ):
                last_timesync = now
                self._send_timesync(now)
            for sysid in self.vehicles:
                sent = self._stream_sent_s.get(sysid)
                if sent is None or now - sent >= self.stream_refresh_s:
                    self.request_streams(sysid)

    def _send_timesync(self, now: float) -> None:
        ts1 = time.monotonic_ns()
        # Keep only the pings still in flight (a lost reply must not grow the table).
        self._timesync_sent_ns = {k: v for k, v in self._timesync_sent_ns.items() if now - v < 30}
        self._timesync_sent_ns[ts1] = now
        self.send(mavlink2.MAVLink_timesync_message(0, ts1))
