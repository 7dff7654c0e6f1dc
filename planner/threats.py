"""Threats in the local frame: radar sites and no-fly polygons, forbidden or costed.

A threat acts below its ceiling (metres AMSL). A forbidden threat must never be entered; a
costed one adds exposure to the planning cost. A pop-up threat is inactive until its
appearance time (mission seconds).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.geo import LocalFrame
from planner.scenario import NoFly, Radar, Scenario

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class RadarSite:
    """A radar: detects within ``radius_m`` of its site, below ``ceiling_m``."""

    id: str
    east_m: float
    north_m: float
    radius_m: float
    ceiling_m: float
    forbidden: bool
    appears_at_s: float | None = None

    def distance_m(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        """Distance (m) from the boundary; negative inside."""
        return np.hypot(east_m - self.east_m, north_m - self.north_m) - self.radius_m

    def exposure(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        """Detection exposure in [0, 1]: 1 at the site, falling to 0 at the radius."""
        d2 = ((east_m - self.east_m) ** 2 + (north_m - self.north_m) ** 2) / self.radius_m**2
        return np.clip(1.0 - d2, 0.0, None)

    def segment_distance_m(self, e0: float, n0: float, e1: float, n1: float) -> float:
        """Smallest distance (m) from the boundary to the segment; negative if it enters."""
        return _point_segment_distance(self.east_m, self.north_m, e0, n0, e1, n1) - self.radius_m

    def bounding_box_m(self) -> tuple[float, float, float, float]:
        """Least and greatest east, least and greatest north (m) of the detection disc."""
        r = self.radius_m
        return (self.east_m - r, self.east_m + r, self.north_m - r, self.north_m + r)


@dataclass(frozen=True, slots=True)
class NoFlyZone:
    """A polygon (vertices in order, not closed) below ``ceiling_m``."""

    id: str
    vertices_m: tuple[tuple[float, float], ...]
    ceiling_m: float
    forbidden: bool
    appears_at_s: float | None = None

    def _arrays(self) -> tuple[FloatArray, FloatArray]:
        v = np.asarray(self.vertices_m, dtype=np.float64)
        return v[:, 0], v[:, 1]

    def contains(self, east_m: FloatArray, north_m: FloatArray) -> NDArray[np.bool_]:
        """Even-odd point-in-polygon test, vectorised."""
        vx, vy = self._arrays()
        inside = np.zeros(np.shape(east_m), dtype=bool)
        e = np.asarray(east_m, dtype=np.float64)
        n = np.asarray(north_m, dtype=np.float64)
        j = len(vx) - 1
        for i in range(len(vx)):
            crosses = (vy[i] > n) != (vy[j] > n)
            with np.errstate(divide="ignore", invalid="ignore"):
                x_at = (vx[j] - vx[i]) * (n - vy[i]) / (vy[j] - vy[i]) + vx[i]
            inside ^= crosses & (e < x_at)
            j = i
        return inside

    def distance_m(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        """Distance (m) from the boundary; negative inside."""
        vx, vy = self._arrays()
        e = np.asarray(east_m, dtype=np.float64)
        n = np.asarray(north_m, dtype=np.float64)
        best = np.full(e.shape, np.inf)
        for i in range(len(vx)):
            j = (i + 1) % len(vx)
            best = np.minimum(best, _points_segment_distance(e, n, vx[i], vy[i], vx[j], vy[j]))
        return np.where(self.contains(e, n), -best, best)

    def exposure(self, east_m: FloatArray, north_m: FloatArray) -> FloatArray:
        return self.contains(east_m, north_m).astype(np.float64)

    def bounding_box_m(self) -> tuple[float, float, float, float]:
        """Least and greatest east, least and greatest north (m) of the polygon."""
        east = [e for e, _ in self.vertices_m]
        north = [n for _, n in self.vertices_m]
        return (min(east), max(east), min(north), max(north))

    def segment_distance_m(self, e0: float, n0: float, e1: float, n1: float) -> float:
        """Smallest distance (m) from the boundary to the segment; negative if it enters.

        A segment that only touches the boundary (through a vertex or along an edge) without
        entering gets 0. Entering through vertices, with no proper edge crossing, is caught
        by testing the pieces between successive boundary contacts for containment.
        """
        if self.contains(np.array([e0, e1]), np.array([n0, n1])).any():
            return -1.0
        best = math.inf
        contacts = [0.0, 1.0]
        verts = self.vertices_m
        de, dn = e1 - e0, n1 - n0
        length2 = de * de + dn * dn
        for i, (ax, ay) in enumerate(verts):
            bx, by = verts[(i + 1) % len(verts)]
            if _segments_intersect(e0, n0, e1, n1, ax, ay, bx, by):
                return -1.0
            d_vertex = _point_segment_distance(ax, ay, e0, n0, e1, n1)
            if d_vertex <= 1e-9 and length2 > 0.0:
                contacts.append(((ax - e0) * de + (ay - n0) * dn) / length2)
            best = min(
                best,
                d_vertex,
                _point_segment_distance(e0, n0, ax, ay, bx, by),
                _point_segment_distance(e1, n1, ax, ay, bx, by),
            )
        if best <= 1e-9:
            t = np.unique(np.clip(contacts, 0.0, 1.0))
            mid = 0.5 * (t[:-1] + t[1:])
            if self.contains(e0 + de * mid, n0 + dn * mid).any():
                return -1.0
            return 0.0
        return best


ThreatZone = RadarSite | NoFlyZone


def _point_segment_distance(
    px: float, py: float, ax: float, ay: float, bx: float, by: float
) -> float:
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / length2))
    return math.hypot(px - (ax + t * dx), py - (ay + t * dy))


def _points_segment_distance(
    px: FloatArray, py: FloatArray, ax: float, ay: float, bx: float, by: float
) -> FloatArray:
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    if length2 == 0.0:
        return np.hypot(px - ax, py - ay)
    t = np.clip(((px - ax) * dx + (py - ay) * dy) / length2, 0.0, 1.0)
    return np.hypot(px - (ax + t * dx), py - (ay + t * dy))


def _orient(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> float:
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def _segments_intersect(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float
) -> bool:
    d1 = _orient(cx, cy, dx, dy, ax, ay)
    d2 = _orient(cx, cy, dx, dy, bx, by)
    d3 = _orient(ax, ay, bx, by, cx, cy)
    d4 = _orient(ax, ay, bx, by, dx, dy)
    return (d1 * d2 < 0.0) and (d3 * d4 < 0.0)


def build_threats(
    scenario: Scenario, takeoff_s: Mapping[str, float] | None = None
) -> list[ThreatZone]:
    """Threats of a scenario in its local frame, with resolved appearance times.

    A threat that appears ``after_takeoff_of`` a vehicle gets that vehicle's takeoff time from
    ``takeoff_s`` plus its delay; without a known takeoff it never appears (``inf``).
    """
    frame: LocalFrame = scenario.frame()
    out: list[ThreatZone] = []
    for t in scenario.threats:
        appears: float | None = None
        if t.appears is not None:
            if t.appears.at_s is not None:
                appears = t.appears.at_s
            else:
                ref = (takeoff_s or {}).get(t.appears.after_takeoff_of or "")
                appears = math.inf if ref is None else ref + t.appears.delay_s
        if isinstance(t, Radar):
            e, n = t.center.local(frame)
            out.append(RadarSite(t.id, e, n, t.radius_m, t.ceiling_m, t.forbidden, appears))
        elif isinstance(t, NoFly):
            verts = tuple(p.local(frame) for p in t.polygon)
            out.append(NoFlyZone(t.id, verts, t.ceiling_m, t.forbidden, appears))
    return out


def active(threats: Iterable[ThreatZone], t_s: float | None) -> list[ThreatZone]:
    """Threats in force at mission time ``t_s`` (``None``: only those with no appearance)."""
    if t_s is None:
        return [t for t in threats if t.appears_at_s is None]
    return [t for t in threats if t.appears_at_s is None or t.appears_at_s <= t_s]


def exposure(
    threats: Sequence[ThreatZone], east_m: FloatArray, north_m: FloatArray, alt_m: FloatArray
) -> FloatArray:
    """Summed exposure of the costed threats at the given points (altitude AMSL)."""
    total = np.zeros(np.shape(east_m), dtype=np.float64)
    for t in threats:
        if not t.forbidden:
            total += np.where(alt_m < t.ceiling_m, t.exposure(east_m, north_m), 0.0)
    return total


def forbidden_mask(
    threats: Sequence[ThreatZone],
    east_m: FloatArray,
    north_m: FloatArray,
    alt_m: FloatArray,
    margin_m: float = 0.0,
) -> NDArray[np.bool_]:
    """True where a point lies within ``margin_m`` of a forbidden threat below its ceiling."""
    mask = np.zeros(np.shape(east_m), dtype=bool)
    for t in threats:
        if t.forbidden:
            mask |= (t.distance_m(east_m, north_m) < margin_m) & (alt_m < t.ceiling_m)
    return mask


def forbidden_at(
    threats: Sequence[ThreatZone], east_m: float, north_m: float, alt_m: float
) -> ThreatZone | None:
    """The first forbidden threat containing the point, if any."""
    e = np.array([east_m])
    n = np.array([north_m])
    for t in threats:
        if t.forbidden and alt_m < t.ceiling_m and t.distance_m(e, n)[0] < 0.0:
            return t
    return None


def polyline_clearance_m(
    threats: Sequence[ThreatZone], points_m: FloatArray, alt_m: FloatArray
) -> tuple[float, str | None]:
    """Smallest distance (m) from any forbidden zone to a polyline, and that zone's id.

    Exact for straight legs. A leg counts against a zone when either end is below the
    zone's ceiling. Negative means the polyline enters the zone.
    """
    best, which = math.inf, None
    pts = np.asarray(points_m, dtype=np.float64)
    alts = np.asarray(alt_m, dtype=np.float64)
    for t in threats:
        if not t.forbidden:
            continue
        for i in range(len(pts) - 1):
            if min(alts[i], alts[i + 1]) >= t.ceiling_m:
                continue
            d = t.segment_distance_m(pts[i, 0], pts[i, 1], pts[i + 1, 0], pts[i + 1, 1])
            if d < best:
                best, which = d, t.id
    return best, which
