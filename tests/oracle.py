"""The flight tests' judge: a flown team measured from the simulator's truth log and the
scenario as planned, with nothing taken from the coordinator's own figures.

It imports nothing from ``gcs`` or ``planner``: it parses the truth log itself
(``tcgcs-truth/1``, docs/sitl_stub.md), places the scenario's local east/north points with
PROJ (the scenario's frame is a Transverse Mercator about the area's origin on WGS84, scale 1
on its central meridian) and measures 3-D distances between earth-centred (ECEF) positions.
The truth's ``alt_m`` is above mean sea level, taken here as height over the ellipsoid: the
geoid's slope over a scenario's tens of kilometres moves a distance by centimetres.

- :func:`read_tracks`: each vehicle's true samples, by system id.
- :func:`goal_passage`: when a vehicle passed its goal, the closest approach within a tight
  radius (150 m, as the goal is flown through), between samples included.
- :func:`separation`: every pair's 3-D distance at every truth sample both are airborne, the
  whole flight long (holds after arrival included).
- :func:`zone_entries`: true samples inside a forbidden zone, below its ceiling, once it was
  there (:func:`scenario_zones`: a zone that appears after a vehicle's takeoff is there from
  when the truth has that vehicle leave the ground, :func:`takeoffs`).
- :func:`planned_slots` and :func:`arrival_misses`: each vehicle's slot as the schedule set it
  before launch (checked against the scenario's arrival rule), and who missed it.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pyproj import Transformer

TRUTH_FORMAT = "tcgcs-truth/1"
GOAL_PASS_M = 150.0
"""A goal passage is looked for this close to the goal (horizontally): every route flies
through its goal (a run-out waypoint lies beyond it)."""

Floats = NDArray[np.float64]


@dataclass(frozen=True)
class Track:
    """One vehicle's true samples in time order (arrays of one length)."""

    utc_s: Floats
    lat_deg: Floats
    lon_deg: Floats
    alt_m: Floats
    """Above mean sea level."""
    terrain_m: Floats
    """The ground under it (AMSL); NaN where the log does not say."""
    airborne: NDArray[np.bool_]
    """Armed and off the ground."""
    crashed: NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.utc_s.size)

    def since(self, utc_s: float) -> Track:
        return self.between(utc_s, math.inf)

    def between(self, from_utc_s: float, to_utc_s: float) -> Track:
        """The samples from ``from_utc_s`` to ``to_utc_s``."""
        keep = (self.utc_s >= from_utc_s) & (self.utc_s <= to_utc_s)
        return Track(*(getattr(self, f)[keep] for f in _FIELDS))


_FIELDS = ("utc_s", "lat_deg", "lon_deg", "alt_m", "terrain_m", "airborne", "crashed")


def read_tracks(path: Path | str) -> dict[int, Track]:
    """Each vehicle's samples by system id. A last line without its newline (the simulator may
    be writing it) is left out; anything else that is not a sample raises ``ValueError``
    naming the line."""
    text = Path(path).read_text(encoding="utf-8")
    lines = text.split("\n")[:-1]
    if not lines:
        raise ValueError(f"{path}: no header line")
    header = json.loads(lines[0])
    if header.get("format") != TRUTH_FORMAT:
        raise ValueError(f"{path} line 1: format {header.get('format')!r}, not {TRUTH_FORMAT}")
    rows: dict[int, list[tuple[float, ...]]] = {}
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
            row = (
                float(r["utc_s"]),
                float(r["lat_deg"]),
                float(r["lon_deg"]),
                float(r["alt_m"]),
                float(r.get("terrain_m", math.nan)),
                float(bool(r["armed"]) and not r.get("on_ground", False)),
                float(bool(r.get("crashed", False))),
            )
            sysid = int(r["sysid"])
        except (ValueError, KeyError, TypeError) as err:
            raise ValueError(f"{path} line {lineno}: not a truth sample ({err})") from None
        rows.setdefault(sysid, []).append(row)
    out: dict[int, Track] = {}
    for sysid, rs in rows.items():
        a = np.array(sorted(rs), dtype=np.float64)
        out[sysid] = Track(*(a[:, k].copy() for k in range(5)), a[:, 5] > 0.5, a[:, 6] > 0.5)
    return out


