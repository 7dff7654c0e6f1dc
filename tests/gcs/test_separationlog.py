"""The flight record's ``separation_events`` (:mod:`gcs.coordination.separationlog`): each
conflict event read as its kind and what was done, with the pair's least 3-D distance over
the encounter measured here from the tracks by the test's own arithmetic."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.separationlog import ENCOUNTER_AFTER_S, separation_events
from gcs.coordination.tracks import TruthSample

START_UTC = 1_800_000_000.0
LAT0, LON0 = 46.0, 8.0
M_PER_DEG_LAT = 111_132.954 - 559.822 * math.cos(2 * math.radians(LAT0))
M_PER_DEG_LON = 111_412.84 * math.cos(math.radians(LAT0))


def _track(east0_m: float, ve_m_s: float, north_m: float, alt_m: float) -> list[TruthSample]:
    """A vehicle flying east along ``north_m`` at ``ve_m_s``, a sample a second for 600 s."""
    return [
        TruthSample(
            START_UTC + t,
            LAT0 + north_m / M_PER_DEG_LAT,
            LON0 + (east0_m + ve_m_s * t) / M_PER_DEG_LON,
            alt_m,
            25.0,
            abs(ve_m_s),
            True,
            False,
        )
        for t in range(600)
    ]


def _event(kind: EventKind, vehicle: str | None, t_s: float, **payload: object) -> FlightEvent:
    return FlightEvent(START_UTC + t_s, t_s, vehicle, kind, f"{kind} at {t_s}", payload=payload)


def _closest_m(
    east_a: float, east_b: float, va: float, vb: float, dn: float, dz: float, t0: float, t1: float
) -> float:
    """The pair's least 3-D distance at the whole seconds from ``t0`` to ``t1``, here."""
    t = np.arange(math.ceil(t0), math.floor(t1) + 1)
    de = (east_a + va * t) - (east_b + vb * t)
    return float(np.sqrt(de**2 + dn**2 + dz**2).min())


def an_encounter() -> list[FlightEvent]:
    """Every kind of separation event of one pair (A, B) whose closest pass, 224 m, is at
    300 s (resolved by speed, by height and by a re-plan's layer), and two events that are
    none."""
    replan = {"pair": ["A", "B"], "distance_m": 224.0, "at_s": 300.0}
    return [
        _event(EventKind.CONFLICT, "A", 250.0, other="B", distance_m=224.0, at_s=300.0),
        _event(
            EventKind.CONFLICT, "A", 260.0, other="B", resolution="speed", airspeed_m_s=16.0,
            until_s=320.0, distance_m=224.0, resolved_m=310.0, at_s=300.0,
        ),
        _event(
            EventKind.CONFLICT, "A", 262.0, other="B", resolution="altitude", offset_m=-300.0,
            alt_m=600.0, until_s=320.0, distance_m=224.0, resolved_m=380.0, at_s=300.0,
        ),
        _event(EventKind.ALARM, "A", 298.0, other="B", distance_m=224.0),
        _event(EventKind.CONFLICT, "A", 330.0, other="B", resolution="released"),
        _event(EventKind.CONFLICT, "A", 100.0, **replan, resolution="altitude", height_m=150.0),
        _event(EventKind.CONFLICT, "A", 100.0, **replan, resolution=None),
        _event(EventKind.ALARM, "A", 100.0, **replan),
        _event(EventKind.ALARM, "B", 120.0, severity=2, text="Crash: going down"),
        _event(EventKind.SPEED, "A", 130.0),
    ]  # fmt: skip


