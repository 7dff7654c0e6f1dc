"""Lock step between the simulator and one ground station: a shared clock file.

At 200x one millisecond of wall time is 0.2 s of flight: a ground station that its machine
keeps waiting for a few milliseconds (another process on the core, a garbage collection, a
planning thread holding the interpreter) answers seconds of flight late, and a rehearsal's
verdict then depends on how busy the machine was. In lock step the simulator and the ground
station keep one clock, the *pace clock*: the simulator's flight time divided by its speed-up.

- the simulator publishes it after each step, before that step's packets go out
  (:meth:`Lockstep.publish`); the ground station reads it as its monotonic clock
  (:meth:`Lockstep.pace_s`), so what it measures between two messages is flight time,
  however late it read them;
- the ground station acknowledges, while its event loop turns, the pace time it has seen
  (:meth:`Lockstep.acknowledge`), and the simulator steps no further than ``lead_s`` of pace
  time beyond that (:meth:`Lockstep.limit_s`): the ground station is never more than the
  lead behind the flight, whatever the load;
- an acknowledgement older than :data:`STALE_WALL_S` of wall time (no ground station, or one
  that stopped) does not hold the simulator back: the flight goes on, as a real one would.

The file is 40 bytes: five native float64 (pace time, acknowledged pace time, the wall time
of the acknowledgement on the machine's monotonic clock, the speed-up and the lead), each
written in one aligned store. Both processes map it; nothing else is exchanged. The ground
station reads the lead too: a report it reads may be up to that much flight older than the
pace clock says, and its mission clock takes no difference that small between two vehicles'
clocks for an offset (:meth:`gcs.coordination.missionclock.MissionClock.follow`).
"""

from __future__ import annotations

import math
import mmap
import os
import time
from pathlib import Path

STALE_WALL_S = 3.0
"""An acknowledgement older than this (monotonic wall seconds) holds nothing back: long
enough that a ground station its machine keeps busy (two other processes on each core, a
planning thread holding the interpreter) is still waited for, short enough that a flight
whose ground station died goes on within seconds."""
DEFAULT_LEAD_S = 1.0
"""How far (flight seconds) the simulator may run ahead of what the ground station has seen."""
LOCKSTEP_BYTES = 40
"""The size of a lock-step file."""
_SIZE = LOCKSTEP_BYTES
_PACE, _ACK, _ACK_WALL, _SPEEDUP, _LEAD = range(5)


class Lockstep:
    """The shared clock file (see the module docstring)."""

    def __init__(
        self,
        path: Path,
        *,
        create: bool = False,
        speedup: float = 1.0,
        lead_s: float = DEFAULT_LEAD_S,
    ) -> None:
        self.path = Path(path)
        flags = os.O_RDWR | (os.O_CREAT if create else 0)
        fd = os.open(self.path, flags, 0o600)
        try:
            if create:
                os.ftruncate(fd, _SIZE)
            elif os.fstat(fd).st_size < _SIZE:
                raise ValueError(f"{self.path}: not a lock-step file ({_SIZE} bytes)")
            self._map = mmap.mmap(fd, _SIZE)
        finally:
            os.close(fd)
        # The five float64 slots, read and written as Python floats (a numpy view's scalar
        # access costs several times more, and the simulator reads them every step).
        self._slots = memoryview(self._map).cast("d")
        if create:
            if not (math.isfinite(speedup) and speedup > 0.0):
                raise ValueError(f"speedup must be a positive number, got {speedup!r}")
            if not (math.isfinite(lead_s) and lead_s > 0.0):
                raise ValueError(f"lead_s must be a positive number of seconds, got {lead_s!r}")
            for slot, value in enumerate((0.0, -math.inf, -math.inf, speedup, lead_s)):
                self._slots[slot] = value

    @property
    def speedup(self) -> float:
        return float(self._slots[_SPEEDUP])

    @property
    def lead_s(self) -> float:
        """How far (flight s) the simulator may run ahead of the acknowledged pace time."""
        return float(self._slots[_LEAD])

    # -- the simulator -------------------------------------------------------------------------

    def publish(self, sim_s: float) -> None:
        """The simulator has flown ``sim_s`` seconds."""
        self._slots[_PACE] = sim_s / self.speedup

    def limit_s(self, wall_s: float | None = None) -> float:
        """The flight time (s) the simulator may step to now: the acknowledged pace time's
        plus the lead, or infinity while no ground station acknowledges (none yet, or its
        last acknowledgement is :data:`STALE_WALL_S` old)."""
        wall = time.monotonic() if wall_s is None else wall_s
        if wall - float(self._slots[_ACK_WALL]) > STALE_WALL_S:
            return math.inf
        return float(self._slots[_ACK]) * self.speedup + self.lead_s

    # -- the ground station --------------------------------------------------------------------

    def pace_s(self) -> float:
        """The pace clock: flight seconds / speed-up (a monotonic clock for the ground station)."""
        return float(self._slots[_PACE])

    def acknowledge(self, pace_s: float | None = None) -> None:
        """The ground station has seen the flight up to ``pace_s`` (default: now)."""
        self._slots[_ACK] = self.pace_s() if pace_s is None else pace_s
        self._slots[_ACK_WALL] = time.monotonic()

    def acknowledged_s(self) -> float:
        """The pace time (s) the ground station last acknowledged (-inf before any)."""
        return float(self._slots[_ACK])

    def release(self) -> None:
        """The ground station holds the simulator back no longer."""
        self._slots[_ACK_WALL] = -math.inf

    def close(self) -> None:
        """Unmap the file; the clock reads on as it last was (a flight record may ask)."""
        # The map cannot close while a view of it lives: go on with a copy of the slots.
        mapped, self._slots = self._slots, memoryview(bytearray(self._slots)).cast("d")
        mapped.release()
        self._map.close()
