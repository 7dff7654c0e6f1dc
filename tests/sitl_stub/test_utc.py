"""Per-vehicle UTC: each vehicle's SYSTEM_TIME may carry its own offset, or no UTC at all."""

from __future__ import annotations

import pytest

from sitl_stub.__main__ import parse_args, utc_offsets_from_args
from sitl_stub.api import Home, SimTeam
from tests.sitl_stub.conftest import Client

HOMES = [Home(-35.36, 149.16, 584.0), Home(-35.37, 149.17, 600.0), Home(-35.38, 149.18, 610.0)]
START_UTC_S = 1_700_000_000.0


async def test_system_time_carries_each_vehicles_offset_over_tcp() -> None:
    """As separately started SITL instances (each with its own clock) or an autopilot without
    GPS time: time_unix_usec = true UTC + offset, or 0; time_boot_ms is unchanged."""
    async with SimTeam.start(
        homes=HOMES,
        tcp_base=0,
        run=False,
        start_utc_s=START_UTC_S,
        utc_offset_s={0: 7.0, 1: -4.0},
        no_utc=[2],
    ) as team:
        clients = [await Client.connect(p) for p in team.ports]
        try:
            team.step(35)
            got = [await c.recv("SYSTEM_TIME") for c in clients]
        finally:
            for c in clients:
                await c.close()
        assert team.utc_s == pytest.approx(START_UTC_S + 3.5)
        assert [v.utc_s for v in team.vehicles] == [team.utc_s + 7.0, team.utc_s - 4.0, None]
    for msg, offset in zip(got[:2], (7.0, -4.0), strict=True):
        # UTC minus boot time is the UTC at boot, whatever step the message came from.
        at_boot_s = msg.time_unix_usec * 1e-6 - msg.time_boot_ms * 1e-3
        assert at_boot_s == pytest.approx(START_UTC_S + offset, abs=2e-3)
    assert got[2].time_unix_usec == 0 and got[2].time_boot_ms > 0


async def test_offset_applies_to_system_time_and_home_position_only() -> None:
    async with SimTeam.start(
        homes=HOMES[:2], tcp_base=0, run=False, start_utc_s=START_UTC_S, utc_offset_s={1: 7.0}
    ) as team:
        team.step(10)
        msg = team.vehicles[1].message("SYSTEM_TIME")
        assert msg.time_unix_usec == round((START_UTC_S + 1.0 + 7.0) * 1e6)
        assert team.vehicles[0].message("SYSTEM_TIME").time_unix_usec == round(
            (START_UTC_S + 1.0) * 1e6
        )
        home = team.vehicles[1].message("HOME_POSITION")
        assert home.time_usec == int((START_UTC_S + 8.0) * 1e6)


def test_utc_options_parse_and_are_checked() -> None:
    args = parse_args(
        ["--vehicles", "3", "--home", "0,0,0", "--utc-offset", "0,7", "--utc-offset", "1,-4",
         "--no-utc", "2"]
    )  # fmt: skip
    assert utc_offsets_from_args(args) == {0: 7.0, 1: -4.0}
    assert args.no_utc == [2]
    with pytest.raises(ValueError, match="--utc-offset '3,1': I"):
        utc_offsets_from_args(parse_args(["--home", "0,0,0", "--utc-offset", "3,1"]))
    with pytest.raises(ValueError, match="--no-utc 0: vehicle 0 also"):
        utc_offsets_from_args(
            parse_args(["--home", "0,0,0", "--utc-offset", "0,1", "--no-utc", "0"])
        )
    with pytest.raises(ValueError, match="no vehicle 5"):
        SimTeam.create(homes=HOMES, no_utc=[5])
