"""Per-vehicle arrival windows, the team arrival time and discrete speed/loiter timing.

The three time strategies of section 4, as pure one-dimensional arithmetic over the length
still to fly (the geometry lives in :mod:`planner.retime`):

* takeoff delay (eq. 5): a vehicle on the ground takes off so that it would arrive on time at
  its cruise speed, within its takeoff window;
* discrete speed (eqs. 6-7): speeds are multiples of a step (0.5 m/s by default), held over
  path pieces. An exact arrival comes from two speeds: the first part of the path at one, the
  rest at another, the split point chosen so that the time comes out exact;
* loiter (eqs. 8-9): ``n`` whole turns of radius ``r`` add ``D_add = 2 n pi r``; the fewest
  turns after which the speed range can absorb the rest (more, where two discrete speeds
  cannot fly the fewest in exactly the time).

A vehicle's feasible arrival window from a moment is ``[t_min, t_max]`` (eq. 1): speed range
always, takeoff freedom only on the ground, ``t_max = inf`` where a loiter is possible.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from planner.errors import InfeasibleError

SPEED_STEP_M_S = 0.5
#: Speed pieces shorter than this are merged into their neighbour (waypoints that close are
#: not worth a DO_CHANGE_SPEED; the timing error is below 0.03 s for 0.5 m/s steps).
MIN_PIECE_M = 5.0
#: Arrival times within this of the target count as exact, s.
TIME_TOL_S = 1e-6

_LOITER_RADIUS_FINE_MAX_M = 255.0


def flyable_loiter_radius_m(min_radius_m: float) -> float:
    """Smallest loiter radius (m) >= ``min_radius_m`` that ArduPlane stores exactly.

    Whole metres up to 255 m, 10 m steps above (see
    :func:`planner.mission.arduplane_loiter_radius_m`, which truncates).
    """
    if min_radius_m <= _LOITER_RADIUS_FINE_MAX_M:
        return float(max(1, math.ceil(min_radius_m - 1e-9)))
    return 10.0 * math.ceil(min_radius_m / 10.0 - 1e-9)


def speed_grid(speed_min_m_s: float, speed_max_m_s: float, step_m_s: float) -> tuple[float, ...]:
    """Allowed speeds (m/s): multiples of ``step_m_s`` inside the range, plus both ends."""
    lo = math.ceil(speed_min_m_s / step_m_s - 1e-9)
    hi = math.floor(speed_max_m_s / step_m_s + 1e-9)
    grid = {speed_min_m_s, speed_max_m_s}
    grid.update(k * step_m_s for k in range(lo, hi + 1))
    return tuple(sorted(v for v in grid if speed_min_m_s - 1e-9 <= v <= speed_max_m_s + 1e-9))


@dataclass(frozen=True, slots=True)
class SpeedLimits:
    """One vehicle's speed range and cruise speed (m/s), and the speed step."""

    speed_min_m_s: float
    speed_max_m_s: float
    cruise_m_s: float
    step_m_s: float = SPEED_STEP_M_S


@dataclass(frozen=True, slots=True)
class ArrivalWindow:
    """Feasible arrival times ``[t_min_s, t_max_s]`` of one vehicle, and why."""

    vehicle_id: str
    t_min_s: float
    t_max_s: float
    min_reason: str
    max_reason: str


