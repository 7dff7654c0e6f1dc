"""The mission clock: the team's UTC, read through the local monotonic clock.

Mission time is what the vehicles say it is: SYSTEM_TIME.time_unix_usec, GPS time on a real
autopilot, simulated UTC on the stub (which runs ``speedup`` times faster than wall time). The
coordinator never reads ``time.time()``; it asks :meth:`MissionClock.now_utc_s`, which maps the
local monotonic clock onto the team's UTC.

Each vehicle keeps its own clock. Real autopilots share GPS time, but simulators started at
different moments do not, nor does an autopilot whose clock was set by hand:

- a vehicle's own UTC at a monotonic instant is the latest extrapolation of its newest
  reports at the fitted rate (receive times carry link delay, which only ever makes a report
  look older than it is: at 200x, 2 ms of delay is 0.4 s of UTC; one delayed packet does not
  drag the clock back);
- the team's UTC is the lower median of the vehicles' clocks; each vehicle's offset from it
  (:meth:`MissionClock.offset_s`) is the median of its recent differences, each taken from
  the least delayed of its last :data:`OFFSET_WINDOW` reports, and a difference far from the
  offset is set aside unless it persists (:data:`OFFSET_CONFIRM` reports over at least
  :data:`OFFSET_CONFIRM_WALL_S` of wall time), and one within what reception jitter makes of
  a clock at this rate is not applied (:data:`OFFSET_JITTER_WALL_S`): a vehicle 7 s ahead
  is judged, commanded and timed on the team's time, and a burst of delayed reports does not
  move it;
- the rate (UTC seconds per monotonic second: 1.0 live, about 200 at 200x) is the median of
  the vehicles' own rates, each a least-squares slope of its UTC against receive time over its
  last ``window`` reports, fitted again on the least delayed half;
- what :meth:`now_utc_s` returns never decreases.

Each vehicle's boot -> UTC offset (``utc - time_boot``) converts the boot-time stamps of its
other messages (GLOBAL_POSITION_INT.time_boot_ms, ...) to team UTC exactly, whatever the link
delay: :meth:`MissionClock.utc_of_boot`. A vehicle that reports no UTC
(:meth:`MissionClock.observe_no_utc`) has its boot time mapped to the team's UTC at the least
delayed reception; :attr:`MissionClock.without_utc` names it.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import statistics
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from gcs.errors import GcsError

ANCHOR_OBSERVATIONS = 5
"""How many of the newest observations "now" is extrapolated from (the latest one wins)."""
JUMP_BACK_S = 1.0
"""A vehicle's UTC going back by more than this resets that vehicle (a new timeline)."""
MIN_FIT_SPAN_S = 0.002
"""The rate is re-fitted only when the window spans at least this much monotonic time."""
OFFSET_SAMPLES = 15
"""A vehicle's offset from the team's UTC is the median of this many recent samples."""
BACKLOG_FRACTION = 0.25
BACKLOG_GAP_S = 0.001
"""A report received less than BACKLOG_GAP_S after the vehicle's previous one, and in less
than BACKLOG_FRACTION of the time its UTC advanced since (at the fitted rate), came out of a
backlog (a stalled loop reading a full socket): it is accepted but does not date the
vehicle's clock, fit its rate or its offset. An 820 ms stall at 100x otherwise read as a clock
27 s off and moved the team time."""
OFFSET_JUMP_S = 0.25
"""Once a vehicle's offset is known, a sample farther than this from it is set aside;
:data:`OFFSET_CONFIRM` of them in a row replace it (the vehicle's clock did move)."""
OFFSET_CONFIRM = 30
"""How many outlying offset samples in a row move a known offset (a clock step is followed
within that many reports; a burst of delayed reports shorter than that is not)."""
OFFSET_JITTER_WALL_S = 0.005
"""Reception jitter (monotonic s) the offsets cannot see through: an offset smaller than this
times the rate (5 ms live, 1 s at 200x) is no evidence of a wrong clock and is not applied.
One simulator's vehicles, on one clock, read as up to a second apart at 200x (each vehicle's
messages leave and are read at their own moment of the tick), and every such offset moved
that vehicle's arrival by as much; a clock set wrong by hand is off by seconds."""
PACED_OFFSET_LEADS = 1.5
"""On a pace clock, an offset within this many lock-step leads is not applied (:meth:`follow`):
a report is dated up to a lead late, and the reference it is compared with up to a lead late
too; a clock set wrong by hand is off by seconds."""
OFFSET_FLOOR_S = 0.05
"""The smallest offset applied at any rate, s."""
OFFSET_CONFIRM_WALL_S = 2.0
"""...and for at least this long (monotonic s): at 200x thirty reports come within 0.15 s of
wall time, as long as one stall of the event loop, which then moved offsets by up to a second
though one simulator gave the vehicles one clock (and every arrival with them)."""
HEARD_WALL_S = 0.5
"""On a pace clock, a vehicle not heard for this long (monotonic wall s: a blackout, a lost
link) no longer holds the lock step back (:meth:`MissionClock.heard_pace_s`)."""
HEARD_SLACK_S = 5.0
"""Flight seconds past the least newest report the lock step may still acknowledge: reports
that are in transit (a few milliseconds of wall time, seconds of flight at 200x) or lost on
a lossy link do not stall the simulator; a router seconds of wall time behind still holds
it."""
HEARD_BEHIND_MAX_PACE_S = 10.0
"""A vehicle whose newest report is stamped this far (pace s) behind the pace clock is on
another time base (not the simulator's: rebooted, or another vehicle): it holds nothing."""
OFFSET_WINDOW = 64
"""Each offset sample compares the least delayed of a vehicle's last this many reports: a
stretch of delayed reports from one vehicle (its link queued, 70 ms of wall time is 14 s of
UTC at 200x) does not move its offset unless it lasts longer than that."""


