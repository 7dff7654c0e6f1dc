"""CLI: ``python -m sitl_stub --vehicles N --tcp-base PORT --speedup S --home ...``.

``--home LAT,LON,ALT[,HDG[,AIR_ALT]]`` is where a vehicle starts: on the ground at ALT (m AMSL),
nose to HDG (degrees, default 0). With AIR_ALT (m AMSL, at least 10 m above ALT) it starts
flying instead: armed, at AIR_ALT over LAT,LON on HDG at its cruise airspeed, in LOITER
circling that point until a ground station takes it over; home stays LAT,LON,ALT on the
ground. With ``--scenario`` and no ``--home``, a scenario vehicle with ``airborne: true``
starts so at its start's ``alt_m``.

Runs until SIGINT/SIGTERM, then closes every socket (and the truth file), writes the final
counters file and exits 0.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import logging
import math
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from sitl_stub.api import DEFAULT_TCP_BASE, Home, SimTeam
from sitl_stub.lockstep import DEFAULT_LEAD_S, Lockstep
from sitl_stub.model import AirframeParams
from sitl_stub.terrain import GridTerrain, Hill
from sitl_stub.truth import DEFAULT_TRUTH_PERIOD_S

if TYPE_CHECKING:
    from planner.scenario import Scenario

log = logging.getLogger("sitl_stub")


class UsageError(ValueError):
    """A command-line value that cannot be used."""


@dataclass(frozen=True, slots=True)
class BlackoutSpec:
    """``--blackout I,START_S,DURATION_S`` (vehicle index, simulated seconds)."""

    vehicle_index: int
    start_sim_s: float
    duration_s: float


def _floats(text: str, name: str, n_min: int, n_max: int) -> list[float]:
    parts = text.split(",")
    if not n_min <= len(parts) <= n_max:
        count = str(n_min) if n_min == n_max else f"{n_min} to {n_max}"
        raise UsageError(f"{name} needs {count} comma-separated numbers, got {text!r}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise UsageError(f"{name}: {text!r} is not a list of numbers") from None
    if not all(math.isfinite(v) for v in values):
        raise UsageError(f"{name}: {text!r} has a non-finite number")
    return values


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m sitl_stub",
        description="Simulated ArduPlane vehicles over MAVLink 2 on TCP (SITL port layout).",
    )
    ap.add_argument("--vehicles", type=int, default=1, help="number of vehicles (default 1)")
    ap.add_argument("--tcp-base", type=int, default=DEFAULT_TCP_BASE, help="port of vehicle 0")
    ap.add_argument("--speedup", type=float, default=1.0, help="simulated/wall time ratio")
    ap.add_argument(
        "--home",
        action="append",
        metavar="LAT,LON,ALT_M[,HDG_DEG[,AIR_ALT_M]]",
        help="start on the ground (ALT_M AMSL), or with AIR_ALT_M (AMSL, >= ALT_M + 10) in "
        "the air: armed, at AIR_ALT_M over LAT,LON in LOITER circling it (home stays on the "
        "ground at ALT_M); once: shared by all vehicles (spaced 30 m across the heading); "
        "repeated once per vehicle: vehicle i at the i-th --home",
    )
    ap.add_argument(
        "--scenario",
        metavar="FILE",
        help="scenario file: the vehicles fly over its terrain (the ground under each one, "
        "every physics step; flown into it, one crashes) and, without --home, start at its "
        "vehicles' starts: on the ground, or an 'airborne: true' vehicle in the air at its "
        "start's alt_m",
    )
    ap.add_argument(
        "--hill",
        action="append",
        metavar="LAT,LON,RADIUS_M,HEIGHT_M",
        help="with --scenario: a hill the scenario's terrain does not have, HEIGHT_M above it "
        "at LAT,LON, a cosine bump of RADIUS_M (a terrain database error to rehearse against; "
        "repeatable)",
    )
    ap.add_argument(
        "--airspeed",
        action="append",
        metavar="MIN,CRUISE,MAX",
        help="airspeeds, m/s (0 < MIN <= CRUISE <= MAX; default: the scenario's with "
        "--scenario, else 15,22,30); once: every vehicle; repeated once per vehicle: vehicle i "
        "gets the i-th",
    )
    ap.add_argument(
        "--takeoff-climb",
        action="append",
        metavar="M_S",
        help="full-throttle climb rate of a takeoff's climb-out, m/s (default: the scenario's "
        "takeoff_climb_m_s with --scenario, else 9); once: every vehicle; repeated once per "
        "vehicle: vehicle i gets the i-th",
    )
    ap.add_argument(
        "--blackout",
        action="append",
        metavar="I,START_S,DURATION_S",
        help="vehicle I's (0-based) link dark, both ways, from START_S simulated seconds after "
        "the clock starts, for DURATION_S simulated seconds (repeatable)",
    )
    ap.add_argument(
        "--truth",
        metavar="FILE",
        help="write every vehicle's true state as JSON lines (format tcgcs-truth/1)",
    )
    ap.add_argument(
        "--counters",
        metavar="FILE",
        help="keep every vehicle's counters in FILE as one JSON document (format "
        "tcgcs-stub-counters/1: arms, auto_mode_changes, mission_uploads, mission_downloads, "
        "failed_uploads, message and link counters), replaced whole about once a wall second "
        "and at exit",
    )
    ap.add_argument(
        "--mission-timeout",
        type=float,
        default=1.5,
        metavar="S",
        help="wall seconds before a lost mission item is re-requested (default 1.5)",
    )
    ap.add_argument(
        "--idle-exit",
        type=float,
        default=None,
        metavar="S",
        help="exit once no vehicle has had a client for S wall seconds (after the first "
        "client): a simulator whose ground station is gone does not run on forever, while "
        "one that restarts within S reaches its vehicles again",
    )
    ap.add_argument(
        "--control-stdin",
        action="store_true",
        help="read control lines from stdin: 'blackout INDEX START_SIM_S DURATION_S'",
    )
    ap.add_argument(
        "--truth-period",
        type=float,
        default=DEFAULT_TRUTH_PERIOD_S,
        metavar="S",
        help=f"truth sample period, simulated s (default {DEFAULT_TRUTH_PERIOD_S:g})",
    )
    ap.add_argument(
        "--start-utc",
        type=float,
        metavar="UTC_S",
        help="simulated UTC (Unix seconds) when the clock starts (default: wall time now)",
    )
    ap.add_argument("--wind", help="SPEED_M_S,FROM_DEG mean wind")
    ap.add_argument("--gust", type=float, default=0.0, help="gust standard deviation, m/s")
    ap.add_argument("--loss", type=float, default=0.0, help="packet loss probability")
    ap.add_argument("--latency-ms", type=float, default=0.0, help="one-way latency, ms")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--legacy-mission-requests",
        action="store_true",
        help="request upload items with MISSION_REQUEST (older ArduPilot), not _INT",
    )
    ap.add_argument(
        "--speed-bias",
        action="append",
        metavar="I,FRACTION",
        help="vehicle I (0-based) flies (1 + FRACTION) x the true airspeed it should, an "
        "airspeed sensor error (e.g. 1,0.05; repeatable)",
    )
    ap.add_argument(
        "--utc-offset",
        action="append",
        metavar="I,SECONDS",
        help="vehicle I's (0-based) SYSTEM_TIME is the true simulated UTC + SECONDS "
        "(repeatable; time_boot and the truth log's utc_s are unchanged)",
    )
    ap.add_argument(
        "--no-utc",
        action="append",
        type=int,
        metavar="I",
        help="vehicle I (0-based) reports no UTC: SYSTEM_TIME.time_unix_usec = 0 (repeatable)",
    )
    ap.add_argument(
        "--true-wind-estimate",
        action="store_true",
        help="WIND reports the true wind (default: with a seeded 0.8-1.6 m/s estimation error "
        "per vehicle, as ArduPlane's estimate has)",
    )
    ap.add_argument(
        "--one-client-per-port",
        action="store_true",
        help="serve one TCP client per vehicle at a time, as ArduPilot SITL (others wait, "
        "connected but unserved, until it disconnects); default: any number of clients",
    )
    ap.add_argument(
        "--exact-missions",
        action="store_true",
        help="read uploaded mission items back exactly as sent (default: in ArduPilot's "
        "stored form: frames 0/3/10, whole-centimetre altitudes, per-command parameters)",
    )
    ap.add_argument(
        "--lockstep",
        metavar="FILE",
        help="keep a clock file (created) that one ground station reads and acknowledges: the "
        "simulation steps no further than --lockstep-lead beyond what it has acknowledged, so "
        "a busy machine slows the flight instead of delaying the ground station's answers "
        "(see sitl_stub.lockstep)",
    )
    ap.add_argument(
        "--lockstep-lead",
        type=float,
        default=DEFAULT_LEAD_S,
        metavar="S",
        help=f"flight seconds the simulation may run ahead of the ground station "
        f"(default {DEFAULT_LEAD_S:g})",
    )
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("-v", "--verbose", action="store_true")
    return ap.parse_args(_join_negative_values(list(sys.argv[1:] if argv is None else argv)))


_VALUE_OPTIONS = (
    "--home",
    "--hill",
    "--wind",
    "--airspeed",
    "--takeoff-climb",
    "--blackout",
    "--speed-bias",
    "--utc-offset",
)


def _join_negative_values(argv: list[str]) -> list[str]:
    # "--home -35.36,149.16,584" would read the value as an option (southern latitudes).
    out: list[str] = []
    it = iter(argv)
    for arg in it:
        if arg in _VALUE_OPTIONS:
            value = next(it, None)
            out.append(arg if value is None else f"{arg}={value}")
        else:
            out.append(arg)
    return out


def homes_from_args(args: argparse.Namespace) -> list[Home]:
    if args.vehicles < 1:
        raise UsageError(f"--vehicles must be at least 1, got {args.vehicles}")
    if not args.home:
        if not args.scenario:
            raise UsageError("give --home (once, or once per vehicle) or --scenario")
        return homes_from_scenario(args.scenario, args.vehicles)
    texts: list[str] = args.home
    _check_count(texts, "--home", args.vehicles)
    if len(texts) == args.vehicles:
        return [_home(text) for text in texts]
    first = _home(texts[0])
    lat, lon, alt, hdg = first.lat_deg, first.lon_deg, first.alt_m, first.heading_deg
    air = first.airborne_alt_m
    # Vehicles share the home point but are spaced 30 m apart across the heading, as
    # aircraft lined up on an apron, so their true positions never coincide.
    from sitl_stub.model import displace_deg

    homes: list[Home] = []
    for i in range(args.vehicles):
        off = 30.0 * i
        right = math.radians(hdg + 90.0)
        la, lo = displace_deg(lat, lon, alt, off * math.cos(right), off * math.sin(right))
        homes.append(Home(la, lo, alt, hdg, air))
    return homes


def _home(text: str) -> Home:
    """LAT,LON,ALT[,HDG[,AIR_ALT]]: on the ground, or with AIR_ALT flying (see Home)."""
    lat, lon, alt, *rest = _floats(text, "--home", 3, 5)
    hdg = rest[0] if rest else 0.0
    air = rest[1] if len(rest) > 1 else None
    try:
        return Home(lat, lon, alt, hdg, air)
    except ValueError as err:
        raise UsageError(f"--home {text!r}: {err}") from None


def _check_count(texts: Sequence[str], name: str, n_vehicles: int) -> None:
    """A per-vehicle option is given once (all vehicles) or once per vehicle."""
    if len(texts) not in (1, n_vehicles):
        raise UsageError(
            f"{name} given {len(texts)} times for --vehicles {n_vehicles}: give it once "
            f"(every vehicle) or {n_vehicles} times (one per vehicle)"
        )


def params_from_args(args: argparse.Namespace) -> list[AirframeParams] | None:
    """Per-vehicle airframe parameters from ``--airspeed`` and ``--takeoff-climb``; without
    them, the scenario's airspeed range, cruise speed and takeoff climb with ``--scenario``
    (None when neither is given: the defaults)."""
    texts: list[str] | None = args.airspeed
    climbs: list[str] | None = args.takeoff_climb
    if not texts and not climbs and not args.scenario:
        return None
    if texts:
        _check_count(texts, "--airspeed", args.vehicles)
        params = []
        for text in texts:
            lo, cruise, hi = _floats(text, "--airspeed", 3, 3)
            if not 0.0 < lo <= cruise <= hi:
                raise UsageError(f"--airspeed needs 0 < MIN <= CRUISE <= MAX (m/s), got {text!r}")
            params.append(_airspeeds(lo, cruise, hi))
        params = params * args.vehicles if len(params) == 1 else params
    elif args.scenario:
        params = airspeeds_from_scenario(args.scenario, args.vehicles)
    else:
        params = [AirframeParams()] * args.vehicles
    if climbs:
        _check_count(climbs, "--takeoff-climb", args.vehicles)
        rates = []
        for text in climbs:
            (rate,) = _floats(text, "--takeoff-climb", 1, 1)
            if not 0.0 < rate <= 50.0:
                raise UsageError(f"--takeoff-climb needs 0 < M_S <= 50 (m/s), got {text!r}")
            rates.append(rate)
        rates = rates * args.vehicles if len(rates) == 1 else rates
        params = [replace(p, takeoff_climb_rate_m_s=r) for p, r in zip(params, rates, strict=True)]
    return params


def _airspeeds(lo_m_s: float, cruise_m_s: float, hi_m_s: float) -> AirframeParams:
    return replace(
        AirframeParams(),
        airspeed_min_m_s=lo_m_s,
        airspeed_cruise_m_s=cruise_m_s,
        airspeed_max_m_s=hi_m_s,
    )


@functools.cache
def _scenario(path: str) -> Scenario:
    """The scenario file, read once for the homes and the airspeeds."""
    from planner.scenario import load_scenario

    return load_scenario(path)


def airspeeds_from_scenario(path: str, n: int) -> list[AirframeParams]:
    """Vehicle i flies scenario vehicle i's airspeed range and cruise speed."""
    vehicles = _scenario(path).vehicles[:n]
    return [
        replace(
            _airspeeds(v.speed_min_m_s, v.cruise_m_s, v.speed_max_m_s),
            takeoff_climb_rate_m_s=v.takeoff_climb_m_s,
        )
        for v in vehicles
    ]


