"""A planning job in lock step takes no flight time: while the mission clock holds
(:meth:`gcs.coordination.missionclock.MissionClock.hold`, the runner's planning jobs), the
ground station acknowledges no pace time past where the hold began, so the simulator waits
there however long the job takes; released, it flies on. Off a pace clock a hold is nothing
(real vehicles do not wait)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from gcs.coordination.missionclock import MissionClock
from gcs.service.stubs import follow_lockstep
from sitl_stub.lockstep import Lockstep


async def test_a_held_clock_acknowledges_nothing_past_the_hold_and_a_release_lets_it_on(
    tmp_path: Path,
) -> None:
    path = tmp_path / "pace"
    sim = Lockstep(path, create=True, speedup=200.0, lead_s=1.0)
    clock = MissionClock()
    pacer = follow_lockstep(path, clock)
    try:
        sim.publish(100.0)  # the simulator has flown 100 s
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == 100.0
        clock.hold()
        clock.hold()  # two jobs at once: held until both end
        assert clock.held_pace_s == 100.0 / 200.0
        sim.publish(100.5)  # within the lead of the acknowledged pace time
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == 100.0
        assert sim.limit_s() == 101.0  # the simulator steps no further than the lead
        clock.release()
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == 100.0 and clock.held_pace_s is not None
        clock.release()
        await asyncio.sleep(0.02)
        assert clock.held_pace_s is None
        assert sim.acknowledged_s() * 200.0 == pytest.approx(100.5)
    finally:
        pacer.cancel()
        await asyncio.gather(pacer, return_exceptions=True)
        sim.close()


def test_off_a_pace_clock_a_hold_is_nothing() -> None:
    clock = MissionClock()
    clock.hold()
    assert clock.held_pace_s is None
    clock.release()
    assert clock.held_pace_s is None