@dataclass(frozen=True, slots=True)
class _Observation:
    """One report of a vehicle's UTC and when it was received (monotonic)."""

    rx_mono_s: float
    utc_s: float


@dataclass
class _VehicleClock:
    """One vehicle's own UTC, as it reports it."""

    boot_offset_s: float
    """Its UTC minus its boot time (or, with no UTC, team UTC minus boot time)."""
    last_utc_s: float
    last_rx_mono_s: float | None = None
    """When its newest report was received (backlogged ones included)."""
    backlog_run: int = 0
    """Reports in a row taken as out of a backlog."""
    recent: deque[_Observation] = field(default_factory=lambda: deque(maxlen=OFFSET_WINDOW))
    offset_samples: deque[float] = field(default_factory=lambda: deque(maxlen=OFFSET_SAMPLES))
    offset_s: float = 0.0
    """Its UTC minus the team's (median of the samples)."""
    has_utc: bool = True
    rate: float | None = None
    """Its UTC seconds per monotonic second, fitted on its own reports."""
    outliers: list[float] = field(default_factory=list)
    """Offset samples in a row too far from its offset to be taken (yet)."""
    outliers_since_mono_s: float = 0.0
    """When the first of them came (monotonic)."""
    version: int = 0
    """Counts the changes of ``recent`` (the cached anchors are kept for one version)."""
    anchors: dict[int, tuple[int, float, float]] = field(default_factory=dict)
    """``reports -> (version, rate, anchor)``: :meth:`MissionClock._anchor`'s cache."""


