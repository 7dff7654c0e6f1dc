"""Read a simulator truth file (``tcgcs-truth/1`` JSON lines) and measure a flight against it.

The file is what ``python -m sitl_stub --truth FILE`` writes (the format is in
docs/sitl_stub.md); this module only parses the lines, it does not import the simulator. A
header line ``{"format": "tcgcs-truth/1", ...}`` is followed by one line per vehicle and sample
time with ``utc_s``, ``sysid``, ``lat_deg``, ``lon_deg``, ``alt_m`` (AMSL), ``airspeed_m_s``,
``groundspeed_m_s``, ``armed`` and (optionally) ``on_ground``.

Distances use a local east/north plane about the point of interest (equirectangular with the
WGS84 meridional and prime-vertical radii there): within a few kilometres it is accurate to
well under a millimetre per metre, far finer than the samples.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gcs.errors import GcsError

TRUTH_FORMAT = "tcgcs-truth/1"

FloatArray = NDArray[np.float64]

_WGS84_A_M = 6378137.0
_WGS84_F = 1.0 / 298.257223563
_WGS84_E2 = _WGS84_F * (2.0 - _WGS84_F)

_NUMBER_FIELDS = ("utc_s", "lat_deg", "lon_deg", "alt_m", "airspeed_m_s", "groundspeed_m_s")


class TruthFileError(GcsError, ValueError):
    """A truth file that cannot be read (names the file and line)."""


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


# -- reading ---------------------------------------------------------------------------------


def read_truth(path: Path | str) -> dict[int, list[TruthSample]]:
    """The samples of each vehicle by system id, in time order.

    A last line without its newline that does not parse is ignored (the simulator may be
    writing it); an empty file, or one holding only part of the header, gives ``{}``.

    Raises
    ------
    TruthFileError
        (a :class:`~gcs.errors.GcsError`) naming the file and line, for a file that cannot be
        read, a header of another format, or a line that is not a sample.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise TruthFileError(f"truth file {path}: cannot read it ({err})") from None
    lines = text.split("\n")
    # The text after the last newline is an unfinished line (or "" when the file ends cleanly).
    complete, partial = lines[:-1], lines[-1]
    out: dict[int, list[TruthSample]] = {}
    for lineno, line in enumerate(complete, start=1):
        _take(out, path, lineno, line, tolerate=False)
    if partial.strip():
        _take(out, path, len(complete) + 1, partial, tolerate=True)
    for samples in out.values():
        samples.sort(key=lambda s: s.utc_s)  # stable, linear when already in order
    return out


def _take(
    out: dict[int, list[TruthSample]], path: Path, lineno: int, line: str, *, tolerate: bool
) -> None:
    where = f"truth file {path} line {lineno}"
    if not line.strip():
        if lineno == 1:
            raise TruthFileError(f"{where}: empty; expected the {TRUTH_FORMAT} header")
        return
    try:
        rec = json.loads(line)
    except ValueError:
        if tolerate:
            return
        raise TruthFileError(f"{where}: not JSON: {_clip(line)}") from None
    if not isinstance(rec, dict):
        raise TruthFileError(f"{where}: expected a JSON object, got {_clip(line)}")
    if lineno == 1:
        fmt = rec.get("format")
        if fmt != TRUTH_FORMAT:
            raise TruthFileError(f"{where}: format is {fmt!r}, expected {TRUTH_FORMAT!r}")
        return
    if "format" in rec:
        raise TruthFileError(f"{where}: a second header")
    sample, sysid = _sample(rec, where)
    out.setdefault(sysid, []).append(sample)


def _sample(rec: dict[str, Any], where: str) -> tuple[TruthSample, int]:
    values: list[float] = []
    for name in _NUMBER_FIELDS:
        v = rec.get(name)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise TruthFileError(f"{where}: {name} is {v!r}, expected a number")
        if not math.isfinite(v):
            raise TruthFileError(f"{where}: {name} is {v!r}, expected a finite number")
        values.append(float(v))
    sysid = rec.get("sysid")
    if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
        raise TruthFileError(f"{where}: sysid is {sysid!r}, expected a system id 1..255")
    armed = rec.get("armed")
    if not isinstance(armed, bool):
        raise TruthFileError(f"{where}: armed is {armed!r}, expected true or false")
    on_ground = rec.get("on_ground")
    if on_ground is not None and not isinstance(on_ground, bool):
        raise TruthFileError(f"{where}: on_ground is {on_ground!r}, expected true or false")
    if not -90.0 <= values[1] <= 90.0:
        raise TruthFileError(f"{where}: lat_deg {values[1]!r} is outside [-90, 90]")
    utc, lat, lon, alt, tas, gs = values
    return TruthSample(utc, lat, lon, alt, tas, gs, armed, on_ground), sysid


def _clip(line: str, n: int = 60) -> str:
    return repr(line if len(line) <= n else line[:n] + "...")


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
    first sample (or ``after_utc_s``). None if the track never comes within the radius.
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
