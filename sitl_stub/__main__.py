"""CLI: ``python -m sitl_stub --vehicles N --tcp-base PORT --speedup S --home LAT,LON,ALT[,HDG]``.

Runs until SIGINT/SIGTERM, then closes every socket and exits 0.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
import sys
import time
from collections.abc import Sequence

from sitl_stub.api import DEFAULT_TCP_BASE, Home, SimTeam

log = logging.getLogger("sitl_stub")


class UsageError(ValueError):
    """A command-line value that cannot be used."""


def _floats(text: str, name: str, n_min: int, n_max: int) -> list[float]:
    parts = text.split(",")
    if not n_min <= len(parts) <= n_max:
        raise UsageError(f"{name} needs {n_min} to {n_max} comma-separated numbers, got {text!r}")
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
    where = ap.add_mutually_exclusive_group(required=True)
    where.add_argument("--home", help="LAT,LON,ALT_M[,HDG_DEG] shared start (vehicles spaced)")
    where.add_argument("--scenario", help="scenario file: each vehicle at its start")
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
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("-v", "--verbose", action="store_true")
    return ap.parse_args(_join_negative_values(list(sys.argv[1:] if argv is None else argv)))


def _join_negative_values(argv: list[str]) -> list[str]:
    # "--home -35.36,149.16,584" would read the value as an option (southern latitudes).
    out: list[str] = []
    it = iter(argv)
    for arg in it:
        if arg in ("--home", "--wind"):
            value = next(it, None)
            out.append(arg if value is None else f"{arg}={value}")
        else:
            out.append(arg)
    return out


def homes_from_args(args: argparse.Namespace) -> list[Home]:
    if args.vehicles < 1:
        raise UsageError(f"--vehicles must be at least 1, got {args.vehicles}")
    if args.scenario:
        return homes_from_scenario(args.scenario, args.vehicles)
    lat, lon, alt, *rest = _floats(args.home, "--home", 3, 4)
    hdg = rest[0] if rest else 0.0
    # Vehicles share the home point but are spaced 30 m apart across the heading, as
    # aircraft lined up on an apron, so their true positions never coincide.
    from sitl_stub.model import displace_deg

    homes = []
    for i in range(args.vehicles):
        off = 30.0 * i
        right = math.radians(hdg + 90.0)
        la, lo = displace_deg(lat, lon, alt, off * math.cos(right), off * math.sin(right))
        homes.append(Home(la, lo, alt, hdg))
    return homes


def initial_bearing_deg(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle initial bearing from point 1 to point 2 (degrees, [0, 360))."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(lon2 - lon1)
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0


def homes_from_scenario(path: str, n: int) -> list[Home]:
    """Vehicle i at scenario vehicle i's start, nose toward its goal."""
    from planner.scenario import load_scenario

    scenario = load_scenario(path)
    frame = scenario.frame()
    vehicles = scenario.vehicles
    if n > len(vehicles):
        raise UsageError(f"--vehicles {n} but {path} defines only {len(vehicles)} vehicles")
    homes = []
    for v in vehicles[:n]:
        lat, lon = frame.to_geodetic(*v.start.local(frame))
        goal_lat, goal_lon = frame.to_geodetic(*v.goal.local(frame))
        hdg = initial_bearing_deg(lat, lon, goal_lat, goal_lon)
        homes.append(Home(float(lat), float(lon), v.start.alt_m, hdg))
    return homes


async def serve(args: argparse.Namespace, homes: list[Home]) -> None:
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
            start_utc_s=time.time(),
            legacy_mission_requests=args.legacy_mission_requests,
        ) as team:
            if args.loss or args.latency_ms:
                for v in team.vehicles:
                    v.link.faults(loss=args.loss, latency_ms=args.latency_ms)
            for i, port in enumerate(team.ports):
                log.info("vehicle %d: sysid %d on tcp:%s:%d", i, i + 1, args.host, port)
            print(f"sitl_stub: {len(homes)} vehicle(s) ready, ports {team.ports}", flush=True)
            await stop.wait()
            stats = team.stats()
            print(
                f"sitl_stub: stopping; simulated {stats.sim_elapsed_s:.1f} s in "
                f"{stats.wall_elapsed_s:.1f} s wall ({stats.rate_fraction:.1%} of requested rate)",
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
        if args.latency_ms < 0:
            raise UsageError(f"--latency-ms must be >= 0, got {args.latency_ms}")
        homes = homes_from_args(args)
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(serve(args, homes))
    except (UsageError, ValueError, OSError) as err:
        print(f"sitl_stub: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
