"""From a scenario to flyable routes: build the world, solve on the grid, smooth, profile, check.

The pipeline is pure: terrain, threats and cost maps from the scenario; the exact search or
the multi-colony ACO on the grid; each route shortened by line-of-sight where that costs no
more, smoothed with Dubins arcs at the minimum turn radius (section 3.2), given an altitude
profile that keeps terrain clearance within the climb gradient, and checked against the
constraints of eq. (4) and the forbidden zones. A route that breaks a safety constraint is an
error naming the vehicle; it is never returned as a plan.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from planner.aco import AcoOptions, solve_aco
from planner.backend import Backend, LocalBackend
from planner.coupling import TimingLimits, team_min_separation_m, team_timing
from planner.errors import InfeasibleError
from planner.flightpath import (
    COLLINEAR_RAD,
    FlightPath,
    Violation,
    check_polyline,
    heading_diff_rad,
    smooth_polyline,
)
from planner.geo import LocalFrame
from planner.grid import CostMap, Grid, VehicleClass, build_cost_map
from planner.landing import check_glide, final_m
from planner.pool import default_workers, forked_map
from planner.problem import Problem, SolveResult, Status, VehicleTask, task_fields
from planner.scenario import (
    Scenario,
    Simultaneous,
    Spaced,
    Vehicle,
    Waves,
    Windows,
)
from planner.search import solve_exact
from planner.terrain import Terrain, build_terrain
from planner.threats import ThreatZone, active, build_threats, forbidden_at, polyline_clearance_m

FloatArray = NDArray[np.float64]
Method = Literal["aco", "astar"]
PROFILE_STEP_M = 50.0
CLIMB_OUT_CLEARANCE_FRACTION = 0.5
"""Climbing from home, the aircraft keeps at least this fraction of the height it has climbed
between it and the terrain (until that is ``clearance_m``): level ground under the climb
leaves all of it, rising ground ahead eats into it. A route whose climb-out rises toward
terrain faster than that is refused (a departure's obstacle-clearance idea: the climb must
outclimb the ground ahead by a margin that grows with the distance flown)."""
CLIMB_HEAD_FACTOR = 1.5
"""A route whose shortened climb from home is too low keeps its grid legs as they are for
this many times the distance that climb took, and is shortened after them."""


def timing_limits(scenario: Scenario) -> list[TimingLimits]:
    """Each vehicle's timing limits under the scenario's arrival constraint."""
    arrival = scenario.arrival
    offsets = scenario.arrival_offsets_s()
    own: dict[str, tuple[float, float]] = {}
    if isinstance(arrival, Windows):
        own = {w.vehicle: (w.earliest_s, w.latest_s) for w in arrival.windows}
    out = []
    for v in scenario.vehicles:
        lo, hi = (0.0, 0.0) if v.airborne else v.takeoff_window_s
        w_lo, w_hi = own.get(v.id, (-math.inf, math.inf))
        out.append(
            TimingLimits(
                v.speed_min_m_s, v.speed_max_m_s, v.cruise_m_s, lo, hi, offsets[v.id], w_lo, w_hi
            )
        )
    return out


def required_arrival_s(scenario: Scenario) -> float | None:
    arrival = scenario.arrival
    if isinstance(arrival, Simultaneous):
        return arrival.required_s
    if isinstance(arrival, Spaced | Waves):
        return arrival.first_s
    return None


@dataclass(frozen=True, eq=False)
class World:
    """Everything the planner derives from a scenario once: frame, terrain, grid, threats."""

    scenario: Scenario
    frame: LocalFrame
    terrain: Terrain
    grid: Grid
    terrain_grid_m: FloatArray
    threats: tuple[ThreatZone, ...]


def build_world(scenario: Scenario, takeoff_s: Mapping[str, float] | None = None) -> World:
    area = scenario.area
    grid = Grid.covering(
        area.min_east_m, area.min_north_m, area.width_m, area.height_m, area.resolution_m
    )
    terrain = build_terrain(scenario)
    east, north = grid.coords()
    return World(
        scenario,
        scenario.frame(),
        terrain,
        grid,
        np.asarray(terrain.elevation_m(east, north), dtype=np.float64),
        tuple(build_threats(scenario, takeoff_s)),
    )


def _vehicle_class(v: Vehicle) -> VehicleClass:
    return VehicleClass(v.clearance_m, v.alt_min_m, v.alt_max_m, max(v.start.alt_m, v.goal.alt_m))


def _free_node(cmap: CostMap, east_m: float, north_m: float) -> int | None:
    """The nearest unblocked node within two cells of a point."""
    grid = cmap.grid
    best, best_d = None, math.inf
    centre = grid.nearest(east_m, north_m)
    ci, cj = centre % grid.n_east, centre // grid.n_east
    for dj in range(-2, 3):
        for di in range(-2, 3):
            i, j = ci + di, cj + dj
            if not (0 <= i < grid.n_east and 0 <= j < grid.n_north):
                continue
            node = j * grid.n_east + i
            if cmap.blocked[node]:
                continue
            d = math.hypot(
                grid.min_east_m + i * grid.resolution_m - east_m,
                grid.min_north_m + j * grid.resolution_m - north_m,
            )
            if d < best_d:
                best, best_d = node, d
    return best


def build_problem(
    world: World,
    *,
    threats: Sequence[ThreatZone],
    starts: Mapping[str, tuple[float, float, float]] | None = None,
    vehicles: Sequence[str] | None = None,
) -> Problem:
    """The grid problem for the chosen vehicles from their scenario (or given) starts.

    Raises
    ------
    InfeasibleError
        A start or goal inside a forbidden zone, or with no free grid node near it.
    """
    scenario = world.scenario
    frame = world.frame
    chosen = [scenario.vehicle(v) for v in vehicles] if vehicles else list(scenario.vehicles)
    limits = dict(zip([v.id for v in scenario.vehicles], timing_limits(scenario), strict=True))
    maps: dict[VehicleClass, CostMap] = {}
    neighbors = world.grid.neighbors()
    w = scenario.weights
    tasks = []
    for v in chosen:
        key = _vehicle_class(v)
        if key not in maps:
            maps[key] = build_cost_map(
                world.grid,
                world.terrain_grid_m,
                threats,
                key,
                threat_weight=w.threat,
                terrain_weight=w.terrain,
                neighbors=neighbors,
            )
        cmap = maps[key]
        start = (starts or {}).get(v.id)
        if start is None:
            se, sn = v.start.local(frame)
            start = (se, sn, v.start.alt_m)
        ge, gn = v.goal.local(frame)
        tail: tuple[tuple[float, float], ...] = ()
        goal_name = "goal"
        if scenario.landing is not None:
            # The search ends where the slot's straight final begins; the final is the tail.
            (ge, gn), fix = final_m(scenario.landing, v, frame)
            tail, goal_name = (fix,), "start of its final"
            check_glide(scenario.landing, v, frame, world.terrain, threats)
            if not scenario.area.contains(ge, gn):
                raise InfeasibleError(
                    f"vehicle {v.id}: the start of its final ({ge:.0f}, {gn:.0f}) m, "
                    f"landing.approach_m {scenario.landing.approach_m:g} before its slot fix, "
                    "is outside the area",
                    vehicle=v.id,
                )
        nodes = []
        for name, (e, n, alt) in (("start", start), (goal_name, (ge, gn, v.goal.alt_m))):
            zone = forbidden_at(threats, e, n, alt)
            if zone is not None:
                raise InfeasibleError(
                    f"vehicle {v.id}: {name} ({e:.0f}, {n:.0f}) m "
                    f"is inside forbidden zone {zone.id}",
                    vehicle=v.id,
                )
            node = _free_node(cmap, e, n)
            if node is None:
                raise InfeasibleError(
                    f"vehicle {v.id}: {name} ({e:.0f}, {n:.0f}) m has no free grid node nearby "
                    "(too close to a forbidden zone, or terrain above alt_max_m)",
                    vehicle=v.id,
                )
            nodes.append(node)
        tasks.append(
            VehicleTask(
                v.id,
                nodes[0],
                nodes[1],
                (start[0], start[1]),
                (ge, gn),
                cmap,
                limits[v.id],
                tail,
            )
        )
    return Problem(tuple(tasks), required_arrival_s(scenario), scenario.separation_m)


def solve(
    problem: Problem,
    method: Method = "aco",
    *,
    rng: np.random.Generator | None = None,
    options: AcoOptions | None = None,
    workers: int = 1,
) -> SolveResult:
    """One entry point for both solvers (``workers``: the ACO's walkers, :func:`solve_aco`)."""
    if method == "astar":
        return solve_exact(problem)
    if method == "aco":
        return solve_aco(
            problem,
            rng=rng if rng is not None else np.random.default_rng(0),
            options=options,
            workers=workers,
        )
    raise ValueError(f"method must be 'aco' or 'astar', not {method!r}")


# --- route post-processing -------------------------------------------------------------


def _sample_chords(
    start_m: FloatArray, ends_m: FloatArray, step_m: float
) -> tuple[FloatArray, FloatArray, list[int]]:
    """Evenly spaced points on the chords from one point to each of ``ends_m`` (K, 2).

    Each chord gets ``max(2, ceil(length / step_m) + 1)`` points, both ends included, at the
    fractions ``np.linspace(0, 1, n)`` gives (``k * (1 / (n - 1))``, the last exactly 1), so a
    chord's points are the same whether it is sampled alone or with others. Returns the
    (N, 2) points, each chord's length (m) and the K + 1 bounds of the chords' rows.
    """
    delta_m = ends_m - start_m
    length_m = np.hypot(delta_m[:, 0], delta_m[:, 1])
    counts = np.maximum(2, np.ceil(length_m / step_m).astype(np.int64) + 1)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    index = np.arange(int(bounds[-1])) - np.repeat(bounds[:-1], counts)
    fraction = index * np.repeat(1.0 / (counts - 1), counts)
    fraction[bounds[1:] - 1] = 1.0
    points = start_m + np.repeat(delta_m, counts, axis=0) * fraction[:, None]
    return np.asarray(points, dtype=np.float64), length_m, bounds.tolist()


def _grid_field(cmap: CostMap, values: FloatArray, pts: FloatArray) -> FloatArray:
    """Bilinear interpolation of a node field at points (order-1 spline)."""
    g = cmap.grid
    i = (pts[:, 0] - g.min_east_m) / g.resolution_m
    j = (pts[:, 1] - g.min_north_m) / g.resolution_m
    return bilinear(values.reshape(g.n_north, g.n_east), j, i)


def bilinear(field: FloatArray, j: FloatArray, i: FloatArray) -> FloatArray:
    """``field`` (rows ``j``, columns ``i``) interpolated bilinearly at fractional indices,
    which are held to the field's edges outside it (an order-1 spline with its edge values
    repeated: ``scipy.ndimage.map_coordinates(field, [j, i], order=1, mode="nearest")``,
    without the second of imports that module costs every process that plans)."""
    n_j, n_i = field.shape
    j = np.clip(np.asarray(j, dtype=np.float64), 0.0, n_j - 1.0)
    i = np.clip(np.asarray(i, dtype=np.float64), 0.0, n_i - 1.0)
    j0 = np.minimum(j.astype(np.int64), max(n_j - 2, 0))
    i0 = np.minimum(i.astype(np.int64), max(n_i - 2, 0))
    j1 = np.minimum(j0 + 1, n_j - 1)
    i1 = np.minimum(i0 + 1, n_i - 1)
    fj, fi = j - j0, i - i0
    top = field[j0, i0] * (1.0 - fi) + field[j0, i1] * fi
    bottom = field[j1, i0] * (1.0 - fi) + field[j1, i1] * fi
    return np.asarray(top * (1.0 - fj) + bottom * fj, dtype=np.float64)


FIRST_CHORD_BATCH = 4
"""Chords from one route point are checked in batches that start at this size and double up
to ``MAX_CHORD_BATCH``: one cost-field and one terrain look-up per batch instead of per chord
(the per-call overhead of those look-ups, not their size, dominated simplification)."""
MAX_CHORD_BATCH = 32


def simplify_route(
    points_m: FloatArray,
    cmap: CostMap,
    threats: Sequence[ThreatZone],
    terrain: Terrain,
    margin_m: float,
) -> FloatArray:
    """Line-of-sight shortening of a grid route.

    A chord replaces a run of grid legs only when it keeps ``margin_m`` from every forbidden
    zone, stays flyable under the vehicle's ceiling, and costs no more than the legs it
    replaces (so exposure never grows). From each kept point the farthest point reached by
    an unbroken run of acceptable chords is kept next (greedy).
    """
    chords = _ChordCheck(points_m, cmap, threats, terrain, margin_m)
    keep = [0]
    i = 0
    last = len(points_m) - 1
    while i < last:
        i = chords.farthest_from(i)
        keep.append(i)
    return np.asarray(points_m[keep], dtype=np.float64)


class _ChordCheck:
    """The chord test of :func:`simplify_route`, evaluated for batches of chord ends.

    Each chord is sampled, looked up and judged exactly as on its own; a batch only shares
    the terrain and cost-field calls, so the greedy result is the same as chord by chord.
    """

    def __init__(
        self,
        points_m: FloatArray,
        cmap: CostMap,
        threats: Sequence[ThreatZone],
        terrain: Terrain,
        margin_m: float,
    ) -> None:
        self.points_m = points_m
        self.cmap = cmap
        self.zones = [(t, t.bounding_box_m()) for t in threats if t.forbidden]
        self.terrain = terrain
        self.margin_m = margin_m
        self.step_m = 0.25 * cmap.grid.resolution_m
        seg_len = np.hypot(*np.diff(points_m, axis=0).T)
        cost_mid = _grid_field(cmap, cmap.node_cost, 0.5 * (points_m[:-1] + points_m[1:]))
        self.leg_cost = np.concatenate([[0.0], np.cumsum(seg_len * cost_mid)])

    def farthest_from(self, i: int) -> int:
        """The last point ``j > i`` such that every chord ``i -> i+2 .. j`` is acceptable."""
        last = len(self.points_m) - 1
        j = i + 1
        batch = FIRST_CHORD_BATCH
        while j < last:
            ends = range(j + 1, min(j + batch, last) + 1)
            accepted = self._leading_ok(i, ends)
            j += accepted
            if accepted < len(ends):
                break
            batch = min(2 * batch, MAX_CHORD_BATCH)
        return j

    def _leading_ok(self, i: int, ends: range) -> int:
        """How many chords ``i -> j`` for ``j`` in ``ends``, in order, pass before one fails."""
        pts, length_m, bounds = _sample_chords(
            self.points_m[i], self.points_m[ends.start : ends.stop], self.step_m
        )
        # The cost test is the cheap one: the terrain is looked up only for the chords before
        # the first that costs more than its legs (a chord must pass every test).
        cost = _grid_field(self.cmap, self.cmap.node_cost, pts)
        affordable = len(ends)
        for k, j in enumerate(ends):
            # The mean of the chord's own slice: the same sum as for the chord alone.
            chord_cost = length_m[k] * float(cost[bounds[k] : bounds[k + 1]].mean())
            if chord_cost > self.leg_cost[j] - self.leg_cost[i] + 1e-6:
                affordable = k
                break
        if affordable == 0:
            return 0
        v = self.cmap.vehicle
        flown = pts[: bounds[affordable]]
        ground_m = self.terrain.elevation_m(flown[:, 0], flown[:, 1])
        alt_m = np.maximum(ground_m + v.clearance_m, v.alt_min_m)
        highest_m = np.maximum.reduceat(alt_m, bounds[:affordable]).tolist()
        lowest_m = np.minimum.reduceat(alt_m, bounds[:affordable]).tolist()
        for k, j in enumerate(ends[:affordable]):
            if highest_m[k] > v.alt_max_m or not self._clear_of_zones(i, j, lowest_m[k]):
                return k
        return affordable

    def _clear_of_zones(self, i: int, j: int, lowest_m: float) -> bool:
        """Whether chord ``i -> j``, flown no lower than ``lowest_m``, keeps the margin."""
        a, b = self.points_m[i], self.points_m[j]
        chord_box = (min(a[0], b[0]), max(a[0], b[0]), min(a[1], b[1]), max(a[1], b[1]))
        for t, zone_box in self.zones:
            if lowest_m >= t.ceiling_m:
                continue
            if _box_gap_m(chord_box, zone_box) > self.margin_m + _BOX_SLACK_M:
                continue  # the exact distance is at least the gap: no need to compute it
            if t.segment_distance_m(a[0], a[1], b[0], b[1]) < self.margin_m:
                return False
        return True


_BOX_SLACK_M = 1.0
# Bounding boxes farther apart than the margin by this much are clear of it after round-off.


def _box_gap_m(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """Distance (m) between two boxes (least east, greatest east, least north, greatest north)."""
    gap_east = max(a[0] - b[1], b[0] - a[1], 0.0)
    gap_north = max(a[2] - b[3], b[2] - a[3], 0.0)
    return math.hypot(gap_east, gap_north)


MIN_PIECE_M = 1.0
""":func:`refine_corners` leaves no piece of a leg shorter than this (m): a split nearer a
corner belongs to a turn too slight for the smoothing to cut inside it (a turn of round-off
only, on a straight line through grid nodes, would give one nanometres from the corner: a
repeated point), and a piece at least this long has a well-defined heading."""


def _fillet_m(turn_rad: FloatArray, radius_m: float) -> FloatArray:
    """Distance (m) from a corner at which its fillet arc at ``radius_m`` begins, with 5 %
    to spare (turns beyond 170 degrees counted as 170)."""
    result: FloatArray = 1.05 * radius_m * np.tan(np.minimum(turn_rad, np.radians(170.0)) / 2.0)
    return result


def _join_m(turn_rad: float, radius_m: float) -> float:
    """Distance (m) along a line from a vehicle on it, heading ``turn_rad`` off it, to the
    nearest point at which a Dubins path at ``radius_m`` joins it without a loop, with 5 % to
    spare: two arcs, toward the line and back onto it, ``r (sin theta + 2 sin beta)`` with
    ``cos beta = (1 + cos theta) / 2``."""
    beta_rad = math.acos(0.5 * (1.0 + math.cos(turn_rad)))
    return 1.05 * radius_m * (math.sin(turn_rad) + 2.0 * math.sin(beta_rad))


def _turns_rad(points_m: FloatArray) -> FloatArray:
    """Absolute heading change at each interior vertex (rad)."""
    legs = np.diff(points_m, axis=0)
    heading = np.arctan2(legs[:, 0], legs[:, 1])
    return np.asarray(np.abs((np.diff(heading) + np.pi) % (2 * np.pi) - np.pi), dtype=np.float64)


def refine_corners(
    points_m: FloatArray, radius_m: float, start_heading_rad: float | None = None
) -> FloatArray:
    """Add collinear points near each corner so midpoint smoothing hugs the corner.

    Section 3.2 joins the midpoints of adjacent legs by a Dubins path. On legs much longer
    than the turn radius that path is nearly the straight chord between the midpoints and cuts
    far inside the corner. Splitting each leg at twice the fillet tangent distance
    ``r tan(theta / 2)`` from its corners puts the midpoints where the Dubins path becomes the
    fillet arc itself; the long middle part of each leg stays straight. With a heading at the
    start, the first leg is split at twice the distance the turn from that heading onto the
    leg takes (:func:`_join_m`). No piece is left shorter than :data:`MIN_PIECE_M`.

    Vertices that go straight on (turning less than :data:`COLLINEAR_RAD`: grid nodes in a
    row) are left out, so that a corner's splits are measured along the whole straight run
    beside it, not along its leg to the next node in the row.
    """
    pts = np.asarray(points_m, dtype=np.float64)
    if len(pts) < 3:
        return pts
    corner = np.concatenate([[True], _turns_rad(pts) >= COLLINEAR_RAD, [True]])
    pts = np.asarray(pts[corner], dtype=np.float64)
    if len(pts) < 3:
        return pts
    legs = np.diff(pts, axis=0)
    length = np.hypot(legs[:, 0], legs[:, 1])
    tangent = _fillet_m(_turns_rad(pts), radius_m)
    join_m = 0.0
    if start_heading_rad is not None:
        first_rad = math.atan2(legs[0, 0], legs[0, 1])
        join_m = _join_m(heading_diff_rad(start_heading_rad, first_rad), radius_m)
    # Distance to split at, from the start and from the end of each leg.
    at_start = np.concatenate([[2.0 * join_m], 2.0 * tangent])
    at_end = np.concatenate([2.0 * tangent, [0.0]])
    out = [pts[0]]
    for k in range(len(legs)):
        a, b, d = pts[k], pts[k + 1], length[k]
        unit = legs[k] / d
        first, last = at_start[k], d - at_end[k]
        if first >= MIN_PIECE_M and first + MIN_PIECE_M < last:
            out.append(a + unit * first)
        if at_end[k] >= MIN_PIECE_M and first + MIN_PIECE_M < last:
            out.append(a + unit * last)
        out.append(b)
    return np.asarray(out, dtype=np.float64)


ONTO_ROUTE_REACH = 6.0
""":func:`onto_route` keeps every vertex at least this many turn radii from the start: as far
as the longest turn onto a leg takes, twice (:func:`_join_m`, at most about 3 radii); a
sharper turn farther on is the route's own (round the tip of a zone), not the start's."""


def onto_route(points_m: FloatArray, radius_m: float, start_heading_rad: float) -> FloatArray:
    """The polyline without the vertices after its start that a vehicle there, heading
    ``start_heading_rad``, is too near to fly by smoothing (the last vertex is always kept).

    A route re-planned in flight starts where the vehicle is, anywhere near the grid node the
    search snapped it to: its first leg may be metres long, point back behind the vehicle, or
    off its heading. Midpoint smoothing (section 3.2) turns through a vertex between the
    midpoints of its legs, and from the start to the first midpoint: when that midpoint is
    nearer than the start turn needs (:func:`_join_m`) or than the fillet of the turn at the
    leg's end (:func:`_fillet_m`), the Dubins path there is a loop of nearly a full circle
    instead of the turn. The start flies straight on to the next vertex until one is far
    enough for both, or :data:`ONTO_ROUTE_REACH` turn radii away.
    """
    pts = np.asarray(points_m, dtype=np.float64)
    while len(pts) > 2:
        leg = pts[1] - pts[0]
        first_m = float(np.hypot(*leg))
        start_turn_rad = heading_diff_rad(start_heading_rad, math.atan2(leg[0], leg[1]))
        need_m = max(
            _join_m(start_turn_rad, radius_m), float(_fillet_m(_turns_rad(pts[:3]), radius_m)[0])
        )
        if first_m >= 2.0 * need_m or first_m >= ONTO_ROUTE_REACH * radius_m:
            break
        pts = np.delete(pts, 1, axis=0)
    return pts


@dataclass(frozen=True)
class AltitudeProfile:
    """Waypoints with altitudes, and the clearance they give along the flown legs."""

    waypoints_m: FloatArray
    s_m: FloatArray
    alt_m: FloatArray
    min_clearance_m: float
    min_clearance_s_m: float
    max_gradient: float
    violations: tuple[Violation, ...]


def sample_by_distance(path: FlightPath, step_m: float) -> tuple[FloatArray, FloatArray]:
    """Evenly spaced along-path distances (m) and the (N, 2) positions there."""
    n = max(2, int(math.ceil(path.length_m / step_m)) + 1)
    s = np.linspace(0.0, path.length_m, n)
    return s, path.poses_at(s)[:, :2]


def _envelope(req: FloatArray, s: FloatArray, g: float) -> FloatArray:
    """Lowest profile above ``req`` whose slope stays within ``g`` (an upper cone envelope)."""
    fwd = np.maximum.accumulate(req + g * s) - g * s
    bwd = (np.maximum.accumulate((req - g * s)[::-1]))[::-1] + g * s
    return np.asarray(np.maximum(fwd, bwd), dtype=np.float64)


def _upper_hull(s_m: FloatArray, z_m: FloatArray) -> list[int]:
    """Indices of the upper convex hull of points sorted by ``s`` (monotone chain)."""
    # Python floats: the same double arithmetic as numpy scalars, without their overhead.
    s: list[float] = s_m.tolist()
    z: list[float] = z_m.tolist()
    hull: list[int] = []
    for k in range(len(s)):
        while len(hull) >= 2:
            i, j = hull[-2], hull[-1]
            if (s[j] - s[i]) * (z[k] - z[i]) - (z[j] - z[i]) * (s[k] - s[i]) >= 0.0:
                hull.pop()
            else:
                break
        hull.append(k)
    return hull


def _leg_breakpoints(
    s: FloatArray, lifted: FloatArray, floor: FloatArray, lo: int, hi: int
) -> list[int]:
    """Few breakpoints on samples ``lo..hi`` whose chords stay above ``floor``.

    Chords join points of the upper hull of ``lifted`` (the requirement plus a buffer), so
    they are never steeper than the requirement's own gradient bound.
    """
    hull = [lo + k for k in _upper_hull(s[lo : hi + 1], lifted[lo : hi + 1])]
    keep = [hull[0]]
    i = 0
    while i < len(hull) - 1:
        # Extend the chord from hull[i] while it stays above the floor, a batch at a time.
        j = i + 1
        batch = FIRST_CHORD_BATCH
        while j + 1 < len(hull):
            ends = hull[j + 1 : j + 1 + batch]
            above = _chords_above(s, lifted, floor, hull[i], ends)
            j += above
            if above < len(ends):
                break
            batch = min(2 * batch, MAX_CHORD_BATCH)
        keep.append(hull[j])
        i = j
    return keep


def _chords_above(
    s: FloatArray, lifted: FloatArray, floor: FloatArray, a: int, ends: list[int]
) -> int:
    """How many chords ``a -> b`` of ``lifted`` for ``b`` in ``ends``, in order, stay above
    ``floor`` (less 1e-6 m) at every sample between, before one dips below.

    The chords are evaluated together with ``np.interp``'s own arithmetic for two points
    (``slope * (x - x_a) + z_a``, exactly ``z_b`` at ``x_b``), so each verdict is the one
    ``np.interp`` on that chord alone gives.
    """
    stops = np.asarray(ends, dtype=np.int64)
    counts = stops - a + 1
    bounds = np.concatenate([[0], np.cumsum(counts)])
    chord = np.repeat(stops, counts)
    index = a + np.arange(int(bounds[-1])) - np.repeat(bounds[:-1], counts)
    slope = (lifted[chord] - lifted[a]) / (s[chord] - s[a])
    z = slope * (s[index] - s[a]) + lifted[a]
    z[bounds[1:] - 1] = lifted[stops]
    below = z < floor[index] - 1e-6
    dips = np.flatnonzero(np.logical_or.reduceat(below, bounds[:-1]))
    return int(dips[0]) if dips.size else len(ends)


def altitude_profile(
    path: FlightPath,
    terrain: Terrain,
    v: Vehicle,
    start_alt_m: float,
    buffer_m: float = 30.0,
    *,
    level_final_m: float = 0.0,
) -> AltitudeProfile:
    """Waypoints and altitudes that keep ``clearance_m`` within ``climb_gradient``.

    The required altitude along the smoothed path is terrain + clearance (not below
    ``alt_min_m``), spread into an envelope whose slope stays within the gradient and bounded
    below by the start and goal altitudes. The autopilot flies straight lines between
    waypoints, so the waypoints are the path's own (segment ends, arc points) plus breakpoints
    of the envelope's upper hull where a straight climb or descent would cut below it.

    ``level_final_m`` > 0 holds the last stretch no lower than the goal altitude (a landing
    slot's final, flown level at the slot fix's altitude rather than climbing up to it).
    """
    g = v.climb_gradient
    length = path.length_m
    s, ps = sample_by_distance(path, PROFILE_STEP_M)
    ground = terrain.elevation_m(ps[:, 0], ps[:, 1])
    ends = np.maximum(start_alt_m - g * s, v.goal.alt_m - g * (length - s))
    req = np.maximum(ground + v.clearance_m, v.alt_min_m)
    final = np.where(s >= length - level_final_m, v.goal.alt_m, -np.inf)
    floor = np.maximum(_envelope(np.maximum(req, final), s, g), ends)
    lifted = np.maximum(_envelope(np.maximum(req + buffer_m, final), s, g), ends)
    lifted = np.maximum(np.minimum(lifted, max(v.alt_max_m, 0.0)), floor)
    base = path.waypoints()
    base_s = path.project_many(base)
    base_s[0], base_s[-1] = 0.0, length
    idx = np.unique(np.clip(np.searchsorted(s, base_s), 0, len(s) - 1))
    chosen: list[int] = [int(idx[0])]
    for lo, hi in zip(idx[:-1].tolist(), idx[1:].tolist(), strict=True):
        chosen.extend(_leg_breakpoints(s, lifted, floor, lo, hi)[1:])
    wp_s = s[chosen]
    wp_alt = lifted[chosen]
    wps = path.poses_at(wp_s)[:, :2]
    wps[0], wps[-1] = ps[0], ps[-1]
    flown = np.interp(s, wp_s, wp_alt)
    clearance = flown - ground
    k = int(np.argmin(clearance))
    ds = np.diff(wp_s)
    grad = np.abs(np.diff(wp_alt)) / np.where(ds > 0, ds, np.inf)
    violations = []
    if clearance[k] < v.clearance_m - 1.0:
        violations.append(
            Violation(
                "clearance",
                k,
                float(clearance[k]),
                v.clearance_m,
                f"{clearance[k]:.0f} m above terrain at {s[k]:.0f} m along the path",
                float(s[k]),
            )
        )
    top = float(wp_alt.max())
    if top > v.alt_max_m + 1e-6:
        violations.append(
            Violation(
                "altitude",
                int(np.argmax(wp_alt)),
                top,
                v.alt_max_m,
                f"needs {top:.0f} m, above alt_max_m {v.alt_max_m:.0f}",
            )
        )
    return AltitudeProfile(
        wps,
        wp_s,
        wp_alt,
        float(clearance[k]),
        float(s[k]),
        float(grad.max(initial=0.0)),
        tuple(violations),
    )


@dataclass(frozen=True)
class PlannedRoute:
    """One vehicle's flyable route and its figures."""

    vehicle_id: str
    grid_nodes: tuple[int, ...]
    grid_points_m: FloatArray
    simplified_m: FloatArray
    path: FlightPath
    waypoints_m: FloatArray
    profile: AltitudeProfile
    cost: float
    optimal_cost: float
    grid_length_m: float
    min_threat_distance_m: float
    nearest_threat: str | None
    constraints: tuple[Violation, ...]

    @property
    def length_m(self) -> float:
        return self.path.length_m


@dataclass(frozen=True)
class Plan:
    """The team's planned routes and the solver's account of them."""

    scenario: Scenario
    method: Method
    result: SolveResult
    routes: tuple[PlannedRoute, ...]
    min_separation_m: float
    nominal_takeoff_s: tuple[float, ...]
    nominal_arrival_s: tuple[float, ...]


def climb_out_violation(
    path: FlightPath, terrain: Terrain, v: Vehicle, profile: AltitudeProfile
) -> Violation | None:
    """The climb from home, checked against the terrain it flies over (None: clear).

    A vehicle that starts on the ground takes off at home (terrain elevation there) and climbs
    along its path at ``climb_gradient`` until it meets the altitude profile; the profile's own
    clearance is checked where it is flown. During the climb the height above terrain must be
    at least ``min(clearance_m, CLIMB_OUT_CLEARANCE_FRACTION * height climbed)``. Returns the
    worst point as a ``clearance`` violation (``index``: the sample, every ``PROFILE_STEP_M``).
    """
    s, pts = sample_by_distance(path, PROFILE_STEP_M)
    ground = terrain.elevation_m(pts[:, 0], pts[:, 1])
    home = float(ground[0])
    climb, planned = _climb_from(home, s, v, profile)
    climbing = climb < planned
    if not climbing[1:].any():
        return None
    flown = np.minimum(climb, planned)
    need = np.minimum(v.clearance_m, CLIMB_OUT_CLEARANCE_FRACTION * (flown - home))
    margin = np.where(climbing, flown - ground - need, np.inf)
    k = int(np.argmin(margin))
    if margin[k] >= -1.0:
        return None
    return Violation(
        "clearance",
        k,
        float(flown[k] - ground[k]),
        float(need[k]),
        f"climbing from home ({home:.0f} m) at gradient {v.climb_gradient:g}, "
        f"{flown[k] - ground[k]:.0f} m above terrain ({ground[k]:.0f} m) at {s[k]:.0f} m "
        f"along the path, needs {need[k]:.0f} m",
        float(s[k]),
    )


def _climb_from(
    home_m: float, s_m: FloatArray, v: Vehicle, profile: AltitudeProfile
) -> tuple[FloatArray, FloatArray]:
    """The climb from home at ``climb_gradient`` and the planned profile, at ``s_m`` (m)."""
    return home_m + v.climb_gradient * s_m, np.interp(s_m, profile.s_m, profile.alt_m)


def climb_end_m(path: FlightPath, terrain: Terrain, v: Vehicle, profile: AltitudeProfile) -> float:
    """How far along ``path`` the climb from home meets the altitude profile, m (the path's
    length if it never does)."""
    s, pts = sample_by_distance(path, PROFILE_STEP_M)
    home = float(terrain.elevation_m(pts[:1, 0], pts[:1, 1])[0])
    climb, planned = _climb_from(home, s, v, profile)
    met = np.flatnonzero(climb[1:] >= planned[1:])
    return float(s[met[0] + 1]) if len(met) else path.length_m


def _where(world: World, path: FlightPath, violation: Violation) -> str:
    """Where a violation at a point of the path is, as latitude and longitude (deg)."""
    if violation.s_m is None:
        return ""
    pose = path.pose_at(violation.s_m)
    lat, lon = world.scenario.frame().to_geodetic(pose.east_m, pose.north_m)
    return f" (lat {float(lat):.5f}, lon {float(lon):.5f})"


def finish_route(
    world: World,
    problem: Problem,
    index: int,
    nodes: Sequence[int],
    cost: float,
    *,
    threats: Sequence[ThreatZone],
    start_alt_m: float | None = None,
    start_heading_rad: float | None = None,
) -> PlannedRoute:
    """Simplify, smooth, profile and check one grid route.

    A vehicle that starts on the ground (``start_alt_m`` None and not ``airborne``) has its
    climb from home checked too (:func:`climb_out_violation`). One re-planned in flight
    (``start_heading_rad`` given) flies on from where it is past the vertices it is too near
    to turn at (:func:`onto_route`).

    Raises
    ------
    InfeasibleError
        The smoothed route enters a forbidden zone, turns tighter than the minimum radius,
        loses terrain clearance (along the profile or climbing from home: the message names
        the vehicle and the position), or exceeds the vehicle's range or ceiling.
    """
    task = problem.tasks[index]
    v = world.scenario.vehicle(task.vehicle_id)
    dist, _ = problem.cost_to_go(index)
    optimal = float(dist[task.start_node])
    pts = problem.route_points(index, np.asarray(nodes))
    grid_length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
    margin = max(v.min_turn_radius_m, 0.5 * world.grid.resolution_m)
    start_alt = v.start.alt_m if start_alt_m is None else start_alt_m
    from_home = start_alt_m is None and not v.airborne
    landing = world.scenario.landing
    final_m = 0.0 if landing is None else landing.approach_m
    route: PlannedRoute | None = None
    failure = ""
    # A tail (a landing slot's final) is flown as it is: only the route to it is shortened.
    head, tail = (
        (pts[: -len(task.tail_m)], pts[-len(task.tail_m) :]) if task.tail_m else (pts, pts[:0])
    )

    # Where the climb from home met the profile on a candidate whose climb was too low.
    climb_m: float | None = None

    def candidates() -> Iterator[FloatArray]:
        """Shortened with the margin, with three times it; then, when the climb from home
        was too low on those, the grid route as it is over the climb and shortened after
        it; then the grid route as it is.

        Built one at a time: most routes are finished by the first, so the others are
        never simplified. A shortened route may take the climb straight over a ridge the
        grid route winds round; the grid route flown all the way is longer by a tenth and
        ends in the turns of its last grid leg, which may lie past the goal.
        """
        for route_margin_m in (margin, 3.0 * margin):
            simplified = simplify_route(head, task.cost_map, threats, world.terrain, route_margin_m)
            yield np.concatenate([simplified, tail])
        if climb_m is not None:
            along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(head, axis=0).T))])
            k = int(np.searchsorted(along, CLIMB_HEAD_FACTOR * climb_m)) + 1
            if k < len(head) - 1:
                rest = simplify_route(head[k:], task.cost_map, threats, world.terrain, margin)
                yield np.concatenate([head[:k], rest, tail])
        yield pts

    for candidate in candidates():
        if start_heading_rad is not None:
            head_m = candidate[: len(candidate) - len(tail)]
            head_m = onto_route(head_m, v.min_turn_radius_m, start_heading_rad)
            candidate = np.concatenate([head_m, tail])
        path = smooth_polyline(
            refine_corners(candidate, v.min_turn_radius_m, start_heading_rad),
            v.min_turn_radius_m,
            start_heading_rad=start_heading_rad,
        )
        profile = altitude_profile(path, world.terrain, v, start_alt, level_final_m=final_m)
        wps = profile.waypoints_m
        samp_s, samples = sample_by_distance(path, PROFILE_STEP_M)
        samp_alt = np.interp(samp_s, profile.s_m, profile.alt_m)
        d_flown, zone_flown = polyline_clearance_m(threats, wps, profile.alt_m)
        d_curve = math.inf
        zone_curve = None
        for t in threats:
            if t.forbidden:
                below = samp_alt < t.ceiling_m
                if below.any():
                    d = float(t.distance_m(samples[below, 0], samples[below, 1]).min())
                    if d < d_curve:
                        d_curve, zone_curve = d, t.id
        d_min, zone = (d_flown, zone_flown) if d_flown <= d_curve else (d_curve, zone_curve)
        constraints = list(
            check_polyline(
                candidate,
                min_leg_m=v.min_leg_length_m,
                max_turn_rad=math.radians(v.max_turn_deg),
                max_range_m=v.max_range_m,
            )
        )
        constraints.extend(profile.violations)
        climb_out = climb_out_violation(path, world.terrain, v, profile) if from_home else None
        if climb_out is not None:
            constraints.append(climb_out)
            climb_m = climb_end_m(path, world.terrain, v, profile)
        if path.length_m > v.max_range_m:
            constraints.append(
                Violation(
                    "range",
                    0,
                    path.length_m,
                    v.max_range_m,
                    f"path {path.length_m / 1000:.1f} km exceeds max_range_m",
                )
            )
        if profile.max_gradient > v.climb_gradient + 1e-3:
            constraints.append(
                Violation(
                    "climb",
                    0,
                    profile.max_gradient,
                    v.climb_gradient,
                    f"climb gradient {profile.max_gradient:.3f} between waypoints",
                )
            )
        hard = [c for c in constraints if c.constraint in ("clearance", "altitude", "range")]
        if d_min < 0.0:
            failure = f"vehicle {v.id}: smoothed path enters forbidden zone {zone}"
            continue
        if path.minimum_turn_radius_m() < v.min_turn_radius_m - 1e-6:
            failure = f"vehicle {v.id}: smoothed path turns tighter than min_turn_radius_m"
            continue
        if hard:
            where = _where(world, path, hard[0])
            failure = f"vehicle {v.id}: {hard[0].constraint}: {hard[0].message}{where}"
            continue
        route = PlannedRoute(
            v.id,
            tuple(int(n) for n in nodes),
            pts,
            candidate,
            path,
            wps,
            profile,
            cost,
            optimal,
            grid_length,
            d_min,
            zone,
            tuple(constraints),
        )
        break
    if route is None:
        raise InfeasibleError(failure)
    return route


