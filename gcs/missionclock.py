"""The mission clock: the vehicles' UTC (SYSTEM_TIME), read through the local monotonic clock.

Mission time is what the vehicles say it is: SYSTEM_TIME.time_unix_usec, GPS time on a real
autopilot, simulated UTC on the stub (which runs ``speedup`` times faster than wall time). The
coordinator never reads ``time.time()``; it asks :meth:`MissionClock.now_utc_s`, which maps the
local monotonic clock onto the vehicles' UTC:

- the rate (UTC seconds per monotonic second: 1.0 live, about 200 at 200x) is the least-squares
  slope of UTC against receive time over the last ``window`` SYSTEM_TIMEs of all vehicles;
- "now" extrapolates from the newest observations with that rate. Receive times carry link
  delay, which only ever makes an observation look older than it is (at 200x, 2 ms of delay is
  0.4 s of UTC), so of the newest :data:`ANCHOR_OBSERVATIONS` extrapolations the latest is
  taken: one delayed packet does not drag the clock back;
- what :meth:`now_utc_s` returns never decreases.

Each vehicle's boot -> UTC offset (``utc - time_boot``) converts the boot-time stamps of its
other messages (GLOBAL_POSITION_INT.time_boot_ms, ...) to UTC exactly, whatever the link
delay: :meth:`MissionClock.utc_of_boot`.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from gcs.errors import GcsError

ANCHOR_OBSERVATIONS = 5
"""How many of the newest observations "now" is extrapolated from (the latest one wins)."""
JUMP_BACK_S = 1.0
"""A vehicle's UTC going back by more than this resets that vehicle (a new timeline)."""
MIN_FIT_SPAN_S = 0.002
"""The rate is re-fitted only when the window spans at least this much monotonic time."""


@dataclass(frozen=True, slots=True)
class _Observation:
    rx_mono_s: float
    utc_s: float
    system_id: int


class MissionClock:
    """Mission UTC from the vehicles' SYSTEM_TIME messages (see the module docstring)."""

    def __init__(self, monotonic: Callable[[], float] = time.monotonic, window: int = 20) -> None:
        if window < 2:
            raise ValueError(f"window must be at least 2 observations, got {window}")
        self._monotonic = monotonic
        self.window = window
        self._obs: deque[_Observation] = deque(maxlen=window)
        self._offset_s: dict[int, float] = {}  # per vehicle: utc - time_boot
        self._last_utc_s: dict[int, float] = {}  # per vehicle: newest accepted UTC
        self._rate = 1.0
        self._max_returned_s = -math.inf
        self.accepted = 0
        self.rejected = 0
        self.resets = 0  # vehicles whose UTC jumped back by more than JUMP_BACK_S

    # -- input -------------------------------------------------------------------------------

    def observe(self, system_id: int, utc_s: float, time_boot_s: float, rx_mono_s: float) -> None:
        """One SYSTEM_TIME of vehicle ``system_id``, received at ``rx_mono_s`` (monotonic).

        Rejected (counted in :attr:`rejected`): non-finite values, ``utc_s <= 0`` (no GPS time
        yet), a negative boot time, and a UTC not later than that vehicle's last one (a
        duplicate or a reordered packet). A UTC more than :data:`JUMP_BACK_S` behind the
        vehicle's last one with a different boot offset (the vehicle rebooted or its time was
        reset; a late packet keeps its offset) also resets the vehicle (counted in
        :attr:`resets`): its older observations leave the rate fit and its timeline starts
        again from this one.
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
        offset = utc_s - time_boot_s
        last = self._last_utc_s.get(system_id)
        if last is not None and utc_s <= last:
            self.rejected += 1
            if utc_s < last - JUMP_BACK_S and abs(offset - self._offset_s[system_id]) > JUMP_BACK_S:
                self.resets += 1
                kept = [o for o in self._obs if o.system_id != system_id]
                self._obs = deque(kept, maxlen=self.window)
                self._accept(system_id, utc_s, offset, rx_mono_s)
            return
        self.accepted += 1
        self._accept(system_id, utc_s, offset, rx_mono_s)

    def _accept(self, system_id: int, utc_s: float, offset_s: float, rx_mono_s: float) -> None:
        self._offset_s[system_id] = offset_s
        self._last_utc_s[system_id] = utc_s
        self._obs.append(_Observation(rx_mono_s, utc_s, system_id))
        self._fit()

    def _fit(self) -> None:
        """Least-squares slope of UTC on receive time over the window (kept if ill-posed)."""
        obs = self._obs
        n = len(obs)
        if n < 2:
            return
        m0 = obs[0].rx_mono_s
        u0 = obs[0].utc_s
        xs = [o.rx_mono_s - m0 for o in obs]
        if max(xs) - min(xs) < MIN_FIT_SPAN_S:
            return
        ys = [o.utc_s - u0 for o in obs]
        mx = sum(xs) / n
        my = sum(ys) / n
        sxx = sum((x - mx) * (x - mx) for x in xs)
        sxy = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True))
        if sxx <= 0.0:
            return
        slope = sxy / sxx
        if math.isfinite(slope) and slope > 0.0:
            self._rate = slope

    # -- queries -------------------------------------------------------------------------------

    @property
    def rate(self) -> float:
        """Estimated UTC seconds per monotonic second (1.0 until two observations)."""
        return self._rate

    @property
    def synced(self) -> bool:
        """At least one SYSTEM_TIME has been accepted."""
        return bool(self._obs)

    def now_utc_s(self) -> float:
        """Mission UTC now: never less than a value returned before.

        Raises
        ------
        GcsError
            Before the first SYSTEM_TIME (:attr:`synced` is False).
        """
        if not self._obs:
            raise GcsError("mission clock: no SYSTEM_TIME received yet (not synced)")
        mono = self._monotonic()
        rate = self._rate
        obs = self._obs
        est = -math.inf
        for k in range(1, min(ANCHOR_OBSERVATIONS, len(obs)) + 1):
            o = obs[-k]
            e = o.utc_s + rate * (mono - o.rx_mono_s)
            if e > est:
                est = e
        if est < self._max_returned_s:
            return self._max_returned_s
        self._max_returned_s = est
        return est

    def utc_of_boot(self, system_id: int, time_boot_s: float) -> float | None:
        """UTC of a vehicle boot-time stamp (e.g. GLOBAL_POSITION_INT.time_boot_ms / 1000).

        None before that vehicle's first SYSTEM_TIME.
        """
        offset = self._offset_s.get(system_id)
        return None if offset is None else offset + time_boot_s

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