def blackouts_from_args(args: argparse.Namespace) -> list[BlackoutSpec]:
    """``--blackout`` values, checked against the number of vehicles."""
    out = []
    for text in args.blackout or ():
        index, start, duration = _floats(text, "--blackout", 3, 3)
        i = _vehicle_index(text, "--blackout", index, args.vehicles)
        if start < 0:
            raise UsageError(f"--blackout {text!r}: START_S must be >= 0")
        if duration <= 0:
            raise UsageError(f"--blackout {text!r}: DURATION_S must be > 0")
        out.append(BlackoutSpec(i, start, duration))
    return out


def _vehicle_index(text: str, name: str, value: float, n_vehicles: int) -> int:
    if not (value.is_integer() and 0 <= value < n_vehicles):
        raise UsageError(
            f"{name} {text!r}: I (the vehicle) must be a whole number in "
            f"0..{n_vehicles - 1} (0-based; --vehicles {n_vehicles})"
        )
    return int(value)


def speed_bias_from_args(args: argparse.Namespace) -> dict[int, float]:
    """``--speed-bias I,FRACTION`` values by vehicle index."""
    out: dict[int, float] = {}
    for text in args.speed_bias or ():
        index, fraction = _floats(text, "--speed-bias", 2, 2)
        i = _vehicle_index(text, "--speed-bias", index, args.vehicles)
        if not -0.5 < fraction < 0.5:
            raise UsageError(f"--speed-bias {text!r}: FRACTION must be in (-0.5, 0.5)")
        out[i] = fraction
    return out