class MissionClock:
    """Mission UTC from the vehicles' SYSTEM_TIME messages (see the module docstring)."""

    def __init__(self, monotonic: Callable[[], float] = time.monotonic, window: int = 20) -> None:
        if window < 2:
            raise ValueError(f"window must be at least 2 observations, got {window}")
        self._monotonic = monotonic
        self.window = window
        self._accepted_utc = False
        self._vehicles: dict[int, _VehicleClock] = {}
        self._rate = 1.0
        self._max_returned_s = -math.inf
        self._changes = 0
        """Counts the changes that can move the team's UTC (reports taken, vehicles reset)."""
        self._team_anchor: tuple[int, float, float] | None = None
        """``(changes, rate, anchor)``: the team's UTC at monotonic ``m`` is ``anchor + rate
        m`` until the next change (:meth:`_team_at`)."""
        self.accepted = 0
        self.rejected = 0
        self.resets = 0  # vehicles whose UTC jumped back by more than JUMP_BACK_S
        self.backlogged = 0  # reports that came out of a backlog (not used for dating)
        self.paced = False
        """Its monotonic clock is the simulator's pace clock (:meth:`follow`)."""
        self._paced_lead_s = 0.0
        self.pace_rate: float | None = None
        """On a pace clock, the simulator's speed-up when it says it (flight s per pace s): the
        rate as the simulator runs it, not as fitted on reports dated when handled (within 3%
        of it on a loaded machine)."""
        self._hold_pace_s: float | None = None
        self._holds = 0
        self._hold_at_utc_s: float | None = None
        """The team UTC at which the simulator is to wait (:meth:`hold_at`)."""
        self._heard: dict[int, tuple[float, float]] = {}
        """On a pace clock: each vehicle's newest report's boot time (s) and the monotonic
        wall time it was handled at (:meth:`heard`)."""

    def follow(
        self, pace_s: Callable[[], float], lead_s: float = 0.0, rate: float | None = None
    ) -> None:
        """Read the simulator's pace clock (flight time / speed-up, :mod:`sitl_stub.lockstep`)
        as the monotonic clock, and date each report when it is handled: a report handled
        late then reads as one sent late, not as a clock behind.

        ``lead_s`` is how far (flight s) the simulator may run ahead of what this process has
        acknowledged: a report may be dated up to about that much late, whatever the rate, so
        an offset between two vehicles within :data:`PACED_OFFSET_LEADS` leads is no evidence
        of a wrong clock and is not applied. On a loaded machine at 100x one simulator's
        vehicles otherwise read as 0.5-0.8 s apart near the end of a flight, and each such
        offset moved that vehicle's arrival by as much. ``rate``: the simulator's speed-up
        (:attr:`pace_rate`), when known.

        Raises
        ------
        GcsError
            After the first observation (the clock would mix two time bases).
        """
        if self._vehicles:
            raise GcsError("mission clock: follow() after the first SYSTEM_TIME")
        if not (math.isfinite(lead_s) and lead_s >= 0.0):
            raise ValueError(f"lead_s must be a number of seconds >= 0, got {lead_s!r}")
        if rate is not None and not (math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"rate must be a positive number, got {rate!r}")
        self._monotonic = pace_s
        self.paced = True
        self._paced_lead_s = lead_s
        self.pace_rate = rate

    def monotonic(self) -> float:
        """The clock's monotonic time now (the pace clock when :attr:`paced`)."""
        return self._monotonic()

    def hold(self) -> None:
        """On a pace clock: the simulator waits where it is now until as many :meth:`release`
        (a planning job then takes no flight time, however busy the machine). Nothing
        otherwise: real vehicles do not wait."""
        if not self.paced:
            return
        if self._holds == 0:
            self._hold_pace_s = self._monotonic()
        self._holds += 1

    def hold_at(self, utc_s: float | None) -> None:
        """On a pace clock: the simulator waits once the team's UTC reaches ``utc_s`` (a
        rehearsal paused there), until called again with another time or None. Nothing
        otherwise: real vehicles do not wait."""
        if utc_s is not None and not math.isfinite(utc_s):
            raise ValueError(f"utc_s must be a finite UTC, got {utc_s!r}")
        self._hold_at_utc_s = utc_s if self.paced else None

    @property
    def held_pace_s(self) -> float | None:
        """While set, the lock step acknowledges no pace time past it: the simulator waits
        there (:meth:`hold`, :meth:`hold_at`, :func:`gcs.service.stubs.follow_lockstep`)."""
        held = self._hold_pace_s
        at_utc_s = self._hold_at_utc_s
        if at_utc_s is not None and self._accepted_utc:
            # The team's UTC is ``anchor + rate m`` at pace time ``m`` (:meth:`_team_at`).
            at_pace_s = (at_utc_s - self._team_at(0.0)) / self._rate
            held = at_pace_s if held is None else min(held, at_pace_s)
        return held

    def heard(self, system_id: int, time_boot_s: float, wall_s: float) -> None:
        """On a pace clock: a report of vehicle ``system_id`` stamped ``time_boot_s`` (the
        simulator's flight time) was handled at monotonic wall time ``wall_s``."""
        if not self.paced or not math.isfinite(time_boot_s):
            return
        newest = self._heard.get(system_id)
        # A late packet keeps the newest stamp, and says the vehicle still talks.
        stamp_s = time_boot_s if newest is None else max(time_boot_s, newest[0])
        self._heard[system_id] = (stamp_s, wall_s)

    def heard_pace_s(self, wall_s: float, rate: float) -> float:
        """On a pace clock running at ``rate`` flight s per pace s, the pace time that every
        vehicle still talking has been heard to: the least of their newest reports' stamps,
        and :data:`HEARD_SLACK_S` of flight.
        What the lock step acknowledges stays within it, so a vehicle whose reports reach
        this process late (a router between them that falls behind on a busy machine) is
        not flown on past what it was last seen doing. Infinite when none holds: none heard
        within :data:`HEARD_WALL_S` of wall time, or its stamps on another time base."""
        least = math.inf
        now_s = self._monotonic()
        for boot_s, at_wall_s in self._heard.values():
            pace_s = boot_s / rate
            if wall_s - at_wall_s > HEARD_WALL_S or pace_s < now_s - HEARD_BEHIND_MAX_PACE_S:
                continue
            least = min(least, pace_s)
        return least + HEARD_SLACK_S / rate

    def release(self) -> None:
        """One :meth:`hold` ended; the last lets the simulator fly on."""
        if self._holds == 0:
            return
        self._holds -= 1
        if self._holds == 0:
            self._hold_pace_s = None

    # -- input -------------------------------------------------------------------------------

    def observe(self, system_id: int, utc_s: float, time_boot_s: float, rx_mono_s: float) -> None:
        """One SYSTEM_TIME of vehicle ``system_id``, received at ``rx_mono_s`` (monotonic).

        Rejected (counted in :attr:`rejected`): non-finite values, ``utc_s <= 0`` (no GPS time
        yet: see :meth:`observe_no_utc`), a negative boot time, and a UTC not later than that
        vehicle's last one (a duplicate or a reordered packet). A UTC more than
        :data:`JUMP_BACK_S` behind the vehicle's last one with a different boot offset (the
        vehicle rebooted or its time was reset; a late packet keeps its offset) also resets
        the vehicle (counted in :attr:`resets`): its older observations leave the rate fit and
        its timeline starts again from this one.
        """
        if not (
            math.isfinite(utc_s)
            and math.isfinite(time_boot_s)
            and math.isfinite(rx_mono_s)
            and utc_s > 0.0
            and time_boot_s >= 0.0
        ):
            self.rejected += 1
            return
        boot_offset = utc_s - time_boot_s
        vc = self._vehicles.get(system_id)
        if vc is not None and vc.has_utc and utc_s <= vc.last_utc_s:
            self.rejected += 1
            if utc_s < vc.last_utc_s - JUMP_BACK_S and abs(boot_offset - vc.boot_offset_s) > (
                JUMP_BACK_S
            ):
                self.resets += 1
                self._changes += 1
                del self._vehicles[system_id]
                self._accept(system_id, utc_s, boot_offset, rx_mono_s)
            return
        if vc is not None and not vc.has_utc:
            self._changes += 1
            del self._vehicles[system_id]  # it has UTC now
        self.accepted += 1
        self._accept(system_id, utc_s, boot_offset, rx_mono_s)

    def observe_no_utc(self, system_id: int, time_boot_s: float, rx_mono_s: float) -> None:
        """A SYSTEM_TIME with no UTC (``time_unix_usec`` 0): the vehicle's boot time is mapped
        to the team's UTC at reception (the least delayed reception wins). Ignored before the
        clock is synced or once the vehicle has reported UTC."""
        if not (math.isfinite(time_boot_s) and math.isfinite(rx_mono_s)) or not self.synced:
            self.rejected += 1
            return
        vc = self._vehicles.get(system_id)
        if vc is not None and vc.has_utc:
            self.rejected += 1
            return
        team_utc = self._team_at(rx_mono_s)
        boot_offset = team_utc - time_boot_s
        self._changes += 1
        if vc is None:
            self._vehicles[system_id] = _VehicleClock(boot_offset, team_utc, has_utc=False)
        elif boot_offset < vc.boot_offset_s or abs(boot_offset - vc.boot_offset_s) > JUMP_BACK_S:
            vc.boot_offset_s = boot_offset  # less delayed, or a reboot
        self.accepted += 1

    def _accept(self, system_id: int, utc_s: float, boot_offset_s: float, rx_mono_s: float) -> None:
        self._changes += 1
        vc = self._vehicles.get(system_id)
        if vc is None:
            vc = self._vehicles[system_id] = _VehicleClock(boot_offset_s, utc_s)
        # A report received much faster than its UTC advanced comes out of a backlog (the
        # loop or the link was stalled): it is as old as the stall, so it dates nothing.
        gap_s = None if vc.last_rx_mono_s is None else rx_mono_s - vc.last_rx_mono_s
        backlog = (
            vc.rate is not None
            and gap_s is not None
            and 0.0 <= gap_s < BACKLOG_GAP_S
            and utc_s > vc.last_utc_s
            and gap_s * vc.rate < BACKLOG_FRACTION * (utc_s - vc.last_utc_s)
            and vc.backlog_run < 2 * self.window  # that many in a row: the rate did change
        )
        vc.backlog_run = vc.backlog_run + 1 if backlog else 0
        vc.boot_offset_s = boot_offset_s
        vc.last_utc_s = utc_s
        vc.last_rx_mono_s = rx_mono_s
        self._accepted_utc = True
        if backlog:
            self.backlogged += 1
            return
        vc.recent.append(_Observation(rx_mono_s, utc_s))
        vc.version += 1
        self._update_offsets(rx_mono_s)
        self._fit(vc)

    def _update_offsets(self, mono_s: float) -> None:
        """Each vehicle's UTC against the team's (the lower median of the vehicles' UTC now),
        once the rate is fitted; the median of the recent samples is kept."""
        clocks = [vc for vc in self._vehicles.values() if vc.has_utc and vc.recent]
        if len(clocks) < 2 or any(vc.rate is None for vc in clocks):
            return
        own = [self._vehicle_at(vc, mono_s, OFFSET_WINDOW) for vc in clocks]
        reference = sorted(own)[(len(own) - 1) // 2]
        for vc, utc in zip(clocks, own, strict=True):
            sample = utc - reference
            full = len(vc.offset_samples) == OFFSET_SAMPLES
            if full and abs(sample - vc.offset_s) > OFFSET_JUMP_S:
                # An outlier (a burst of delayed reports, the rate re-fitting after a stall),
                # unless the samples keep saying so: then the clock really moved.
                if not vc.outliers:
                    vc.outliers_since_mono_s = mono_s
                vc.outliers.append(sample)
                if (
                    len(vc.outliers) < OFFSET_CONFIRM
                    or mono_s - vc.outliers_since_mono_s < OFFSET_CONFIRM_WALL_S
                ):
                    continue
                vc.offset_samples.clear()
                vc.offset_samples.extend(vc.outliers[-OFFSET_SAMPLES:])
            else:
                vc.offset_samples.append(sample)
            vc.outliers.clear()
            vc.offset_s = _median(vc.offset_samples)

    def _vehicle_at(
        self, vc: _VehicleClock, mono_s: float, reports: int = ANCHOR_OBSERVATIONS
    ) -> float:
        """A vehicle's own UTC at ``mono_s``: the latest extrapolation of its newest
        ``reports`` reports (the least delayed one wins)."""
        return self._anchor(vc, reports) + self._rate * mono_s

    def _anchor(self, vc: _VehicleClock, reports: int) -> float:
        """``max(utc - rate rx)`` over the vehicle's newest ``reports`` reports: each report
        extrapolates to ``utc + rate (m - rx)`` at monotonic ``m``, so the latest of them is
        this plus ``rate m``. Kept until a report or the rate changes: the clock is read at
        every fix of every vehicle, and recomputing it each time was a fifth of a 30-vehicle
        flight's loop."""
        rate = self._rate
        hit = vc.anchors.get(reports)
        if hit is not None and hit[0] == vc.version and hit[1] == rate:
            return hit[2]
        recent = vc.recent
        first = max(len(recent) - reports, 0)
        # A list rather than a generator (or indexing the deque): the same maximum, taken
        # at every report for every vehicle (each report moves the fitted rate).
        anchor = max([o.utc_s - rate * o.rx_mono_s for o in itertools.islice(recent, first, None)])
        vc.anchors[reports] = (vc.version, rate, anchor)
        return anchor

    def _team_at(self, mono_s: float) -> float:
        """Team UTC at ``mono_s``: the lower median of the vehicles' UTC less their offsets.
        Every vehicle's UTC runs at the one rate, so their order does not change with
        ``mono_s`` and the median is taken once per change."""
        rate = self._rate
        cached = self._team_anchor
        if cached is None or cached[0] != self._changes or cached[1] != rate:
            anchors = sorted(
                self._anchor(vc, ANCHOR_OBSERVATIONS) - self._applied(vc)
                for vc in self._vehicles.values()
                if vc.has_utc and vc.recent
            )
            cached = self._team_anchor = (self._changes, rate, anchors[(len(anchors) - 1) // 2])
        return cached[2] + rate * mono_s

    def _applied(self, vc: _VehicleClock) -> float:
        """The offset a vehicle's times are mapped by: none while it is within what reception
        jitter makes of a clock at this rate (:data:`OFFSET_JITTER_WALL_S`), or on a pace
        clock within what the lock step's lead makes of it (:data:`PACED_OFFSET_LEADS`)."""
        floor = max(
            OFFSET_FLOOR_S,
            OFFSET_JITTER_WALL_S * self._rate,
            PACED_OFFSET_LEADS * self._paced_lead_s,
        )
        return vc.offset_s if abs(vc.offset_s) > floor else 0.0

    def _fit(self, vc: _VehicleClock) -> None:
        """The team's rate: the median of the vehicles' own rates, each the slope of its UTC
        on receive time over its last ``window`` reports, robust to delayed reports (a least
        squares fit, then again on the least delayed half: a delayed report lies below the
        line). One vehicle's queued link bends only its own slope."""
        recent = list(vc.recent)[-self.window :]
        if len(recent) < 2:
            return
        m0, u0 = recent[0].rx_mono_s, recent[0].utc_s
        xs = [o.rx_mono_s - m0 for o in recent]
        ys = [o.utc_s - u0 for o in recent]
        line = _least_squares(xs, ys)
        if line is None:
            return
        if len(recent) >= 8:
            slope, icpt = line
            ranked = sorted(range(len(xs)), key=lambda k: ys[k] - (icpt + slope * xs[k]))
            keep = ranked[len(ranked) // 2 :]
            line = _least_squares([xs[k] for k in keep], [ys[k] for k in keep]) or line
        if math.isfinite(line[0]) and line[0] > 0.0:
            vc.rate = line[0]
        rates = sorted(v.rate for v in self._vehicles.values() if v.rate is not None)
        if rates:
            self._rate = rates[(len(rates) - 1) // 2]

    # -- queries -------------------------------------------------------------------------------

    @property
    def rate(self) -> float:
        """Estimated UTC seconds per monotonic second (1.0 until two observations)."""
        return self._rate

    def start_lead_s(self) -> float:
        """How far ahead of now (UTC s) a mission starts when no start is given: 10 s, or two
        wall seconds' worth at this clock's rate when that is more (a simulator at 200x)."""
        return max(10.0, 2.0 * self._rate)

    @property
    def synced(self) -> bool:
        """At least one SYSTEM_TIME with UTC has been accepted."""
        return self._accepted_utc

    def now_utc_s(self) -> float:
        """Team UTC now: never less than a value returned before.

        Raises
        ------
        GcsError
            Before the first SYSTEM_TIME (:attr:`synced` is False).
        """
        if not self._accepted_utc:
            raise GcsError("mission clock: no SYSTEM_TIME received yet (not synced)")
        est = self._team_at(self._monotonic())
        if est < self._max_returned_s:
            return self._max_returned_s
        self._max_returned_s = est
        return est

    def utc_of_boot(self, system_id: int, time_boot_s: float) -> float | None:
        """Team UTC of a vehicle boot-time stamp (e.g. GLOBAL_POSITION_INT.time_boot_ms / 1000).

        The vehicle's own UTC less its offset from the team's. None before that vehicle's
        first SYSTEM_TIME.
        """
        vc = self._vehicles.get(system_id)
        return None if vc is None else vc.boot_offset_s + time_boot_s - self._applied(vc)

    def offset_s(self, system_id: int) -> float | None:
        """How far a vehicle's UTC is ahead of the team's, s, as its times are mapped (None:
        unknown or no UTC; 0 within the reception jitter, :data:`OFFSET_JITTER_WALL_S`)."""
        vc = self._vehicles.get(system_id)
        return None if vc is None or not vc.has_utc else self._applied(vc)

    @property
    def without_utc(self) -> frozenset[int]:
        """Vehicles that report no UTC (their times are mapped at reception)."""
        return frozenset(sid for sid, vc in self._vehicles.items() if not vc.has_utc)

    # -- waiting -------------------------------------------------------------------------------

    async def sleep_until(self, utc_s: float, *, max_wall_step_s: float = 0.05) -> None:
        """Return once :meth:`now_utc_s` has reached ``utc_s``.

        Sleeps in wall steps of at most ``max_wall_step_s``, re-estimating after each (the rate
        may change while waiting).

        Raises
        ------
        GcsError
            If the clock is not synced.
        ValueError
            If ``utc_s`` is not a number or ``max_wall_step_s`` is not positive.
        """
        if math.isnan(utc_s):
            raise ValueError("sleep_until: utc_s is not a number")
        if not (math.isfinite(max_wall_step_s) and max_wall_step_s > 0.0):
            raise ValueError(f"max_wall_step_s must be > 0, got {max_wall_step_s!r}")
        while True:
            now = self.now_utc_s()
            if now >= utc_s:
                return
            wall = (utc_s - now) / self._rate
            await asyncio.sleep(min(wall, max_wall_step_s))

    async def sleep(self, mission_s: float) -> None:
        """Wait ``mission_s`` seconds of mission time (UTC) from now; <= 0 returns at once."""
        if math.isnan(mission_s):
            raise ValueError("sleep: mission_s is not a number")
        if mission_s <= 0.0:
            return
        await self.sleep_until(self.now_utc_s() + mission_s)


def _median(samples: Iterable[float]) -> float:
    """:func:`statistics.median` of floats (the mean of the middle two of an even count),
    without its generality: the offsets take one at every report."""
    data = sorted(samples)
    n = len(data)
    if n == 0:
        raise statistics.StatisticsError("no median for empty data")
    i = n // 2
    return data[i] if n % 2 == 1 else (data[i - 1] + data[i]) / 2


def _least_squares(xs: list[float], ys: list[float]) -> tuple[float, float] | None:
    """(slope, intercept) of y on x; None when x spans less than :data:`MIN_FIT_SPAN_S`."""
    n = len(xs)
    if n < 2 or max(xs) - min(xs) < MIN_FIT_SPAN_S:
        return None
    mx = sum(xs) / n
    my = sum(ys) / n
    # Sums of lists, not of generators: the same terms added in the same order, faster.
    sxx = sum([(x - mx) * (x - mx) for x in xs])
    if sxx <= 0.0:
        return None
    slope = sum([(x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)]) / sxx
    return slope, my - slope * mx