def solve_and_finish(
    world: World,
    problem: Problem,
    method: Method,
    *,
    threats: Sequence[ThreatZone],
    rng: np.random.Generator | None = None,
    options: AcoOptions | None = None,
    airborne: Mapping[str, tuple[float, float]] | None = None,
    workers: int | None = None,
    backend: Backend | None = None,
) -> tuple[SolveResult, list[PlannedRoute]]:
    """Solve on the grid, refuse an infeasible result, and finish every route.

    ``airborne`` gives, per vehicle id, the altitude (m AMSL) and compass heading (rad) of a
    vehicle re-planned in flight; the others start from their scenario start. ``workers`` > 1
    computes the cost-to-go fields, walks the ACO's colonies and finishes the routes in that
    many forked processes (:func:`fill_fields`, :func:`planner.aco.solve_aco`,
    :func:`finish_routes`; None: :func:`planner.pool.default_workers`); a ``backend``
    (:mod:`planner.backend`, e.g. Ray) computes the fields and finishes the routes instead.
    """
    if workers is None:
        workers = default_workers(len(problem.tasks))
    worker = backend if backend is not None else LocalBackend(workers)
    worker.fill_fields(problem)
    result = solve(problem, method, rng=rng, options=options, workers=workers)
    if result.status is Status.INFEASIBLE or not all(result.routes):
        raise InfeasibleError(result.message)
    jobs = []
    for i, r in enumerate(result.routes):
        assert r is not None
        alt, heading = (airborne or {}).get(r.vehicle_id, (None, None))
        jobs.append(FinishJob(i, r.nodes, r.cost, alt, heading))
    return result, worker.finish_routes(world, problem, jobs, threats=threats)


