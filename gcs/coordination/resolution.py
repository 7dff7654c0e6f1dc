"""Predicted losses of separation resolved ahead of time, by speed (pure: no clock, no I/O).

Each vehicle's next seconds are predicted along its own route (not in a straight line: the
routes turn), its loiter turns included, from its last fix: in its wind estimate at the ground
speed its true airspeed makes good on each leg (a turn from a tailwind into a crosswind slows
it), with what it makes good beyond that at its fix counted on every leg (so that in still air
it is its present ground speed all along, as it is without a wind estimate). A
pair predicted to come closer than the separation within the look-ahead is resolved by one of
the two flying the slowest or the fastest airspeed of its range until their closest approach
has passed: of the four choices, the one predicted to keep them farthest apart (the smaller
change of speed between two that keep the separation equally well). A new speed is reached in
``response_s`` (the prediction holds the old one until then). When no choice keeps the whole
separation, the one that keeps them farthest apart is still taken if it opens their closest
approach by :data:`MIN_GAIN_FRACTION` of the separation or more (two aircraft abreast on
routes that cross at a shallow angle, already a little under the separation, drift to a few
tens of metres as they fly; one flown faster passes ahead): its event says the separation is
not kept, as the alarm does if it comes true. A choice that gains less (head-on on one line)
is not taken.

A vehicle flying a resolution is not timed for its slot meanwhile; once released, its arrival
controller makes up the time. So a resolution is held no longer than that can be done with
:data:`RECOVERY_SHARE` of the speed range left on the other side over the rest of the way to
the slot (:func:`longest_hold_s`), and each choice is judged as flown that long and then at the
speed before it: near the goals a resolution is short or not taken, where held until the
closest approach it judged it would have brought its mover to the goal tens of seconds early
or late (and into the vehicles arriving beside it).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.wind import Wind, groundspeed_m_s

FloatArray = NDArray[np.float64]

MIN_GAIN_FRACTION = 0.1
"""A choice that keeps less than the whole separation is taken only if it opens the pair's
closest approach by this fraction of the separation or more (:func:`resolve`)."""
CLOCK_FIRST_LEGS = 64
"""The legs of a forecast's first window in the wind (:meth:`Ahead._clock`)."""
RECOVERY_SHARE = 0.5
"""A resolution is held only as long as its mover's arrival can make up with this share of the
speed range on the other side of its speed (:func:`longest_hold_s`); the rest is left for
what else it meets."""


