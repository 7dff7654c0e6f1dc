"""Flights that ended before this service process started, read from what they left.

A flight that ends leaves in its folder (``DATA_DIR/flights/<id>/``) its record
(``flight.json``), its report (``report/``), and, written here, its last snapshot and map
(``final.json``); its events are in the store. A restarted service answers such a flight
from them, the same as the process that flew it did.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["FINAL_FILE", "EndedFlight", "EndedFlights", "keep_final"]

FINAL_FILE = "final.json"
_FLIGHT_ID = re.compile(r"[0-9a-f]{32}")


@dataclass(frozen=True)
class EndedFlight:
    """What an ended flight left: its last snapshot and map, and its folder."""

    id: str
    snapshot: dict[str, Any]
    map: dict[str, Any] | None
    folder: Path

    @property
    def state(self) -> str:
        return str(self.snapshot.get("state"))

    @property
    def record_path(self) -> Path:
        return self.folder / "flight.json"

    @property
    def report_dir(self) -> Path:
        return self.folder / "report"


def keep_final(folder: Path, snapshot: dict[str, Any], flight_map: dict[str, Any] | None) -> None:
    """Write an ended flight's last snapshot and map beside its record (whole or not at all:
    written aside, then renamed)."""
    folder.mkdir(parents=True, exist_ok=True)
    part = folder / (FINAL_FILE + ".part")
    part.write_text(json.dumps({"snapshot": snapshot, "map": flight_map}) + "\n")
    part.replace(folder / FINAL_FILE)


class EndedFlights:
    """The ended flights under ``DATA_DIR/flights``, read once each."""

    def __init__(self, flights_dir: Path) -> None:
        self.flights_dir = flights_dir
        self._read: dict[str, EndedFlight] = {}

    def get(self, flight_id: str) -> EndedFlight | None:
        """The ended flight ``flight_id`` (a flight id names a folder: nothing else is read),
        or None."""
        found = self._read.get(flight_id)
        if found is not None or not _FLIGHT_ID.fullmatch(flight_id):
            return found
        folder = self.flights_dir / flight_id
        try:
            doc = json.loads((folder / FINAL_FILE).read_text())
        except (OSError, ValueError):
            return None
        found = EndedFlight(flight_id, doc["snapshot"], doc.get("map"), folder)
        self._read[flight_id] = found
        return found
