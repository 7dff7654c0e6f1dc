"""The simulated clock: fixed steps at speed-up x wall time, slipping when late."""

from __future__ import annotations

import pytest

from sitl_stub.clock import SimClock


def run(clock: SimClock, wall_s: float) -> int:
    n = clock.steps_due(wall_s)
    for _ in range(n):
        clock.advance()
    return n


def test_steps_follow_speedup() -> None:
    clock = SimClock(speedup=100.0, step_s=0.1, start_utc_s=1000.0)
    clock.start(10.0)
    assert run(clock, 10.05) == 50
    assert clock.sim_time_s == pytest.approx(5.0)
    assert clock.utc_s == pytest.approx(1005.0)
    assert clock.time_boot_ms == 5000
    assert clock.stats(10.05).rate_fraction == pytest.approx(1.0)


def test_late_clock_slips_instead_of_spiralling() -> None:
    clock = SimClock(speedup=10.0, step_s=0.1, max_lag_s=0.5)
    clock.start(0.0)
    assert run(clock, 100.0) == 50
    stats = clock.stats(100.0)
    assert stats.slipped_sim_s == pytest.approx(995.0)
    assert stats.rate_fraction < 0.01
    assert run(clock, 100.1) == 10


def test_wall_until_next_step() -> None:
    clock = SimClock(speedup=2.0, step_s=0.1)
    clock.start(0.0)
    assert clock.wall_until_next_step(0.0) == pytest.approx(0.05)
    run(clock, 0.05)
    assert clock.wall_until_next_step(0.06) == pytest.approx(0.04)


@pytest.mark.parametrize("speedup", [0.0, -1.0, float("inf")])
def test_invalid_speedup_is_rejected(speedup: float) -> None:
    with pytest.raises(ValueError, match="speedup"):
        SimClock(speedup=speedup)