def utc_offsets_from_args(args: argparse.Namespace) -> dict[int, float]:
    """``--utc-offset I,SECONDS`` values by vehicle index (checked against ``--no-utc``)."""
    out: dict[int, float] = {}
    for text in args.utc_offset or ():
        index, seconds = _floats(text, "--utc-offset", 2, 2)
        out[_vehicle_index(text, "--utc-offset", index, args.vehicles)] = seconds
    for i in args.no_utc or ():
        _vehicle_index(str(i), "--no-utc", float(i), args.vehicles)
        if i in out:
            raise UsageError(f"--no-utc {i}: vehicle {i} also has a --utc-offset")
    return out


def initial_bearing_deg(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle initial bearing from point 1 to point 2 (degrees, [0, 360))."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(lon2 - lon1)
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0


def terrain_from_args(args: argparse.Namespace, homes: Sequence[Home]) -> GridTerrain | None:
    """The ground the vehicles fly over: ``--scenario``'s terrain with any ``--hill`` on it
    (None without a scenario: flat at each home's altitude). Where the terrain has no data
    (an SRTM tile missing) the ground is flat at the lowest home's altitude."""
    hills = [_hill(text) for text in args.hill or ()]
    if not args.scenario:
        if hills:
            raise UsageError("--hill needs --scenario (the terrain it stands on)")
        return None
    import numpy as np

    from planner.terrain import build_terrain
    from sitl_stub.terrain import with_hills

    scenario = _scenario(args.scenario)
    frame = scenario.frame()
    terrain = build_terrain(scenario)

    def elevation(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
        east, north = frame.to_local(lat_deg, lon_deg)
        return terrain.elevation_m(np.asarray(east), np.asarray(north))

    grid = GridTerrain(with_hills(elevation, hills), fallback_m=min(h.alt_m for h in homes))
    for i, home in enumerate(homes):
        below = home.alt_m - grid.elevation_m(home.lat_deg, home.lon_deg)
        if abs(below) > 5.0:
            log.warning(
                "vehicle %d: home altitude %.1f m is %+.1f m from the terrain there: its "
                "terrain is moved by that to put home on the ground",
                i,
                home.alt_m,
                below,
            )
    return grid


def _hill(text: str) -> Hill:
    lat, lon, radius, height = _floats(text, "--hill", 4, 4)
    try:
        return Hill(lat, lon, radius, height)
    except ValueError as err:
        raise UsageError(f"--hill {text!r}: {err}") from None


def homes_from_scenario(path: str, n: int) -> list[Home]:
    """Vehicle i at scenario vehicle i's start, nose toward its goal.

    The home altitude is the scenario terrain's elevation there (not the start's ``alt_m``,
    which is a flight altitude): the vehicle starts on the ground, or, if the scenario
    vehicle is ``airborne``, flying at its start's ``alt_m`` (AMSL) above that ground, in
    LOITER circling its start.
    """
    import numpy as np

    from planner.terrain import build_terrain

    scenario = _scenario(path)
    frame = scenario.frame()
    vehicles = scenario.vehicles
    if n > len(vehicles):
        raise UsageError(f"--vehicles {n} but {path} defines only {len(vehicles)} vehicles")
    terrain = build_terrain(scenario)
    homes = []
    for v in vehicles[:n]:
        east, north = v.start.local(frame)
        lat, lon = frame.to_geodetic(east, north)
        ground = terrain.elevation_m(np.array([east]), np.array([north]))
        goal_lat, goal_lon = frame.to_geodetic(*v.goal.local(frame))
        hdg = initial_bearing_deg(lat, lon, goal_lat, goal_lon)
        air = float(v.start.alt_m) if v.airborne else None
        try:
            homes.append(Home(float(lat), float(lon), float(ground[0]), hdg, air))
        except ValueError as err:
            raise UsageError(f"{path}: vehicle {v.id}: {err}") from None
    return homes


async def _control(team: SimTeam, stop: asyncio.Event) -> None:
    """Control lines on stdin (a rehearsal driving its simulator). EOF ends the control
    input only: the team runs on until it is signalled."""
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    while True:
        line = await reader.readline()
        if not line:
            return
        words = line.decode(errors="replace").split()
        try:
            if words and words[0] == "blackout" and len(words) == 4:
                i, start, duration = int(words[1]), float(words[2]), float(words[3])
                if not 0 <= i < len(team.vehicles) or start < 0 or duration <= 0:
                    raise ValueError("index, start or duration out of range")
                team.schedule_blackout(i, start, duration)
                print(
                    f"sitl_stub: blackout vehicle {i} at {start:g} s for {duration:g} s", flush=True
                )
            elif words:
                raise ValueError("expected 'blackout INDEX START_SIM_S DURATION_S'")
        except ValueError as err:
            print(
                f"sitl_stub: control: {line.decode(errors='replace').strip()!r}: {err}",
                file=sys.stderr,
            )


async def _idle_exit(team: SimTeam, idle_s: float, stop: asyncio.Event) -> None:
    """Set ``stop`` once no vehicle has had a client for ``idle_s`` wall seconds, counted from
    the last client gone (a team that never had one waits for its first)."""
    served = False
    idle_since: float | None = None
    while True:
        await asyncio.sleep(min(1.0, idle_s / 4))
        if any(port.connections for port in team.server.ports):
            served, idle_since = True, None
            continue
        if not served:
            continue
        now = time.monotonic()
        idle_since = now if idle_since is None else idle_since
        if now - idle_since >= idle_s:
            stop.set()
            # The ground station that started it may be gone, and its end of stdout with it.
            with contextlib.suppress(OSError):
                print(f"sitl_stub: no client for {idle_s:g} s; stopping", flush=True)
            return


async def serve(
    args: argparse.Namespace,
    homes: list[Home],
    params: list[AirframeParams] | None = None,
    blackouts: Sequence[BlackoutSpec] = (),
    terrain: GridTerrain | None = None,
) -> None:
    from sitl_stub.model import Wind

    wind = None
    if args.wind or args.gust:
        speed, from_deg = _floats(args.wind, "--wind", 2, 2) if args.wind else (0.0, 0.0)
        wind = Wind(speed_m_s=speed, from_rad=math.radians(from_deg), gust_m_s=args.gust)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        async with SimTeam.start(
            homes=homes,
            tcp_base=args.tcp_base,
            speedup=args.speedup,
            wind=wind,
            seed=args.seed,
            host=args.host,
            params=params,
            start_utc_s=time.time() if args.start_utc is None else args.start_utc,
            legacy_mission_requests=args.legacy_mission_requests,
            ardupilot_mission_storage=not args.exact_missions,
            speed_bias=speed_bias_from_args(args),
            utc_offset_s=utc_offsets_from_args(args),
            no_utc=tuple(args.no_utc or ()),
            wind_estimate_error=not args.true_wind_estimate,
            one_client_per_port=args.one_client_per_port,
            mission_timeout_s=args.mission_timeout,
            truth_out=args.truth,
            truth_period_s=args.truth_period,
            counters_out=args.counters,
            terrain=terrain,
        ) as team:
            if args.loss or args.latency_ms:
                for v in team.vehicles:
                    v.link.faults(loss=args.loss, latency_ms=args.latency_ms)
            for b in blackouts:
                team.schedule_blackout(b.vehicle_index, b.start_sim_s, b.duration_s)
            if args.lockstep:
                team.server.lockstep = Lockstep(
                    Path(args.lockstep),
                    create=True,
                    speedup=args.speedup,
                    lead_s=args.lockstep_lead,
                )
            for i, port in enumerate(team.ports):
                log.info("vehicle %d: sysid %d on tcp:%s:%d", i, i + 1, args.host, port)
            print(f"sitl_stub: {len(homes)} vehicle(s) ready, ports {team.ports}", flush=True)
            tasks = []
            if args.control_stdin:
                tasks.append(loop.create_task(_control(team, stop)))
            if args.idle_exit is not None:
                tasks.append(loop.create_task(_idle_exit(team, args.idle_exit, stop)))
            await stop.wait()
            for task in tasks:
                task.cancel()
            stats = team.stats()
            with contextlib.suppress(OSError):  # stdout may be a pipe whose reader is gone
                print(
                    f"sitl_stub: stopping; simulated {stats.sim_elapsed_s:.1f} s in "
                    f"{stats.wall_elapsed_s:.1f} s wall "
                    f"({stats.rate_fraction:.1%} of requested rate)",
                    flush=True,
                )
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING)
    try:
        if not (math.isfinite(args.speedup) and args.speedup > 0):
            raise UsageError(f"--speedup must be a positive number, got {args.speedup}")
        if not 0.0 <= args.loss <= 1.0:
            raise UsageError(f"--loss must be in [0, 1], got {args.loss}")
        if not (math.isfinite(args.mission_timeout) and args.mission_timeout > 0):
            raise UsageError(f"--mission-timeout must be > 0, got {args.mission_timeout}")
        if args.latency_ms < 0:
            raise UsageError(f"--latency-ms must be >= 0, got {args.latency_ms}")
        if args.start_utc is not None and not (
            math.isfinite(args.start_utc) and args.start_utc >= 0
        ):
            raise UsageError(f"--start-utc must be Unix seconds >= 0, got {args.start_utc}")
        for option, path in (("--truth", args.truth), ("--counters", args.counters)):
            if path and not Path(path).resolve().parent.is_dir():
                raise UsageError(f"{option} {path}: directory does not exist")
        if not (math.isfinite(args.lockstep_lead) and args.lockstep_lead > 0):
            raise UsageError(f"--lockstep-lead must be a positive number, got {args.lockstep_lead}")
        if args.lockstep and not Path(args.lockstep).resolve().parent.is_dir():
            raise UsageError(f"--lockstep {args.lockstep}: directory does not exist")
        if not (math.isfinite(args.truth_period) and args.truth_period > 0):
            raise UsageError(f"--truth-period must be a positive number, got {args.truth_period}")
        homes = homes_from_args(args)
        terrain = terrain_from_args(args, homes)
        params = params_from_args(args)
        blackouts = blackouts_from_args(args)
        speed_bias_from_args(args)  # usage errors before anything starts
        utc_offsets_from_args(args)
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(serve(args, homes, params, blackouts, terrain))
    except (UsageError, ValueError, OSError) as err:
        print(f"sitl_stub: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