@dataclass(frozen=True)
class Ahead:
    """One vehicle's flight ahead, as its last fix has it."""

    vehicle: str
    t_s: float
    s_m: float
    """Along its flight at the fix (``route_s_m``'s axis), m."""
    groundspeed_m_s: float
    airspeed_m_s: float
    """The airspeed it flies (commanded), m/s."""
    tas_per_eas: float
    """True airspeed per unit of commanded airspeed (altitude): a change of airspeed changes
    the ground speed by this much times it (the wind kept)."""
    airspeed_min_m_s: float
    airspeed_max_m_s: float
    alt_m: float
    route_s_m: FloatArray
    """The flight's samples (its route, with the loiter turns it has still to fly spliced in:
    :meth:`~gcs.coordination.routetrack.RouteTrack.flight_samples`): along-track distance
    (not decreasing), east and north, m."""
    route_east_m: FloatArray
    route_north_m: FloatArray
    horizon_s: float
    """How far ahead of its fix it may be predicted at all (its slot: its route turns into
    the goal there)."""
    movable: bool = True
    """Whether it may be asked another speed (not on its final approach, say)."""
    final_s: float = 0.0
    """How long its final approach lasts, at the end of its horizon: no speed is asked there,
    so a resolution's speed must be made up before it."""
    route_rise_m: FloatArray | None = None
    """How far its profile's height at each of the flight's samples lies above its profile's
    height where it is (m, with ``route_s_m``; None: it keeps the height it has). A re-plan
    lifts a vehicle over part of its route, and a pair judged at their present heights was
    resolved onto one height: the 60-vehicle crowd's R59 climbed 450 m away from R00 to
    where R00's new mission took it, and they came 289 m apart."""
    off_profile_m: float = 0.0
    """How far it is above (+) or below (-) its profile where it is, m (with
    :attr:`route_rise_m`): its autopilot flies it back at :attr:`return_rate_m_s`. Back from
    a height resolution, the crowd's R00 was 215 m above its profile and sank to it at 5 m/s;
    forecast to keep that height, it was forecast 320 m from R59 beneath and came 186 m."""
    return_rate_m_s: float = 5.0
    """How fast it climbs or sinks back to its profile, m/s."""
    hold_until_s: float | None = None
    """Flying a height resolution: it holds :attr:`alt_m` (the height asked) until then, and
    is back on its profile after it as fast as it returns (:attr:`off_profile_m` is then how
    far the height asked lies off its profile where it is). Forecast at that height all along,
    the crowd's R00, held 300 m under its profile for R03, was climbed over by R01 from a
    forecast that never had it back; it came back up, and the pair came 272 m apart."""
    until_s: float = math.inf
    """Flying a speed resolution (:attr:`airspeed_m_s`): when it is released. Flown as it
    flies, it is forecast at :attr:`resume_m_s` after it."""
    resume_m_s: float | None = None
    """The airspeed it flies for its slot once its resolution is released (None: it flies
    none). Forecast at its resolution's speed all along, a vehicle released to slow for its
    slot was forecast far ahead of where it flew: another was sped into it, and the pair came
    193 m apart, no speed or height left to part them."""
    wind: Wind | None = None
    """Its wind estimate: each leg ahead flown at the ground speed its true airspeed makes
    good there (None or calm: at its present ground speed all along). In 10 m/s across the paper's
    routes a vehicle that turned from a 37 m/s tailwind leg into a 30 m/s crosswind was
    forecast 300 m ahead of where it flew, and a pair resolved to pass 700 m apart came 418 m
    apart."""

    @functools.cached_property
    def _fix_leg(self) -> int:
        """The leg the fix is on (the index of the sample it starts at; 0 for a flight of one
        sample)."""
        n = self.route_s_m.size
        leg = int(np.searchsorted(self.route_s_m, self.s_m, side="right")) - 1
        return max(min(leg, n - 2), 0)

    @functools.cached_property
    def _first(self) -> int:
        """The first sample of the legs its forecast in the wind needs: the one the fix's leg
        starts at, or the last that moves before it (a leg that does not move, a loiter's
        detour held at its point, takes the track of the one before it)."""
        first = self._fix_leg
        e, nn = self.route_east_m, self.route_north_m
        while first > 0 and math.hypot(e[first + 1] - e[first], nn[first + 1] - nn[first]) < 1e-9:
            first -= 1
        return first

    def _legs(self, last: int) -> tuple[FloatArray, FloatArray]:
        """The legs from sample :attr:`_first` to sample ``last``: their lengths (m) and
        ground tracks (rad; a leg of no length takes the one before it)."""
        lo = self._first
        e = self.route_east_m[lo : last + 1]
        n = self.route_north_m[lo : last + 1]
        de, dn = np.diff(e), np.diff(n)
        ds = np.diff(self.route_s_m[lo : last + 1])
        track = np.arctan2(de, dn)
        flat = np.hypot(de, dn) < 1e-9
        if flat.any():
            idx = np.where(flat, 0, np.arange(track.size))
            np.maximum.accumulate(idx, out=idx)
            track = track[idx]
        return ds, track

    @functools.cached_property
    def _made_good_error_m_s(self) -> float:
        """Its ground speed at the fix less the one its airspeed makes good in :attr:`wind` on
        the leg it flies (an airspeed not yet reached, an estimate's error): counted on every
        leg, so that in still air the forecast is the one at its present ground speed."""
        assert self.wind is not None
        if self.route_s_m.size < 2:
            return 0.0
        _, track = self._legs(self._fix_leg + 1)
        tas = self.airspeed_m_s * self.tas_per_eas
        return self.groundspeed_m_s - groundspeed_m_s(tas, float(track[-1]), self.wind)

    def _clock(self, airspeed_m_s: float, s_m: float, dt_s: float) -> tuple[FloatArray, FloatArray]:
        """The flight's samples from :attr:`_first` on (m along it) and when (s, from the
        first of them) each is passed flying ``airspeed_m_s`` (commanded) in :attr:`wind`,
        with the error made good at the fix (a leg it cannot make good at 1 m/s): as far as
        ``dt_s`` after it passes ``s_m``, or to the flight's end. The legs are taken in
        windows, each twice the last, from the fix on: a forecast reaches a minute or two
        ahead of a route of thousands of samples, and it is made at every fix."""
        cache = self.__dict__.setdefault("_clocks", {})
        last_sample = self.route_s_m.size - 1
        hit: tuple[FloatArray, FloatArray] | None = cache.get(airspeed_m_s)
        while True:
            if hit is not None:
                along, clock = hit
                if along.size - 1 + self._first == last_sample or (
                    along[-1] >= s_m and clock[-1] >= float(np.interp(s_m, along, clock)) + dt_s
                ):
                    return hit
                legs = 2 * (along.size - 1)
            else:
                legs = CLOCK_FIRST_LEGS
            assert self.wind is not None
            last = min(self._first + legs, last_sample)
            ds, track = self._legs(last)
            gs = groundspeed_m_s(airspeed_m_s * self.tas_per_eas, track, self.wind)
            gs += self._made_good_error_m_s
            clock = np.empty(ds.size + 1)
            clock[0] = 0.0
            np.cumsum(ds / np.maximum(gs, 1.0), out=clock[1:])
            hit = cache[airspeed_m_s] = (self.route_s_m[self._first : last + 1], clock)

    def _flown(self, s_m: FloatArray, dt_s: FloatArray, airspeed_m_s: float) -> FloatArray:
        """Where along the flight (m) a vehicle at ``s_m`` is ``dt_s`` later at that airspeed
        in :attr:`wind` (at the flight's ends at most)."""
        if not s_m.size:
            return s_m.copy()
        along, clock = self._clock(airspeed_m_s, float(s_m.max()), float(dt_s.max()))
        at = np.interp(s_m, along, clock)
        at += dt_s
        return np.interp(at, clock, along)

    def positions(
        self,
        t_s: FloatArray,
        airspeed_m_s: float,
        response_s: float,
        until_s: float = math.inf,
    ) -> FloatArray:
        """(east, north, height AMSL) at the times ``t_s`` flying ``airspeed_m_s`` from its fix
        (reached ``response_s`` after it) until ``until_s``, at its present speed again after
        it; flown as it flies (at :attr:`airspeed_m_s`), a resolution's until its release
        and :attr:`resume_m_s` after it. NaN past its look-ahead. The height is its present
        one, changed as its profile changes ahead (:attr:`route_rise_m`), and back on its
        profile as fast as it returns to it (:attr:`off_profile_m`)."""
        dt = t_s - self.t_s
        after = self.airspeed_m_s
        if airspeed_m_s == self.airspeed_m_s and self.resume_m_s is not None:
            until_s, after = self.until_s, self.resume_m_s
        held = max(until_s - self.t_s, response_s)
        s = self._along_any(dt, airspeed_m_s, response_s, held, after)
        out = np.empty((*s.shape, 3))
        out[..., 0] = np.interp(s, self.route_s_m, self.route_east_m)
        out[..., 1] = np.interp(s, self.route_s_m, self.route_north_m)
        if self.route_rise_m is None:
            out[..., 2] = self.alt_m
        elif self.hold_until_s is not None:
            profile = np.interp(s, self.route_s_m, self.route_rise_m)
            profile += self.alt_m - self.off_profile_m
            off = self.alt_m - profile
            back = np.maximum(t_s - self.hold_until_s, 0.0) * self.return_rate_m_s
            out[..., 2] = profile + np.sign(off) * np.maximum(np.abs(off) - back, 0.0)
        else:
            out[..., 2] = np.interp(s, self.route_s_m, self.route_rise_m)
            out[..., 2] += self.alt_m
            if self.off_profile_m:
                back = np.minimum(
                    np.maximum(dt, 0.0) * self.return_rate_m_s, abs(self.off_profile_m)
                )
                out[..., 2] -= math.copysign(1.0, self.off_profile_m) * back
        out[dt > self.horizon_s] = np.nan
        return out

    def _along_any(
        self, dt: FloatArray, airspeed_m_s: float, response_s: float, held: float, after: float
    ) -> FloatArray:
        """Along the flight (m) ``dt`` after the fix: its airspeed until ``response_s``,
        ``airspeed_m_s`` until ``held`` (no earlier), ``after`` then."""
        if self.wind is None or self.wind.calm:
            # In still air the leg-by-leg forecast is this one (the present ground speed all
            # along), done without a table of the legs: this runs at every forecast.
            return self._along(dt, airspeed_m_s, response_s, held, after)
        return self._along_in_wind(dt, airspeed_m_s, response_s, held, after)

    def _along_in_wind(
        self, dt: FloatArray, airspeed_m_s: float, response_s: float, held_s: float, after: float
    ) -> FloatArray:
        """Along the flight (m) ``dt`` after the fix: its airspeed until ``response_s``,
        ``airspeed_m_s`` until ``held_s``, ``after`` then, each leg at the ground speed that
        makes good in :attr:`wind`."""
        own = self.airspeed_m_s
        start = np.full(dt.shape, self.s_m)
        if airspeed_m_s == own == after:
            return self._flown(start, dt, own)
        s = self._flown(start, np.minimum(dt, response_s), own)
        s = self._flown(s, np.clip(dt - response_s, 0.0, held_s - response_s), airspeed_m_s)
        return self._flown(s, np.maximum(dt - held_s, 0.0), after)

    def _along(
        self, dt: FloatArray, airspeed_m_s: float, response_s: float, held: float, after: float
    ) -> FloatArray:
        """Along the flight (m) ``dt`` after the fix at its present ground speed, changed by
        the change of airspeed from ``response_s`` until ``held``, and to ``after`` then."""
        gs = self.groundspeed_m_s
        new_gs = max(gs + (airspeed_m_s - self.airspeed_m_s) * self.tas_per_eas, 0.0)
        # s_m + gs min(dt, response) + after_gs max(dt - held, 0) + new_gs clip(dt - response,
        # 0, held - response), clipped to the route (after_gs the ground speed ``after`` makes
        # good: gs itself when it is its airspeed, the two terms of gs then summed first):
        # done in place, and np.clip as maximum then minimum (its values, without its Python
        # wrapper): this runs at every forecast.
        s = np.minimum(dt, response_s)
        part = dt - held
        np.maximum(part, 0.0, out=part)
        if after == self.airspeed_m_s:
            s += part
            s *= gs
        else:
            s *= gs
            part *= max(gs + (after - self.airspeed_m_s) * self.tas_per_eas, 0.0)
            s += part
        s += self.s_m
        np.subtract(dt, response_s, out=part)
        np.minimum(np.maximum(part, 0.0, out=part), held - response_s, out=part)
        part *= new_gs
        s += part
        np.minimum(np.maximum(s, self.route_s_m[0], out=s), self.route_s_m[-1], out=s)
        return s

    def slot_airspeed_m_s(self, from_s: float) -> float:
        """The airspeed (commanded) that flies it from where it is at ``from_s`` (flying as
        it does) to the end of its flight at its slot (its horizon), in its range: what it
        is timed to once a resolution is released. The ground made good per unit of airspeed
        is the fix's."""
        wanted_m_s = self.slot_groundspeed_m_s(from_s)
        if wanted_m_s is None:
            return self.airspeed_min_m_s
        per_airspeed = self.groundspeed_m_s / max(self.airspeed_m_s, 1.0)
        wanted = wanted_m_s / max(per_airspeed, 1e-3)
        return min(max(wanted, self.airspeed_min_m_s), self.airspeed_max_m_s)

    def slot_groundspeed_m_s(self, from_s: float) -> float | None:
        """The mean speed over the ground that takes it from where it is at ``from_s``
        (flying as it does) to the end of its flight at its slot, m/s (None: its slot is
        then)."""
        dt = np.array([max(from_s - self.t_s, 0.0)])
        own = self.airspeed_m_s
        there = float(self._along_any(dt, own, 0.0, 0.0, own)[0])
        left_s = self.t_s + self.horizon_s - max(from_s, self.t_s)
        if left_s <= 0.0:
            return None
        return (float(self.route_s_m[-1]) - there) / left_s


