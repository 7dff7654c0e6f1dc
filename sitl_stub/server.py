"""Asyncio transport for a team of stub vehicles: TCP listeners and the simulation loop.

Each vehicle listens on its own TCP port; every client connection is a link. Incoming bytes
are decoded per connection (bad CRCs and garbage are counted and dropped), passed through
the vehicle's link faults and handed to :class:`~sitl_stub.vehicle.Vehicle`. Outgoing
packets go to the addressed link or to all links, each copy through the faults.

Connections are ``asyncio.Protocol`` objects (no per-connection tasks); delayed packets are
``call_at`` timers cancelled on close. The only task is the simulation loop, which the caller
runs inside its own ``TaskGroup``.

With ``one_client_per_port`` a vehicle serves one client at a time, as ArduPilot SITL's TCP
serial ports do (libraries/AP_HAL_SITL/UARTDriver.cpp: ``listen(fd, 5)``, and
``_check_connection`` accepts only while not connected): a second client's connect succeeds
but it is neither read nor sent anything until the first disconnects; then the longest-waiting
client is served.

Writes are batched: a packet is appended to its connection's buffer and every buffer touched
during one pass of the event loop goes out in ONE ``transport.write`` at the start of the next
pass (a ``call_soon``), so the order of packets on a connection is kept and a simulation tick
costs one send system call per client instead of one per packet. Each packet is packed once
by the vehicle and the same ``bytes`` object is queued for every client.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
from collections.abc import Sequence
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.clock import SimClock
from sitl_stub.link import DelayQueue
from sitl_stub.lockstep import Lockstep
from sitl_stub.mission_server import LinkId
from sitl_stub.vehicle import Vehicle

log = logging.getLogger(__name__)

# A client that does not read is treated like a saturated radio: telemetry is dropped.
MAX_WRITE_BUFFER_BYTES = 1 << 20
# Yield to the event loop after this many catch-up steps so I/O is served.
STEPS_PER_YIELD = 10

_link_ids = itertools.count(1)


class WriteBatcher:
    """Connections with queued bytes, written out together once per event-loop pass."""

    def __init__(self) -> None:
        self._dirty: list[_Connection] = []

    def mark(self, conn: _Connection) -> None:
        """Queue ``conn`` for the next flush (the caller marks it once per batch)."""
        if not self._dirty:
            asyncio.get_running_loop().call_soon(self.flush)
        self._dirty.append(conn)

    def flush(self) -> None:
        dirty = self._dirty
        self._dirty = []
        for conn in dirty:
            try:
                conn.flush()
            except Exception:  # one broken transport must not stall the other clients
                log.exception("link %d: write failed", conn.link_id)


class _Connection(asyncio.Protocol):
    """One TCP client of one vehicle (a link)."""

    def __init__(self, port: VehiclePort) -> None:
        self.port = port
        self.link_id: LinkId = next(_link_ids)
        self.transport: asyncio.Transport | None = None
        self._parser = self._new_parser()
        self._loop = asyncio.get_running_loop()
        self._out: DelayQueue[bytes] = DelayQueue()
        self._in: DelayQueue[Any] = DelayQueue()
        self._timer: asyncio.TimerHandle | None = None
        self._wbuf: list[bytes] = []  # packets for the next batched write
        self._open = False
        self.dropped_backpressure = 0

    @staticmethod
    def _new_parser() -> Any:
        parser = mavlink2.MAVLink(None)
        parser.robust_parsing = True
        return parser

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        port = self.port
        if port.one_client and (port.connections or port.waiting):
            # Like a connection in SITL's listen backlog: connected, never read, sent nothing.
            transport.pause_reading()
            port.waiting.append(self)
            return
        self.activate()

    def activate(self) -> None:
        """Start serving this client (at once, or when the client before it has gone)."""
        self._open = True
        self.port.connections[self.link_id] = self

    def connection_lost(self, exc: Exception | None) -> None:
        was_served = self.port.connections.pop(self.link_id, None) is not None
        if self in self.port.waiting:
            self.port.waiting.remove(self)
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._open = False
        self._wbuf.clear()
        self.transport = None
        if was_served:
            self.port.serve_next()

    def close(self) -> None:
        if self.transport is not None:
            self.flush()
            self._open = False
            self.transport.close()

    def resume(self) -> None:
        if self.transport is not None:
            self.transport.resume_reading()

    # -- inbound ---------------------------------------------------------------------------

    def data_received(self, data: bytes) -> None:
        vehicle = self.port.vehicle
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception:  # pymavlink can raise on pathological input; resync
            vehicle.note_bad_data()
            self._parser = self._new_parser()
            return
        now = self._loop.time()
        link = vehicle.link
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                vehicle.note_bad_data()
                continue
            if link.transparent:
                vehicle.handle(msg, self.link_id, now)
                continue
            for at in link.schedule(now, outbound=False):
                if at <= now:
                    vehicle.handle(msg, self.link_id, now)
                else:
                    self._in.push(at, msg)
                    self._arm_timer()

    # -- outbound --------------------------------------------------------------------------

    def send(self, data: bytes) -> None:
        if not self._open:
            return
        link = self.port.vehicle.link
        if not self._out and link.transparent:
            self._write(data)
            return
        now = self._loop.time()
        for at in link.schedule(now, outbound=True):
            if at <= now and not self._out:
                self._write(data)
            else:
                self._out.push(at, data)
                self._arm_timer()

    def _write(self, data: bytes) -> None:
        """Queue for the batched write (see :class:`WriteBatcher`)."""
        if not self._open:
            return
        buf = self._wbuf
        if not buf:
            self.port.batcher.mark(self)
        buf.append(data)

    def flush(self) -> None:
        """Write the queued packets in one call (or drop them if the client does not read)."""
        buf = self._wbuf
        if not buf:
            return
        self._wbuf = []
        t = self.transport
        if t is None or t.is_closing():
            return
        if t.get_write_buffer_size() > MAX_WRITE_BUFFER_BYTES:
            self.dropped_backpressure += len(buf)
            return
        t.write(b"".join(buf))

    # -- delayed delivery ----------------------------------------------------------------

    def _arm_timer(self) -> None:
        due = [d for d in (self._out.next_due(), self._in.next_due()) if d is not None]
        if not due or self.transport is None:
            return
        at = min(due)
        if self._timer is not None:
            if self._timer.when() <= at:
                return
            self._timer.cancel()
        self._timer = self._loop.call_at(at, self._flush)

    def _flush(self) -> None:
        self._timer = None
        if self.transport is None:
            return
        now = self._loop.time()
        for data in self._out.pop_due(now):
            self._write(data)
        for msg in self._in.pop_due(now):
            self.port.vehicle.handle(msg, self.link_id, now)
        self._arm_timer()


class VehiclePort:
    """The TCP listener of one vehicle and its connections."""

    def __init__(
        self,
        vehicle: Vehicle,
        host: str,
        port: int,
        batcher: WriteBatcher | None = None,
        *,
        one_client: bool = False,
    ) -> None:
        self.vehicle = vehicle
        self.one_client = one_client
        # Clients connected while another is served (one_client only), oldest first.
        self.waiting: list[_Connection] = []
        self.host = host
        self.requested_port = port
        self.port = port
        self.connections: dict[LinkId, _Connection] = {}
        self._server: asyncio.Server | None = None
        self.batcher = batcher or WriteBatcher()
        vehicle.set_sender(self.send)

    def send(self, link: LinkId | None, data: bytes) -> None:
        if link is None:
            # Sending only queues bytes: no connection can come or go during the loop.
            for conn in self.connections.values():
                conn.send(data)
        else:
            target = self.connections.get(link)
            if target is not None:
                target.send(data)

    def serve_next(self) -> None:
        """Serve the longest-waiting client, if any (the served one has gone)."""
        while self.waiting and not self.connections:
            conn = self.waiting.pop(0)
            if conn.transport is None or conn.transport.is_closing():
                continue
            conn.resume()
            conn.activate()

    def new_connection(self) -> asyncio.Protocol:
        """The protocol object for one new client (the listener's factory)."""
        return _Connection(self)

    async def open(self) -> None:
        loop = asyncio.get_running_loop()
        self._server = await loop.create_server(
            self.new_connection, self.host, self.requested_port, reuse_address=True
        )
        self.port = self._server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
        waiting, self.waiting = self.waiting, []
        for conn in [*self.connections.values(), *waiting]:
            conn.close()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None
        # Let connection_lost callbacks run so transports are released.
        for _ in range(3):
            if not self.connections:
                break
            await asyncio.sleep(0)

    @property
    def dropped_backpressure(self) -> int:
        return sum(c.dropped_backpressure for c in self.connections.values())


class TeamServer:
    """All vehicles of a process on one clock."""

    def __init__(
        self,
        vehicles: Sequence[Vehicle],
        clock: SimClock,
        *,
        host: str = "127.0.0.1",
        ports: Sequence[int],
        one_client_per_port: bool = False,
    ) -> None:
        if len(ports) != len(vehicles):
            raise ValueError("one port per vehicle")
        self.vehicles = list(vehicles)
        self.clock = clock
        batcher = WriteBatcher()  # one batch per event-loop pass for every client
        self.ports = [
            VehiclePort(v, host, p, batcher, one_client=one_client_per_port)
            for v, p in zip(vehicles, ports, strict=True)
        ]
        self._step_listeners: list[Any] = []
        self.lockstep: Lockstep | None = None
        """With it, the steps wait for the ground station (:mod:`sitl_stub.lockstep`)."""

    async def open(self) -> None:
        try:
            for port in self.ports:
                await port.open()
        except BaseException:
            await self.close()
            raise

    async def close(self) -> None:
        for port in self.ports:
            await port.close()

    def add_step_listener(self, callback: Any) -> None:
        """Call ``callback()`` after every simulation step (all vehicles stepped)."""
        self._step_listeners.append(callback)

    def remove_step_listener(self, callback: Any) -> None:
        if callback in self._step_listeners:
            self._step_listeners.remove(callback)

    def step_once(self) -> None:
        self.clock.advance()
        dt = self.clock.step_s
        for v in self.vehicles:
            v.step(dt)
        if self._step_listeners:
            for cb in list(self._step_listeners):
                cb()

    async def run(self) -> None:
        """Run the simulation until cancelled."""
        loop = asyncio.get_running_loop()
        clock = self.clock
        clock.start(loop.time())
        while True:
            due = clock.steps_due(loop.time())
            paced = self.lockstep
            if paced is not None:
                limit_s = paced.limit_s()
                if limit_s < math.inf:
                    due = min(due, max(int((limit_s - clock.sim_time_s) / clock.step_s), 0))
            for k in range(due):
                if paced is not None and paced.limit_s() - clock.sim_time_s < clock.step_s:
                    # Acknowledged during the batch (the first acknowledgement, or the first
                    # after a stale one, came while a batch worked out without one ran).
                    break
                self.step_once()
                if paced is not None:
                    # Each step's packets go out with the pace clock at that step: a ground
                    # station dating what it reads on the pace clock sees them no older than
                    # they are (a batch sent at its end made its first steps' look older).
                    paced.publish(clock.sim_time_s)
                    await asyncio.sleep(0)
                elif k % STEPS_PER_YIELD == STEPS_PER_YIELD - 1:
                    await asyncio.sleep(0)
            now = loop.time()
            for v in self.vehicles:
                v.tick_wall(now)
            await asyncio.sleep(max(clock.wall_until_next_step(loop.time()), 0.0005))
