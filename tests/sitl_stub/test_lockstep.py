"""Lock step (:mod:`sitl_stub.lockstep`): the simulation steps no further than the lead beyond
what the ground station acknowledged, runs on by itself once the acknowledgements stop, and
publishes its pace clock; the ground station's mission clock reads that clock."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path

import numpy as np
import pytest

from gcs.coordination.missionclock import (
    HEARD_BEHIND_MAX_PACE_S,
    HEARD_SLACK_S,
    HEARD_WALL_S,
    MissionClock,
)
from gcs.errors import GcsError
from gcs.service.stubs import follow_lockstep
from sitl_stub.api import SimTeam
from sitl_stub.lockstep import STALE_WALL_S, Lockstep

HOME = (46.0, 8.0, 500.0)


def test_the_clock_file_is_shared_and_an_old_acknowledgement_holds_nothing(
    tmp_path: Path,
) -> None:
    sim = Lockstep(tmp_path / "pace", create=True, speedup=200.0, lead_s=0.5)
    ground = Lockstep(tmp_path / "pace")
    assert (ground.speedup, ground.lead_s) == (200.0, 0.5)
    assert sim.limit_s() == math.inf  # no ground station yet
    sim.publish(40.0)
    assert ground.pace_s() == pytest.approx(0.2)
    ground.acknowledge()
    now = time.monotonic()
    assert sim.limit_s(now) == pytest.approx(40.5)
    assert sim.limit_s(now + STALE_WALL_S + 0.1) == math.inf
    ground.release()
    assert sim.limit_s(now) == math.inf
    ground.close()
    assert ground.pace_s() == pytest.approx(0.2)  # reads on as it last was
    sim.close()
    (tmp_path / "short").write_bytes(b"\0" * 8)
    with pytest.raises(ValueError, match="not a lock-step file"):
        Lockstep(tmp_path / "short")


@pytest.mark.slow  # several seconds: left out of make test-quick
async def test_the_simulation_waits_for_the_ground_station_then_runs_on_without_it(
    tmp_path: Path,
) -> None:
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=200.0) as team:
        team.server.lockstep = Lockstep(tmp_path / "pace", create=True, speedup=200.0, lead_s=0.5)
        ground = Lockstep(tmp_path / "pace")
        await asyncio.sleep(0.05)
        ground.acknowledge()  # once, then silent: the flight may go 0.5 s further
        held_at = team.clock.sim_time_s
        await asyncio.sleep(0.4)  # 80 s of flight at 200x, were it not held
        assert team.clock.sim_time_s <= held_at + 0.5 + 2 * team.clock.step_s
        assert ground.pace_s() == pytest.approx(team.clock.sim_time_s / 200.0)
        # Acknowledged as it goes: it flies on.
        for _ in range(100):
            ground.acknowledge()
            await asyncio.sleep(0.002)
        moved = team.clock.sim_time_s
        assert moved > held_at + 5.0
        # Silent for longer than STALE_WALL_S: on by itself.
        await asyncio.sleep(STALE_WALL_S + 0.5)
        assert team.clock.sim_time_s > moved + 20.0
        ground.close()


def test_a_mission_clock_on_the_pace_clock_counts_flight_time_not_wall_time() -> None:
    pace = [10.0]
    clock = MissionClock()
    clock.follow(lambda: pace[0])
    assert clock.paced and clock.monotonic() == 10.0
    for k in range(30):  # two vehicles' SYSTEM_TIME at 200x, dated on the pace clock
        pace[0] = 10.0 + 0.005 * k
        for sysid in (1, 2):
            clock.observe(sysid, 1_000.0 + k, 1.0 + k, pace[0])
    assert clock.rate == pytest.approx(200.0)
    pace[0] += 0.01  # 10 ms of pace: 2 s of flight, however long the wall took
    assert clock.now_utc_s() == pytest.approx(1_031.0, abs=1e-6)
    with pytest.raises(GcsError, match="follow"):
        clock.follow(lambda: 0.0)


def test_the_pace_heard_is_the_least_newest_report_of_the_vehicles_still_talking() -> None:
    """At 200x: vehicle 2's reports come 20 s of flight behind vehicle 1's (a router between
    them falls behind); a late packet does not take its newest stamp back; one silent for
    HEARD_WALL_S of wall time (a blackout) holds nothing, nor does one whose stamps are on
    another time base; off a pace clock nothing is heard."""
    pace = [0.5]
    clock = MissionClock()
    clock.follow(lambda: pace[0], 1.0, 200.0)
    assert clock.heard_pace_s(10.0, 200.0) == math.inf  # none heard yet
    slack = HEARD_SLACK_S / 200.0  # reports in transit
    clock.heard(1, 100.0, 10.0)
    clock.heard(2, 80.0, 10.0)
    assert clock.heard_pace_s(10.0, 200.0) == pytest.approx(80.0 / 200.0 + slack)
    clock.heard(2, 70.0, 10.1)  # a late packet: talking, and heard to 80 s still
    assert clock.heard_pace_s(10.1 + 0.9 * HEARD_WALL_S, 200.0) == pytest.approx(0.4 + slack)
    clock.heard(1, 100.5, 10.4)
    assert clock.heard_pace_s(10.1 + 1.1 * HEARD_WALL_S, 200.0) == pytest.approx(
        100.5 / 200 + slack
    )
    assert clock.heard_pace_s(10.4 + 1.1 * HEARD_WALL_S, 200.0) == math.inf
    clock.heard(3, 5.0, 11.0)  # 5 s stamps while the pace clock says 100 s of flight
    pace[0] = 5.0 / 200.0 + HEARD_BEHIND_MAX_PACE_S + 0.1
    assert clock.heard_pace_s(11.0, 200.0) == math.inf
    unpaced = MissionClock()
    unpaced.heard(1, 100.0, 10.0)
    assert unpaced.heard_pace_s(10.0, 200.0) == math.inf


async def test_the_ground_station_acknowledges_no_further_than_its_vehicles_were_heard(
    tmp_path: Path,
) -> None:
    """The simulator steps no further than the lead (and the slack for reports in transit)
    past the newest report of the vehicle heard least far; once that one's reports catch up,
    it flies on."""
    path = tmp_path / "pace"
    sim = Lockstep(path, create=True, speedup=200.0, lead_s=1.0)
    clock = MissionClock()
    pacer = follow_lockstep(path, clock)
    try:
        sim.publish(100.0)
        clock.heard(1, 100.0, time.monotonic())
        clock.heard(2, 80.0, time.monotonic())
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == pytest.approx(80.0 + HEARD_SLACK_S)
        assert sim.limit_s() == pytest.approx(81.0 + HEARD_SLACK_S)
        clock.heard(2, 100.0, time.monotonic())
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == pytest.approx(100.0)
        assert sim.limit_s() == pytest.approx(101.0)
    finally:
        pacer.cancel()
        await asyncio.gather(pacer, return_exceptions=True)
        sim.close()


def _paced_team(lead_s: float, true_offsets_s: dict[int, float]) -> MissionClock:
    """Five vehicles' SYSTEM_TIME at 100x on a pace clock, read the way a loaded machine
    reads them in lock step: vehicles 1 and 2 each time they are sent, vehicles 3-5 always
    late by 0.6-0.8 s of flight (within the 1 s lead: the simulator ran on while the loop
    was busy elsewhere). ``true_offsets_s``: clocks set apart on purpose."""
    pace = [0.0]
    clock = MissionClock()
    clock.follow(lambda: pace[0], lead_s)
    rng = np.random.default_rng(5)
    reads = sorted(
        (flight_s + (0.0 if sysid <= 2 else float(rng.uniform(0.6, 0.8))), sysid, flight_s)
        for flight_s in 0.25 * np.arange(400)
        for sysid in range(1, 6)
    )
    for read_flight_s, sysid, flight_s in reads:
        pace[0] = read_flight_s / 100.0
        utc = 1_000.0 + flight_s + true_offsets_s.get(sysid, 0.0)
        clock.observe(sysid, utc, flight_s, pace[0])
    return clock


def test_one_simulators_vehicles_read_late_within_the_lead_keep_one_clock() -> None:
    """Dated on the pace clock, vehicles read 0.6-0.8 s of flight late look that much behind
    the others; at 100x that is more than what wall-time jitter covers (0.5 s), and such an
    offset moved a vehicle's arrival by as much. Within 1.5 leads it is not applied: every
    vehicle's stamps map to its own UTC. A clock really set 4 s apart still is mapped."""
    clock = _paced_team(1.0, {})
    for sysid in range(1, 6):
        assert clock.offset_s(sysid) == 0.0, sysid
        assert clock.utc_of_boot(sysid, 50.0) == pytest.approx(1_050.0, abs=1e-9)
    # Without the lead the same reports read as offsets, and the stamps move.
    unled = _paced_team(0.0, {})
    assert max(abs(unled.offset_s(s) or 0.0) for s in range(1, 6)) > 0.5
    # A clock 4 s ahead is mapped to the team's, lead or not.
    apart = _paced_team(1.0, {4: 4.0})
    assert apart.offset_s(4) == pytest.approx(4.0, abs=0.85)
    assert apart.utc_of_boot(4, 50.0) == pytest.approx(1_050.0, abs=0.85)


def test_the_lead_must_be_a_number_of_seconds() -> None:
    with pytest.raises(ValueError, match="lead_s"):
        MissionClock().follow(lambda: 0.0, math.nan)
