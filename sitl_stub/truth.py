"""The simulator's true state as JSON lines, for checking a ground station against the truth.

File format ``tcgcs-truth/1``: a header line ::

    {"format": "tcgcs-truth/1", "vehicles": N, "speedup": S, "start_utc_s": U, "period_s": P}

then, every ``period_s`` simulated seconds, one line per vehicle ::

    {"utc_s": ..., "i": 0, "sysid": 1, "lat_deg": ..., "lon_deg": ..., "alt_m": ...,
     "airspeed_m_s": ..., "eas_m_s": ..., "groundspeed_m_s": ..., "armed": false,
     "on_ground": true, "terrain_m": ..., "crashed": false}

``utc_s`` is the TRUE simulated UTC of the step (all vehicles of one row share it; a vehicle
started with a UTC offset, or without UTC, reports other times in SYSTEM_TIME), ``alt_m`` is
AMSL, ``airspeed_m_s`` the TRUE airspeed and ``eas_m_s`` the true equivalent airspeed (what
ArduPlane's airspeeds are; with a speed bias the vehicle's VFR_HUD differs from it),
``terrain_m`` the ground AMSL under the vehicle and ``crashed`` whether it has been flown into
it (from the impact on, before the vehicle says so). Lines
are buffered and written whole: the file is flushed every ``flush_lines`` lines, at least
every ``flush_wall_s`` wall seconds while recording, and on :meth:`TruthRecorder.close`, so a
reader tailing it only ever sees a partial last line while a flush is in progress.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from sitl_stub.clock import SimClock
from sitl_stub.vehicle import Vehicle

TRUTH_FORMAT = "tcgcs-truth/1"
DEFAULT_TRUTH_PERIOD_S = 0.5
FLUSH_LINES = 50
FLUSH_WALL_S = 1.0


class TruthRecorder:
    """Writes the true state of ``vehicles`` every ``period_s`` simulated seconds.

    Call :meth:`on_step` after every simulation step (``TeamServer.add_step_listener``); it
    costs one comparison unless a sample falls due. The first row is written by
    :meth:`start` (the state at that moment).
    """

    def __init__(
        self,
        out: TextIO,
        vehicles: Sequence[Vehicle],
        clock: SimClock,
        *,
        period_s: float = DEFAULT_TRUTH_PERIOD_S,
        flush_lines: int = FLUSH_LINES,
        flush_wall_s: float = FLUSH_WALL_S,
        close_out: bool = False,
    ) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"truth period must be a positive number of seconds, got {period_s!r}")
        if flush_lines < 1:
            raise ValueError(f"flush_lines must be at least 1, got {flush_lines}")
        self._out = out
        self._close_out = close_out
        self.vehicles = list(vehicles)
        self.clock = clock
        self.period_s = float(period_s)
        self.flush_lines = flush_lines
        self.flush_wall_s = flush_wall_s
        self._buf: list[str] = []
        self._next_due_s = math.inf  # set by start()
        self._last_flush_wall_s = time.monotonic()
        self.lines_recorded = 0  # sample lines (not the header), buffered or written
        self.closed = False

    @classmethod
    def open(
        cls,
        path: str | Path,
        vehicles: Sequence[Vehicle],
        clock: SimClock,
        *,
        period_s: float = DEFAULT_TRUTH_PERIOD_S,
        flush_lines: int = FLUSH_LINES,
        flush_wall_s: float = FLUSH_WALL_S,
    ) -> TruthRecorder:
        """A recorder writing to a new file at ``path`` (closed by :meth:`close`)."""
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"truth period must be a positive number of seconds, got {period_s!r}")
        out = Path(path).open("w", encoding="utf-8")  # noqa: SIM115 (closed by close())
        return cls(
            out,
            vehicles,
            clock,
            period_s=period_s,
            flush_lines=flush_lines,
            flush_wall_s=flush_wall_s,
            close_out=True,
        )

    def start(self) -> None:
        """Write the header and the first row (the state now); flushes."""
        header = {
            "format": TRUTH_FORMAT,
            "vehicles": len(self.vehicles),
            "speedup": self.clock.speedup,
            "start_utc_s": self.clock.start_utc_s,
            "period_s": self.period_s,
        }
        self._buf.append(json.dumps(header) + "\n")
        self._next_due_s = self.clock.sim_time_s
        self.on_step()
        self.flush()

    def on_step(self) -> None:
        """Step listener: record a row if one is due."""
        now = self.clock.sim_time_s
        if now + 1e-9 < self._next_due_s:
            return
        self.record()
        nxt = self._next_due_s + self.period_s
        self._next_due_s = nxt if nxt > now + 1e-9 else now + self.period_s
        if (
            len(self._buf) >= self.flush_lines
            or time.monotonic() - self._last_flush_wall_s >= self.flush_wall_s
        ):
            self.flush()

    def record(self) -> None:
        """Buffer one row (one line per vehicle) with the state now."""
        utc = round(self.clock.utc_s, 6)
        buf = self._buf
        for i, v in enumerate(self.vehicles):
            s = v.autopilot.state
            lat, lon, alt = round(s.lat_deg, 9), round(s.lon_deg, 9), round(s.alt_m, 3)
            tas, gs = round(s.airspeed_m_s, 3), round(s.groundspeed_m_s, 3)
            eas = round(v.autopilot.eas_m_s, 3)
            armed, ground = v.autopilot.armed, s.on_ground
            terrain = round(v.autopilot.ground_alt_m, 2)
            crashed = v.autopilot.crash_time_s is not None
            if math.isfinite(utc + lat + lon + alt + tas + eas + gs + terrain):
                # Hand-formatted (3x faster than json.dumps); float repr is valid JSON.
                buf.append(
                    f'{{"utc_s": {utc!r}, "i": {i}, "sysid": {v.system_id}, '
                    f'"lat_deg": {lat!r}, "lon_deg": {lon!r}, "alt_m": {alt!r}, '
                    f'"airspeed_m_s": {tas!r}, "eas_m_s": {eas!r}, '
                    f'"groundspeed_m_s": {gs!r}, '
                    f'"armed": {"true" if armed else "false"}, '
                    f'"on_ground": {"true" if ground else "false"}, '
                    f'"terrain_m": {terrain!r}, "crashed": {"true" if crashed else "false"}}}\n'
                )
            else:  # never expected; json.dumps writes NaN/Infinity, which Python reads
                row = {
                    "utc_s": utc,
                    "i": i,
                    "sysid": v.system_id,
                    "lat_deg": lat,
                    "lon_deg": lon,
                    "alt_m": alt,
                    "airspeed_m_s": tas,
                    "eas_m_s": eas,
                    "groundspeed_m_s": gs,
                    "armed": armed,
                    "on_ground": ground,
                    "terrain_m": terrain,
                    "crashed": crashed,
                }
                buf.append(json.dumps(row) + "\n")
        self.lines_recorded += len(self.vehicles)

    def flush(self) -> None:
        """Write the buffered lines (whole lines, one write) and flush the file."""
        self._last_flush_wall_s = time.monotonic()
        if self.closed:
            return
        if self._buf:
            self._out.write("".join(self._buf))
            self._buf.clear()
        self._out.flush()

    def close(self) -> None:
        """Flush; close the file if this recorder opened it. Idempotent."""
        if self.closed:
            return
        try:
            self.flush()
        finally:
            self.closed = True
            if self._close_out:
                self._out.close()
