"""Link faults: loss, latency, duplication, reordering and blackout, seeded."""

from __future__ import annotations

import numpy as np
import pytest

from sitl_stub.link import DelayQueue, Faults, FaultyLink


class FakeSim:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def make(seed: int = 1, **faults: float) -> tuple[FaultyLink, FakeSim]:
    sim = FakeSim()
    link = FaultyLink(np.random.default_rng(seed), sim)
    link.faults(**faults)
    return link, sim


def test_clean_link_delivers_immediately() -> None:
    link, _ = make()
    assert link.transparent
    assert link.schedule(5.0, outbound=True) == [5.0]
    assert link.outbound.passed == 1


def test_loss_rate_matches_probability() -> None:
    link, _ = make(loss=0.3)
    delivered = sum(bool(link.schedule(0.0, outbound=True)) for _ in range(10_000))
    assert 0.68 < delivered / 10_000 < 0.72
    assert link.outbound.lost == 10_000 - delivered


def test_same_seed_gives_same_losses() -> None:
    a, _ = make(seed=7, loss=0.5)
    b, _ = make(seed=7, loss=0.5)
    assert [a.schedule(0, True) for _ in range(200)] == [b.schedule(0, True) for _ in range(200)]


def test_latency_delays_delivery_in_wall_time() -> None:
    link, _ = make(latency_ms=250)
    assert link.schedule(1.0, outbound=False) == [pytest.approx(1.25)]


def test_duplication_delivers_two_copies() -> None:
    link, _ = make(duplicate=1.0)
    assert len(link.schedule(0.0, outbound=True)) == 2
    assert link.outbound.duplicated == 1


def test_reordered_packet_is_overtaken_by_the_next() -> None:
    link, _ = make(reorder=1.0, reorder_delay_ms=100)
    first = link.schedule(0.0, outbound=True)[0]
    link.faults(reorder=0.0)
    second = link.schedule(0.01, outbound=True)[0]
    assert second < first


def test_blackout_drops_everything_for_simulated_duration() -> None:
    link, sim = make()
    link.blackout(30.0)
    sim.t = 29.9
    assert link.schedule(0.0, outbound=True) == []
    assert link.schedule(0.0, outbound=False) == []
    sim.t = 30.0
    assert link.schedule(0.0, outbound=True) == [0.0]
    assert link.outbound.blacked_out == 1 and link.inbound.blacked_out == 1


def test_faults_change_at_run_time_and_clear() -> None:
    link, _ = make(loss=1.0)
    assert link.schedule(0.0, True) == []
    link.clear()
    assert link.schedule(0.0, True) == [0.0]


@pytest.mark.parametrize("bad", [{"loss": 1.5}, {"latency_ms": -1.0}, {"reorder": float("nan")}])
def test_invalid_fault_settings_are_rejected(bad: dict[str, float]) -> None:
    link, _ = make()
    with pytest.raises(ValueError):
        link.faults(**bad)


def test_unknown_fault_name_is_rejected() -> None:
    link, _ = make()
    with pytest.raises(TypeError, match="jitter"):
        link.faults(jitter=1.0)


def test_faults_value_is_frozen() -> None:
    assert Faults(loss=0.1).clean is False and Faults().clean


def test_delay_queue_releases_in_time_order() -> None:
    q: DelayQueue[str] = DelayQueue()
    q.push(2.0, "b")
    q.push(1.0, "a")
    q.push(2.0, "c")
    assert q.next_due() == 1.0
    assert q.pop_due(1.5) == ["a"]
    assert q.pop_due(2.0) == ["b", "c"]
    assert len(q) == 0 and q.next_due() is None


def test_losses_follow_the_generators_sequence_of_random_draws() -> None:
    link, _ = make(seed=7, loss=0.5)
    draws = np.random.default_rng(7).random(1000)  # one draw per packet: only loss is on
    delivered = [bool(link.schedule(0.0, outbound=i % 2 == 0)) for i in range(1000)]
    assert delivered == [bool(d >= 0.5) for d in draws]
