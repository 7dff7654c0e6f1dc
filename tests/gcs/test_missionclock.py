"""gcs.coordination.missionclock: the vehicles' UTC through the local monotonic clock."""

from __future__ import annotations

import asyncio
import itertools
import math
import time

import numpy as np
import pytest

from gcs.coordination.missionclock import (
    ANCHOR_OBSERVATIONS,
    OFFSET_CONFIRM_WALL_S,
    MissionClock,
)
from gcs.errors import GcsError

UTC0 = 1_704_067_200.0


class FakeMono:
    """A monotonic clock the test sets by hand."""

    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def feed(
    clock: MissionClock,
    mono: FakeMono,
    *,
    rate: float,
    n: int,
    sysids: tuple[int, ...] = (1,),
    period_utc_s: float = 1.0,
    boot0_s: dict[int, float] | None = None,
    delays_s: np.ndarray | None = None,
) -> None:
    """``n`` SYSTEM_TIMEs per vehicle, one every ``period_utc_s`` of UTC, true rate ``rate``.

    UTC is ``UTC0 + rate * (mono - 1000)``; each packet arrives ``delays_s[k]`` late.
    """
    boot0 = boot0_s or {}
    k = 0
    for j in range(n):
        utc = UTC0 + j * period_utc_s
        sent = 1000.0 + (utc - UTC0) / rate
        for sid in sysids:
            delay = 0.0 if delays_s is None else float(delays_s[k])
            k += 1
            mono.t = max(mono.t, sent + delay)
            clock.observe(sid, utc, boot0.get(sid, 0.0) + j * period_utc_s, sent + delay)


def truth(mono: FakeMono, rate: float) -> float:
    return UTC0 + rate * (mono.t - 1000.0)


def test_not_synced_until_the_first_system_time() -> None:
    clock = MissionClock(FakeMono())
    assert not clock.synced and clock.rate == 1.0
    with pytest.raises(GcsError, match="not synced"):
        clock.now_utc_s()
    assert clock.utc_of_boot(1, 5.0) is None
    clock.observe(1, UTC0, 10.0, 1000.0)
    assert clock.synced and clock.rate == 1.0  # one observation: rate 1 assumed
    assert clock.now_utc_s() == UTC0
    with pytest.raises(ValueError, match="window"):
        MissionClock(window=1)


@pytest.mark.parametrize("rate", [1.0, 200.0])
def test_rate_and_now_without_jitter(rate: float) -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    feed(clock, mono, rate=rate, n=30)
    assert clock.rate == pytest.approx(rate, rel=1e-9)
    for dt_wall in (0.0, 0.3 / rate, 0.9 / rate):
        mono.t = 1000.0 + 29.0 / rate + dt_wall
        assert clock.now_utc_s() == pytest.approx(truth(mono, rate), abs=1e-6)


def test_rate_follows_a_change_of_speedup_within_the_window() -> None:
    mono = FakeMono()
    clock = MissionClock(mono, window=10)
    for j in range(10):  # 1x
        mono.t = 1000.0 + j
        clock.observe(1, UTC0 + j, float(j), mono.t)
    assert clock.rate == pytest.approx(1.0)
    t0, u0 = mono.t, UTC0 + 9.0
    for j in range(1, 11):  # then 50x
        mono.t = t0 + j * 0.02
        clock.observe(1, u0 + j, 9.0 + j, mono.t)
    assert clock.rate == pytest.approx(50.0)


def test_jitter_at_200x_keeps_now_within_a_fraction_of_a_second() -> None:
    rng = np.random.default_rng(7)
    rate, n, sysids = 200.0, 400, (1, 2, 3)
    # One-sided link delays: mostly ~0.3 ms, 5 % of packets 2 ms late (0.4 s of UTC).
    delays = rng.exponential(0.0003, n * 3) + np.where(rng.random(n * 3) < 0.05, 0.002, 0.0)
    mono = FakeMono()
    clock = MissionClock(mono)
    errors = []
    k = 0
    for j in range(n):
        utc = UTC0 + j
        sent = 1000.0 + j / rate
        for sid in sysids:
            clock.observe(sid, utc, float(j), sent + delays[k])
            k += 1
        if j > 20:
            # Query between this SYSTEM_TIME and the next (wall 5 ms later).
            mono.t = max(mono.t, sent + float(delays[k - 3 : k].max()) + rng.random() * 0.004)
            errors.append(clock.now_utc_s() - truth(mono, rate))
    err = np.array(errors)
    assert clock.rate == pytest.approx(rate, rel=0.1)
    assert np.sqrt(np.mean(err**2)) < 0.15
    assert np.max(np.abs(err)) < 0.6


