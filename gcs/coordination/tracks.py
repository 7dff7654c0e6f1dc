"""Sampled tracks: where a vehicle was, its closest approach to a point, and the least
separation between vehicles, from time-stamped positions (a simulator's truth log, or the
coordinator's own fixes).

Distances use a local east/north plane about the point of interest (equirectangular with the
WGS84 meridional and prime-vertical radii there): within a few kilometres it is accurate to
well under a millimetre per metre, far finer than the samples.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

_WGS84_A_M = 6378137.0
_WGS84_F = 1.0 / 298.257223563
_WGS84_E2 = _WGS84_F * (2.0 - _WGS84_F)


@dataclass(frozen=True, slots=True)
class TruthSample:
    """One vehicle's true state at one simulated UTC (``alt_m`` AMSL).

    ``on_ground`` is None when the file does not say (then "airborne" means "armed").
    """

    utc_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    airspeed_m_s: float
    groundspeed_m_s: float
    armed: bool
    on_ground: bool | None = None

    @property
    def airborne(self) -> bool:
        """Armed and (when the file says) off the ground."""
        return self.armed and not self.on_ground


# -- geometry --------------------------------------------------------------------------------


def metres_per_degree(lat_deg: FloatArray | float) -> tuple[FloatArray, FloatArray]:
    """Metres per degree of latitude (north) and of longitude (east) at ``lat_deg``, WGS84."""
    phi = np.radians(np.asarray(lat_deg, dtype=np.float64))
    s2 = np.sin(phi) ** 2
    w = 1.0 - _WGS84_E2 * s2
    meridional = _WGS84_A_M * (1.0 - _WGS84_E2) / (w * np.sqrt(w))
    prime_vertical = _WGS84_A_M / np.sqrt(w)
    k = math.pi / 180.0
    return meridional * k, prime_vertical * np.cos(phi) * k


def _east_north_m(
    lat_deg: FloatArray, lon_deg: FloatArray, lat0_deg: float, lon0_deg: float
) -> tuple[FloatArray, FloatArray]:
    m_north, m_east = metres_per_degree(lat0_deg)
    dlon = (lon_deg - lon0_deg + 180.0) % 360.0 - 180.0
    return dlon * m_east, (lat_deg - lat0_deg) * m_north


def closest_approach(
    samples: Sequence[TruthSample],
    lat_deg: float,
    lon_deg: float,
    radius_m: float,
    after_utc_s: float | None = None,
) -> tuple[float, float] | None:
    """``(utc_s, distance_m)`` of the first pass within ``radius_m`` of a point, interpolated.

    The track is the polyline through the samples (in time order), each chord flown at
    constant speed. The answer is the first local minimum of the horizontal distance to the
    point once the track is within ``radius_m`` (considering only times at or after
    ``after_utc_s``): on its chord the point is projected onto the chord and the time
    interpolated linearly. A track that starts inside the radius and only moves away gives its
    first sample (or ``after_utc_s``). None if the track never comes within the radius, or if
    it is still closing on the point where it ends (a log read before the pass was written).
    """
    if not (math.isfinite(radius_m) and radius_m >= 0):
        raise ValueError(f"radius_m must be >= 0, got {radius_m!r}")
    if not samples:
        return None
    utc = np.fromiter((s.utc_s for s in samples), np.float64, len(samples))
    lat = np.fromiter((s.lat_deg for s in samples), np.float64, len(samples))
    lon = np.fromiter((s.lon_deg for s in samples), np.float64, len(samples))
    east, north = _east_north_m(lat, lon, lat_deg, lon_deg)
    if after_utc_s is not None:
        j = int(np.searchsorted(utc, after_utc_s, side="left"))
        if j >= len(utc):
            return None
        if j > 0 and utc[j] > after_utc_s:  # start the track at after_utc_s on chord j-1
            f = (after_utc_s - utc[j - 1]) / (utc[j] - utc[j - 1])
            e0 = east[j - 1] + f * (east[j] - east[j - 1])
            n0 = north[j - 1] + f * (north[j] - north[j - 1])
            utc = np.concatenate(([after_utc_s], utc[j:]))
            east = np.concatenate(([e0], east[j:]))
            north = np.concatenate(([n0], north[j:]))
        else:
            utc, east, north = utc[j:], east[j:], north[j:]
    if len(utc) == 1:
        d0 = float(math.hypot(east[0], north[0]))
        return (float(utc[0]), d0) if d0 <= radius_m else None
    # Each chord k: P_k + t (P_{k+1} - P_k), t in [0, 1]; nearest t to the origin, clamped.
    de, dn = np.diff(east), np.diff(north)
    len2 = de * de + dn * dn
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(len2 > 0.0, -(east[:-1] * de + north[:-1] * dn) / len2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    dist = np.hypot(east[:-1] + t * de, north[:-1] + t * dn)
    inside = np.flatnonzero(dist <= radius_m)
    if inside.size == 0:
        return None
    k = int(inside[0])
    # Still closing at the chord's end: the minimum lies further on (distance is convex on
    # each chord, so the first chord whose nearest point is not its end holds the minimum).
    last = len(t) - 1
    while k < last and t[k] >= 1.0:
        k += 1
    if k == last and t[k] >= 1.0:
        return None  # still closing where the track ends: the pass is not in it yet
    when = float(utc[k] + t[k] * (utc[k + 1] - utc[k]))
    return when, float(dist[k])


# -- separation ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Track:
    utc_s: FloatArray
    lat_deg: FloatArray
    lon_deg: FloatArray
    alt_m: FloatArray
    ok: NDArray[np.bool_]
    half_period_s: float


def _track(samples: Sequence[TruthSample], airborne_only: bool, until: float | None) -> _Track:
    n = len(samples)
    utc = np.fromiter((s.utc_s for s in samples), np.float64, n)
    ok = (
        np.fromiter((s.airborne for s in samples), np.bool_, n)
        if airborne_only
        else np.ones(n, dtype=np.bool_)
    )
    if until is not None:
        ok &= utc <= until
    steps = np.diff(utc)
    steps = steps[steps > 0]
    half = 0.5 * float(np.median(steps)) if steps.size else 1e-6
    return _Track(
        utc,
        np.fromiter((s.lat_deg for s in samples), np.float64, n),
        np.fromiter((s.lon_deg for s in samples), np.float64, n),
        np.fromiter((s.alt_m for s in samples), np.float64, n),
        ok,
        half,
    )


def min_separation(
    tracks: Mapping[int, Sequence[TruthSample]],
    *,
    airborne_only: bool = True,
    until_utc_s: Mapping[int, float] | None = None,
) -> tuple[float, int, int, float] | None:
    """``(distance_m, sysid_a, sysid_b, utc_s)``: the least 3-D distance between two vehicles.

    Measured at the samples of ``sysid_a`` (the lower id) against the nearest sample of
    ``sysid_b`` in time, when they are within half a sample period of each other (one recorder
    stamps every vehicle of a row alike). With ``airborne_only`` a pair counts only while both
    are airborne (armed, and off the ground when the file says so); a vehicle's samples after
    its ``until_utc_s`` (its arrival) are left out. Between samples the distance is not
    interpolated: two vehicles closing at ``v`` m/s may pass up to ``v * period / 2`` nearer.
    None when no pair shares a counted time.
    """
    until = until_utc_s or {}
    ids = sorted(tracks)
    prepared = {
        i: _track(tracks[i], airborne_only, until.get(i)) for i in ids if len(tracks[i]) > 0
    }
    best: tuple[float, int, int, float] | None = None
    for ai, a_id in enumerate(ids):
        a = prepared.get(a_id)
        if a is None:
            continue
        for b_id in ids[ai + 1 :]:
            b = prepared.get(b_id)
            if b is None:
                continue
            found = _pair_min(a, b)
            if found is not None and (best is None or found[0] < best[0]):
                best = (found[0], a_id, b_id, found[1])
    return best


def _pair_min(a: _Track, b: _Track) -> tuple[float, float] | None:
    """(distance_m, utc_s) of the nearest approach of two tracks at a's sample times."""
    ia = np.flatnonzero(a.ok)
    if ia.size == 0 or not b.ok.any():
        return None
    ua = a.utc_s[ia]
    j = np.searchsorted(b.utc_s, ua)
    lo = np.clip(j - 1, 0, len(b.utc_s) - 1)
    hi = np.clip(j, 0, len(b.utc_s) - 1)
    jb = np.where(np.abs(b.utc_s[hi] - ua) < np.abs(ua - b.utc_s[lo]), hi, lo)
    tol = max(a.half_period_s, b.half_period_s)
    keep = (np.abs(b.utc_s[jb] - ua) <= tol) & b.ok[jb]
    if not keep.any():
        return None
    ia, jb = ia[keep], jb[keep]
    lat_a, lon_a, lat_b, lon_b = a.lat_deg[ia], a.lon_deg[ia], b.lat_deg[jb], b.lon_deg[jb]
    m_north, m_east = metres_per_degree(0.5 * (lat_a + lat_b))
    dlon = (lon_b - lon_a + 180.0) % 360.0 - 180.0
    d = np.sqrt(
        (dlon * m_east) ** 2 + ((lat_b - lat_a) * m_north) ** 2 + (b.alt_m[jb] - a.alt_m[ia]) ** 2
    )
    k = int(np.argmin(d))
    return float(d[k]), float(a.utc_s[ia[k]])
