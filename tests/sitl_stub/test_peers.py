"""Independent MAVLink peers against the stub: MAVSDK (4.x native) and MAVProxy."""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.api import Home, SimTeam
from sitl_stub.model import displace_deg
from tests.sitl_stub.conftest import Client, mavproxy_wp_list, wp

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)


def north(d: float) -> tuple[float, float]:
    return displace_deg(HOME.lat_deg, HOME.lon_deg, HOME.alt_m, d, 0.0)


async def test_mavsdk_uploads_arms_starts_and_gets_position_while_flying() -> None:
    """MAVSDK flies the mission: position telemetry in the climb and after the takeoff item."""
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    def item(seq: int, cmd: int, d: float, alt: float) -> MissionItem:
        lat, lon = north(d)
        return MissionItem(
            seq=seq, frame=3, command=cmd, current=int(seq == 0), autocontinue=1,
            param1=0.0, param2=0.0, param3=0.0, param4=0.0,
            x=round(lat * 1e7), y=round(lon * 1e7), z=alt, mission_type=0,
        )  # fmt: skip

    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=10.0) as team:
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        # Inside SimTeam: MAVSDK (its C threads and callbacks) is closed before the vehicle.
        async with Mavsdk(config) as mavsdk, asyncio.timeout(25):
            await mavsdk.add_any_connection(f"tcpout://127.0.0.1:{team.ports[0]}")
            system = await mavsdk.first_autopilot(timeout_s=10.0)
            assert system is not None
            assert await system.get_system_id() == 1
            mission = MissionRawAsync(system)
            telemetry = TelemetryAsync(system)
            items = [
                item(0, 16, 0.0, 0.0),
                item(1, 22, 300.0, 60.0),
                item(2, 16, 2000.0, 100.0),
                item(3, 16, 4000.0, 100.0),
            ]
            await mission.upload_mission(items)
            assert [it.x for it in team.vehicles[0].autopilot.mission[1:]] == [
                it.x for it in items[1:]
            ]
            await ActionAsync(system).arm()
            await mission.start_mission()
            assert team.vehicles[0].autopilot.mode == 10

            # Climbing out: MAVSDK's position shows the aircraft 20 m up and north of home.
            async with contextlib.aclosing(telemetry.subscribe_position()) as positions:
                async for pos in positions:
                    if pos.relative_altitude_m > 20.0:
                        break
            assert pos.latitude_deg > HOME.lat_deg + 1e-4  # rolled and climbed north
            assert pos.absolute_altitude_m == pytest.approx(
                HOME.alt_m + pos.relative_altitude_m, abs=0.01
            )
            assert not team.true_state(0).on_ground

            # Past the takeoff item (MISSION_CURRENT via MAVSDK's mission progress) ...
            async with contextlib.aclosing(mission.subscribe_mission_progress()) as progress:
                async for prog in progress:
                    if prog.current >= 2:
                        break
            # ... and still reporting position, now at the takeoff altitude or above.
            async with contextlib.aclosing(telemetry.subscribe_position()) as positions:
                async for pos in positions:
                    if pos.latitude_deg > north(500.0)[0]:
                        break
            assert pos.relative_altitude_m > 55.0
            assert team.vehicles[0].autopilot.current_seq >= 2


async def test_mavproxy_lists_waypoints_uploaded_by_another_client(tmp_path: Path) -> None:
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=1.0) as team:
        c = await Client.connect(team.ports[0])
        try:
            items = [wp(0, *north(0))] + [wp(i, *north(700.0 * i)) for i in range(1, 4)]
            assert await c.upload(items) == mavlink2.MAV_MISSION_ACCEPTED
        finally:
            await c.close()
        text = await mavproxy_wp_list(
            f"tcp:127.0.0.1:{team.ports[0]}", tmp_path, len(items), timeout_s=40.0
        )
        assert "Saved 4 waypoints" in text, text
        saved = (tmp_path / "way.txt").read_text() if (tmp_path / "way.txt").exists() else text
        for it in items[1:]:
            assert f"{it.x * 1e-7:.6f}"[:8] in saved, saved