def tracks_by_vehicle(truth: Path | str, record: Mapping[str, Any]) -> dict[str, Track]:
    """The truth log's tracks by vehicle id, through the record's system ids (the only thing
    taken from the record: which simulated vehicle each id is)."""
    by_sysid = read_tracks(truth)
    return {v["id"]: by_sysid[v["system_id"]] for v in record["vehicles"]}


# -- the scenario's ground -------------------------------------------------------------------


class Ground:
    """The scenario's local east/north plane (m), by PROJ."""

    def __init__(self, origin_lat_deg: float, origin_lon_deg: float) -> None:
        tm = (
            f"+proj=tmerc +lat_0={origin_lat_deg!r} +lon_0={origin_lon_deg!r} +k=1 "
            "+x_0=0 +y_0=0 +ellps=WGS84 +units=m"
        )
        self._to_local = Transformer.from_crs("EPSG:4326", tm, always_xy=True)

    @classmethod
    def of(cls, scenario: Mapping[str, Any]) -> Ground:
        """The plane of a scenario document (its ``area.origin``)."""
        o = scenario["area"]["origin"]
        return cls(float(o["lat_deg"]), float(o["lon_deg"]))

    def local(self, track: Track) -> tuple[Floats, Floats]:
        return self.to_local(track.lat_deg, track.lon_deg)

    def to_local(self, lat_deg: Any, lon_deg: Any) -> tuple[Floats, Floats]:
        """East and north (m) of points given in degrees (numbers or arrays)."""
        e, n = self._to_local.transform(lon_deg, lat_deg)
        return np.asarray(e, dtype=np.float64), np.asarray(n, dtype=np.float64)

    def to_geodetic(self, east_m: Any, north_m: Any) -> tuple[Floats, Floats]:
        """Latitude and longitude (deg) of local points: the inverse of :meth:`to_local`."""
        lon, lat = self._to_local.transform(east_m, north_m, direction="INVERSE")
        return np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64)


_ECEF = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


def _ecef(track: Track) -> Floats:
    x, y, z = _ECEF.transform(track.lon_deg, track.lat_deg, track.alt_m)
    return np.column_stack([x, y, z]).astype(np.float64)


# -- goal passages ---------------------------------------------------------------------------


def goal_passage(
    track: Track,
    ground: Ground,
    goal_en_m: tuple[float, float],
    *,
    radius_m: float = GOAL_PASS_M,
    after_utc_s: float | None = None,
) -> float | None:
    """The UTC of the first passage of the goal: the closest approach (horizontal, linear
    between airborne samples) of the first run of the track within ``radius_m`` of it, after
    takeoff (and after ``after_utc_s``); None if it never came that close."""
    t = track if after_utc_s is None else track.since(after_utc_s)
    ok = t.airborne
    if ok.sum() < 2:
        return None
    idx = np.flatnonzero(ok)
    utc = t.utc_s[idx]
    e, n = ground.local(t)
    e, n = e[idx] - goal_en_m[0], n[idx] - goal_en_m[1]
    # The closest point of each segment between consecutive airborne samples.
    de, dn = np.diff(e), np.diff(n)
    u = np.clip(-(e[:-1] * de + n[:-1] * dn) / np.maximum(de * de + dn * dn, 1e-12), 0.0, 1.0)
    miss = np.hypot(e[:-1] + u * de, n[:-1] + u * dn)
    close = np.flatnonzero(miss <= radius_m)
    if close.size == 0:
        return None
    breaks = np.flatnonzero(np.diff(close) > 1)
    run = close if breaks.size == 0 else close[: breaks[0] + 1]
    k = int(run[np.argmin(miss[run])])
    return float(utc[k] + u[k] * (utc[k + 1] - utc[k]))


# -- separation ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Separation:
    """The least 3-D distance between two airborne vehicles over the whole log."""

    least_m: float
    pair: tuple[str, str]
    utc_s: float
    compared: int
    """Pair-samples compared (both airborne at one truth time)."""

    def __str__(self) -> str:
        a, b = self.pair
        return f"{self.least_m:.0f} m ({a}, {b} at UTC {self.utc_s:.1f}; {self.compared} compared)"