def vehicle_window(
    vehicle_id: str,
    *,
    now_s: float,
    remaining_m: float,
    limits: SpeedLimits,
    takeoff_window_s: tuple[float, float] | None = None,
    can_loiter: bool = False,
    tas_per_eas: float | Callable[[float], float] = 1.0,
    climb_s: float = 0.0,
) -> ArrivalWindow:
    """The arrival window of one vehicle from ``now_s``.

    Parameters
    ----------
    vehicle_id
        Named in the reasons.
    now_s
        The moment the window is computed at, mission s.
    remaining_m
        Length still to fly (the whole path on the ground), m.
    limits
        Speed range, m/s.
    takeoff_window_s
        ``(earliest, latest)`` takeoff, s, for a vehicle on the ground; None when airborne.
    can_loiter
        A buffer area on the remaining path allows holding turns: no latest arrival.
    tas_per_eas
        Ground metres per metre of the (equivalent) speed along the remaining path: the true
        airspeed ratio, or a function of the speed when a wind counts too.
    climb_s
        On the ground: the takeoff's climb-out, s, after which ``remaining_m`` is left.
    """
    vmin, vmax = limits.speed_min_m_s, limits.speed_max_m_s
    km = remaining_m / 1000.0
    ratio = tas_per_eas if callable(tas_per_eas) else (lambda _v, r=tas_per_eas: r)
    r_max, r_min = ratio(vmax), ratio(vmin)

    def true(r: float) -> str:
        return "" if r == 1.0 else f" (x{r:.3f} over the ground)"

    if takeoff_window_s is None:
        depart_lo = depart_hi = now_s
        where = f"airborne at {now_s:.1f} s"
    else:
        depart_lo = max(takeoff_window_s[0], now_s)
        depart_hi = max(takeoff_window_s[1], depart_lo)
        where = f"takeoff in [{depart_lo:.1f}, {depart_hi:.1f}] s"
        if climb_s > 0.0:
            where += f", {climb_s:.0f} s climbing out"
    t_min = depart_lo + climb_s + (remaining_m / r_max / vmax if r_max > 0.0 else math.inf)
    min_reason = (
        f"{vehicle_id} cannot arrive before {t_min:.1f} s ({where}, {km:.1f} km at "
        f"{vmax:g} m/s{true(r_max)})"
    )
    if can_loiter:
        return ArrivalWindow(vehicle_id, t_min, math.inf, min_reason, f"{vehicle_id} can loiter")
    t_max = depart_hi + climb_s + (remaining_m / r_min / vmin if r_min > 0.0 else math.inf)
    max_reason = (
        f"{vehicle_id} cannot arrive after {t_max:.1f} s ({where}, {km:.1f} km at {vmin:g} m/s"
        f"{true(r_min)}, no buffer area to loiter in)"
    )
    return ArrivalWindow(vehicle_id, t_min, t_max, min_reason, max_reason)


@dataclass(frozen=True, slots=True)
class TeamWindow:
    """The team reference arrival times every vehicle can make (the intersection of eq. 1's
    windows, each shifted by its vehicle's offset), and the vehicles that bound it."""

    earliest_s: float
    latest_s: float
    """inf when every vehicle can loiter."""
    earliest_vehicle: str
    latest_vehicle: str
    earliest_reason: str
    """Why ``earliest_vehicle`` cannot arrive sooner."""
    latest_reason: str
    """Why ``latest_vehicle`` cannot arrive later."""


def team_window(
    windows: Sequence[ArrivalWindow], *, offsets_s: Mapping[str, float] | None = None
) -> TeamWindow:
    """The team's feasible reference arrival times; vehicle ``i`` arrives at
    ``reference + offsets_s[i]``. It may be empty (``earliest_s > latest_s``)."""
    if not windows:
        raise ValueError("team_window needs at least one window")
    off = offsets_s or {}
    lo = max(windows, key=lambda w: w.t_min_s - off.get(w.vehicle_id, 0.0))
    hi = min(windows, key=lambda w: w.t_max_s - off.get(w.vehicle_id, 0.0))
    return TeamWindow(
        lo.t_min_s - off.get(lo.vehicle_id, 0.0),
        hi.t_max_s - off.get(hi.vehicle_id, 0.0),
        lo.vehicle_id,
        hi.vehicle_id,
        lo.min_reason,
        hi.max_reason,
    )


