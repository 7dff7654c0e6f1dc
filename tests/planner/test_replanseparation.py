"""A re-plan is deconflicted in 4-D before it is installed (:mod:`planner.replanseparation`).

Thirty or sixty vehicles converge on a target from a ring (:func:`tests.teams.ring_team`); a
forbidden disc appears across the routes where they bunch, and the vehicles it touches are
routed round it, some along their neighbours' routes. The scenario names no altitude layers:
the re-plan times the re-routed apart, then lifts onto the in-flight resolution's layers
(half ``d_s`` and its multiples), and says what is left.

Each verdict is the test's own: every schedule is sampled here, second by second from the
re-plan's start, at its position along its path (:meth:`VehicleSchedule.state_at`) and the
altitude its profile has there, and every pair's least 3-D distance taken from those samples,
not from :mod:`planner.deconflict`. The same re-plan with no time left to separate (same
routes, same seed) is the reference: what the separation changed is measured against it.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

from planner import replanseparation
from planner.deconflict import separation
from planner.plan import build_world, plan
from planner.popup import PopupOutcome, apply_popup, popup_zones
from planner.retime import build_schedule
from planner.scenario import parse_scenario
from planner.schedule import Schedule, VehicleSchedule
from planner.threats import active, build_threats
from tests.teams import ring_team

AT_S = 150.0
STEP_S = 0.25
"""Sampling of the test's own closest approaches: two vehicles close at 60 m/s at most, 15 m
between samples."""


def _flown(
    data: dict[str, Any],
    centre_m: tuple[float, float] = (30_000.0, 41_000.0),
    radius_m: float = 2_500.0,
    at_s: float = AT_S,
    seed: int = 0,
    separate: bool = True,
) -> tuple[Schedule, PopupOutcome]:
    data["threats"].append(
        {
            "kind": "radar", "id": "POP", "forbidden": True,
            "center": {"east_m": centre_m[0], "north_m": centre_m[1]}, "radius_m": radius_m,
            "appears": {"at_s": at_s},
        }
    )  # fmt: skip
    scenario = parse_scenario(data)
    world = build_world(scenario)
    schedule = build_schedule(scenario, plan(scenario, rng=np.random.default_rng(0), world=world))
    (zone,) = popup_zones(build_threats(scenario))
    outcome = apply_popup(
        schedule, zone, at_s=at_s, world=world, threats=active(world.threats, at_s),
        rng=np.random.default_rng(seed), separation_up=None if separate else lambda: True,
    )  # fmt: skip
    return schedule, outcome


def _track(vs: VehicleSchedule, t_s: np.ndarray) -> np.ndarray:
    """East, north and altitude (m) at each time of ``t_s``; NaN where it does not fly."""
    out = np.full((len(t_s), 3), np.nan)
    for k, t in enumerate(t_s):
        if not vs.takeoff_s <= t <= vs.arrival_s:
            continue
        p = vs.position_at(float(t))
        if p is None:
            continue
        s_m = vs.state_at(float(t))[1]
        out[k] = (p[0], p[1], float(np.interp(s_m, vs.wp_s_m, vs.wp_alt_m)))
    return out


def _closest_pairs(schedule: Schedule, from_s: float) -> dict[tuple[str, str], tuple[float, float]]:
    """Every pair's least 3-D distance (m) from ``from_s`` on, and when (s)."""
    end_s = max(vs.arrival_s for vs in schedule.vehicles)
    t_s = np.arange(from_s, end_s + STEP_S, STEP_S)
    tracks = {vs.vehicle_id: _track(vs, t_s) for vs in schedule.vehicles}
    out = {}
    for a, b in itertools.combinations(sorted(tracks), 2):
        d = np.linalg.norm(tracks[a] - tracks[b], axis=1)
        if np.isnan(d).all():
            continue
        k = int(np.nanargmin(d))
        out[(a, b)] = (float(d[k]), float(t_s[k]))
    return out


@pytest.fixture(scope="module")
def out_of_time() -> tuple[Schedule, PopupOutcome]:
    return _flown(ring_team(30), separate=False)