def separation(tracks: Mapping[str, Track], *, from_utc_s: float | None = None) -> Separation:
    """Every pair at every truth time both are airborne, in 3-D (ECEF)."""
    ids = sorted(tracks)
    stamps = np.unique(np.concatenate([np.round(tracks[v].utc_s, 3) for v in ids]))
    if from_utc_s is not None:
        stamps = stamps[stamps >= from_utc_s]
    pos = np.full((stamps.size, len(ids), 3), np.nan)
    for j, vid in enumerate(ids):
        tr = tracks[vid]
        at = np.round(tr.utc_s, 3)
        keep = tr.airborne & np.isin(at, stamps)
        rows = np.searchsorted(stamps, at[keep])
        pos[rows, j] = _ecef(tr)[keep]
    best = (math.inf, ("", ""), math.nan)
    compared = 0
    for j in range(len(ids) - 1):
        d = np.linalg.norm(pos[:, j + 1 :] - pos[:, j : j + 1], axis=2)
        compared += int(np.isfinite(d).sum())
        if np.isfinite(d).any():
            k_t, k_p = np.unravel_index(np.nanargmin(d), d.shape)
            if d[k_t, k_p] < best[0]:
                best = (float(d[k_t, k_p]), (ids[j], ids[j + 1 + k_p]), float(stamps[k_t]))
    return Separation(best[0], best[1], best[2], compared)


# -- zones -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Zone:
    """A forbidden zone as the scenario (or the operator) gives it: a disc or a polygon (local
    m) below a ceiling (AMSL), there from ``from_utc_s`` on."""

    id: str
    ceiling_m: float
    from_utc_s: float
    centre_en_m: tuple[float, float] | None = None
    radius_m: float = 0.0
    polygon_en_m: tuple[tuple[float, float], ...] = ()

    @classmethod
    def of(cls, threat: Mapping[str, Any], from_utc_s: float) -> Zone:
        """From a scenario threat (``radar`` or ``no_fly``) given in local metres."""
        ceiling = float(threat.get("ceiling_m", 30_000.0))
        if threat["kind"] == "radar":
            c = threat["center"]
            centre = (float(c["east_m"]), float(c["north_m"]))
            return cls(threat["id"], ceiling, from_utc_s, centre, float(threat["radius_m"]))
        poly = tuple((float(p["east_m"]), float(p["north_m"])) for p in threat["polygon"])
        return cls(threat["id"], ceiling, from_utc_s, polygon_en_m=poly)

    def inside(self, east: Floats, north: Floats) -> NDArray[np.bool_]:
        if self.centre_en_m is not None:
            dist = np.hypot(east - self.centre_en_m[0], north - self.centre_en_m[1])
            return np.asarray(dist < self.radius_m)
        # Even-odd rule: a ray east from each point crosses the edges.
        inside = np.zeros(east.shape, dtype=np.bool_)
        poly = self.polygon_en_m
        for (x0, y0), (x1, y1) in zip(poly, poly[1:] + poly[:1], strict=True):
            straddles = (y0 > north) != (y1 > north)
            with np.errstate(divide="ignore", invalid="ignore"):
                x_cross = x0 + (north - y0) * (x1 - x0) / (y1 - y0)
            inside ^= straddles & (east < x_cross)
        return inside


def zone_entries(
    tracks: Mapping[str, Track], ground: Ground, zones: Iterable[Zone]
) -> list[tuple[str, str, float]]:
    """``(vehicle, zone, utc_s)`` of every airborne true sample inside a zone below its
    ceiling once the zone was there."""
    out: list[tuple[str, str, float]] = []
    for vid, tr in sorted(tracks.items()):
        e, n = ground.local(tr)
        for z in zones:
            bad = tr.airborne & (tr.utc_s >= z.from_utc_s) & (tr.alt_m < z.ceiling_m)
            bad &= z.inside(e, n)
            out += [(vid, z.id, float(u)) for u in tr.utc_s[bad]]
    return out