@dataclass(frozen=True)
class Resolution:
    """One vehicle flies ``airspeed_m_s`` until ``until_s`` to keep the separation from
    ``other``."""

    vehicle: str
    other: str
    airspeed_m_s: float
    until_s: float
    predicted_m: float
    """The pair's closest approach so resolved, m (under the separation: the best there was,
    :attr:`keeps_separation` False)."""
    unresolved_m: float
    """Their closest approach as they fly, m."""
    at_s: float
    """When that would be."""
    keeps_separation: bool = True
    """Whether :attr:`predicted_m` is the whole separation or more."""
    hold_end_s: float = math.inf
    """The latest it can be held and its mover still make its slot (:func:`longest_hold_s`):
    held on past :attr:`until_s` until the pair is past each other, never past this."""


def closest_m(
    a: Ahead,
    b: Ahead,
    t_s: FloatArray,
    airspeed_a_m_s: float,
    airspeed_b_m_s: float,
    response_s: float,
    until_s: float = math.inf,
) -> tuple[float, float]:
    """The pair's least 3-D distance (their heights as :meth:`Ahead.positions` has them)
    over the times ``t_s`` at these airspeeds (flown until ``until_s``), and when;
    ``(inf, nan)`` when they are never predicted together."""
    pa = a.positions(t_s, airspeed_a_m_s, response_s, until_s)
    pb = b.positions(t_s, airspeed_b_m_s, response_s, until_s)
    d = np.sqrt(((pa - pb) ** 2).sum(axis=1))
    if np.isnan(d).all():
        return math.inf, math.nan
    k = int(np.nanargmin(d))
    return float(d[k]), float(t_s[k])