@dataclass(frozen=True)
class FinishJob:
    """The arguments of one :func:`finish_route` call besides the world and the problem."""

    index: int
    nodes: tuple[int, ...]
    cost: float
    start_alt_m: float | None
    start_heading_rad: float | None


def finish_job(
    world: World, problem: Problem, threats: Sequence[ThreatZone], job: FinishJob
) -> PlannedRoute:
    """One job's route (:func:`finish_route`)."""
    return finish_route(
        world,
        problem,
        job.index,
        job.nodes,
        job.cost,
        threats=threats,
        start_alt_m=job.start_alt_m,
        start_heading_rad=job.start_heading_rad,
    )


def finish_routes(
    world: World,
    problem: Problem,
    jobs: Sequence[FinishJob],
    *,
    threats: Sequence[ThreatZone],
    workers: int = 1,
) -> list[PlannedRoute]:
    """:func:`finish_route` for every job, in order, optionally in forked worker processes
    (:func:`planner.pool.forked_map`).

    Each route is finished on its own (pure code), so workers give the same routes as one
    process. The first failing route (in job order) raises its ``InfeasibleError``, as
    without workers.
    """
    shared = (world, problem, tuple(threats))
    routes = forked_map(_finish_shared, shared, jobs, workers)
    if routes is None:
        return [finish_job(world, problem, threats, job) for job in jobs]
    return routes