def team_arrival(
    windows: Sequence[ArrivalWindow],
    requested_s: float | None,
    *,
    offsets_s: Mapping[str, float] | None = None,
) -> tuple[float, str]:
    """The team's reference arrival time (s) and the reason for it (eq. 1).

    Vehicle ``i`` arrives at ``reference + offsets_s[i]`` (0 for simultaneous arrivals; the
    slot offset for spaced ones). The requested time is kept when every shifted window holds
    it; otherwise the earliest time of the windows' intersection, the reason naming the vehicle
    that forced it (a schedule whose reference is not the requested time fails
    :func:`planner.retime.check_arrival`).

    Raises
    ------
    InfeasibleError
        The windows do not intersect; names the vehicle that cannot wait long enough and the
        shortfall in seconds.
    """
    if not windows:
        raise ValueError("team_arrival needs at least one window")
    w = team_window(windows, offsets_s=offsets_s)
    t_lo, t_hi = w.earliest_s, w.latest_s
    if t_lo > t_hi + TIME_TOL_S:
        raise InfeasibleError(
            f"vehicle {w.latest_vehicle}: {w.latest_reason}, but {w.earliest_reason}: "
            f"short by {t_lo - t_hi:.1f} s",
            vehicle=w.latest_vehicle,
        )
    if requested_s is not None and t_lo - TIME_TOL_S <= requested_s <= t_hi + TIME_TOL_S:
        return requested_s, "requested arrival time is feasible for every vehicle"
    if requested_s is None:
        return t_lo, f"earliest common arrival: {w.earliest_reason}"
    if requested_s < t_lo:
        return t_lo, f"requested {requested_s:.1f} s is too early: {w.earliest_reason}"
    return t_lo, (
        f"requested {requested_s:.1f} s is too late: {w.latest_reason}; earliest common "
        f"arrival: {w.earliest_reason}"
    )


@dataclass(frozen=True, slots=True)
class Piece:
    """A stretch flown at one speed: a path leg, or a loiter (and its detour)."""

    kind: Literal["leg", "loiter"]
    length_m: float
    speed_m_s: float

    @property
    def duration_s(self) -> float:
        return self.length_m / self.speed_m_s


@dataclass(frozen=True, slots=True)
class LoiterSite:
    """Where a loiter can be flown: ``at_m`` ahead along the remaining path.

    ``detour_m`` is the extra flying besides the turns when the circle cannot touch the path
    (out to it, the line-up on the path's course after the turns, and back).
    """

    at_m: float
    radius_m: float
    detour_m: float = 0.0


@dataclass(frozen=True, slots=True)
class Timing:
    """How one vehicle flies its remaining path in a given time."""

    pieces: tuple[Piece, ...]
    turns: int
    """Loiter turns (0: speed alone suffices)."""

    @property
    def duration_s(self) -> float:
        return math.fsum(p.duration_s for p in self.pieces)

    @property
    def added_m(self) -> float:
        return math.fsum(p.length_m for p in self.pieces if p.kind == "loiter")


def _merge(pieces: list[Piece]) -> tuple[Piece, ...]:
    """Drop empty pieces, join equal-speed neighbours, fold tiny legs into a neighbour leg."""
    out: list[Piece] = []
    for p in pieces:
        if p.length_m <= 1e-9:
            continue
        if out and out[-1].kind == p.kind == "leg" and out[-1].speed_m_s == p.speed_m_s:
            out[-1] = Piece("leg", out[-1].length_m + p.length_m, p.speed_m_s)
        else:
            out.append(p)
    changed = True
    while changed:
        changed = False
        for k, p in enumerate(out):
            if p.kind != "leg" or p.length_m >= MIN_PIECE_M or len(out) == 1:
                continue
            # Fold into the neighbouring leg (the next one, else the previous one).
            for j in (k + 1, k - 1):
                if 0 <= j < len(out) and out[j].kind == "leg":
                    q = out[j]
                    out[j] = Piece("leg", q.length_m + p.length_m, q.speed_m_s)
                    del out[k]
                    changed = True
                    break
            if changed:
                break
    return tuple(out)