def resolve(
    a: Ahead,
    b: Ahead,
    *,
    now_s: float,
    separation_m: float,
    look_ahead_s: float = 90.0,
    step_s: float = 1.0,
    response_s: float = 5.0,
    release_after_s: float = 10.0,
    neighbours: Mapping[str, Sequence[Ahead]] | None = None,
) -> Resolution | None:
    """The speed that keeps ``a`` and ``b`` apart if they are predicted to come closer than
    ``separation_m`` within ``look_ahead_s`` (None if they are not, or if no choice keeps
    them apart or, short of that, opens their closest approach by :data:`MIN_GAIN_FRACTION`
    of the separation).

    A choice is judged over twice the look-ahead (so that it does not merely put the meeting
    beyond it) and held until ``release_after_s`` past the closest approach so resolved, or
    for as long as its mover can still make its slot (:func:`longest_hold_s`), whichever
    comes first; it is judged as held that long.
    ``neighbours`` are, for ``a`` and for ``b`` (by vehicle id), the other vehicles near it:
    a choice that would bring its mover closer to one of them than the separation, and closer
    than it flies now, is not taken (in a crowd, one pair's resolution otherwise pushed the
    middle one of three aircraft abreast into the third)."""
    bound = min(a.t_s + a.horizon_s, b.t_s + b.horizon_s)
    if min(bound, now_s + look_ahead_s) <= now_s:
        return None
    t = np.arange(now_s, min(bound, now_s + look_ahead_s) + step_s, step_s)
    as_flown, at = closest_m(a, b, t, a.airspeed_m_s, b.airspeed_m_s, response_s)
    if not as_flown < separation_m:
        return None
    t = np.arange(now_s, min(bound, now_s + 2.0 * look_ahead_s) + step_s, step_s)
    choices = []
    for mover in (a, b):
        if not mover.movable:
            continue
        near = (neighbours or {}).get(mover.vehicle, ())
        near_now = _nearest_m(mover, mover.airspeed_m_s, near, t, response_s)
        for speed in (mover.airspeed_min_m_s, mover.airspeed_max_m_s):
            if abs(speed - mover.airspeed_m_s) < 1e-9:
                continue
            hold_end = now_s + longest_hold_s(mover, speed, now_s, response_s + mover.final_s)
            if hold_end - now_s <= response_s:
                continue  # its slot leaves no time to fly it
            near_so = _nearest_m(mover, speed, near, t, response_s, hold_end)
            if near_so < separation_m and near_so < near_now:
                continue  # into another conflict, or deeper into one
            if mover is a:
                d, when = closest_m(a, b, t, speed, b.airspeed_m_s, response_s, hold_end)
            else:
                d, when = closest_m(a, b, t, a.airspeed_m_s, speed, response_s, hold_end)
            kept = min(d, separation_m)  # beyond the separation, the smaller change
            choices.append(
                (-kept, abs(speed - mover.airspeed_m_s), mover.vehicle, speed, d, when, hold_end)
            )
    if not choices:
        return None
    _, _, vid, speed, d, when, hold_end = min(choices)
    if d < separation_m:
        # Judged over the same times as the choices (as flown, the closest may lie beyond
        # the look-ahead).
        flown_long, _ = closest_m(a, b, t, a.airspeed_m_s, b.airspeed_m_s, response_s)
        if d < flown_long + MIN_GAIN_FRACTION * separation_m:
            return None
    other = b.vehicle if vid == a.vehicle else a.vehicle
    until = (when if math.isfinite(when) else at) + release_after_s
    if d < separation_m:
        # Short of the separation, the pair is closest under the new speed soon after it is
        # taken: held only that long, it was given up before the pair had drawn apart (two
        # abreast hovered some 50 m under the separation for minutes). Held past the meeting
        # as they fly instead.
        until = max(until, at + release_after_s)
    until = min(until, hold_end)
    return Resolution(vid, other, speed, until, d, as_flown, at, d >= separation_m, hold_end)