def test_a_late_newest_packet_does_not_drag_now_back() -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    feed(clock, mono, rate=200.0, n=10)
    mono.t += 0.004
    before = clock.now_utc_s()
    # The next SYSTEM_TIME arrives 3 ms late (0.6 s of UTC): extrapolating from it alone
    # would put now 0.6 s early; the other anchors keep the estimate.
    sent = 1000.0 + 10 / 200.0
    mono.t = sent + 0.003
    clock.observe(1, UTC0 + 10.0, 10.0, mono.t)
    assert clock.now_utc_s() == pytest.approx(truth(mono, 200.0), abs=0.05)
    assert clock.now_utc_s() >= before
    assert ANCHOR_OBSERVATIONS > 1


def test_now_never_decreases() -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    clock.observe(1, UTC0, 0.0, 1000.0)
    mono.t = 1001.0
    clock.observe(1, UTC0 + 1.0, 1.0, 1001.0)
    mono.t = 1005.0
    high = clock.now_utc_s()  # rate 1: UTC0 + 5
    assert high == pytest.approx(UTC0 + 5.0)
    # The vehicles turn out to run slower: the estimate falls; the clock holds still.
    mono.t = 1010.0
    clock.observe(1, UTC0 + 2.0, 2.0, 1010.0)
    assert clock.rate < 0.5
    assert clock.now_utc_s() == high
    values = []
    for _ in range(200):
        mono.t += 0.5
        values.append(clock.now_utc_s())
    assert all(b >= a for a, b in itertools.pairwise(values))
    assert values[-1] > high


def test_two_vehicles_keep_their_own_boot_offsets() -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    feed(clock, mono, rate=200.0, n=5, sysids=(1, 2), boot0_s={1: 0.0, 2: 123.456})
    assert clock.utc_of_boot(1, 2.5) == pytest.approx(UTC0 + 2.5)
    assert clock.utc_of_boot(2, 123.456 + 2.5) == pytest.approx(UTC0 + 2.5)
    assert clock.utc_of_boot(3, 1.0) is None
    assert clock.rate == pytest.approx(200.0)
    assert clock.rejected == 0 and clock.accepted == 10


def test_bad_duplicate_reordered_and_reset_samples() -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    feed(clock, mono, rate=1.0, n=10)  # UTC0 .. UTC0 + 9, boot 0 .. 9
    rate = clock.rate
    for bad in (
        (1, math.nan, 1.0, 1000.0),
        (1, UTC0 + 20, math.inf, 1000.0),
        (1, 0.0, 1.0, 1000.0),  # no GPS time yet
        (1, UTC0 + 20, -1.0, 1000.0),
        (1, UTC0 + 9.0, 9.0, 1009.5),  # duplicate
        (1, UTC0 + 8.5, 8.5, 1009.6),  # reordered
        (1, UTC0 + 3.0, 3.0, 1009.7),  # very late, same boot offset: not a reset
    ):
        clock.observe(*bad)
    assert clock.rejected == 7 and clock.resets == 0
    assert clock.rate == rate and clock.utc_of_boot(1, 9.0) == pytest.approx(UTC0 + 9.0)
    # The vehicle's time is set back by 100 s (boot time runs on): a new timeline.
    clock.observe(1, UTC0 - 90.0, 10.0, 1010.0)
    assert clock.rejected == 8 and clock.resets == 1
    assert clock.utc_of_boot(1, 10.0) == pytest.approx(UTC0 - 90.0)
    mono.t = 1011.0
    clock.observe(1, UTC0 - 89.0, 11.0, 1011.0)
    assert clock.rejected == 8 and clock.accepted == 11


