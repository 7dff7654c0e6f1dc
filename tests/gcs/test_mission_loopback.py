"""Mission transfers with their default options over loopback TCP against the stub: 30 % loss
each way, and a vehicle that goes silent mid-transfer."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from dataclasses import replace

import pytest

from gcs.mavlink.link import Link
from gcs.mavlink.mission_client import download_mission, upload_mission
from gcs.mavlink.mission_errors import MissionTimeout
from gcs.mavlink.retry import DEFAULT_POLICY
from planner.mission import Autopilot, MissionItem, items_equal
from sitl_stub.api import SimTeam
from tests.gcs.test_mission_client import HOME, _planner, stored, waypoints

SPEEDUP = 20.0
VEHICLES = 4
RUNS = 20


@contextlib.asynccontextmanager
async def team_and_links(n: int) -> AsyncIterator[tuple[SimTeam, list[Link]]]:
    """``n`` stub vehicles with their default mission timers, one link to each."""
    async with (
        SimTeam.start(homes=[HOME] * n, tcp_base=0, speedup=SPEEDUP) as team,
        contextlib.AsyncExitStack() as stack,
    ):
        links = []
        for i, port in enumerate(team.ports):
            link = await stack.enter_async_context(Link.open(f"tcp:127.0.0.1:{port}"))
            await link.wait_vehicle(i + 1, timeout_s=10.0)
            links.append(link)
        yield team, links


def shifted(items: list[MissionItem], run: int) -> list[MissionItem]:
    """A different mission for each run (so a run cannot pass on the last one's items)."""
    return [it if it.seq == 0 else replace(it, x=it.x + 100 * run, z=it.z + run) for it in items]


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_200_items_up_and_down_at_30_percent_loss_with_defaults_in_20_of_20_runs() -> None:
    """Default options only; 20 runs shared by 4 vehicles of one team, run side by side.
    Every upload is checked against what the stub stores, every download against it."""
    base = waypoints(200)
    outcomes: dict[int, str] = {}
    async with team_and_links(VEHICLES) as (team, links), asyncio.timeout(600):
        for v in team.vehicles:
            v.link.faults(loss=0.3)

        async def runs_on(i: int) -> None:
            sysid, vehicle = i + 1, team.vehicles[i]
            for run in range(i, RUNS, VEHICLES):
                items = shifted(base, run)
                try:
                    await upload_mission(links[i], sysid, items)
                    held = [_planner(it) for it in vehicle.mission.items(0)]
                    got = await download_mission(links[i], sysid)
                except MissionTimeout as err:
                    outcomes[run] = f"timeout: {err}"
                    continue
                up_ok = items_equal(items, held, autopilot=Autopilot.ARDUPILOT, compare_home=False)
                down_ok = items_equal(held, got, compare_home=False)
                outcomes[run] = "ok" if up_ok and down_ok else f"upload {up_ok}, download {down_ok}"

        async with asyncio.TaskGroup() as tg:
            for i in range(VEHICLES):
                tg.create_task(runs_on(i))
        for v in team.vehicles:
            assert v.link.inbound.lost > 100 and v.link.outbound.lost > 100
    failed = {run: why for run, why in outcomes.items() if why != "ok"}
    assert len(outcomes) == RUNS and not failed, failed


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_a_vehicle_that_goes_silent_mid_upload_fails_it_by_the_silence_bound() -> None:
    """Nothing heard for policy.silence_s (default options): MissionTimeout, and the vehicle
    keeps the mission it had."""
    old, new = waypoints(20), shifted(waypoints(200), 1)
    blackout_at: list[float] = []
    async with team_and_links(1) as (team, (link,)):
        loop = asyncio.get_running_loop()
        await upload_mission(link, 1, old)
        before = team.vehicles[0].mission.items(0)
        assert items_equal(old, stored(team), autopilot=Autopilot.ARDUPILOT, compare_home=False)

        def go_silent_midway(done: int, total: int) -> None:
            if done >= 100 and not blackout_at:
                # Longer than the bound: the transfer must end while the vehicle is silent.
                team.vehicles[0].link.blackout((DEFAULT_POLICY.silence_s + 20.0) * SPEEDUP)
                blackout_at.append(loop.time())

        async with asyncio.timeout(DEFAULT_POLICY.silence_s + 15.0):  # a hang guard only
            with pytest.raises(MissionTimeout) as e:
                await upload_mission(link, 1, new, progress=go_silent_midway)
        assert blackout_at and loop.time() - blackout_at[0] >= DEFAULT_POLICY.silence_s
        assert e.value.vehicle == 1 and e.value.operation == "upload"
        assert f"nothing heard from the vehicle for {DEFAULT_POLICY.silence_s:.0f}." in str(e.value)
        assert team.vehicles[0].link.inbound.blacked_out > 0
        assert team.vehicles[0].mission.items(0) == before  # untouched