def longest_hold_s(mover: Ahead, airspeed_m_s: float, now_s: float, spare_s: float = 0.0) -> float:
    """How long (s) ``mover`` may fly ``airspeed_m_s`` from ``now_s`` and still make its slot
    (``horizon_s`` after its fix): the distance it gains or loses on the mean airspeed its
    slot asks from now (:meth:`Ahead.slot_airspeed_m_s`) made up over the rest of the way but
    its last ``spare_s`` (its final approach, the response to the speed that takes the
    resolution back) with :data:`RECOVERY_SHARE` of the room its speed range leaves on the
    other side of that mean (``H * |change| <= share * room * (left - H)``). Made up over the
    whole rest, a crowd's resolution held to 6 s before the slot left its mover 1.7 s early;
    judged on the airspeed it flew, one flying slowly to the place a re-plan timed it
    through, its slot asking its top speed after it, was held at its minimum and arrived
    6.6 s late."""
    left_s = mover.t_s + mover.horizon_s - now_s - spare_s
    mean = mover.slot_airspeed_m_s(now_s)
    change = abs(airspeed_m_s - mean)
    if left_s <= 0.0 or change < 1e-9:
        return max(left_s, 0.0)
    room = mean - mover.airspeed_min_m_s if airspeed_m_s > mean else mover.airspeed_max_m_s - mean
    recover = RECOVERY_SHARE * max(room, 0.0)
    return left_s * recover / (change + recover)


