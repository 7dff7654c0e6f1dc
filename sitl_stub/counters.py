"""The simulator's counters as a JSON file that another process can read while it runs.

A test driving a ground station in one process and the simulator in another reads this file
to see what the vehicles were made to do: armed twice? launched twice? given the same mission
again? File format ``tcgcs-stub-counters/1``, one JSON document (not lines)::

    {"format": "tcgcs-stub-counters/1", "sim_time_s": T, "final": false,
     "vehicles": [{"index": 0, "system_id": 1, "arms": N, "auto_mode_changes": N,
                   "mission_uploads": N, "mission_downloads": N, "failed_uploads": N, ...}]}

- ``arms``: transitions from disarmed to armed (arming an armed vehicle does not count);
- ``auto_mode_changes``: mode changes into AUTO from another mode;
- ``mission_uploads``: uploads the vehicle completed and accepted (MISSION_ACK accepted);
- ``mission_downloads``: downloads served to the end (every item of the announced list sent);
- ``failed_uploads``: uploads that ended in an error or timed out;
- then the other counters: ``missions_stored`` (every replacement of stored items, clears
  included), ``mission_items_ignored`` (duplicate or out-of-order items and confused
  requests), ``received``, ``sent``, ``bad_data``, ``handler_errors``,
  ``unsupported_commands`` (MAVLink messages), ``link_inbound`` / ``link_outbound``
  (:class:`~sitl_stub.link.LinkCounters`: packets passed, lost, blacked out, duplicated,
  reordered).

The mission counters count every mission type (mission, fence, rally). Counters start at 0
when the simulator starts. The file is rewritten about once a wall second and at exit
(``"final": true``), each time whole: the document goes to a temporary file in the same
directory, which then replaces the file (``os.replace``), so a reader never sees a partial
document.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sitl_stub.clock import SimClock
from sitl_stub.vehicle import Vehicle

COUNTERS_FORMAT = "tcgcs-stub-counters/1"
DEFAULT_COUNTERS_PERIOD_S = 1.0  # wall seconds


def vehicle_counters(index: int, v: Vehicle) -> dict[str, Any]:
    """One vehicle's entry in the counters document."""
    ap, mission = v.autopilot.counters, v.mission.counters
    return {
        "index": index,
        "system_id": v.system_id,
        "arms": ap["arms"],
        "auto_mode_changes": ap["auto_mode_changes"],
        "mission_uploads": mission["accepted_uploads"],
        "mission_downloads": mission["downloads"],
        "failed_uploads": mission["failed_uploads"],
        "missions_stored": mission["uploads"],
        "mission_items_ignored": mission["ignored"],
        **v.counters,
        "link_inbound": dataclasses.asdict(v.link.inbound),
        "link_outbound": dataclasses.asdict(v.link.outbound),
    }


def counters_document(
    vehicles: Sequence[Vehicle], clock: SimClock, *, final: bool = False
) -> dict[str, Any]:
    """The whole ``tcgcs-stub-counters/1`` document, as it stands now."""
    return {
        "format": COUNTERS_FORMAT,
        "sim_time_s": round(clock.sim_time_s, 6),
        "final": final,
        "vehicles": [vehicle_counters(i, v) for i, v in enumerate(vehicles)],
    }


class CountersWriter:
    """Rewrites the counters file at least every ``period_s`` wall seconds while stepping.

    Call :meth:`on_step` after every simulation step (``TeamServer.add_step_listener``); it
    costs one clock read unless a write is due. :meth:`start` writes the first document,
    :meth:`close` the final one.
    """

    def __init__(
        self,
        path: str | Path,
        vehicles: Sequence[Vehicle],
        clock: SimClock,
        *,
        period_s: float = DEFAULT_COUNTERS_PERIOD_S,
    ) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(
                f"counters period must be a positive number of seconds, got {period_s!r}"
            )
        self.path = Path(path)
        self.vehicles = list(vehicles)
        self.clock = clock
        self.period_s = float(period_s)
        self._last_write_wall_s = -math.inf
        self.writes = 0
        self.closed = False

    def start(self) -> None:
        """Write the first document (every counter 0 unless something already happened)."""
        self.write()

    def on_step(self) -> None:
        """Step listener: rewrite the file if the last write is ``period_s`` old."""
        if time.monotonic() - self._last_write_wall_s >= self.period_s:
            self.write()

    def write(self, *, final: bool = False) -> None:
        """Replace the file with the document as it stands now (atomically)."""
        self._last_write_wall_s = time.monotonic()
        text = json.dumps(counters_document(self.vehicles, self.clock, final=final))
        fd, tmp = tempfile.mkstemp(
            prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent
        )
        try:
            os.fchmod(fd, 0o644)  # as an ordinary file (mkstemp's is private)
            with os.fdopen(fd, "w", encoding="utf-8") as out:
                out.write(text + "\n")
            os.replace(tmp, self.path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
        self.writes += 1

    def close(self) -> None:
        """Write the final document (``"final": true``). Idempotent."""
        if self.closed:
            return
        self.closed = True
        self.write(final=True)