def scenario_zones(
    scenario: Mapping[str, Any],
    start_utc_s: float,
    takeoffs_utc_s: Mapping[str, float | None] | None = None,
) -> list[Zone]:
    """The scenario's forbidden zones there from the start, from a fixed mission time
    (``appears.at_s``) or ``delay_s`` after a vehicle's takeoff (``after_takeoff_of``): that
    vehicle's takeoff as ``takeoffs_utc_s`` gives it (:func:`takeoffs`: when the truth has it
    leave the ground). A zone whose vehicle never took off never appeared."""
    out = []
    for t in scenario.get("threats", []):
        if not t.get("forbidden", t["kind"] == "no_fly"):
            continue
        appears = t.get("appears")
        if appears is None:
            out.append(Zone.of(t, start_utc_s))
        elif appears.get("at_s") is not None:
            out.append(Zone.of(t, start_utc_s + float(appears["at_s"])))
        else:
            vid = appears["after_takeoff_of"]
            if takeoffs_utc_s is None or vid not in takeoffs_utc_s:
                raise ValueError(f"{t['id']}: appears after {vid}'s takeoff; give its time")
            took_off = takeoffs_utc_s[vid]
            if took_off is not None:
                out.append(Zone.of(t, took_off + float(appears.get("delay_s", 0.0))))
    return out


def takeoffs(tracks: Mapping[str, Track]) -> dict[str, float | None]:
    """When each vehicle first left the ground (its first airborne true sample), by the
    truth; None if it never did. A vehicle airborne from the first sample (one taken over in
    flight) took off then."""
    out: dict[str, float | None] = {}
    for vid, tr in tracks.items():
        up = np.flatnonzero(tr.airborne)
        out[vid] = float(tr.utc_s[up[0]]) if up.size else None
    return out


# -- slots -----------------------------------------------------------------------------------


Slot = tuple[float, float]
"""Earliest and latest arrival (mission s): one time twice for a team slot, a window for
``windows``."""


def waves(arrival: Mapping[str, Any], slots_s: Mapping[str, float]) -> list[list[str]]:
    """The waves' vehicles: as named (``groups``), or, given only their sizes (the planner
    fills them, soonest first), read from the slots ``slots_s`` in time order."""
    groups = arrival.get("groups")
    if groups is not None:
        return [list(g) for g in groups]
    order, out, k = sorted(slots_s, key=slots_s.__getitem__), [], 0
    for size in arrival["sizes"]:
        out.append(order[k : k + size])
        k += size
    return out


def planned_slots(scenario: Mapping[str, Any], record: Mapping[str, Any]) -> dict[str, Slot]:
    """Each vehicle's slot as the schedule set it before launch (the record's
    ``planned_arrival_s``), checked here against the scenario's arrival rule: one team time
    for ``simultaneous``; the interval between consecutive slots for ``spaced`` (in the
    scenario's ``order``, else in the order its vehicles are given); the waves' groups (or
    sizes) and gap for ``waves``; inside each vehicle's window for ``windows`` (the slot
    returned is then the window)."""
    planned = {v["id"]: float(v["planned_arrival_s"]) for v in record["vehicles"]}
    arrival = scenario["arrival"]
    kind = arrival["kind"]
    if kind == "windows":
        windows = {
            w["vehicle"]: (float(w["earliest_s"]), float(w["latest_s"])) for w in arrival["windows"]
        }
        outside = {v: t for v, t in planned.items() if not windows[v][0] <= t <= windows[v][1]}
        assert not outside, f"planned outside their windows: {outside} {windows}"
        return windows
    ref = record["planned_arrival_s"]
    assert ref is not None, "a team arrival with no planned team time"
    ref = float(ref)
    rule: dict[str, float]
    if kind == "simultaneous":
        rule = dict.fromkeys(planned, ref)
    elif kind == "spaced":
        # The scenario's order, or else the order its vehicles are given in (the format's).
        order = list(arrival.get("order") or [v["id"] for v in scenario["vehicles"]])
        rule = {v: ref + k * float(arrival["interval_s"]) for k, v in enumerate(order)}
    elif kind == "waves":
        gap_s = float(arrival["gap_s"])
        groups = waves(arrival, planned)
        rule = {v: ref + k * gap_s for k, group in enumerate(groups) for v in group}
    else:
        raise ValueError(f"arrival kind {kind!r}")
    off = {v: round(planned[v] - rule[v], 3) for v in planned if abs(planned[v] - rule[v]) > 1e-3}
    assert not off, f"the planned slots break the {kind} rule by {off} (s)"
    return {v: (t, t) for v, t in rule.items()}