async def test_sleep_until_and_sleep_at_200x_in_real_time() -> None:
    """On time.monotonic and asyncio.sleep: a sleep never ends before the UTC asked for. Each
    SYSTEM_TIME is stamped with the monotonic time it was sent at (a link without delay), so
    the clock's estimate is the vehicle's UTC however late a busy machine runs the tasks; how
    long past the target a sleep returns is the scheduler's, bounded only as a hang."""
    clock = MissionClock()  # time.monotonic
    rate = 200.0
    t0 = time.monotonic()

    def utc_now() -> float:
        return UTC0 + rate * (time.monotonic() - t0)

    async def vehicle() -> None:  # SYSTEM_TIME at 1 Hz of simulated time
        j = 0
        while True:
            clock.observe(1, UTC0 + j, float(j), t0 + j / rate)
            j += 1
            await asyncio.sleep(max(0.0, t0 + j / rate - time.monotonic()))

    task = asyncio.create_task(vehicle())
    try:
        async with asyncio.timeout(30.0):  # a hang guard only
            while clock.rate == 1.0:
                await asyncio.sleep(0.001)
        assert clock.rate == pytest.approx(rate)
        before = utc_now()
        estimate = clock.now_utc_s()
        after = utc_now()
        assert before - 1e-3 <= estimate <= after + 1e-3  # the vehicle's UTC, read between
        w0 = time.monotonic()
        target = utc_now() + 20.0  # 0.1 s of wall
        async with asyncio.timeout(30.0):
            await clock.sleep_until(target)
        waited = time.monotonic() - w0
        assert clock.now_utc_s() >= target
        assert utc_now() >= target - 1e-3  # not early
        assert waited > 0.1 - 1e-3
        w0 = time.monotonic()
        start = clock.now_utc_s()
        async with asyncio.timeout(30.0):
            await clock.sleep(10.0)
        assert clock.now_utc_s() >= start + 10.0
        assert utc_now() >= start + 10.0 - 1e-3
        assert time.monotonic() - w0 > 0.05 - 1e-3
        await clock.sleep(0.0)
        await clock.sleep(-3.0)
        with pytest.raises(ValueError, match="not a number"):
            await clock.sleep(math.nan)
        with pytest.raises(ValueError, match="max_wall_step_s"):
            await clock.sleep_until(target, max_wall_step_s=0.0)
    finally:
        task.cancel()


async def test_sleep_until_with_an_advancing_fake_clock() -> None:
    mono = FakeMono(0.0)
    clock = MissionClock(mono)
    with pytest.raises(GcsError, match="not synced"):
        await clock.sleep_until(UTC0)
    clock.observe(1, UTC0, 0.0, 0.0)
    mono.t = 0.1
    clock.observe(1, UTC0 + 1.0, 1.0, 0.1)  # rate 10

    async def advance() -> None:
        while True:
            await asyncio.sleep(0.001)
            mono.t += 0.05  # 0.5 s of UTC per real millisecond

    task = asyncio.create_task(advance())
    try:
        async with asyncio.timeout(5):
            await clock.sleep_until(UTC0 + 30.0, max_wall_step_s=0.002)
        assert clock.now_utc_s() >= UTC0 + 30.0
        assert mono.t * 10.0 < 30.0 + 2.0
        # Already past: returns at once.
        await clock.sleep_until(UTC0)
    finally:
        task.cancel()


def _feed_offsets(
    clock: MissionClock,
    mono: FakeMono,
    *,
    rate: float,
    n: int,
    offsets_s: dict[int, float],
    delays_s: np.ndarray,
) -> None:
    """Like :func:`feed`, each vehicle reporting true UTC plus its own offset."""
    k = 0
    for j in range(n):
        utc = UTC0 + j
        sent = 1000.0 + (utc - UTC0) / rate
        for sid, off in offsets_s.items():
            mono.t = max(mono.t, sent + float(delays_s[k]))
            clock.observe(sid, utc + off, float(j), sent + float(delays_s[k]))
            k += 1


def test_vehicles_with_their_own_utc_are_mapped_to_the_team_clock() -> None:
    """Simulators started apart: +7 s and -4 s. The team clock is the median vehicle's, each
    vehicle's stamps are mapped to it, and each offset is reported."""
    mono = FakeMono()
    clock = MissionClock(mono)
    rate = 200.0
    offsets = {1: 0.0, 2: 7.0, 3: -4.0}
    delays = np.random.default_rng(3).uniform(0.0002, 0.003, 3 * 120)
    _feed_offsets(clock, mono, rate=rate, n=120, offsets_s=offsets, delays_s=delays)
    for sid, off in offsets.items():
        got = clock.offset_s(sid)
        assert got is not None and got == pytest.approx(off, abs=0.25)
        # GLOBAL_POSITION_INT at boot 100.5 s is true UTC0 + 100.5 on the team clock
        assert clock.utc_of_boot(sid, 100.5) == pytest.approx(UTC0 + 100.5, abs=0.25)
    assert clock.now_utc_s() == pytest.approx(truth(mono, rate), abs=0.6)
    assert clock.rate == pytest.approx(rate, rel=0.05)