def split_speeds(
    length_m: float,
    duration_s: float,
    limits: SpeedLimits,
    *,
    current_m_s: float | None = None,
) -> tuple[Piece, ...]:
    """Two adjacent discrete speeds that fly ``length_m`` in exactly ``duration_s`` (eq. 6).

    The first part is flown at the speed nearer ``current_m_s`` (fewer changes), the rest at
    the other. Both speeds lie in the range (eq. 7); the caller checks that the mean speed
    does.
    """
    if length_m <= 0.0:
        return ()
    grid = speed_grid(limits.speed_min_m_s, limits.speed_max_m_s, limits.step_m_s)
    v_req = length_m / duration_s
    v_req = min(max(v_req, grid[0]), grid[-1])
    k = max(0, min(len(grid) - 2, _bisect(grid, v_req))) if len(grid) > 1 else 0
    if len(grid) == 1 or abs(grid[k] - v_req) < 1e-12:
        return _merge([Piece("leg", length_m, grid[k])])
    if abs(grid[k + 1] - v_req) < 1e-12:
        return _merge([Piece("leg", length_m, grid[k + 1])])
    v_lo, v_hi = grid[k], grid[k + 1]
    ref = limits.cruise_m_s if current_m_s is None else current_m_s
    first, second = (v_lo, v_hi) if abs(v_lo - ref) <= abs(v_hi - ref) else (v_hi, v_lo)
    # a / first + (L - a) / second = T
    a = (duration_s - length_m / second) / (1.0 / first - 1.0 / second)
    a = min(max(a, 0.0), length_m)
    return _merge([Piece("leg", a, first), Piece("leg", length_m - a, second)])


def _bisect(grid: Sequence[float], v: float) -> int:
    """Index k with grid[k] <= v < grid[k + 1] (clamped)."""
    k = 0
    while k + 1 < len(grid) and grid[k + 1] <= v:
        k += 1
    return k


def fewest_turns(
    remaining_m: float,
    duration_s: float,
    limits: SpeedLimits,
    site: LoiterSite,
    margin_m_s: float = 0.0,
) -> int:
    """Fewest loiter turns after which the speed range absorbs the rest (eq. 8); 0 if none.

    With ``margin_m_s`` > 0 the turns are the fewest that leave the mean speed at least that
    far above the minimum (a closed loop keeps room to slow down after the loiter); when no
    such count fits the range, the fewest without the margin.

    Raises
    ------
    ValueError
        No whole number of turns fits between the slowest and fastest flying times.
    """
    vmin, vmax = limits.speed_min_m_s, limits.speed_max_m_s
    if duration_s * vmin <= remaining_m + 1e-9:
        return 0
    per_turn = 2.0 * math.pi * site.radius_m
    if margin_m_s > 0.0:
        slow = min(vmin + margin_m_s, vmax)
        n = max(1, math.ceil((duration_s * slow - remaining_m - site.detour_m) / per_turn - 1e-12))
        if remaining_m + site.detour_m + n * per_turn <= duration_s * vmax + 1e-9:
            return n
    n = max(1, math.ceil((duration_s * vmin - remaining_m - site.detour_m) / per_turn - 1e-12))
    if remaining_m + site.detour_m + n * per_turn > duration_s * vmax + 1e-9:
        raise ValueError("no whole number of loiter turns fits the speed range")
    return n


