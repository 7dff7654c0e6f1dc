"""A rehearsal's pauses: mission seconds at which its bundled simulator, in lock step with the
flight, waits until the operator resumes it (to brief, to try a command at a set moment, to
script a rehearsal whose verdict no machine's speed can move).

Only a simulator in lock step can wait: real vehicles, and a simulator on the wall clock, fly
on whatever the ground station does, so such a flight refuses a pause. While paused the flight
is steered as ever (threats, team time, abort); its planning takes no flight time either.

The pauses are kept beside the flight's files (:data:`PAUSES_FILE`) as they change: a flight
worker started again on the flight's checkpoint keeps them. Its simulator flies on while no
ground station acknowledges it (after :data:`sitl_stub.lockstep.STALE_WALL_S`), so a flight
paused when its worker died waits again where its simulator had got to.
"""

from __future__ import annotations

import bisect
import contextlib
import json
import math
from pathlib import Path
from typing import Any

from gcs.coordination.missionclock import MissionClock
from gcs.service.scenariotext import Conflict, InvalidInput

__all__ = ["PAUSES_FILE", "Pauses"]

PAUSES_FILE = "pauses.json"
"""The mission seconds a flight is to pause at (a JSON list), beside its other files."""


class Pauses:
    """The pauses of one flight flown on ``clock`` (a simulator's pace clock when paced)."""

    def __init__(self, flight_id: str, clock: MissionClock, folder: Path | None = None) -> None:
        """``folder``: the flight's, where the pauses are kept (and read back from, for a
        flight taken on)."""
        self.flight_id = flight_id
        self.clock = clock
        self.folder = folder
        self.at_s: list[float] = _kept(folder)
        """Mission seconds still to pause at (or paused at: the first), in order."""
        self.start_utc_s: float | None = None
        """The mission's start (UTC s), once launched."""

    def launched(self, start_utc_s: float) -> None:
        self.start_utc_s = start_utc_s
        self._apply()

    def add(self, at_s: float | None, now_s: float | None) -> dict[str, Any]:
        """Pause at mission second ``at_s`` (None: now), the flight being at ``now_s`` (None:
        not launched yet).

        Raises
        ------
        Conflict
            The flight's vehicles cannot wait (not a simulator in lock step), or ``at_s`` has
            passed.
        InvalidInput
            ``at_s`` is not a number of seconds.
        """
        if not self.clock.paced:
            raise Conflict(
                f"flight {self.flight_id} cannot pause: only a rehearsal in lock step waits "
                "(real vehicles and a simulator on the wall clock fly on)"
            )
        if at_s is None:
            at_s = 0.0 if now_s is None else now_s
        if not math.isfinite(at_s):
            raise InvalidInput(f"at_s: {at_s!r} is not a mission time in seconds")
        if now_s is not None and at_s < now_s:
            raise Conflict(
                f"flight {self.flight_id} is at mission second {now_s:.1f}: {at_s:.1f} has passed"
            )
        bisect.insort(self.at_s, float(at_s))
        self._keep()
        self._apply()
        return self.view(now_s)

    def resume(self, now_s: float | None) -> dict[str, Any]:
        """Fly on from the pause the flight is at (every pause reached by ``now_s``); the
        later ones stay.

        Raises
        ------
        Conflict
            The flight is not paused.
        """
        if not self.paused(now_s):
            raise Conflict(f"flight {self.flight_id} is not paused")
        assert now_s is not None
        del self.at_s[: bisect.bisect_right(self.at_s, now_s)]
        self._keep()
        self._apply()
        return self.view(now_s)

    def paused(self, now_s: float | None) -> bool:
        """The flight has reached its first pause (and waits there)."""
        return now_s is not None and bool(self.at_s) and self.at_s[0] <= now_s

    def view(self, now_s: float | None) -> dict[str, Any]:
        """The snapshot's ``pause``: whether the flight can pause at all, is paused now, and
        the pauses to come."""
        return {"pausable": self.clock.paced, "paused": self.paused(now_s), "at_s": list(self.at_s)}

    def _keep(self) -> None:
        """Write the pauses beside the flight's files (whole or not at all)."""
        if self.folder is not None:
            part = self.folder / (PAUSES_FILE + ".part")
            part.write_text(json.dumps(self.at_s) + "\n", encoding="utf-8")
            part.replace(self.folder / PAUSES_FILE)

    def _apply(self) -> None:
        start = self.start_utc_s
        self.clock.hold_at(None if start is None or not self.at_s else start + self.at_s[0])


def _kept(folder: Path | None) -> list[float]:
    """The pauses kept in ``folder`` (none when there are none, or they do not read)."""
    if folder is None:
        return []
    with contextlib.suppress(OSError, ValueError, TypeError):
        return sorted(float(x) for x in json.loads((folder / PAUSES_FILE).read_text()))
    return []