def test_a_re_plan_left_unseparated_is_alarmed_with_the_pair_the_time_and_the_distance(
    out_of_time: tuple[Schedule, PopupOutcome],
) -> None:
    """No wall time left to separate the re-plan: every pair under d_s is said at the
    re-plan's start, before anything is installed."""
    _, outcome = out_of_time
    required = outcome.schedule.scenario.separation_m
    found = _closest_pairs(outcome.schedule, AT_S)
    under = {pair: seen for pair, seen in found.items() if seen[0] < required - TOL_M}
    assert under, "the re-plan puts no pair under d_s: nothing to show"
    alarms = [e for e in outcome.events if e.kind == "alarm"]
    conflicts = [e for e in outcome.events if e.kind == "conflict" and "pair" in e.payload]
    said = {tuple(sorted(e.payload["pair"])): e for e in alarms}
    # Every pair the test finds under d_s is alarmed, with its distance and time as found here.
    for pair, (distance_m, at_s) in under.items():
        assert pair in said, (pair, distance_m, [e.text for e in alarms])
        e = said[pair]
        assert e.payload["distance_m"] == pytest.approx(distance_m, abs=5.0)
        assert e.payload["at_s"] == pytest.approx(at_s, abs=2.0)
        assert f"{e.payload['distance_m']:.0f} m" in e.text and "time ran out" in e.text
        assert e.time_s == AT_S  # said at the re-plan, before anything is installed
    assert {tuple(sorted(e.payload["pair"])) for e in conflicts} == set(said)
    # And nothing is alarmed that the test does not find close.
    for pair in said:
        assert found[pair][0] < required, (pair, found[pair])


TOL_M = 15.0
"""The test's own sampling (:data:`STEP_S`) finds a closest approach up to 15 m too far."""

BUNCHED = {
    "30, wide disc": (30, (30_000.0, 40_000.0), 4_500.0, 40.0),
    "30, late disc": (30, (30_000.0, 39_000.0), 2_500.0, 95.0),
    "60": (60, (30_000.0, 38_000.0), 2_000.0, 95.0),
}
"""Teams and pop-up zones across the routes where they bunch: ``(vehicles, centre (east,
north) m, radius m, appearing at s)``."""


@pytest.fixture(scope="module", params=sorted(BUNCHED))
def bunched(
    request: pytest.FixtureRequest,
) -> tuple[str, PopupOutcome, PopupOutcome]:
    n, centre_m, radius_m, at_s = BUNCHED[request.param]
    args = {"centre_m": centre_m, "radius_m": radius_m, "at_s": at_s, "seed": 1}
    _, separated = _flown(ring_team(n), **args)
    _, reference = _flown(ring_team(n), separate=False, **args)
    return request.param, separated, reference


def test_a_re_plan_across_a_bunch_keeps_d_s_in_3d_from_its_start_or_says_the_pair(
    bunched: tuple[str, PopupOutcome, PopupOutcome],
) -> None:
    """Every pair keeps d_s from the re-plan's start on by the test's own samples, or is
    alarmed with the pair, the time and the distance found here; fewer pairs are left than
    the unseparated re-plan has, and none for thirty vehicles."""
    name, outcome, reference = bunched
    at_s = BUNCHED[name][3]
    required = outcome.schedule.scenario.separation_m
    found = _closest_pairs(outcome.schedule, at_s)
    said = {tuple(sorted(e.payload["pair"])): e for e in outcome.events if e.kind == "alarm"}
    for pair, (distance_m, when_s) in found.items():
        if distance_m >= required - TOL_M:
            continue
        assert pair in said, (pair, distance_m, when_s)
        e = said[pair]
        assert e.payload["distance_m"] == pytest.approx(distance_m, abs=TOL_M)
        assert e.payload["at_s"] == pytest.approx(when_s, abs=2.0)
        assert e.time_s == at_s
    before = {p for p, (d, _) in _closest_pairs(reference.schedule, at_s).items() if d < required}
    assert len(said) < len(before), (sorted(said), sorted(before))
    if BUNCHED[name][0] == 30:
        assert not said, [e.text for e in said.values()]
    done = [e for e in outcome.events if e.payload.get("resolution") in ("timing", "altitude")]
    assert done, [e.text for e in outcome.events]


def test_a_separated_re_plan_keeps_every_slot_and_flies_within_its_altitude_limits(
    bunched: tuple[str, PopupOutcome, PopupOutcome],
) -> None:
    """Every vehicle arrives at its slot as the unseparated re-plan has it; on the same path,
    never lower than that profile (the terrain clearance only gains), never above its
    ceiling nor a layer's height above the profile, and as it was up to where it is at the
    re-plan's start."""
    name, outcome, reference = bunched
    at_s = BUNCHED[name][3]
    scenario = outcome.schedule.scenario
    ground_m = float(scenario.terrain.elevation_m)  # flat
    highest_m = 1.5 * scenario.separation_m  # three layers of half d_s
    wider = {
        e.payload["pair"][0] for e in outcome.events if e.payload.get("resolution") == "offset"
    }
    for vs in outcome.schedule.vehicles:
        ref = reference.schedule.vehicle(vs.vehicle_id)
        v = scenario.vehicle(vs.vehicle_id)
        assert vs.arrival_s == pytest.approx(ref.arrival_s, abs=0.05), vs.vehicle_id
        if vs.vehicle_id in wider:
            continue  # another route round the zone (the test above)
        assert vs.path.length_m == pytest.approx(ref.path.length_m)
        s = np.linspace(0.0, vs.path.length_m, 4001)
        z = np.interp(s, vs.wp_s_m, vs.wp_alt_m)
        z_ref = np.interp(s, ref.wp_s_m, ref.wp_alt_m)
        assert (z >= z_ref - 1e-6).all(), vs.vehicle_id
        assert (z <= v.alt_max_m + 1e-6).all(), vs.vehicle_id
        assert float((z - z_ref).max()) <= highest_m + 1e-6, vs.vehicle_id
        s_start = ref.state_at(at_s)[1]
        ahead = s >= max(s_start, vs.climb_s_m)
        assert (z[ahead] >= ground_m + v.clearance_m - 1e-6).all(), vs.vehicle_id
        assert np.allclose(z[s <= s_start], z_ref[s <= s_start]), vs.vehicle_id
        # Where it is in the air before the re-plan's start is not changed.
        t_s = np.arange(vs.takeoff_s, at_s, 1.0)
        assert np.allclose(_track(vs, t_s), _track(ref, t_s), equal_nan=True), vs.vehicle_id


