"""A planning job or a mission upload in lock step takes no flight time: while the mission
clock holds (:meth:`gcs.coordination.missionclock.MissionClock.hold`, the runner's planning
jobs and in-flight uploads), the ground station acknowledges no pace time past where the hold
began, so the simulator waits there however long the job takes; released, it flies on. Off a
pace clock a hold is nothing (real vehicles do not wait)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace

import pytest

from gcs.coordination import actions as act
from gcs.coordination import runner as runner_module
from gcs.coordination.missionclock import MissionClock
from gcs.coordination.runner import FlightRunner
from gcs.errors import GcsError
from gcs.service.stubs import follow_lockstep
from planner.scenario import load_scenario
from sitl_stub.lockstep import Lockstep

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_three_uav.yaml"


@contextlib.asynccontextmanager
async def _paced(tmp_path: Path) -> AsyncIterator[tuple[Lockstep, MissionClock]]:
    """A simulator's lock step at 200x (lead 1 s) and a mission clock following it."""
    path = tmp_path / "pace"
    sim = Lockstep(path, create=True, speedup=200.0, lead_s=1.0)
    clock = MissionClock()
    pacer = follow_lockstep(path, clock)
    try:
        yield sim, clock
    finally:
        pacer.cancel()
        await asyncio.gather(pacer, return_exceptions=True)
        sim.close()


async def test_a_held_clock_acknowledges_nothing_past_the_hold_and_a_release_lets_it_on(
    tmp_path: Path,
) -> None:
    async with _paced(tmp_path) as (sim, clock):
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


async def test_a_clock_held_at_a_utc_stops_the_simulator_there_until_let_go(
    tmp_path: Path,
) -> None:
    """A rehearsal paused at a mission time (:meth:`MissionClock.hold_at`): the lock step
    acknowledges pace time up to the one at which the team's UTC reaches it, and no further,
    until let go; a planning job's hold inside it holds it where it is."""
    utc0 = 1.7e9
    async with _paced(tmp_path) as (sim, clock):
        for flown_s in (100.0, 120.0):  # the vehicle's UTC at 200 flight s per pace s
            sim.publish(flown_s)
            clock.observe(1, utc0 + flown_s, flown_s, flown_s / 200.0)
        clock.hold_at(utc0 + 150.0)
        assert clock.held_pace_s == pytest.approx(150.0 / 200.0)
        sim.publish(149.0)
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == pytest.approx(149.0)
        sim.publish(151.0)  # the simulator's lead took it past the pause
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == pytest.approx(150.0)
        assert clock.now_utc_s() == pytest.approx(utc0 + 151.0)
        clock.hold()
        clock.release()
        assert clock.held_pace_s == pytest.approx(150.0 / 200.0)  # still paused
        clock.hold_at(None)
        await asyncio.sleep(0.02)
        assert clock.held_pace_s is None
        assert sim.acknowledged_s() * 200.0 == pytest.approx(151.0)


def test_off_a_pace_clock_a_hold_is_nothing() -> None:
    clock = MissionClock()
    clock.hold()
    assert clock.held_pace_s is None
    clock.release()
    assert clock.held_pace_s is None
    clock.observe(1, 1.7e9, 0.0, 0.0)
    clock.hold_at(1.7e9 + 10.0)
    assert clock.held_pace_s is None
    with pytest.raises(ValueError, match="utc_s"):
        clock.hold_at(float("nan"))


class _SlowUpload:
    """A vehicle whose mission upload takes as long as the test lets it (wall time)."""

    def __init__(self) -> None:
        self.started = asyncio.Event()
        self.finish = asyncio.Event()

    async def upload_mission(self, items: list[object], **_: object) -> None:
        self.started.set()
        await self.finish.wait()


def _synced(clock: MissionClock) -> None:
    """The simulator's SYSTEM_TIME for its first 100 s of flight, received as sent (pace time
    = flight time / 200)."""
    for t_s in range(101):
        clock.observe(1, 1.7e9 + t_s, float(t_s), t_s / 200.0)


def _upload(vehicle_id: str) -> act.Upload:
    return act.Upload(
        vehicle_id=vehicle_id,
        mission=SimpleNamespace(items=()),  # type: ignore[arg-type]
        schedule=None,  # type: ignore[arg-type]
        keep_seq=None,
        what="after POPUP1",
        in_flight=True,
    )