def time_path(
    vehicle_id: str,
    remaining_m: float,
    duration_s: float,
    limits: SpeedLimits,
    *,
    site: LoiterSite | None = None,
    current_m_s: float | None = None,
    loiter_margin_m_s: float = 0.0,
    tas_per_eas: float = 1.0,
    loiter_tas_per_eas: float | None = None,
) -> Timing:
    """Speeds, and loiter turns where needed, to fly ``remaining_m`` in exactly ``duration_s``.

    Parameters
    ----------
    vehicle_id
        Named in errors.
    remaining_m
        Path length still to fly, m.
    duration_s
        Time to fly it in, s.
    limits
        Speed range and step, m/s.
    site
        Where a loiter can be flown; None when no buffer area is on the remaining path.
    current_m_s
        Speed flown now; the first piece keeps the nearer of two speeds.
    loiter_margin_m_s
        Turns leave the mean speed at least this far above the minimum when they can
        (see :func:`fewest_turns`).
    tas_per_eas
        Ground metres per metre of speed along the path (the speeds are equivalent airspeeds:
        the true airspeed ratio, the wind counted in where there is one): the arithmetic runs
        on path lengths divided by it, and so do the leg pieces returned.
    loiter_tas_per_eas
        The same for the loiter and its detour (flown at the true airspeed: the wind averages
        out over whole turns); ``tas_per_eas`` when None.

    Returns
    -------
    Timing
        Pieces in flying order, their lengths in metres / ``tas_per_eas`` (loiters: /
        ``loiter_tas_per_eas``). Without a loiter:
        at most two legs at adjacent grid speeds. With one: the fewest turns (eq. 8), or
        when two discrete speeds cannot fly those in exactly ``duration_s``, the fewest more
        that they can; the loiter flown at the speed of the leg that leads to it (ArduPlane
        keeps the airspeed through NAV_LOITER_TURNS).

    Raises
    ------
    InfeasibleError
        Too little time even at the top speed, or too much with no buffer to loiter in; the
        message names the vehicle and the shortfall in seconds. Also when no whole number of
        turns fits the speed range, or none that fits can be flown with the path in exactly
        ``duration_s`` at two discrete speeds.
    """
    vmin, vmax = limits.speed_min_m_s, limits.speed_max_m_s
    km = remaining_m / 1000.0
    loiter_ratio = tas_per_eas if loiter_tas_per_eas is None else loiter_tas_per_eas
    if tas_per_eas != 1.0 or loiter_ratio != 1.0:
        remaining_m /= tas_per_eas
        if site is not None:
            site = LoiterSite(
                site.at_m / tas_per_eas,
                site.radius_m / loiter_ratio,
                site.detour_m / loiter_ratio,
            )
    fastest = remaining_m / vmax
    slowest = remaining_m / vmin
    if duration_s < fastest - TIME_TOL_S:
        raise InfeasibleError(
            f"vehicle {vehicle_id}: {km:.1f} km need at least {fastest:.1f} s at "
            f"{vmax:g} m/s but only {duration_s:.1f} s are left: short by "
            f"{fastest - duration_s:.1f} s",
            vehicle=vehicle_id,
        )
    if duration_s <= slowest + TIME_TOL_S:
        pieces = split_speeds(remaining_m, duration_s, limits, current_m_s=current_m_s)
        return Timing(pieces, 0)
    if site is None:
        raise InfeasibleError(
            f"vehicle {vehicle_id}: must lose {duration_s - slowest:.1f} s more than its minimum "
            f"speed {vmin:g} m/s allows and no buffer area on its path allows a loiter: short by "
            f"{duration_s - slowest:.1f} s",
            vehicle=vehicle_id,
        )
    try:
        n = fewest_turns(remaining_m, duration_s, limits, site, loiter_margin_m_s)
    except ValueError:
        raise InfeasibleError(
            f"vehicle {vehicle_id}: loiter turns of "
            f"{2 * math.pi * site.radius_m * loiter_ratio:.0f} m cannot "
            f"be trimmed to {duration_s:.1f} s within [{vmin:g}, {vmax:g}] m/s",
            vehicle=vehicle_id,
        ) from None
    per_turn_m = 2.0 * math.pi * site.radius_m
    tried: list[int] = []
    for turns in _turn_counts(remaining_m, duration_s, limits, site, n):
        loiter_m = site.detour_m + per_turn_m * turns
        split = _loiter_split(remaining_m, duration_s, limits, site.at_m, loiter_m, current_m_s)
        if split is not None:
            return Timing(split, turns)
        tried.append(turns)
    counts = f"{min(tried)}" if len(tried) == 1 else f"{min(tried)} to {max(tried)}"
    raise InfeasibleError(
        f"vehicle {vehicle_id}: no pair of discrete speeds flies {counts} loiter turns "
        f"and {km:.1f} km in {duration_s:.1f} s",
        vehicle=vehicle_id,
    )


