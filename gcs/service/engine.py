"""The service's engine: the fleet, the store, planning (:mod:`gcs.service.planning`) and the
flights, for the life of the process.

Everything an API request does goes through :class:`Engine`: register a vehicle (or start
bundled simulator vehicles), keep a scenario and plan a schedule as a job (its
:class:`~gcs.service.planning.Planning`), create a flight on a schedule and vehicles, upload,
launch, steer it (threats, team time, abort) and read it (snapshot, events, record, report).
A flight is a :class:`~gcs.coordination.runner.FlightRunner` with its event and checkpoint
writers to the store; its vehicles are claimed from the fleet for as long as it runs. Errors
are :class:`ServiceError` subclasses that name what is wrong; the API maps them to status
codes.
"""

from __future__ import annotations

import asyncio
import json
import logging
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gcs.coordination.config import FlightConfig
from gcs.coordination.events import FlightEvent
from gcs.coordination.runner import ENDED
from gcs.errors import GcsError
from gcs.mavlink.signing import SigningConfig
from gcs.service.ended import EndedFlight, EndedFlights
from gcs.service.fleet import Fleet, FleetVehicle
from gcs.service.flight import Flight, Rehearsal
from gcs.service.planning import Limits, Planning
from gcs.service.scenariotext import (
    Conflict,
    Infeasible,
    InvalidInput,
    NotFound,
    PreconditionFailed,
    ServiceError,
    TooBusy,
    parse_scenario_text,
)
from gcs.service.stubs import StubProcess
from gcs.store.repository import Store
from planner.scenario import Threat

__all__ = [
    "Conflict",
    "Engine",
    "Flight",
    "Infeasible",
    "InvalidInput",
    "Limits",
    "NotFound",
    "PreconditionFailed",
    "Rehearsal",
    "ServiceError",
    "TooBusy",
    "parse_scenario_text",
]

log = logging.getLogger(__name__)

ENDED_STATES = tuple(s.value for s in ENDED)
"""The store's states of a flight that has ended."""


