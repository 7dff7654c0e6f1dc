"""Benchmark: our 200-item mission upload next to MAVSDK's ``mission_raw``, same stub vehicle.

One stub vehicle runs in a child process (1x). This process holds both clients on the same
vehicle at once: a ``gcs.mavlink.link.Link`` and MAVSDK 4.x (its C core, over ``tcpout://``). Each
round uploads the same 200 items with ours, then with MAVSDK (the order alternates between
rounds), and downloads them back with each; every upload is checked against the vehicle's
download. The figures are the ratios of medians, ours / MAVSDK, for upload and download.

    python bench/bench_gcs_mission.py --items 200 --rounds 9 [--loss 0.0]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import statistics
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from gcs.mavlink.link import Link
from gcs.mavlink.mission_client import download_mission, upload_mission
from planner.mission import Autopilot, MissionItem, items_equal
from sitl_stub.api import Home, SimTeam
from sitl_stub.model import displace_deg

HOME = Home(-35.363261, 149.165230, 584.0)


def stub(loss: float, out: mp.Queue, stop: Any) -> None:  # type: ignore[type-arg]
    async def run() -> None:
        async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=1.0) as team:
            if loss > 0:
                team.vehicles[0].link.faults(loss=loss)
            out.put(team.ports[0])
            while not stop.is_set():
                await asyncio.sleep(0.1)

    asyncio.run(run())


def mission(n: int, shift_m: float) -> list[MissionItem]:
    rel = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    items = []
    for i in range(n):
        lat, lon = displace_deg(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, 40.0 * i, shift_m)
        frame, z = (mavlink2.MAV_FRAME_GLOBAL, HOME.alt_m) if i == 0 else (rel, 100.0 + i % 50)
        x, y = round(lat * 1e7), round(lon * 1e7)
        current = int(i == 0)  # MAVSDK insists on exactly one current item
        items.append(MissionItem(i, frame, 16, current, 1, 0.0, 0.0, 0.0, 0.0, x, y, z))
    return items


def to_mavsdk(items: list[MissionItem]) -> list[Any]:
    from mavsdk.asyncio.plugins.mission_raw import MissionItem as RawItem

    fields = ("seq", "frame", "command", "current", "autocontinue", "param1", "param2",
              "param3", "param4", "x", "y", "z", "mission_type")  # fmt: skip
    return [RawItem(**{f: getattr(it, f) for f in fields}) for it in items]


async def bench(port: int, n: int, rounds: int) -> dict[str, list[float]]:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

    keys = ("ours_up", "mavsdk_up", "ours_down", "mavsdk_down")
    times: dict[str, list[float]] = {k: [] for k in keys}
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with (
        Link.open(f"tcp:127.0.0.1:{port}", system_id=254) as link,
        Mavsdk(config) as mavsdk,
    ):
        await link.wait_vehicle(1, timeout_s=10.0)
        await mavsdk.add_any_connection(f"tcpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=10.0)
        assert system is not None
        raw = MissionRawAsync(system)

        async def ours(items: list[MissionItem]) -> None:
            t0 = time.perf_counter()
            await upload_mission(link, 1, items)
            times["ours_up"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            got = await download_mission(link, 1)
            times["ours_down"].append(time.perf_counter() - t0)
            same = items_equal(items, got, autopilot=Autopilot.ARDUPILOT, compare_home=False)
            assert same, "our upload did not arrive intact (in the form ArduPilot stores it)"

        async def theirs(items: list[MissionItem]) -> None:
            t0 = time.perf_counter()
            await raw.upload_mission(to_mavsdk(items))
            times["mavsdk_up"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            got = await raw.download_mission()
            times["mavsdk_down"].append(time.perf_counter() - t0)
            assert [g.x for g in got[1:]] == [it.x for it in items[1:]], "MAVSDK upload differs"

        for r in range(rounds + 1):  # round 0 warms both up and is not counted
            a, b = mission(n, 10.0 * r), mission(n, 10.0 * r + 5.0)
            pair = (ours(a), theirs(b)) if r % 2 == 0 else (theirs(b), ours(a))
            for coro in pair:
                await coro
            if r == 0:
                for v in times.values():
                    v.clear()
    return times


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--items", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--loss", type=float, default=0.0, help="stub link loss, both directions")
    args = ap.parse_args()
    ctx = mp.get_context("spawn")
    out: mp.Queue = ctx.Queue()  # type: ignore[type-arg]
    stop = ctx.Event()
    proc = ctx.Process(target=stub, args=(args.loss, out, stop))
    proc.start()
    try:
        times = asyncio.run(bench(out.get(timeout=60), args.items, args.rounds))
    finally:
        stop.set()
        proc.join(timeout=30)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(
        "| items | loss | rounds | ours upload (s) | MAVSDK upload (s) | upload ours/MAVSDK "
        "| ours download (s) | MAVSDK download (s) | download ours/MAVSDK |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print(
        f"| {args.items} | {args.loss:.0%} | {args.rounds} | {med['ours_up']:.3f} "
        f"| {med['mavsdk_up']:.3f} | {med['ours_up'] / med['mavsdk_up']:.2f} "
        f"| {med['ours_down']:.3f} | {med['mavsdk_down']:.3f} "
        f"| {med['ours_down'] / med['mavsdk_down']:.2f} |"
    )


if __name__ == "__main__":
    main()