def test_a_pair_on_the_zones_edge_that_no_timing_separates_is_routed_round_it_wider(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The wide disc sends R01 and R02 (and R28 and R29) round one edge of it, together: with
    the timing and layer stages left out, one of each pair goes round the zone wider (the
    zone widened for its route search alone) and keeps its slot. By the test's own samples
    every pair keeps d_s from the re-plan's start; the vehicle routed wider keeps that much
    more room from the zone as it goes round."""

    def untimed(
        team: list[VehicleSchedule], required_m: float, *, from_s: float, **_: object
    ) -> tuple[dict[str, object], object]:
        return {}, separation(list(team), required_m, from_s=from_s)

    def unlifted(
        team: list[VehicleSchedule],
        _planned: object,
        _vehicles: object,
        _heights_m: object,
        required_m: float,
        *_: object,
        from_s: float,
        **__: object,
    ) -> tuple[dict[str, object], object]:
        return {}, separation(list(team), required_m, from_s=from_s)

    monkeypatch.setattr(replanseparation, "time_apart", untimed)
    monkeypatch.setattr(replanseparation, "lift_team", unlifted)
    n, centre_m, radius_m, at_s = BUNCHED["30, wide disc"]
    args = {"centre_m": centre_m, "radius_m": radius_m, "at_s": at_s, "seed": 1}
    _, outcome = _flown(ring_team(n), **args)
    _, reference = _flown(ring_team(n), separate=False, **args)
    required = outcome.schedule.scenario.separation_m
    wider = [e for e in outcome.events if e.payload.get("resolution") == "offset"]
    assert wider and not [e for e in outcome.events if e.kind == "alarm"], [
        e.text for e in outcome.events
    ]
    found = _closest_pairs(outcome.schedule, at_s)
    assert min(d for d, _ in found.values()) >= required - TOL_M
    for e in wider:
        vid = e.payload["pair"][0]
        assert e.text.startswith(f"{vid} goes round the zone {e.payload['offset_m']:.0f} m wider")
        vs, ref = outcome.schedule.vehicle(vid), reference.schedule.vehicle(vid)
        assert vs.arrival_s == pytest.approx(ref.arrival_s, abs=0.05)
        assert vs.path.length_m > ref.path.length_m

        # Its least room from the zone's edge as it goes round: at least the offset (clear of
        # the zone so widened), and more than the route first re-planned left.
        def room_m(x: VehicleSchedule) -> float:
            s = np.linspace(x.state_at(at_s)[1], x.path.length_m, 2000)
            en = np.array([(p.east_m, p.north_m) for p in (x.path.pose_at(float(k)) for k in s)])
            return float(
                (np.hypot(en[:, 0] - centre_m[0], en[:, 1] - centre_m[1]) - radius_m).min()
            )

        assert room_m(vs) >= max(e.payload["offset_m"], room_m(ref)), (room_m(vs), room_m(ref))


def test_a_vehicle_timed_apart_carries_the_place_and_time_its_flight_aims_at(
    bunched: tuple[str, PopupOutcome, PopupOutcome],
) -> None:
    """A vehicle the re-plan timed apart passes the place of its closest approach earlier or
    later: its schedule says where and when (``via``, which the flight aims at before its
    slot), and by its own timing it is there then; the others are timed for their slots
    alone (one timed again on a layer or round the zone wider, for its slot, too)."""
    _, outcome, _ = bunched

    def by(resolution: str) -> set[str]:
        events = outcome.events
        return {e.payload["pair"][0] for e in events if e.payload.get("resolution") == resolution}

    timed = by("timing") - by("altitude") - by("offset")
    assert timed
    for vs in outcome.schedule.vehicles:
        if vs.vehicle_id not in timed:
            assert vs.via is None, vs.vehicle_id
            continue
        assert vs.via is not None, vs.vehicle_id
        via_s_m, via_t_s = vs.via
        assert vs.state_at(via_t_s)[1] == pytest.approx(via_s_m, abs=1.0), vs.vehicle_id
