"""The mission item value shared by the stub's autopilot and its MAVLink mission server."""

from __future__ import annotations

from dataclasses import dataclass

MAV_MISSION_TYPE_MISSION = 0
MAV_MISSION_TYPE_FENCE = 1
MAV_MISSION_TYPE_RALLY = 2


@dataclass(frozen=True, slots=True)
class MissionItem:
    """One MISSION_ITEM_INT as stored on the vehicle (lat/lon as int 1e7, z in metres)."""

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    mission_type: int = MAV_MISSION_TYPE_MISSION

    @property
    def lat_deg(self) -> float:
        return self.x * 1e-7

    @property
    def lon_deg(self) -> float:
        return self.y * 1e-7