def slot_rule_breaks(scenario: Mapping[str, Any], slots_s: Mapping[str, float]) -> list[str]:
    """How the slots ``slots_s`` (mission s, each vehicle's, as moved in flight) break the
    scenario's arrival rule, where slots move apart (ordered kinds): ``spaced``, consecutive
    slots (in their order as moved: a vehicle may take a later place) closer than the
    interval; ``waves``, a wave's vehicles on different slots, or consecutive waves closer
    than the gap; ``simultaneous``, vehicles on different slots. Nothing for ``windows``."""
    arrival = scenario["arrival"]
    kind = arrival["kind"]
    same_s = 1e-3
    if kind == "windows" or not slots_s:
        return []
    if kind == "simultaneous":
        lo, hi = min(slots_s.values()), max(slots_s.values())
        return (
            [f"slots {lo:.3f}-{hi:.3f} s apart in a simultaneous arrival"]
            if hi - lo > same_s
            else []
        )
    if kind == "spaced":
        spacing_s, groups = float(arrival["interval_s"]), [[v] for v in slots_s]
    else:
        spacing_s, groups = float(arrival["gap_s"]), waves(arrival, slots_s)
    out = []
    at: list[tuple[float, list[str]]] = []
    for group in groups:
        times = [slots_s[v] for v in group if v in slots_s]
        if not times:
            continue
        if max(times) - min(times) > same_s:
            out.append(f"one wave on slots {min(times):.3f}-{max(times):.3f} s: {group}")
        at.append((min(times), group))
    at.sort(key=lambda x: x[0])
    for (t0, g0), (t1, g1) in itertools.pairwise(at):
        if t1 - t0 < spacing_s - same_s:
            out.append(f"{g0} and {g1} on slots {t1 - t0:.3f} s apart (at least {spacing_s:g})")
    return out


def arrival_misses(
    passages: Mapping[str, float | None],
    slots: Mapping[str, Slot],
    *,
    tolerance_s: float,
    shift_s: float | Mapping[str, float] = 0.0,
) -> dict[str, Any]:
    """The vehicles that did not pass their goal within ``tolerance_s`` of their slot moved by
    ``shift_s`` (a team time the test allowed to move, or each vehicle's own slot's move),
    with how far off (s) or ``None`` (never passed)."""
    out: dict[str, Any] = {}
    for vid, (lo, hi) in slots.items():
        t = passages.get(vid)
        shift_s_v = shift_s[vid] if isinstance(shift_s, Mapping) else shift_s
        lo, hi = lo + shift_s_v, hi + shift_s_v
        if t is None:
            out[vid] = None
        elif not lo - tolerance_s <= t <= hi + tolerance_s:
            out[vid] = round(t - lo if t < lo else t - hi, 2)
    return out


def passages(
    tracks: Mapping[str, Track],
    ground: Ground,
    goals_en_m: Mapping[str, tuple[float, float]],
    start_utc_s: float,
    *,
    radius_m: float = GOAL_PASS_M,
) -> dict[str, float | None]:
    """Each vehicle's first goal passage after takeoff, in mission s (None: never)."""
    out: dict[str, float | None] = {}
    for vid, goal in goals_en_m.items():
        utc = goal_passage(tracks[vid], ground, goal, radius_m=radius_m)
        out[vid] = None if utc is None else utc - start_utc_s
    return out


def goals(scenario: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    """Each vehicle's goal (local m) as the scenario gives it."""
    return {
        v["id"]: (float(v["goal"]["east_m"]), float(v["goal"]["north_m"]))
        for v in scenario["vehicles"]
    }


def below_terrain(tracks: Mapping[str, Track], clearance_m: float) -> list[tuple[str, float]]:
    """``(vehicle, utc_s)`` where an airborne vehicle was under ``clearance_m`` above the ground
    the simulator had under it."""
    out: list[tuple[str, float]] = []
    for vid, tr in sorted(tracks.items()):
        low = tr.airborne & (tr.alt_m - tr.terrain_m < clearance_m)
        out += [(vid, float(u)) for u in tr.utc_s[low]]
    return out


def summary(seq: Sequence[Any], limit: int = 8) -> str:
    """The first ``limit`` items of a long list of findings, and how many there are."""
    more = f" ... ({len(seq)} in all)" if len(seq) > limit else ""
    return ", ".join(map(str, seq[:limit])) + more
