"""Benchmark: N stub vehicles at a speed-up, a pymavlink-codec client on each, default streams.

Prints one markdown row: vehicles, requested speed-up, wall seconds, achieved speed-up and the
fraction of the requested rate (goal >= 95% for 10 vehicles at 100x), the messages per wall
second the clients decoded, and the simulator's CPU time as a share of one core (its
headroom). The clients run in a separate process so their decoding does not share the
simulator's core. The vehicles sit on the ground, disarmed; ``--fly`` arms them and flies a
long AUTO mission instead (takeoff, then a 4 km square circuit), which costs more physics;
``--terrain`` flies them over a seeded 40-hill synthetic terrain (the ground under each vehicle
looked up every physics step, as with ``python -m sitl_stub --scenario``) instead of flat
ground, and streams TERRAIN_REPORT at 1 Hz.

    python bench/bench_sitl_stub.py --vehicles 10 --speedup 100 --seconds 21 [--fly] [--terrain]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import time

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from planner.geo import LocalFrame
from planner.terrain import SyntheticTerrain
from sitl_stub.api import Home, SimTeam
from sitl_stub.items import MissionItem
from sitl_stub.model import displace_deg
from sitl_stub.terrain import GridTerrain


def clients(ports: list[int], seconds: float, result: mp.Queue) -> None:  # type: ignore[type-arg]
    async def one(port: int) -> int:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        parser = mavlink2.MAVLink(None)
        parser.robust_parsing = True
        n = 0
        try:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    async with asyncio.timeout(1.0):
                        data = await reader.read(65536)
                except TimeoutError:
                    continue
                if not data:
                    break
                n += len(parser.parse_buffer(data) or [])
        finally:
            writer.close()
            await writer.wait_closed()
        return n

    async def all_() -> list[int]:
        return list(await asyncio.gather(*(one(p) for p in ports)))

    result.put(sum(asyncio.run(all_())))


def circuit(home: Home) -> list[MissionItem]:
    """Takeoff, then a 4 km square flown four times (about 70 km, 50 simulated minutes)."""

    def item(seq: int, cmd: int, north: float, east: float, alt: float) -> MissionItem:
        lat, lon = displace_deg(home.lat_deg, home.lon_deg, home.alt_m, north, east)
        rel = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT
        return MissionItem(seq, rel, cmd, x=round(lat * 1e7), y=round(lon * 1e7), z=alt)

    items = [item(0, mavlink2.MAV_CMD_NAV_WAYPOINT, 0, 0, 0)]
    items.append(item(1, mavlink2.MAV_CMD_NAV_TAKEOFF, 300, 0, 60))
    corners = [(4000, 0), (4000, 4000), (0, 4000), (0, 0)] * 4
    for north, east in corners:
        items.append(item(len(items), mavlink2.MAV_CMD_NAV_WAYPOINT, north, east, 120))
    return items


def hills(home: Home) -> GridTerrain:
    """40 hills up to 50 m over a 20 km square around the homes (the circuit clears them)."""
    frame = LocalFrame(home.lat_deg, home.lon_deg)
    terrain = SyntheticTerrain.generate(
        seed=1, min_east_m=-10e3, max_east_m=10e3, min_north_m=-10e3, max_north_m=10e3,
        base_m=home.alt_m, peak_m=50.0, hills=40,
    )  # fmt: skip

    def elevation(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
        return terrain.elevation_m(*frame.to_local(lat_deg, lon_deg))

    return GridTerrain(elevation)


async def run(n: int, speedup: float, seconds: float, fly: bool, terrain: bool) -> str:
    homes = [Home(-35.36 + 0.001 * i, 149.16, 584.0) for i in range(n)]
    ground = hills(homes[0]) if terrain else None
    async with SimTeam.start(homes=homes, tcp_base=0, speedup=speedup, terrain=ground) as team:
        if fly:
            for v, home in zip(team.vehicles, homes, strict=True):
                items = tuple(circuit(home))
                v.mission.store(items)
                v.autopilot.replace_mission(items)
                v.autopilot.arm()
                assert v.autopilot.start_mission()
        q: mp.Queue = mp.Queue()  # type: ignore[type-arg]
        proc = mp.Process(target=clients, args=(team.ports, seconds, q))
        proc.start()
        await asyncio.sleep(0.5)
        loop = asyncio.get_running_loop()
        s0, w0, c0 = team.sim_time_s, loop.time(), time.process_time()
        await asyncio.sleep(seconds - 1.0)
        sim, wall = team.sim_time_s - s0, loop.time() - w0
        cpu = time.process_time() - c0
        msgs = await loop.run_in_executor(None, q.get)
        await loop.run_in_executor(None, proc.join)
        if fly:
            assert all(not v.true_state.on_ground for v in team.vehicles), "not flying"
    achieved = sim / wall
    where = ("flying" if fly else "on ground") + (" over terrain" if terrain else "")
    return (
        f"| {n} | {speedup:g} | {where} | {wall:.1f} "
        f"| {achieved:.1f} | {achieved / speedup:.1%} | {msgs / seconds:.0f} "
        f"| {cpu / wall:.0%} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--vehicles", type=int, default=10)
    ap.add_argument("--speedup", type=float, default=100.0)
    ap.add_argument("--seconds", type=float, default=21.0)
    ap.add_argument("--fly", action="store_true", help="arm and fly an AUTO mission")
    ap.add_argument("--terrain", action="store_true", help="over synthetic hills, not flat")
    args = ap.parse_args()
    row = asyncio.run(run(args.vehicles, args.speedup, args.seconds, args.fly, args.terrain))
    print(
        "| vehicles | speed-up | vehicles are | wall s | achieved speed-up | of requested "
        "| msgs/s to clients | simulator CPU (one core) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    print(row)


if __name__ == "__main__":
    main()