class Engine:
    """The fleet, the store, jobs and flights of one service process."""

    def __init__(
        self,
        store: Store,
        data_dir: Path,
        *,
        config: FlightConfig | None = None,
        limits: Limits | None = None,
    ):
        self.store = store
        self.data_dir = data_dir
        self.config = config or FlightConfig()
        self.limits = limits or Limits()
        self.planning = Planning(store, self.limits, self.config.method)
        """Scenarios, planning jobs and planned schedules."""
        self.ended = EndedFlights(data_dir / "flights")
        """Flights that ended before this process started (read from their folders)."""
        self.fleet = Fleet()
        self.flights: dict[str, Flight] = {}
        self.vehicle_ids: dict[str, str] = {}
        """Vehicle id (the API's) -> connection string."""
        self._named = 0
        self._tasks: set[asyncio.Task[Any]] = set()
        self._stubs: list[StubProcess] = []

    async def close(self) -> None:
        """Stop: flights on bundled simulator vehicles end (failed: their simulator stops
        with the service); flights on live vehicles stay running in the store, and the next
        service process flies them on (:meth:`resume_kept`)."""
        for flight in list(self.flights.values()):
            await flight.close()
        for task in list(self._tasks):
            task.cancel()
        await self.planning.close()
        await self.fleet.close()
        for stub in self._stubs:
            await stub.stop()

    def _spawn(self, coro: Any) -> asyncio.Task[Any]:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- vehicles -------------------------------------------------------------------------------

    async def add_vehicle(
        self, connection: str, *, system_id: int | None = None, signing_key: str | None = None
    ) -> dict[str, Any]:
        """Register a live vehicle by connection string (its link opened, HEARTBEAT heard).

        Raises
        ------
        InvalidInput
            A malformed connection string or signing key.
        ServiceError
            No vehicle answered there.
        """
        for vid, conn in self.vehicle_ids.items():
            if conn == connection:
                return self.vehicle_view(vid)
        try:
            signing = None if signing_key is None else _signing(signing_key)
            held = await self.fleet.vehicle(connection, system_id, signing=signing)
        except ValueError as err:
            raise InvalidInput(f"connection: {err}") from None
        except (GcsError, TimeoutError, OSError) as err:
            raise ServiceError(f"no vehicle answered at {connection}: {err}") from None
        return self.vehicle_view(self._name(held.connection))

    def _name(self, connection: str) -> str:
        """The API's id of the vehicle at ``connection`` (a new one the first time: ids are
        never given twice, even once a vehicle has gone)."""
        for vid, conn in self.vehicle_ids.items():
            if conn == connection:
                return vid
        self._named += 1
        vid = f"v{self._named}"
        self.vehicle_ids[vid] = connection
        return vid

    def _held(self, vehicle_id: str) -> FleetVehicle:
        conn = self.vehicle_ids.get(vehicle_id)
        held = None if conn is None else self.fleet.held(conn)
        if held is None:
            raise NotFound(f"no vehicle {vehicle_id!r}")
        return held

    def vehicle_view(self, vehicle_id: str) -> dict[str, Any]:
        """A vehicle held by the service: its link, and its mode and armed state while the
        link is up (null once it is down, its last word kept as ``last_mode`` and
        ``last_armed``)."""
        held = self._held(vehicle_id)
        st = held.vehicle.state
        c = held.link.counters
        now_s = held.link.clock()  # what it stamps receptions with
        age = st.heartbeat_age_s(now_s)
        mode, armed = st.mode_now(now_s)
        return {
            "id": vehicle_id,
            "connection": held.connection,
            "system_id": held.vehicle.system_id,
            "flight_id": held.flight_id,
            "link": {
                "heartbeat_age_s": None if age is None else round(max(age, 0.0), 3),
                "healthy": st.link_ok(now_s),
                "received": c.received,
                "sent": c.sent,
                "malformed": c.malformed + c.crc_errors,
                "rtt_s": c.rtt_s,
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

    def vehicle_views(self) -> list[dict[str, Any]]:
        return [self.vehicle_view(vid) for vid in self.vehicle_ids]

    # -- flights --------------------------------------------------------------------------------

    async def create_flight(
        self,
        schedule_id: str,
        vehicles: Mapping[str, str] | None,
        rehearsal: Rehearsal | None,
    ) -> Flight:
        """A flight of ``schedule_id`` on registered vehicles (scenario vehicle -> vehicle
        id), or, with ``rehearsal`` and no vehicles, on bundled simulator vehicles started for
        it (on the ground at each start, nose along its path).

        Raises
        ------
        NotFound
            No such schedule or vehicle.
        Conflict
            A vehicle is already in a flight (named, with that flight).
        InvalidInput
            A scenario vehicle without a vehicle, or one named that the scenario lacks.
        """
        entry = await self.planning.planned(schedule_id)
        ids = [v.id for v in entry.scenario.vehicles]
        held: list[tuple[str, int | None]] | None = None
        if vehicles is not None:
            unknown = sorted(set(vehicles) - set(ids))
            if unknown:
                raise InvalidInput(f"vehicles: {', '.join(unknown)} not in the scenario")
            missing = [i for i in ids if i not in vehicles]
            if missing:
                raise InvalidInput(f"vehicles: no vehicle for {', '.join(missing)}")
            chosen = [self._held(vehicles[i]) for i in ids]
            held = [(h.connection, h.vehicle.system_id) for h in chosen]
        fid = uuid.uuid4().hex
        flight = await Flight.create(
            fid, entry, held, rehearsal, store=self.store, fleet=self.fleet,
            folder=self.data_dir / "flights" / fid,
        )  # fmt: skip
        self._adopt(flight)
        return flight

    def _adopt(self, flight: Flight) -> None:
        for conn in flight.connections.values():
            self._name(conn)
        flight.on_over = self._over
        self.flights[flight.id] = flight

    def _over(self, flight: Flight) -> None:
        if flight.simulated:
            # Its simulator vehicles went with their simulator: no longer the service's.
            gone = set(flight.connections.values())
            self.vehicle_ids = {v: c for v, c in self.vehicle_ids.items() if c not in gone}

    # -- restart --------------------------------------------------------------------------------

    def resume_kept(self) -> list[str]:
        """Fly on every flight the store says is running (its service process died): from its
        checkpoint, on the vehicles it was flying (reached again by their connections), each
        mission compared before anything is sent. Returns their ids; each goes on in a task
        (a vehicle that cannot be reached fails the flight, with an event)."""
        resumed = []
        for fid in self.store.flights_in(("running",)):
            if fid in self.flights:
                continue
            flight = Flight.resumed(
                fid, store=self.store, fleet=self.fleet, folder=self.data_dir / "flights" / fid
            )
            if flight is None:
                continue
            self._adopt(flight)
            resumed.append(fid)
        return resumed

    def flight(self, flight_id: str) -> Flight:
        """A flight of this process (running, or ended since it started)."""
        flight = self.flights.get(flight_id)
        if flight is None:
            raise NotFound(f"no flight {flight_id!r}")
        return flight

    def known(self, flight_id: str) -> Flight | EndedFlight:
        """A flight of this process, or one that ended before it started."""
        flight = self.flights.get(flight_id)
        if flight is not None:
            return flight
        ended = self.ended.get(flight_id)
        if ended is None:
            raise NotFound(f"no flight {flight_id!r}")
        return ended

    async def record(self, flight_id: str) -> dict[str, Any]:
        """The flight record (``tcgcs-flight/1``) once the flight is over."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            try:
                doc: dict[str, Any] = json.loads(
                    await asyncio.to_thread(found.record_path.read_text)
                )
            except (OSError, ValueError):
                raise NotFound(f"flight {flight_id} left no record") from None
            return doc
        if found.record is None:
            raise NotFound(f"flight {flight_id} has no record yet (it is {found.state})")
        return found.record

    def report_dir(self, flight_id: str) -> Path:
        """The folder of the flight's report."""
        found = self.known(flight_id)
        folder = found.report_dir
        if folder is None or not folder.is_dir():
            raise NotFound(f"flight {flight_id} has no report yet")
        return folder

    # -- steering -------------------------------------------------------------------------------

    def upload(self, flight_id: str) -> dict[str, Any]:
        """Start the upload of every vehicle's mission (:meth:`Flight.upload`)."""
        return self.flight(flight_id).upload()

    def launch(
        self, flight_id: str, start_utc_s: float | None, delay_s: float | None
    ) -> dict[str, Any]:
        """Start the flight at a UTC, or ``delay_s`` mission seconds from now
        (:meth:`Flight.launch`)."""
        return self.flight(flight_id).launch(start_utc_s, delay_s)

    def add_threat(self, flight_id: str, threat: Threat, at_s: float | None) -> dict[str, Any]:
        return self.flight(flight_id).add_threat(threat, at_s)

    def remove_threat(self, flight_id: str, threat_id: str) -> None:
        self.flight(flight_id).remove_threat(threat_id)

    def team_time(self, flight_id: str) -> dict[str, Any]:
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            snap = found.snapshot
            return {"team_time_s": snap["team_time_s"], "version": snap["team_time_version"]}
        return found.team_time()

    def move_team_time(
        self, flight_id: str, arrival_s: float, version: int | None
    ) -> dict[str, Any]:
        """Move the team arrival, mission s (:meth:`Flight.move_team_time`)."""
        return self.flight(flight_id).move_team_time(arrival_s, version)

    async def abort(self, flight_id: str, vehicle: str | None, mode: str) -> dict[str, Any]:
        return await self.flight(flight_id).abort(vehicle, mode)

    # -- reading --------------------------------------------------------------------------------

    def snapshot(self, flight_id: str, *, max_age_s: float = 0.0) -> dict[str, Any]:
        """The flight's snapshot; with ``max_age_s``, one taken that recently may be given
        again (many stream clients share one per flight)."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            return found.snapshot
        return found.snapshot(max_age_s=max_age_s)

    def flight_map(self, flight_id: str) -> dict[str, Any]:
        """What the map draws (:meth:`Flight.flight_map`)."""
        found = self.known(flight_id)
        if isinstance(found, EndedFlight):
            if found.map is None:
                raise NotFound(f"flight {flight_id} left no map")
            return found.map
        return found.flight_map()

    def flight_views(self) -> list[dict[str, Any]]:
        """Every flight: this process's, then those that ended before it started."""
        out: list[dict[str, Any]] = [
            {"id": fid, "state": f.state.value, "schedule_id": f.schedule.id}
            for fid, f in self.flights.items()
        ]
        for fid in self.store.flights_in(ENDED_STATES):
            ended = None if fid in self.flights else self.ended.get(fid)
            if ended is not None:
                schedule_id = ended.snapshot.get("schedule_id")
                out.append({"id": fid, "state": ended.state, "schedule_id": schedule_id})
        return out

    def events(self, flight_id: str, after_seq: int, limit: int) -> list[FlightEvent]:
        self.known(flight_id)
        return self.store.events(flight_id, after_seq=after_seq, limit=limit)


def _signing(key_hex: str) -> SigningConfig:
    """A 32-byte signing key given as 64 hex digits."""
    try:
        return SigningConfig.from_hex(key_hex)
    except ValueError as err:
        raise InvalidInput(f"signing_key: {err}") from None