def _nearest_m(
    mover: Ahead,
    airspeed_m_s: float,
    others: Sequence[Ahead],
    t_s: FloatArray,
    response_s: float,
    until_s: float = math.inf,
) -> float:
    """The mover's least distance to any of ``others`` (flying as they do) over ``t_s`` at
    ``airspeed_m_s`` (until ``until_s``), m (inf with none)."""
    return min(
        (
            closest_m(mover, o, t_s, airspeed_m_s, o.airspeed_m_s, response_s, until_s)[0]
            for o in others
        ),
        default=math.inf,
    )


class Forecasts:
    """Each vehicle's positions ahead along its route on whole seconds of mission time, from
    its last :meth:`update`, in one array (a row per vehicle of the team): one vehicle's pairs
    are screened against all the others at once (array arithmetic: a hundred vehicles in tens
    of microseconds), and only a pair screened under the separation is resolved
    (:func:`resolve`)."""

    def __init__(
        self, vehicles: Sequence[str], look_ahead_s: float, response_s: float, stale_s: float = 5.0
    ) -> None:
        self.look_ahead_s = look_ahead_s
        self.response_s = response_s
        self.stale_s = stale_s
        """A forecast made longer ago than this is not compared (the vehicle's link is
        silent)."""
        self.ahead: dict[str, Ahead] = {}
        self._ids = list(vehicles)
        self._row = {vid: k for k, vid in enumerate(self._ids)}
        n = len(self._ids)
        self._positions = np.full((n, self.steps, 3), np.nan)
        """(vehicle row, whole second from its start, east/north/height), NaN where not
        forecast."""
        self._start_s = np.zeros(n)
        self._fix_s = np.full(n, -np.inf)
        """When each row was forecast from (-inf: never, or dropped)."""

    @property
    def steps(self) -> int:
        return int(math.ceil(self.look_ahead_s)) + 1

    def update(self, a: Ahead, now_s: float) -> None:
        """Forecast ``a`` from the next whole second on, ``look_ahead_s`` ahead."""
        row = self._row[a.vehicle]
        start = float(math.ceil(now_s))
        t = start + np.arange(self.steps, dtype=np.float64)
        self.ahead[a.vehicle] = a
        self._positions[row] = a.positions(t, a.airspeed_m_s, self.response_s)
        self._start_s[row] = start
        self._fix_s[row] = a.t_s

    def drop(self, vehicle: str) -> None:
        """No forecast for the vehicle (not on its route, say) until its next update."""
        self.ahead.pop(vehicle, None)
        row = self._row.get(vehicle)
        if row is not None:
            self._fix_s[row] = -np.inf

    def near(
        self, vehicle: str, separation_m: float, now_s: float, *, heights: bool = True
    ) -> list[str]:
        """The others forecast to come under ``separation_m`` of ``vehicle`` (3-D, their
        heights as forecast; over the ground alone without ``heights``: for a change of
        height) in the time both forecasts cover, nearest first."""
        me = self._row.get(vehicle)
        if me is None or vehicle not in self.ahead:
            return []
        k = self.steps
        live = now_s - self._fix_s <= self.stale_s
        live[me] = False
        rows = live.nonzero()[0]  # np.flatnonzero's, without its wrappers
        if not rows.size:
            return []
        # Their forecast's second that is my forecast's first (theirs started earlier): a
        # few distinct values (the forecasts are a second or two apart), each one slice.
        shift = np.rint(self._start_s[me] - self._start_s[rows]).astype(np.int64)
        mine = self._positions[me]
        least2 = np.full(len(rows), np.inf)
        shifts = set(shift.tolist())  # np.unique's values (the order does not matter)
        for sh in shifts:
            if abs(sh) >= k:
                continue
            # One shift (the usual case): every row, with no mask to build and apply.
            sel: slice | NDArray[np.bool_] = slice(None) if len(shifts) == 1 else shift == sh
            theirs = (
                self._positions[rows[sel], sh:] if sh >= 0 else self._positions[rows[sel], : k + sh]
            )
            ours = mine[: k - sh] if sh >= 0 else mine[-sh:]
            de = theirs[:, :, 0] - ours[:, 0]
            dn = theirs[:, :, 1] - ours[:, 1]
            de *= de
            dn *= dn
            de += dn
            if heights:
                dz = theirs[:, :, 2] - ours[:, 2]
                dz *= dz
                de += dz
            # The least over the seconds both forecast (fmin skips NaN: not forecast), inf
            # where there is none: NaN replaced by inf, then the minimum, in two passes.
            least2[sel] = np.fmin(np.fmin.reduce(de, axis=1), np.inf)
        least = np.sqrt(least2)
        close = (least < separation_m).nonzero()[0]
        return [self._ids[rows[i]] for i in close[least[close].argsort()]]