def test_a_vehicle_without_utc_is_named_and_mapped_at_reception() -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    clock.observe_no_utc(4, 3.0, 1000.0)  # before any UTC: nothing to map to
    assert clock.rejected == 1 and clock.without_utc == frozenset()
    feed(clock, mono, rate=1.0, n=10)
    # Vehicle 4 booted at true UTC0 + 2 (its boot 0); its reports arrive 0.1-0.3 s late.
    for j, delay in enumerate((0.3, 0.1, 0.2)):
        boot = 5.0 + j
        clock.observe_no_utc(4, boot, 1000.0 + 2.0 + boot + delay)
    assert clock.without_utc == frozenset({4})
    assert clock.offset_s(4) is None
    got = clock.utc_of_boot(4, 8.0)
    assert got is not None and got == pytest.approx(UTC0 + 10.0 + 0.1, abs=1e-6)
    # Once it reports UTC it is an ordinary vehicle.
    clock.observe(4, UTC0 + 9.5, 7.5, 1009.6)
    assert clock.without_utc == frozenset()


def test_offsets_hold_through_a_queued_link_and_a_stalled_loop_at_200x() -> None:
    """One vehicle's reports arrive 70 ms late for 30 s of UTC (its link queued), later
    everyone's for 20 s (the ground station's loop stalled): 14 s of UTC at 200x. Offsets
    stay within 0.1 s, so no vehicle's fixes are dated seconds off."""
    mono = FakeMono()
    clock = MissionClock(mono)
    rate = 200.0
    offsets = {1: 0.0, 2: 7.0, 3: -4.0}
    rng = np.random.default_rng(1)
    worst = 0.0
    for j in range(2400):
        utc = UTC0 + j
        sent = 1000.0 + j / rate
        for sid, off in offsets.items():
            delay = float(rng.uniform(0.0002, 0.002))
            if 1000 < j < 1030 and sid == 3:
                delay += 0.07
            if 2000 < j < 2020:
                delay += 0.07
            if rng.random() < 0.1:
                continue  # lost
            mono.t = max(mono.t, sent + delay)
            clock.observe(sid, utc + off, float(j), sent + delay)
        if j > 100:
            for sid, off in offsets.items():
                got = clock.offset_s(sid)
                assert got is not None
                worst = max(worst, abs(got - off))
    assert worst < 0.1
    assert clock.rate == pytest.approx(rate, rel=0.02)


def test_a_clock_that_really_steps_forward_is_followed() -> None:
    mono = FakeMono()
    clock = MissionClock(mono)
    delays = np.full(3 * 200, 0.0005)
    _feed_offsets(clock, mono, rate=200.0, n=100, offsets_s={1: 0.0, 2: 0.0, 3: 0.0},
                  delays_s=delays)  # fmt: skip
    assert clock.offset_s(3) == pytest.approx(0.0, abs=0.05)
    # Vehicle 3's clock is set 3 s ahead (forward: not a reset); the others run on. It is
    # followed once it has lasted OFFSET_CONFIRM_WALL_S (and its reports), not before.
    moved_at = None
    for j in range(100, 1100):
        utc = UTC0 + j
        sent = 1000.0 + j / 200.0
        for sid in (1, 2, 3):
            mono.t = max(mono.t, sent + 0.0005)
            clock.observe(sid, utc + (3.0 if sid == 3 else 0.0), float(j), sent + 0.0005)
        if moved_at is None and abs((clock.offset_s(3) or 0.0) - 3.0) <= 0.05:
            moved_at = sent
    assert moved_at is not None, clock.offset_s(3)
    step_at = 1000.0 + 100 / 200.0
    assert OFFSET_CONFIRM_WALL_S <= moved_at - step_at <= OFFSET_CONFIRM_WALL_S + 0.5


def test_a_burst_of_delayed_reports_from_one_vehicle_does_not_move_its_offset() -> None:
    """At 200x one vehicle's reports come 5 ms late (1 s of its UTC) for 0.5 s of wall time,
    a stalled reader's: its offset stays, though the burst is far longer than OFFSET_CONFIRM
    reports (one simulator gave the three vehicles one clock)."""
    mono = FakeMono()
    clock = MissionClock(mono)
    for j in range(0, 600):
        utc = UTC0 + j
        sent = 1000.0 + j / 200.0
        for sid in (1, 2, 3):
            late = 0.005 if sid == 3 and 300 <= j < 400 else 0.0005
            mono.t = max(mono.t, sent + late)
            clock.observe(sid, utc, float(j), sent + late)
        if j >= 100:
            assert clock.offset_s(3) == pytest.approx(0.0, abs=0.05), j


