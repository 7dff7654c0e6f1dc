"""The CLI as a subprocess: serves on the SITL port layout and exits 0 on SIGINT."""

from __future__ import annotations

import asyncio
import math
import re
import signal
import sys
from pathlib import Path

from tests.sitl_stub.conftest import Client, free_port_base


async def test_cli_serves_two_vehicles_and_stops_cleanly_on_sigint() -> None:
    base = free_port_base(2)
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", "--vehicles", "2", "--tcp-base", str(base),
        "--speedup", "10", "--home", "-35.36,149.16,584,90", "--wind", "5,270",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        async with asyncio.timeout(20):
            line = await proc.stdout.readline()
        assert b"ready" in line, line
        for i in range(2):
            c = await Client.connect(base + 10 * i)
            try:
                hb = await c.recv("HEARTBEAT")
                assert hb.get_srcSystem() == i + 1
            finally:
                await c.close()
        proc.send_signal(signal.SIGINT)
        async with asyncio.timeout(20):
            _, err = await proc.communicate()
        assert proc.returncode == 0, err
        assert b"Traceback" not in err
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_cli_rejects_bad_home_with_clear_message() -> None:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", "--home", "95,10,0",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    async with asyncio.timeout(20):
        _, err = await proc.communicate()
    assert proc.returncode == 2
    assert b"latitude" in err


async def test_cli_scenario_places_each_vehicle_at_its_start() -> None:
    from planner.geo import geodesic_distance_m
    from planner.scenario import load_scenario

    path = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"
    scenario = load_scenario(path)
    frame = scenario.frame()
    starts = []
    for v in scenario.vehicles[:3]:
        lat, lon = frame.to_geodetic(*v.start.local(frame))
        goal = v.goal.local(frame)
        start = v.start.local(frame)
        # Grid bearing to the goal; true north differs by the meridian convergence (< 1 deg).
        grid_hdg = math.degrees(math.atan2(goal[0] - start[0], goal[1] - start[1])) % 360.0
        starts.append((lat, lon, v.start.alt_m, grid_hdg))

    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sitl_stub", "--scenario", str(path), "--vehicles", "3",
        "--tcp-base", "0", "--speedup", "1",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        async with asyncio.timeout(30):
            line = (await proc.stdout.readline()).decode()
        found = re.search(r"ready, ports \[([\d, ]+)\]", line)
        assert found, line
        ports = [int(p) for p in found.group(1).split(",")]
        assert len(ports) == 3
        for i, (port, (lat, lon, alt, hdg)) in enumerate(zip(ports, starts, strict=True)):
            c = await Client.connect(port)
            try:
                pos = await c.recv("GLOBAL_POSITION_INT", timeout=10)
            finally:
                await c.close()
            assert pos.get_srcSystem() == i + 1
            assert geodesic_distance_m(lat, lon, pos.lat * 1e-7, pos.lon * 1e-7) < 5.0
            assert pos.alt == round(alt * 1000) and pos.relative_alt == 0
            assert abs((pos.hdg / 100.0 - hdg + 180.0) % 360.0 - 180.0) < 2.0
        proc.send_signal(signal.SIGINT)
        async with asyncio.timeout(20):
            _, err = await proc.communicate()
        assert proc.returncode == 0, err
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
