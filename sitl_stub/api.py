"""Python API for tests and rehearsals: a team of stub vehicles on one simulated clock.

Example::

    async with SimTeam.start(homes=[Home(-35.36, 149.16, 584.0)], tcp_base=0, speedup=50) as team:
        port = team.ports[0]                       # tcp_base=0: free ports chosen by the OS
        team.vehicles[0].link.faults(loss=0.3)     # runtime link faults
        t = await team.watch_crossing(0, lat, lon, radius_m=50.0)   # exact simulated time
        print(team.vehicles[0].true_state, team.sim_time_s, team.utc_s)

``SimTeam.start(..., truth_out="truth.jsonl")`` records every vehicle's true state as JSON
lines (:mod:`sitl_stub.truth`); ``counters_out="counters.json"`` keeps a file of what the
vehicles were made to do (arms, AUTO entries, mission transfers: :mod:`sitl_stub.counters`);
``team.schedule_blackout(i, start_sim_s, duration_s)`` cuts a vehicle's link at a simulated
time. ``SimTeam.start(..., terrain=GridTerrain(elevation))`` flies the vehicles over terrain
(:mod:`sitl_stub.terrain`) instead of flat ground at each home's altitude; one flown into it
crashes (``team.vehicles[i].autopilot.crash_time_s``).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Collection, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sitl_stub.autopilot import Autopilot, Ground
from sitl_stub.clock import DEFAULT_EPOCH_UTC_S, ClockStats, SimClock
from sitl_stub.counters import DEFAULT_COUNTERS_PERIOD_S, CountersWriter
from sitl_stub.link import FaultyLink
from sitl_stub.model import AirframeParams, FlightState, Wind
from sitl_stub.server import TeamServer
from sitl_stub.truth import DEFAULT_TRUTH_PERIOD_S, TruthRecorder
from sitl_stub.vehicle import Vehicle
from sitl_stub.wind_estimate import WindEstimateError

DEFAULT_TCP_BASE = 5760
PORT_STRIDE = 10

HomeTuple = (
    tuple[float, float, float]
    | tuple[float, float, float, float]
    | tuple[float, float, float, float, float | None]
)
"""``Home``'s fields in order: (lat, lon, alt[, heading[, airborne_alt]])."""


AIRBORNE_MIN_HEIGHT_M = 10.0
"""An airborne start is at least this far above its home (the ground there)."""


@dataclass(frozen=True, slots=True)
class Home:
    """Where a vehicle starts: on the ground at home, nose to ``heading_deg``.

    With ``airborne_alt_m`` (m AMSL, at least :data:`AIRBORNE_MIN_HEIGHT_M` above ``alt_m``)
    it starts flying instead: armed, over home at that altitude on ``heading_deg`` at its
    cruise airspeed, in LOITER circling home's position. Home itself stays on the ground
    (``alt_m``: RTL and relative altitudes are from there).
    """

    lat_deg: float
    lon_deg: float
    alt_m: float
    heading_deg: float = 0.0
    airborne_alt_m: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat_deg) and -90.0 <= self.lat_deg <= 90.0):
            raise ValueError(f"home latitude {self.lat_deg!r} is outside [-90, 90]")
        if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"home longitude {self.lon_deg!r} is outside [-180, 180]")
        if not math.isfinite(self.alt_m):
            raise ValueError(f"home altitude {self.alt_m!r} is not a number")
        air = self.airborne_alt_m
        if air is not None and not (
            math.isfinite(air) and air >= self.alt_m + AIRBORNE_MIN_HEIGHT_M
        ):
            raise ValueError(
                f"airborne altitude {air!r} must be a number at least "
                f"{AIRBORNE_MIN_HEIGHT_M:g} m above the home altitude {self.alt_m:g} m"
            )


def _check_indices(name: str, indices: Mapping[int, object] | Sequence[int], n: int) -> None:
    """Per-vehicle options name vehicles by 0-based index."""
    for i in indices:
        if not 0 <= i < n:
            raise ValueError(f"{name}: no vehicle {i} (0-based; the team has {n})")


