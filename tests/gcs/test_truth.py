"""gcs.rehearsal.truth: reading simulator truth files, closest approach and minimum separation."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gcs.coordination.tracks import (
    TruthSample,
    closest_approach,
    metres_per_degree,
    min_separation,
)
from gcs.errors import GcsError
from gcs.rehearsal.truth import read_truth
from planner.geo import LocalFrame, geodesic_distance_m

LAT0, LON0 = -35.363261, 149.165230
FRAME = LocalFrame(LAT0, LON0)
UTC0 = 1_704_067_200.0


def track(
    east_north_alt: list[tuple[float, float, float]] | np.ndarray,
    utc: list[float] | np.ndarray,
    *,
    armed: bool = True,
    on_ground: bool | None = None,
) -> list[TruthSample]:
    """Samples at local (east, north, alt) points about (LAT0, LON0)."""
    out = []
    for (e, n, a), t in zip(east_north_alt, utc, strict=True):
        lat, lon = FRAME.to_geodetic(float(e), float(n))
        out.append(TruthSample(float(t), lat, lon, float(a), 22.0, 22.0, armed, on_ground))
    return out


def straight(
    speed_m_s: float,
    t_closest_s: float,
    offset_north_m: float,
    *,
    t0_s: float = 0.0,
    t1_s: float = 200.0,
    period_s: float = 0.5,
    alt_m: float = 500.0,
) -> list[TruthSample]:
    """Flying east at ``speed_m_s``, passing ``offset_north_m`` north of the point."""
    t = np.arange(t0_s, t1_s, period_s)
    east = speed_m_s * (t - t_closest_s)
    pts = np.column_stack([east, np.full_like(t, offset_north_m), np.full_like(t, alt_m)])
    return track(pts, UTC0 + t)


# -- closest approach ------------------------------------------------------------------------


@pytest.mark.parametrize("speed_m_s", [17.3, 23.7, 41.0])
@pytest.mark.parametrize("offset_m", [0.0, 12.5, 40.0, -77.0])
def test_straight_pass_gives_the_time_within_a_millisecond(
    speed_m_s: float, offset_m: float
) -> None:
    t_closest = 97.3137  # between samples
    got = closest_approach(straight(speed_m_s, t_closest, offset_m), LAT0, LON0, radius_m=100.0)
    assert got is not None
    utc, dist = got
    assert utc == pytest.approx(UTC0 + t_closest, abs=1e-3)
    assert dist == pytest.approx(abs(offset_m), abs=0.01)


def test_never_within_radius_gives_none() -> None:
    samples = straight(23.0, 50.0, 150.0)
    assert closest_approach(samples, LAT0, LON0, radius_m=100.0) is None
    assert closest_approach([], LAT0, LON0, radius_m=100.0) is None
    # Sampled so sparsely that no sample is inside, but a chord passes within the radius.
    sparse = straight(25.0, 50.0, 30.0, period_s=7.0)
    got = closest_approach(sparse, LAT0, LON0, radius_m=50.0)
    assert got is not None and got[0] == pytest.approx(UTC0 + 50.0, abs=1e-3)


def test_first_local_minimum_within_radius_wins_over_a_closer_later_one() -> None:
    # Out east past the point 60 m north (t = 20 s), turn, back west 10 m north (t = 60 s).
    t = np.arange(0.0, 80.0, 0.5)
    east = np.where(t < 40.0, 20.0 * (t - 20.0), 20.0 * (60.0 - t))
    north = np.where(t < 40.0, 60.0, 10.0)
    samples = track(np.column_stack([east, north, np.full_like(t, 300.0)]), UTC0 + t)
    first = closest_approach(samples, LAT0, LON0, radius_m=100.0)
    assert first is not None
    assert first[0] == pytest.approx(UTC0 + 20.0, abs=1e-3)
    assert first[1] == pytest.approx(60.0, abs=0.01)
    # With after_utc_s past the first pass, the second (inside a chord start) is found.
    second = closest_approach(samples, LAT0, LON0, radius_m=100.0, after_utc_s=UTC0 + 30.25)
    assert second is not None
    assert second[0] == pytest.approx(UTC0 + 60.0, abs=1e-3)
    assert second[1] == pytest.approx(10.0, abs=0.01)
    # A radius only the second pass reaches.
    only = closest_approach(samples, LAT0, LON0, radius_m=30.0)
    assert only is not None and only[0] == pytest.approx(UTC0 + 60.0, abs=1e-3)
    # after_utc_s beyond the data.
    assert closest_approach(samples, LAT0, LON0, 100.0, after_utc_s=UTC0 + 1e4) is None


def test_after_utc_s_inside_the_pass_and_a_track_leaving_the_point() -> None:
    samples = straight(20.0, 50.0, 0.0)
    # Starting after the closest approach, the track only moves away: the start is nearest.
    got = closest_approach(samples, LAT0, LON0, radius_m=100.0, after_utc_s=UTC0 + 51.2)
    assert got is not None
    assert got[0] == pytest.approx(UTC0 + 51.2, abs=1e-9)
    assert got[1] == pytest.approx(24.0, abs=0.01)
    one = closest_approach(samples[100:101], LAT0, LON0, radius_m=100.0)
    assert one is not None and one[0] == samples[100].utc_s
    with pytest.raises(ValueError, match="radius_m"):
        closest_approach(samples, LAT0, LON0, radius_m=-1.0)


def test_a_log_that_ends_before_the_pass_gives_none_not_its_last_sample() -> None:
    # A truth log read while the simulator still held the pass in its buffer: the track is
    # inside the radius and still closing where it ends, so the pass is not in it.
    samples = straight(20.0, 50.0, 0.0)
    cut = [s for s in samples if s.utc_s < UTC0 + 48.0]
    assert closest_approach(cut, LAT0, LON0, radius_m=100.0) is None
    # One sample past the pass is enough to find it.
    upto = [s for s in samples if s.utc_s <= UTC0 + 50.5]
    got = closest_approach(upto, LAT0, LON0, radius_m=100.0)
    assert got is not None and got[0] == pytest.approx(UTC0 + 50.0, abs=1e-3)


def test_local_metres_per_degree_match_geodesic_distance() -> None:
    m_north, m_east = metres_per_degree(LAT0)
    d_north = geodesic_distance_m(LAT0, LON0, LAT0 + 0.01, LON0)
    d_east = geodesic_distance_m(LAT0, LON0, LAT0, LON0 + 0.01)
    assert float(m_north) * 0.01 == pytest.approx(d_north, rel=1e-6)
    assert float(m_east) * 0.01 == pytest.approx(d_east, rel=1e-6)


# -- separation ------------------------------------------------------------------------------


def test_min_separation_known_answer_and_filters() -> None:
    t = np.arange(0.0, 100.0, 0.5)
    # Head-on on parallel tracks 100 m apart laterally and 30 m vertically, abeam at t = 40.
    a = track(np.column_stack([20.0 * (t - 40.0), 0.0 * t, 500.0 + 0.0 * t]), UTC0 + t)
    b = track(np.column_stack([-20.0 * (t - 40.0), 100.0 + 0.0 * t, 530.0 + 0.0 * t]), UTC0 + t)
    far = track(np.column_stack([0.0 * t, 5000.0 + 0.0 * t, 500.0 + 0.0 * t]), UTC0 + t)
    got = min_separation({1: a, 2: b, 3: far})
    assert got is not None
    dist, sa, sb, utc = got
    assert (sa, sb) == (1, 2)
    assert dist == pytest.approx(math.hypot(100.0, 30.0), abs=0.05)
    assert utc == pytest.approx(UTC0 + 40.0)
    # Vehicle 1 arrived at t = 30 s: afterwards it does not count (closing at 40 m/s).
    got = min_separation({1: a, 2: b, 3: far}, until_utc_s={1: UTC0 + 30.0})
    assert got is not None
    assert got[3] == pytest.approx(UTC0 + 30.0)
    assert got[0] == pytest.approx(math.hypot(400.0, 100.0, 30.0), abs=0.1)
    # Not armed, or on the ground: not counted; without airborne_only it is.
    b_ground = [
        TruthSample(s.utc_s, s.lat_deg, s.lon_deg, s.alt_m, 0.0, 0.0, True, True) for s in b
    ]
    got = min_separation({1: a, 2: b_ground, 3: far})
    assert got is not None and (got[1], got[2]) == (1, 3)
    got = min_separation({1: a, 2: b_ground}, airborne_only=False)
    assert got is not None and got[0] == pytest.approx(math.hypot(100.0, 30.0), abs=0.05)
    disarmed = track(np.column_stack([0.0 * t, 0.0 * t, 500.0 + 0.0 * t]), UTC0 + t, armed=False)
    assert min_separation({1: a, 2: disarmed}) is None
    assert min_separation({1: a}) is None
    assert min_separation({}) is None


def test_min_separation_aligns_samples_within_half_a_period() -> None:
    t = np.arange(0.0, 50.0, 0.5)
    a = track(np.column_stack([0.0 * t, 0.0 * t, 500.0 + 0.0 * t]), UTC0 + t)
    # Stamped 0.2 s later (within half a period): matched.
    b = track(np.column_stack([0.0 * t, 200.0 + 0.0 * t, 500.0 + 0.0 * t]), UTC0 + t + 0.2)
    got = min_separation({1: a, 2: b})
    assert got is not None and got[0] == pytest.approx(200.0, abs=0.01)
    # 0.3 s off a track sampled every 0.5 s, but within half of the other's 1 s period.
    t1 = np.arange(0.0, 50.0, 1.0)
    c = track(np.column_stack([0.0 * t1, 300.0 + 0.0 * t1, 500.0 + 0.0 * t1]), UTC0 + t1 + 0.3)
    got = min_separation({1: a, 3: c})
    assert got is not None and got[0] == pytest.approx(300.0, abs=0.01)
    assert min_separation({1: a, 3: c[:1]}) is not None  # one sample: matched within 0.25 s
    # No overlap in time at all: nothing to compare.
    late = track(np.column_stack([0.0 * t, 0.0 * t, 500.0 + 0.0 * t]), UTC0 + t + 1000.0)
    assert min_separation({1: a, 2: late}) is None


@pytest.mark.slow  # several seconds: left out of make test-quick
def test_min_separation_on_long_tracks_finds_the_start_where_they_are_closest() -> None:
    """Three 20,000-sample straight tracks (the kernel ``bench/bench_geometry.py`` times),
    against the least distance between their local positions worked out here."""
    n = 20_000
    t = np.arange(n) * 0.5
    tracks = {
        i: track(
            np.column_stack(
                [25.0 * t * math.cos(i), 25.0 * t * math.sin(i) + 300 * i, 500 + t * 0]
            ),
            UTC0 + t,
        )
        for i in range(1, 4)
    }
    got = min_separation(tracks)
    en = {i: (25.0 * t * math.cos(i), 25.0 * t * math.sin(i) + 300 * i) for i in range(1, 4)}
    pairs = [(1, 2), (1, 3), (2, 3)]
    gaps = {p: np.hypot(en[p[0]][0] - en[p[1]][0], en[p[0]][1] - en[p[1]][1]) for p in pairs}
    least = min(pairs, key=lambda p: float(gaps[p].min()))
    assert got is not None and got[1:3] == least
    assert got[0] == pytest.approx(float(gaps[least].min()), rel=2e-3)
    assert got[3] == pytest.approx(UTC0 + float(t[int(np.argmin(gaps[least]))]), abs=0.01)


# -- reading ---------------------------------------------------------------------------------

HEADER = {"format": "tcgcs-truth/1", "vehicles": 2, "speedup": 1.0, "start_utc_s": UTC0}


def line(sysid: int, utc: float, **over: object) -> str:
    rec: dict[str, object] = {
        "utc_s": utc,
        "i": sysid - 1,
        "sysid": sysid,
        "lat_deg": LAT0,
        "lon_deg": LON0 + 0.001 * sysid,
        "alt_m": 584.0,
        "airspeed_m_s": 0.0,
        "groundspeed_m_s": 0.0,
        "armed": False,
    }
    rec.update(over)
    return json.dumps(rec)


def test_read_truth_groups_by_sysid_and_tolerates_a_truncated_last_line(tmp_path: Path) -> None:
    path = tmp_path / "truth.jsonl"
    rows = [line(1, UTC0), line(2, UTC0), line(1, UTC0 + 0.5, armed=True, on_ground=False)]
    text = "\n".join([json.dumps(HEADER), *rows, line(2, UTC0 + 0.5)]) + "\n"
    path.write_text(text + line(1, UTC0 + 1.0)[:37])  # the writer is mid-line
    got = read_truth(path)
    assert sorted(got) == [1, 2]
    assert [s.utc_s for s in got[1]] == [UTC0, UTC0 + 0.5]
    assert got[1][1] == TruthSample(UTC0 + 0.5, LAT0, LON0 + 0.001, 584.0, 0.0, 0.0, True, False)
    assert got[1][1].airborne and not got[1][0].airborne
    assert got[2][0].on_ground is None
    # A complete last line without its newline is read.
    path.write_text(text + line(1, UTC0 + 1.0))
    assert len(read_truth(path)[1]) == 3
    # Empty, or only part of the header: nothing yet.
    path.write_text("")
    assert read_truth(path) == {}
    path.write_text(json.dumps(HEADER)[:20])
    assert read_truth(path) == {}


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        ([json.dumps(HEADER), line(1, UTC0), "garbage{", line(1, UTC0 + 1)], "line 3: not JSON"),
        ([json.dumps(HEADER), line(1, UTC0, lat_deg="x")], "line 2: lat_deg is 'x'"),
        ([json.dumps(HEADER), line(1, UTC0, armed=1)], "line 2: armed is 1"),
        ([json.dumps(HEADER), line(0, UTC0)], "line 2: sysid is 0"),
        ([json.dumps(HEADER), line(1, UTC0, utc_s=None)], "line 2: utc_s is None"),
        ([json.dumps(HEADER), "[1, 2]"], "line 2: expected a JSON object"),
        ([json.dumps({**HEADER, "format": "other/2"})], "line 1: format is 'other/2'"),
        ([line(1, UTC0)], "line 1: format is None"),
        ([json.dumps(HEADER), json.dumps(HEADER)], "line 2: a second header"),
        (["", line(1, UTC0)], "line 1: empty"),
    ],
)
def test_read_truth_names_file_and_line_of_garbage(
    tmp_path: Path, lines: list[str], message: str
) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(GcsError, match=message) as info:
        read_truth(path)
    assert str(path) in str(info.value)


def test_read_truth_missing_file_is_a_gcs_error(tmp_path: Path) -> None:
    with pytest.raises(GcsError, match="cannot read"):
        read_truth(tmp_path / "none.jsonl")


async def test_reads_what_the_simulator_writes(tmp_path: Path) -> None:
    from sitl_stub.api import Home, SimTeam
    from sitl_stub.autopilot import Mode

    out = tmp_path / "truth.jsonl"
    homes = [Home(LAT0, LON0, 584.0, 90.0), Home(LAT0 + 0.01, LON0, 590.0)]
    expected: dict[int, list[tuple[float, float, float, bool]]] = {1: [], 2: []}
    async with SimTeam.start(homes=homes, tcp_base=0, run=False, truth_out=out) as team:
        team.vehicles[0].autopilot.arm(force=True)
        team.vehicles[0].autopilot.set_mode(Mode.TAKEOFF)
        for _ in range(40):
            team.step(5)
            for i in range(2):
                s = team.true_state(i)
                expected[i + 1].append((team.utc_s, s.lat_deg, s.lon_deg, s.on_ground))
    got = read_truth(out)
    for sysid in (1, 2):
        samples = got[sysid][1:]  # the first row is the state at start
        assert len(samples) == 40
        for sample, (utc, lat, lon, ground) in zip(samples, expected[sysid], strict=True):
            assert sample.utc_s == pytest.approx(utc, abs=1e-6)
            assert (sample.lat_deg, sample.lon_deg) == pytest.approx((lat, lon), abs=1e-8)
            assert sample.on_ground is ground
    assert got[1][-1].airborne and not got[2][-1].armed
    sep = min_separation(got, airborne_only=False)
    assert sep is not None and sep[1:3] == (1, 2)
