"""Lock step (:mod:`sitl_stub.lockstep`): the simulation steps no further than the lead beyond
what the ground station acknowledged, runs on by itself once the acknowledgements stop, and
publishes its pace clock; the ground station's mission clock reads that clock."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path

import pytest

from gcs.coordination.missionclock import MissionClock
from gcs.errors import GcsError
from sitl_stub.api import SimTeam
from sitl_stub.lockstep import STALE_WALL_S, Lockstep

HOME = (46.0, 8.0, 500.0)


def test_the_clock_file_is_shared_and_an_old_acknowledgement_holds_nothing(
    tmp_path: Path,
) -> None:
    sim = Lockstep(tmp_path / "pace", create=True, speedup=200.0)
    ground = Lockstep(tmp_path / "pace")
    assert ground.speedup == 200.0
    assert sim.limit_s(0.5) == math.inf  # no ground station yet
    sim.publish(40.0)
    assert ground.pace_s() == pytest.approx(0.2)
    ground.acknowledge()
    now = time.monotonic()
    assert sim.limit_s(0.5, now) == pytest.approx(40.5)
    assert sim.limit_s(0.5, now + STALE_WALL_S + 0.1) == math.inf
    ground.release()
    assert sim.limit_s(0.5, now) == math.inf
    ground.close()
    assert ground.pace_s() == pytest.approx(0.2)  # reads on as it last was
    sim.close()
    (tmp_path / "short").write_bytes(b"\0" * 8)
    with pytest.raises(ValueError, match="not a lock-step file"):
        Lockstep(tmp_path / "short")


async def test_the_simulation_waits_for_the_ground_station_then_runs_on_without_it(
    tmp_path: Path,
) -> None:
    async with SimTeam.start(homes=[HOME], tcp_base=0, speedup=200.0) as team:
        team.server.lockstep = Lockstep(tmp_path / "pace", create=True, speedup=200.0)
        team.server.lockstep_lead_s = 0.5
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