def _turn_counts(
    remaining_m: float, duration_s: float, limits: SpeedLimits, site: LoiterSite, first: int
) -> Iterator[int]:
    """Loiter turn counts to try, in order: ``first`` (from :func:`fewest_turns`), then one
    more turn at a time while path, detour and turns still fit in ``duration_s`` at the
    maximum speed, then the counts below ``first`` that the minimum speed can still stretch
    to ``duration_s`` (``first`` is above the fewest when it keeps a margin above the minimum
    speed).

    The loiter is flown at one discrete speed, so only the legs can trim the time; with the
    loiter part-way along they may not reach between two of the times the loiter's speeds
    give, and a count with the loiter longer or shorter by a turn moves those times.
    """
    per_turn_m = 2.0 * math.pi * site.radius_m
    turns = first
    while True:
        yield turns
        turns += 1
        if (
            remaining_m + site.detour_m + turns * per_turn_m
            > duration_s * limits.speed_max_m_s + 1e-9
        ):
            break
    yield from range(fewest_turns(remaining_m, duration_s, limits, site), first)


def _loiter_split(
    path_m: float,
    duration_s: float,
    limits: SpeedLimits,
    at_m: float,
    loiter_m: float,
    current_m_s: float | None,
) -> tuple[Piece, ...] | None:
    """Two discrete speeds over path + loiter, the loiter inside one speed's stretch.

    The loiter takes the speed of the path just before it, so the split point is either after
    the loiter point (loiter at the first speed) or strictly before it (at the second).
    Adjacent speeds bracketing the mean are tried first, then any pair.
    """
    grid = speed_grid(limits.speed_min_m_s, limits.speed_max_m_s, limits.step_m_s)
    v_mean = (path_m + loiter_m) / duration_s
    ref = limits.cruise_m_s if current_m_s is None else current_m_s
    best: tuple[tuple[float, float, float], tuple[Piece, ...]] | None = None
    for v1 in grid:
        for v2 in grid:
            for loiter_first in (True, False):
                if v1 == v2:
                    if abs((path_m + loiter_m) / v1 - duration_s) > TIME_TOL_S:
                        continue
                    a = path_m if loiter_first else 0.0
                elif loiter_first:
                    a = (duration_s - loiter_m / v1 - path_m / v2) / (1.0 / v1 - 1.0 / v2)
                    if not at_m - 1e-9 <= a <= path_m + 1e-9:
                        continue
                else:
                    a = (duration_s - (path_m + loiter_m) / v2) / (1.0 / v1 - 1.0 / v2)
                    if not -1e-9 <= a <= at_m - MIN_PIECE_M:
                        continue
                a = min(max(a, 0.0), path_m)
                if loiter_first:
                    raw = [
                        Piece("leg", at_m, v1),
                        Piece("loiter", loiter_m, v1),
                        Piece("leg", a - at_m, v1),
                        Piece("leg", path_m - a, v2),
                    ]
                else:
                    raw = [
                        Piece("leg", a, v1),
                        Piece("leg", at_m - a, v2),
                        Piece("loiter", loiter_m, v2),
                        Piece("leg", path_m - at_m, v2),
                    ]
                pieces = _merge(raw)
                tiny = sum(1 for p in raw if 0.0 < p.length_m < MIN_PIECE_M)
                spread = max(abs(v1 - v_mean), abs(v2 - v_mean))
                score = (float(tiny), spread, abs(v1 - ref))
                if best is None or score < best[0]:
                    best = (score, pieces)
    return None if best is None else best[1]


def takeoff_time_s(
    length_m: float,
    target_s: float,
    limits: SpeedLimits,
    window_s: tuple[float, float],
    tas_per_eas: float = 1.0,
    climb_s: float = 0.0,
) -> float:
    """Takeoff time (s) by eq. 5: arrive at ``target_s`` at cruise speed (an equivalent
    airspeed carrying the aircraft ``tas_per_eas`` times as fast over the ground), within the
    window; ``length_m`` is what is left after a climb-out of ``climb_s`` seconds."""
    lo, hi = window_s
    flying_s = length_m / (limits.cruise_m_s * tas_per_eas) if tas_per_eas > 0.0 else math.inf
    return min(max(target_s - climb_s - flying_s, lo), hi)