def test_each_conflict_event_is_read_as_its_kind_with_what_was_done_and_the_true_closest() -> None:
    # A and B head for each other along lines 200 m apart, B 100 m higher: closest at 300 s.
    tracks = {"A": _track(0.0, 20.0, 0.0, 800.0), "B": _track(15_000.0, -30.0, 200.0, 900.0)}
    events = an_encounter()
    out = separation_events(events, tracks, START_UTC)
    kinds = [(e["kind"], e["action"]) for e in out]
    assert kinds == [
        ("predicted", "none"),
        ("resolved", "speed 16 m/s"),
        ("resolved", "altitude -300 m"),
        ("loss", "alarm"),
        ("released", "released"),
        ("resolved", "altitude +150 m"),
        ("unresolved", "alarm"),
    ]
    ends = [300.0, 320.0, 320.0, 298.0, 330.0, 300.0, 300.0]
    starts = (250.0, 260.0, 262.0, 298.0, 330.0, 100.0, 100.0)
    for e, t0, end in zip(out, starts, ends, strict=True):
        assert e["pair"] == ["A", "B"] and e["t_s"] == t0
        assert e["until_utc_s"] == pytest.approx(START_UTC + end + ENCOUNTER_AFTER_S)
        expected = _closest_m(0.0, 15_000.0, 20.0, -30.0, 200.0, 100.0, t0, end + 60.0)
        assert e["closest_m"] == pytest.approx(expected, rel=2e-3, abs=1.0), e
    # The encounters that hold the pass: about 224 m (200 m across, 100 m up); the release
    # after it measures the pair opening again.
    assert out[0]["closest_m"] == pytest.approx(math.hypot(200.0, 100.0), abs=1.0)
    assert out[4]["closest_m"] > 1_000.0
    assert out[0]["said_m"] == 224.0 and out[4]["said_m"] is None


def test_a_pair_not_flying_then_has_no_closest() -> None:
    tracks = {"A": _track(0.0, 20.0, 0.0, 800.0)}
    events = [_event(EventKind.CONFLICT, "A", 50.0, other="B", distance_m=100.0, at_s=80.0)]
    (e,) = separation_events(events, tracks, START_UTC)
    assert e["closest_m"] is None and e["closest_utc_s"] is None


def test_the_closest_distance_is_over_the_window_the_entry_states() -> None:
    """An event 0.4 ms after a sample: the entry states its window to the millisecond, so it
    starts at that sample, and the closest distance is measured from it (the pair opening
    after their pass, the sample at the window's start is the nearest). Whoever measures the
    stated window again from the same samples finds the same distance."""
    tracks = {"A": _track(0.0, 20.0, 0.0, 800.0), "B": _track(15_000.0, -30.0, 200.0, 900.0)}
    t_s = 330.0 + 4e-4
    events = [_event(EventKind.CONFLICT, "A", t_s, other="B", resolution="released")]
    (e,) = separation_events(events, tracks, START_UTC)
    assert e["utc_s"] == START_UTC + 330.0
    assert e["closest_utc_s"] == START_UTC + 330.0
    expected = _closest_m(0.0, 15_000.0, 20.0, -30.0, 200.0, 100.0, 330.0, 330.0 + 60.0)
    assert e["closest_m"] == pytest.approx(expected, rel=2e-3)  # the next sample: 50 m more


def test_a_re_plan_that_times_a_pair_apart_or_routes_one_wider_is_read_as_resolved() -> None:
    tracks = {"A": _track(0.0, 20.0, 0.0, 800.0), "B": _track(15_000.0, -30.0, 200.0, 900.0)}
    replan = {"pair": ["A", "B"], "distance_m": 224.0, "at_s": 300.0}
    timed = _event(EventKind.CONFLICT, "A", 100.0, **replan, resolution="timing", shift_s=-15.0)
    (out,) = separation_events([timed], tracks, START_UTC)
    assert (out["kind"], out["action"], out["pair"]) == ("resolved", "timing -15 s", ["A", "B"])
    wider = _event(EventKind.CONFLICT, "B", 100.0, **replan, resolution="offset", offset_m=450.0)
    (out,) = separation_events([wider], tracks, START_UTC)
    assert (out["kind"], out["action"], out["pair"]) == ("resolved", "offset 450 m", ["A", "B"])
