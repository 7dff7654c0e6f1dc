"""The fleet: every vehicle link the process holds, and which flight each vehicle is in.

Links are opened once, by connection string, and kept for the life of the fleet: a flight
borrows its vehicles (:meth:`Fleet.claim`) and gives them back when it ends
(:meth:`Fleet.release`), so several flights run at once on distinct vehicles, and a vehicle
is in at most one flight at a time. Live vehicles are reached by connection string; bundled
simulator vehicles are started on request (:meth:`Fleet.start_stubs`).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from gcs.errors import GcsError
from gcs.mavlink.link import Link
from gcs.mavlink.signing import SigningConfig
from gcs.mavlink.vehicle import Vehicle
from gcs.service.stubs import StubProcess

__all__ = ["Fleet", "FleetVehicle", "VehicleBusy", "unreached_view"]


class VehicleBusy(GcsError):
    """A vehicle asked for by a flight is already in another one (both named)."""

    def __init__(self, connection: str, flight_id: str) -> None:
        super().__init__(f"vehicle {connection} is already in flight {flight_id}")
        self.connection = connection
        self.flight_id = flight_id


@dataclass
class FleetVehicle:
    """One vehicle the fleet holds: its connection string, link and the flight it is in."""

    connection: str
    link: Link
    vehicle: Vehicle
    flight_id: str | None = None
    lent: bool = False
    """Lent to a flight flown by another process (:meth:`Fleet.lend`): its link is closed."""

    def view(self) -> dict[str, Any]:
        """The vehicle as ``/v1/vehicles`` shows it (without the API's id): its link, and its
        mode and armed state while the link is up (null once it is down, its last word kept
        as ``last_mode`` and ``last_armed``)."""
        st = self.vehicle.state
        c = self.link.counters
        now_s = self.link.clock()  # what it stamps receptions with
        age = st.heartbeat_age_s(now_s)
        mode, armed = st.mode_now(now_s)
        return {
            "connection": self.connection,
            "system_id": self.vehicle.system_id,
            "flight_id": self.flight_id,
            "link": {
                # Up to the next millisecond: an age past the link's timeout never reads
                # as within it beside "healthy": false.
                "heartbeat_age_s": None if age is None else math.ceil(max(age, 0.0) * 1e3) / 1e3,
                "healthy": st.link_ok(now_s),
                "received": c.received,
                "sent": c.sent,
                "malformed": c.malformed + c.crc_errors,
                "rtt_s": c.rtt_s,
                "open": True,
            },
            "counters": {
                "received": c.received,
                "sent": c.sent,
                "malformed": c.malformed,
                "crc_errors": c.crc_errors,
                "seq_lost": c.seq_lost,
            },
            "mode": mode,
            "armed": armed,
            "last_mode": st.mode,
            "last_armed": st.armed,
            "lat_deg": st.lat_deg,
            "lon_deg": st.lon_deg,
            "alt_amsl_m": st.alt_amsl_m,
            "battery_pct": st.battery_remaining_pct,
        }


_LAST_WORD = ("last_mode", "last_armed", "lat_deg", "lon_deg", "alt_amsl_m", "battery_pct")
"""The fields of a vehicle's view that hold what it last said (kept while its link is down)."""


def unreached_view(
    connection: str, system_id: int | None, last: dict[str, Any] | None = None
) -> dict[str, Any]:
    """A vehicle whose link is not open, as ``/v1/vehicles`` shows it (the fields of
    :meth:`FleetVehicle.view`): the link dead, nothing known now, and its last word as
    ``last`` (an earlier view of it) holds it, else null."""
    last = last or {}
    return {
        "connection": connection,
        "system_id": last.get("system_id", system_id),
        "flight_id": None,
        "link": {
            "heartbeat_age_s": None,
            "healthy": False,
            "received": 0,
            "sent": 0,
            "malformed": 0,
            "rtt_s": None,
            "open": False,
        },
        "mode": None,
        "armed": None,
        **{name: last.get(name) for name in _LAST_WORD},
    }


class Fleet:
    """Vehicle links for the life of the process; each vehicle in at most one flight."""

    def __init__(self, *, wait_s: float = 15.0) -> None:
        self.wait_s = wait_s
        self._vehicles: dict[str, FleetVehicle] = {}
        self.signing: dict[str, SigningConfig] = {}
        """Per connection, the signing of its link when none is given (a worker's vehicles)."""
        self._stack = contextlib.AsyncExitStack()
        self._opening: dict[str, asyncio.Lock] = {}
        """Per connection: one link opened at a time (a vehicle that does not answer holds
        up no other)."""

    async def vehicle(
        self,
        connection: str,
        system_id: int | None = None,
        *,
        signing: SigningConfig | None = None,
    ) -> FleetVehicle:
        """The vehicle at ``connection``, its link opened (signed with ``signing``) and its
        HEARTBEAT heard the first time it is asked for.

        Raises
        ------
        ValueError
            A malformed connection string.
        """
        async with self._opening.setdefault(connection, asyncio.Lock()):
            held = self._vehicles.get(connection)
            if held is not None:
                return held
            signing = signing or self.signing.get(connection)
            link = Link.open(connection, signing=signing)
            await link.start()
            try:
                peer = await link.wait_vehicle(system_id, timeout_s=self.wait_s)
            except BaseException:
                await link.close()
                raise
            self._stack.push_async_callback(link.close)
            if signing is not None:
                self.signing[connection] = signing
            held = FleetVehicle(connection, link, Vehicle(link, peer.system_id, peer.component_id))
            self._vehicles[connection] = held
            return held

    async def claim(
        self,
        connections: Sequence[str],
        flight_id: str,
        system_ids: Sequence[int | None] | None = None,
    ) -> list[FleetVehicle]:
        """Put the vehicles at ``connections`` in flight ``flight_id``; all or none.

        Raises
        ------
        VehicleBusy
            One of them is in another flight (the first such is named, with its flight);
            nothing is claimed.
        """
        ids = list(system_ids) if system_ids is not None else [None] * len(connections)
        for conn in connections:
            held = self._vehicles.get(conn)
            if held is not None and held.flight_id not in (None, flight_id):
                raise VehicleBusy(conn, held.flight_id)
        vehicles = [await self.vehicle(c, s) for c, s in zip(connections, ids, strict=True)]
        for held in vehicles:  # checked again: another flight may have claimed meanwhile
            if held.flight_id not in (None, flight_id):
                raise VehicleBusy(held.connection, held.flight_id)
        for held in vehicles:
            held.flight_id = flight_id
        return vehicles

    async def start_stubs(
        self, count: int, args: Sequence[str], *, control: bool = False
    ) -> StubProcess:
        """Bundled simulator vehicles (``python -m sitl_stub ARGS``), stopped when the fleet
        closes; claim them by :attr:`StubProcess.connections` like any others."""
        stub = await StubProcess.start(count, args, control=control)
        self._stack.push_async_callback(stub.stop)
        return stub

    async def lend(self, connections: Sequence[str], flight_id: str) -> None:
        """Lend the vehicles at ``connections`` to flight ``flight_id`` flown by another
        process (a flight worker): their links are closed here, so that it can open its own,
        and they stay known, in that flight, until :meth:`take_back`.

        Raises
        ------
        VehicleBusy
            One of them is in another flight; nothing is lent.
        """
        held = [self._vehicles[c] for c in connections]
        for h in held:
            if h.flight_id not in (None, flight_id):
                raise VehicleBusy(h.connection, h.flight_id)
        for h in held:
            h.flight_id = flight_id
            h.lent = True
            await h.link.close()

    async def take_back(self, connections: Sequence[str]) -> list[str]:
        """Open the links of lent vehicles again (their flight has ended); returns the
        connections no vehicle answered at (forgotten)."""
        gone = []
        for conn in connections:
            lent = self._vehicles.pop(conn, None)
            if lent is None:
                continue
            try:
                await self.vehicle(conn, lent.vehicle.system_id)
            except (GcsError, TimeoutError, OSError, ValueError):
                gone.append(conn)
        return gone

    def release(self, flight_id: str) -> None:
        """The flight's vehicles are free again (their links stay open)."""
        for held in self._vehicles.values():
            if held.flight_id == flight_id:
                held.flight_id = None

    async def drop(self, connections: Sequence[str]) -> None:
        """Close the links to these vehicles and forget them (a flight's bundled simulator
        vehicles, once it has ended: their simulator is stopped)."""
        for conn in connections:
            held = self._vehicles.pop(conn, None)
            if held is not None:
                await held.link.close()

    def held(self, connection: str) -> FleetVehicle | None:
        """The vehicle at ``connection`` if its link is open."""
        return self._vehicles.get(connection)

    def flight_of(self, connection: str) -> str | None:
        held = self._vehicles.get(connection)
        return None if held is None else held.flight_id

    async def close(self) -> None:
        """Close every link."""
        self._vehicles.clear()
        await self._stack.aclose()

    async def __aenter__(self) -> Fleet:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