def test_a_backlog_read_after_a_stalled_loop_dates_no_clock() -> None:
    """The loop stalls 820 ms at 100x: 82 reports per vehicle wait in the sockets, then are
    read vehicle after vehicle within a millisecond. Seen in a two-flight rehearsal, the
    backlog read as a clock 27 s off and moved the team time; it must date nothing."""
    mono = FakeMono()
    clock = MissionClock(mono)
    rate = 100.0
    offsets = {1: 0.0, 2: 7.0, 3: -4.0}
    worst = 0.0
    backlog: list[tuple[int, float, float]] = []
    for j in range(600):
        utc = UTC0 + j
        sent = 1000.0 + j / rate
        stalled = 300 <= j < 382
        if j == 382:  # the loop runs again: the sockets are read one after another
            mono.t = max(mono.t, sent)
            for sid, u, boot in sorted(backlog, key=lambda r: r[0]):
                mono.t += 0.00001
                clock.observe(sid, u, boot, mono.t)
                for other, off in offsets.items():
                    got = clock.offset_s(other)
                    assert got is not None
                    worst = max(worst, abs(got - off))
        for sid, off in offsets.items():
            if stalled:
                backlog.append((sid, utc + off, float(j)))
                continue
            mono.t = max(mono.t, sent + 0.0005)
            clock.observe(sid, utc + off, float(j), mono.t)
    assert worst < 0.1
    assert clock.backlogged > 200
    for sid in offsets:
        assert clock.utc_of_boot(sid, 590.0) == pytest.approx(UTC0 + 590.0, abs=0.1)


@pytest.mark.parametrize(("rate", "applied"), [(200.0, False), (1.0, True)])
def test_an_offset_within_the_reception_jitter_at_the_rate_is_not_applied(
    rate: float, applied: bool
) -> None:
    """Vehicle 3 reads 0.6 s ahead. At 200x that is 3 ms of reception: within what jitter
    makes of one simulator's clock (OFFSET_JITTER_WALL_S x rate = 1 s), so its stamps are not
    moved; live, 0.6 s is a wrong clock, mapped. A 3 s offset is applied at either rate."""
    for off, expect in ((0.6, applied), (3.0, True)):
        mono = FakeMono()
        clock = MissionClock(mono)
        offsets = {1: 0.0, 2: 0.0, 3: off}
        _feed_offsets(clock, mono, rate=rate, n=100, offsets_s=offsets,
                      delays_s=np.full(300, 0.0005))  # fmt: skip
        want = off if expect else 0.0
        assert clock.offset_s(3) == pytest.approx(want, abs=0.05), (rate, off)
        utc = clock.utc_of_boot(3, 50.0)
        assert utc == pytest.approx(UTC0 + 50.0 + off - want, abs=0.05)


def _team_utc_by_definition(clock: MissionClock, mono_s: float) -> float:
    """The team's UTC from the clock's state, recomputed from the reports each time: the
    lower median over the vehicles of the latest extrapolation of each one's newest reports,
    less its applied offset."""
    rate = clock.rate
    estimates = []
    for vc in clock._vehicles.values():
        if not (vc.has_utc and vc.recent):
            continue
        newest = list(vc.recent)[-ANCHOR_OBSERVATIONS:]
        own = max(o.utc_s + rate * (mono_s - o.rx_mono_s) for o in newest)
        estimates.append(own - clock._applied(vc))
    estimates.sort()
    return estimates[(len(estimates) - 1) // 2]


def test_the_team_utc_read_between_reports_is_what_the_reports_say_at_every_read() -> None:
    """The team's UTC is read at every fix and recomputed only when a report comes: after any
    interleaving of reports (delayed, from vehicles with their own offsets, one reset) and
    reads, it equals the definition recomputed from scratch."""
    rng = np.random.default_rng(7)
    mono = FakeMono()
    clock = MissionClock(mono, window=8)
    offsets = {1: 0.0, 2: 7.0, 3: -4.0, 4: 0.3}
    rate = 200.0
    for step in range(600):
        mono.t += float(rng.uniform(0.0, 0.004))
        sid = int(rng.integers(1, 5))
        utc_sent = UTC0 + rate * (mono.t - 1000.0) + offsets[sid]
        if step == 300:
            utc_sent -= 50.0  # vehicle sid's clock set back: it is reset
        delay_s = float(rng.exponential(0.001))
        clock.observe(sid, utc_sent - rate * delay_s, 10.0 + mono.t, mono.t)
        for _ in range(int(rng.integers(0, 4))):
            mono.t += float(rng.uniform(0.0, 0.001))
            assert clock._team_at(mono.t) == pytest.approx(
                _team_utc_by_definition(clock, mono.t), abs=1e-6
            )
    assert clock.resets == 1