def _finish_shared(
    shared: tuple[World, Problem, Sequence[ThreatZone]], job: FinishJob
) -> PlannedRoute:
    return finish_job(*shared, job)


FIELDS_PER_CHUNK = 8
"""Cost-to-go fields a worker computes per task it is given (:func:`fill_fields`)."""


def fill_fields(problem: Problem, workers: int = 1) -> None:
    """Compute every task's cost-to-go field now, in forked workers when ``workers`` > 1
    (:func:`planner.pool.forked_map`); with one worker they are left to be computed as they
    are asked for (:meth:`planner.problem.Problem.cost_to_go`). The fields are the same."""
    todo = problem.fields_missing()
    chunks = [todo[k : k + FIELDS_PER_CHUNK] for k in range(0, len(todo), FIELDS_PER_CHUNK)]
    fields = forked_map(task_fields, problem, chunks, workers)
    if fields is None:
        return
    for chunk, got in zip(chunks, fields, strict=True):
        problem.put_fields(chunk, got)


def plan(
    scenario: Scenario,
    method: Method = "aco",
    *,
    rng: np.random.Generator | None = None,
    options: AcoOptions | None = None,
    world: World | None = None,
    workers: int | None = None,
    backend: Backend | None = None,
) -> Plan:
    """Plan every vehicle's flyable route for the static threats of a scenario.

    ``workers`` > 1 computes the vehicles' cost-to-go fields and finishes the routes
    (simplify, smooth, profile, check) in that many forked processes: the same plan, sooner on
    a multi-core machine for a large team. None (the default) uses every core for a team of
    :data:`planner.pool.PARALLEL_MIN_VEHICLES` or more, one process below. A ``backend``
    (:mod:`planner.backend`: Ray, on this machine or a cluster) does that work instead; the
    plan is the same for the same seed wherever its work is done.

    Raises
    ------
    InfeasibleError
        A start or goal inside a forbidden zone, an unreachable goal, or a route that cannot be
        made flyable; the message names the vehicle.
    """
    world = world if world is not None else build_world(scenario)
    threats = active(world.threats, None)
    problem = build_problem(world, threats=threats)
    result, routes = solve_and_finish(
        world,
        problem,
        method,
        threats=threats,
        rng=rng,
        options=options,
        workers=workers,
        backend=backend,
    )
    limits = [t.timing for t in problem.tasks]
    timing = team_timing([r.length_m for r in routes], limits, problem.required_arrival_s)
    sep = _min_separation(routes, timing.takeoff_s, timing.speed_m_s, scenario.separation_m)
    return Plan(scenario, method, result, tuple(routes), sep, timing.takeoff_s, timing.arrival_s)


def _min_separation(
    routes: Sequence[PlannedRoute],
    takeoff_s: Sequence[float],
    speed_m_s: Sequence[float],
    d_s: float,
) -> float:
    vmax = max(speed_m_s) if speed_m_s else 1.0
    tracks = [r.path.sample(PROFILE_STEP_M)[:, :2] for r in routes]
    return team_min_separation_m(tracks, takeoff_s, speed_m_s, step_s=max(d_s / (8.0 * vmax), 0.25))
