"""The fleet: links held for the process, each vehicle in at most one flight (stub vehicles
over loopback)."""

from __future__ import annotations

import asyncio

import pytest

from gcs.service.fleet import Fleet, VehicleBusy
from sitl_stub.api import Home, SimTeam
from tests.gcs.conftest import HOME


async def test_vehicles_are_claimed_whole_flights_at_a_time_and_links_are_kept() -> None:
    async with (
        SimTeam.start(homes=[Home(*HOME)] * 3, tcp_base=0, speedup=5.0) as team,
        Fleet(wait_s=10.0) as fleet,
        asyncio.timeout(30),
    ):
        conns = [f"tcp:127.0.0.1:{p}" for p in team.ports]
        first = await fleet.claim(conns[:2], "flight-a")
        assert [h.vehicle.system_id for h in first] == [1, 2]
        assert fleet.flight_of(conns[0]) == "flight-a" and fleet.flight_of(conns[2]) is None
        with pytest.raises(VehicleBusy, match=f"vehicle {conns[1]} is already in flight flight-a"):
            await fleet.claim([conns[2], conns[1]], "flight-b")
        assert fleet.flight_of(conns[2]) is None  # all or none: the free one was not taken
        again = await fleet.claim(conns[:2], "flight-a")  # the same flight may ask again
        assert [h.link for h in again] == [h.link for h in first]
        fleet.release("flight-a")
        second = await fleet.claim([conns[1], conns[2]], "flight-b")
        assert second[0].link is first[1].link  # the link outlived the first flight
        assert second[0].link.vehicles[2].system_id == 2


async def test_bundled_simulator_vehicles_are_started_on_request_and_stopped_with_the_fleet() -> (
    None
):
    home = ",".join(f"{x:g}" for x in HOME)
    async with asyncio.timeout(60):
        async with Fleet(wait_s=10.0) as fleet:
            stub = await fleet.start_stubs(2, ["--home", home, "--speedup", "5"])
            held = await fleet.claim(stub.connections, "rehearsal", [1, 2])
            assert [h.vehicle.system_id for h in held] == [1, 2]
            assert stub.proc.returncode is None
        assert stub.proc.returncode == 0  # interrupted cleanly when the fleet closed