@contextlib.asynccontextmanager
async def _uploading(
    tmp_path: Path,
) -> AsyncIterator[tuple[Lockstep, MissionClock, asyncio.Task[None], _SlowUpload, float]]:
    """A runner on a simulator's pace clock at 200x, 100 s into the flight, uploading a
    mission to a vehicle that answers when the test says so: the simulator, the clock, the
    upload, the vehicle and the upload's share of the lead (flight s)."""
    path = tmp_path / "pace"
    sim = Lockstep(path, create=True, speedup=200.0, lead_s=1.0)
    clock = MissionClock()
    pacer = follow_lockstep(path, clock)
    runner = FlightRunner(load_scenario(PAPER), clock)
    vehicle = _SlowUpload()
    runner.vehicles = {"UAV1": vehicle}  # type: ignore[dict-item]
    _synced(clock)
    upload = None
    try:
        sim.publish(100.0)
        await asyncio.sleep(0.02)
        upload = asyncio.create_task(runner._upload(_upload("UAV1")))
        await vehicle.started.wait()
        yield sim, clock, upload, vehicle, 0.5 * runner._lead_s()
    finally:
        if upload is not None:
            upload.cancel()
        pacer.cancel()
        await asyncio.gather(*(t for t in (pacer, upload) if t is not None), return_exceptions=True)
        sim.close()


async def test_an_upload_in_flight_in_lock_step_takes_no_flight_time(tmp_path: Path) -> None:
    """A mission going up in flight holds the simulator: its round trips and resends are
    timed in wall time, and on a busy machine a 52-item upload after a pop-up outlasted its
    78 s of flight at 200x (the vehicle was held short of the zone much later, and the team
    time moved 375 s). Once on board the flight goes on."""
    async with _uploading(tmp_path) as (sim, clock, upload, vehicle, _):
        assert clock.held_pace_s == 100.0 / 200.0
        sim.publish(100.8)
        await asyncio.sleep(0.3)  # 60 s of flight at 200x, had the simulator not waited
        assert sim.acknowledged_s() * 200.0 == 100.0
        vehicle.finish.set()
        await upload
        assert clock.held_pace_s is None
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == pytest.approx(100.8)


async def test_a_vehicle_that_does_not_answer_an_upload_holds_the_flight_only_so_long(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A vehicle that does not answer (a blackout, which ends in flight time) must not stop
    the flight: the hold ends after :data:`PACED_UPLOAD_HOLD_WALL_S` of wall time, and the
    upload then fails when its share of the lead has been flown."""
    monkeypatch.setattr(runner_module, "PACED_UPLOAD_HOLD_WALL_S", 0.1)
    async with _uploading(tmp_path) as (sim, clock, upload, _, budget_s):
        await asyncio.sleep(0.3)
        assert clock.held_pace_s is None
        t_s = 100.0
        while not upload.done() and t_s < 100.0 + 2.0 * budget_s:
            t_s += 1.0
            sim.publish(t_s)
            await asyncio.sleep(0.005)
        with pytest.raises(GcsError, match=f"within {budget_s:.0f} s of flight"):
            await upload
        assert 100.0 + budget_s <= t_s <= 100.0 + budget_s + 2.0


class _SlowLaunch:
    """A vehicle on the ground whose arming and mode change answer when the test says so."""

    def __init__(self) -> None:
        self.state = SimpleNamespace(armed=False)
        self.link = SimpleNamespace(counters=SimpleNamespace(rtt_s=0.001))
        self.asked: list[str] = []
        self.answer = asyncio.Event()

    async def arm(self, **_: object) -> None:
        self.asked.append("arm")
        await self.answer.wait()

    async def set_mode(self, mode: str, **_: object) -> None:
        self.asked.append(mode)


@pytest.mark.parametrize("silent", [False, True], ids=["heard", "silent"])
async def test_a_launch_in_lock_step_takes_no_flight_time_unless_its_vehicle_is_silent(
    tmp_path: Path, silent: bool
) -> None:
    """The launch's arm and AUTO hold the simulator while they go (timed in wall time, a
    busy machine's launch came 3.2 s of flight late at 200x, and its vehicle missed its slot
    by 1 s); a vehicle whose reports have stopped holds nothing (its blackout ends in flight
    time)."""
    async with _paced(tmp_path) as (sim, clock):
        runner = FlightRunner(load_scenario(PAPER), clock)
        vehicle = _SlowLaunch()
        runner.vehicles = {"UAV1": vehicle}  # type: ignore[dict-item]
        members = {"UAV1": SimpleNamespace(link_silent=silent)}
        runner.team = SimpleNamespace(members=members)  # type: ignore[assignment]
        fed: list[act.Input] = []
        runner._feed = fed.append  # type: ignore[method-assign]
        _synced(clock)
        sim.publish(100.0)
        await asyncio.sleep(0.02)
        launch = asyncio.create_task(runner._launch(act.Launch("UAV1", airborne=False)))
        await asyncio.sleep(0.01)
        assert vehicle.asked == ["arm"]
        sim.publish(100.8)
        await asyncio.sleep(0.05)  # 10 s of flight at 200x, had the simulator not waited
        assert sim.acknowledged_s() * 200.0 == pytest.approx(100.8 if silent else 100.0)
        vehicle.answer.set()
        await launch
        assert vehicle.asked == ["arm", "AUTO"]
        assert fed == [act.Launched("UAV1", None)]
        assert clock.held_pace_s is None
        await asyncio.sleep(0.02)
        assert sim.acknowledged_s() * 200.0 == pytest.approx(100.8)