class SimTeam:
    """Running vehicles, their TCP ports and the shared simulated clock."""

    def __init__(self, server: TeamServer) -> None:
        self.server = server
        self.clock = server.clock
        self.vehicles: list[Vehicle] = server.vehicles
        self.truth: TruthRecorder | None = None  # set by start(truth_out=...)
        self.counters_file: CountersWriter | None = None  # set by start(counters_out=...)

    @classmethod
    @contextlib.asynccontextmanager
    async def start(
        cls,
        *,
        homes: Sequence[Home | HomeTuple],
        tcp_base: int = DEFAULT_TCP_BASE,
        speedup: float = 1.0,
        wind: Wind | None = None,
        seed: int = 0,
        step_s: float = 0.1,
        params: AirframeParams | Sequence[AirframeParams] | None = None,
        host: str = "127.0.0.1",
        start_utc_s: float = DEFAULT_EPOCH_UTC_S,
        mission_timeout_s: float = 1.5,
        legacy_mission_requests: bool = False,
        ardupilot_mission_storage: bool = True,
        speed_bias: Mapping[int, float] | None = None,
        utc_offset_s: Mapping[int, float] | None = None,
        no_utc: Collection[int] = (),
        wind_estimate_error: bool = True,
        one_client_per_port: bool = False,
        run: bool = True,
        truth_out: str | Path | None = None,
        truth_period_s: float = DEFAULT_TRUTH_PERIOD_S,
        counters_out: str | Path | None = None,
        counters_period_s: float = DEFAULT_COUNTERS_PERIOD_S,
        terrain: Ground | None = None,
    ) -> AsyncIterator[SimTeam]:
        """Start the team; vehicle ``i`` has system id ``i + 1`` on ``tcp_base + 10*i``.

        ``tcp_base=0`` lets the OS pick free ports (see :attr:`ports`). With ``run=False``
        the clock does not run by itself; call :meth:`step` to advance it. With
        ``legacy_mission_requests=True`` the vehicles request upload items with legacy
        MISSION_REQUEST instead of MISSION_REQUEST_INT (as older ArduPilot does). With
        ``truth_out`` the true state of every vehicle is written to that file every
        ``truth_period_s`` simulated seconds (:class:`~sitl_stub.truth.TruthRecorder`,
        available as :attr:`truth`; flushed and closed when the team stops). With
        ``counters_out`` the vehicles' counters are kept in that file, rewritten whole every
        ``counters_period_s`` wall seconds and when the team stops
        (:class:`~sitl_stub.counters.CountersWriter`, available as :attr:`counters_file`).
        With ``terrain`` every vehicle flies over it (the ground under it each physics step;
        its TERRAIN_REPORT streams at 1 Hz); without, the ground is flat at its home altitude.
        """
        team = cls.create(
            homes=homes,
            speedup=speedup,
            wind=wind,
            seed=seed,
            step_s=step_s,
            params=params,
            host=host,
            start_utc_s=start_utc_s,
            mission_timeout_s=mission_timeout_s,
            legacy_mission_requests=legacy_mission_requests,
            ardupilot_mission_storage=ardupilot_mission_storage,
            speed_bias=speed_bias,
            utc_offset_s=utc_offset_s,
            no_utc=no_utc,
            wind_estimate_error=wind_estimate_error,
            one_client_per_port=one_client_per_port,
            tcp_base=tcp_base,
            terrain=terrain,
        )
        if truth_out is not None:
            team.truth = TruthRecorder.open(
                truth_out, team.vehicles, team.clock, period_s=truth_period_s
            )
            team.truth.start()
            team.server.add_step_listener(team.truth.on_step)
        try:
            if counters_out is not None:
                writer = CountersWriter(
                    counters_out, team.vehicles, team.clock, period_s=counters_period_s
                )
                writer.start()
                team.counters_file = writer
                team.server.add_step_listener(writer.on_step)
            await team.server.open()
        except BaseException:
            try:
                team._close_truth()
            finally:
                team._close_counters()
            raise
        try:
            async with asyncio.TaskGroup() as tg:
                runner = tg.create_task(team.server.run()) if run else None
                try:
                    yield team
                finally:
                    if runner is not None:
                        runner.cancel()
        finally:
            team._cancel_waiters()
            try:
                team._close_truth()
                await team.server.close()
            finally:
                team._close_counters()  # after the last message was handled

    @classmethod
    def create(
        cls,
        *,
        homes: Sequence[Home | HomeTuple],
        speedup: float = 1.0,
        wind: Wind | None = None,
        seed: int = 0,
        step_s: float = 0.1,
        params: AirframeParams | Sequence[AirframeParams] | None = None,
        host: str = "127.0.0.1",
        start_utc_s: float = DEFAULT_EPOCH_UTC_S,
        mission_timeout_s: float = 1.5,
        legacy_mission_requests: bool = False,
        ardupilot_mission_storage: bool = True,
        speed_bias: Mapping[int, float] | None = None,
        utc_offset_s: Mapping[int, float] | None = None,
        no_utc: Collection[int] = (),
        wind_estimate_error: bool = True,
        one_client_per_port: bool = False,
        tcp_base: int = DEFAULT_TCP_BASE,
        terrain: Ground | None = None,
    ) -> SimTeam:
        """Build the team without opening sockets (``start`` is the usual entry)."""
        if not homes:
            raise ValueError("at least one home is needed")
        if not 0 <= tcp_base <= 65535 - PORT_STRIDE * (len(homes) - 1):
            raise ValueError(f"tcp_base {tcp_base} leaves no room for {len(homes)} vehicles")
        _check_indices("speed_bias", speed_bias or {}, len(homes))
        for i, bias in (speed_bias or {}).items():
            if not (math.isfinite(bias) and -0.5 < bias < 0.5):
                raise ValueError(f"speed_bias of vehicle {i} must be in (-0.5, 0.5), got {bias!r}")
        utc_offsets = dict(utc_offset_s or {})
        _check_indices("utc_offset_s", utc_offsets, len(homes))
        _check_indices("no_utc", list(no_utc), len(homes))
        for i, offset in utc_offsets.items():
            if not math.isfinite(offset):
                raise ValueError(f"utc_offset_s of vehicle {i} must be a number, got {offset!r}")
        clock = SimClock(speedup=speedup, step_s=step_s, start_utc_s=start_utc_s)
        # Children 0..2n-1 seed the flight and the link as before; 2n+i the wind estimate.
        seeds = np.random.SeedSequence(seed).spawn(3 * len(homes))
        vehicles: list[Vehicle] = []
        for i, raw in enumerate(homes):
            home = raw if isinstance(raw, Home) else Home(*raw)
            p = params[i] if isinstance(params, Sequence) else (params or AirframeParams())
            if speed_bias and i in speed_bias:
                p = replace(p, speed_bias=float(speed_bias[i]))
            autopilot = Autopilot(
                params=p,
                home_lat_deg=home.lat_deg,
                home_lon_deg=home.lon_deg,
                home_alt_m=home.alt_m,
                heading_deg=home.heading_deg,
                airborne_alt_m=home.airborne_alt_m,
                wind=wind or Wind(),
                rng=np.random.default_rng(seeds[2 * i]),
                time_s=0.0,
                terrain=terrain,
            )
            link = FaultyLink(np.random.default_rng(seeds[2 * i + 1]), lambda: clock.sim_time_s)
            vehicles.append(
                Vehicle(
                    system_id=i + 1,
                    autopilot=autopilot,
                    clock=clock,
                    link=link,
                    mission_timeout_s=mission_timeout_s,
                    legacy_mission_requests=legacy_mission_requests,
                    ardupilot_mission_storage=ardupilot_mission_storage,
                    utc_offset_s=None if i in no_utc else float(utc_offsets.get(i, 0.0)),
                    wind_error=WindEstimateError.draw(
                        np.random.default_rng(seeds[2 * len(homes) + i])
                    )
                    if wind_estimate_error
                    else None,
                )
            )
        ports = [0 if tcp_base == 0 else tcp_base + PORT_STRIDE * i for i in range(len(homes))]
        return cls(
            TeamServer(
                vehicles, clock, host=host, ports=ports, one_client_per_port=one_client_per_port
            )
        )

    # -- queries -------------------------------------------------------------------------

    @property
    def ports(self) -> list[int]:
        """The TCP port of each vehicle (actual ports when ``tcp_base=0``)."""
        return [p.port for p in self.server.ports]

    @property
    def sim_time_s(self) -> float:
        return self.clock.sim_time_s

    @property
    def utc_s(self) -> float:
        """True simulated UTC, seconds since the Unix epoch (SYSTEM_TIME of a vehicle without
        a UTC offset; ``vehicles[i].utc_s`` is what vehicle ``i`` reports)."""
        return self.clock.utc_s

    def true_state(self, i: int) -> FlightState:
        return self.vehicles[i].true_state

    def stats(self) -> ClockStats:
        return self.clock.stats(asyncio.get_running_loop().time())

    def set_wind(self, wind: Wind) -> None:
        for v in self.vehicles:
            v.autopilot.set_wind(wind)

    # -- waiting on the simulation -------------------------------------------------------

    def watch_crossing(
        self, i: int, lat_deg: float, lon_deg: float, radius_m: float = 0.0
    ) -> asyncio.Future[float]:
        """A future for the exact simulated time vehicle ``i`` first comes within radius.

        The time is interpolated within the physics step from the true state, not from
        telemetry. Every crossing is also recorded in ``vehicles[i].crossings``.
        """
        fut: asyncio.Future[float] = asyncio.get_running_loop().create_future()

        def done(t: float) -> None:
            if not fut.done():
                fut.set_result(t)

        watch = self.vehicles[i].watch_crossing(lat_deg, lon_deg, radius_m, done)
        fut.add_done_callback(lambda _f: self.vehicles[i].unwatch(watch))
        return fut

    async def wait_sim_time(self, sim_time_s: float) -> None:
        """Return once the simulated clock has reached ``sim_time_s``."""
        if self.clock.sim_time_s >= sim_time_s:
            return
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        def check() -> None:
            if self.clock.sim_time_s >= sim_time_s and not fut.done():
                fut.set_result(None)

        self.server.add_step_listener(check)
        try:
            await fut
        finally:
            self.server.remove_step_listener(check)

    def schedule_blackout(self, i: int, start_sim_s: float, duration_s: float) -> None:
        """Cut vehicle ``i``'s link (both ways) from ``start_sim_s`` for ``duration_s``.

        Times are simulated seconds since the clock started. The blackout begins at the first
        physics step at or after ``start_sim_s`` (at once if that time has passed) and ends at
        ``start_sim_s + duration_s``; a blackout already running that ends later is kept.
        """
        if not 0 <= i < len(self.vehicles):
            raise ValueError(f"no vehicle {i}: the team has {len(self.vehicles)} (0-based)")
        if not (math.isfinite(start_sim_s) and start_sim_s >= 0):
            raise ValueError(f"blackout start must be >= 0 simulated s, got {start_sim_s!r}")
        if not (math.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"blackout duration must be > 0 simulated s, got {duration_s!r}")
        link = self.vehicles[i].link
        end_sim_s = start_sim_s + duration_s

        def begin() -> bool:
            now = self.clock.sim_time_s
            if now + 1e-9 < start_sim_s:
                return False
            if end_sim_s > max(now, link.blackout_until_sim_s):
                link.blackout(end_sim_s - now)
            return True

        def listener() -> None:
            if begin():
                self.server.remove_step_listener(listener)

        if not begin():
            self.server.add_step_listener(listener)

    def step(self, n: int = 1) -> None:
        """Advance the simulation by ``n`` physics steps now (for ``run=False`` teams)."""
        for _ in range(n):
            self.server.step_once()

    def _cancel_waiters(self) -> None:
        for v in self.vehicles:
            v.clear_watches()

    def _close_truth(self) -> None:
        if self.truth is not None:
            self.server.remove_step_listener(self.truth.on_step)
            self.truth.close()

    def _close_counters(self) -> None:
        if self.counters_file is not None:
            self.server.remove_step_listener(self.counters_file.on_step)
            self.counters_file.close()
