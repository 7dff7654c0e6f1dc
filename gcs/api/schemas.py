"""Request and response bodies of the API (what is not here is returned as the engine's views,
documented as objects)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from gcs.service.stubs import DEFAULT_SPEEDUP
from planner.scenario import Threat

__all__ = [
    "AbortIn",
    "FlightIn",
    "LaunchIn",
    "Problem",
    "RehearsalIn",
    "ScheduleIn",
    "TeamTimeIn",
    "TeamTimeOut",
    "ThreatIn",
    "TileSourceOut",
    "VehicleIn",
]


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Problem(BaseModel):
    """Every error: what is wrong in words, and where it says so, the field paths."""

    detail: str
    errors: list[dict[str, Any]] | None = None
    earliest_feasible_s: float | None = None
    """For an infeasible time: the earliest one every vehicle can make (mission s)."""
    latest_feasible_s: float | None = None
    """For a team time later than some vehicle can wait (no slower speed or loiter turns
    left to it): the latest one every vehicle can make (mission s)."""
    vehicle: str | None = None
    """For an infeasible time: the vehicle that forces it."""


class VehicleIn(_Body):
    connection: str = Field(min_length=1, max_length=200, examples=["tcp:127.0.0.1:5760"])
    system_id: int | None = Field(default=None, ge=1, le=255)
    signing_key: str | None = Field(
        default=None, description="64 hex digits; kept for the link, never returned or logged"
    )


class ScheduleIn(_Body):
    scenario_id: str = Field(min_length=1, max_length=64)
    required_arrival_s: float | None = Field(default=None, ge=0.0, le=1e7)
    seed: int = Field(default=0, ge=0, le=2**31 - 1)
    dry_run: bool = False
    """Only say whether the time can be met (and the schedule's figures); nothing is kept."""


class RehearsalIn(_Body):
    """Bundled simulator vehicles for the flight, started when it is created."""

    speedup: float = Field(default=DEFAULT_SPEEDUP, gt=0.0, le=1000.0)
    wind_m_s: float | None = Field(default=None, ge=0.0, le=40.0)
    wind_from_deg: float = Field(default=0.0, ge=0.0, lt=360.0)
    loss: float = Field(default=0.0, ge=0.0, lt=1.0)
    seed: int = Field(default=0, ge=0, le=2**31 - 1)
    lockstep: bool = Field(
        default=True,
        description="the simulator waits for the flight's worker (a busy machine slows the "
        "rehearsal instead of making it late); false: it runs on the wall clock, as real "
        "vehicles do",
    )


class FlightIn(_Body):
    schedule_id: str = Field(min_length=1, max_length=64)
    vehicles: dict[str, str] | None = Field(
        default=None, description="scenario vehicle id -> registered vehicle id"
    )
    rehearsal: RehearsalIn | None = None
    lockstep: str | None = Field(
        default=None,
        min_length=1,
        max_length=4096,
        description="with vehicles on a simulator started apart: its lock-step file "
        "(sitl_stub --lockstep, in the service's TCGCS_LOCKSTEP_DIR); the simulator then waits "
        "for the flight's worker, as a rehearsal's own does",
    )


class LaunchIn(_Body):
    start_utc_s: float | None = Field(default=None, gt=0.0, le=1e11)
    delay_s: float | None = Field(default=None, ge=0.0, le=86_400.0)
    """Mission seconds from now (default: 10 s, or one wall second of a simulator's time)."""


class AbortIn(_Body):
    vehicle: str | None = Field(default=None, description="None: every vehicle")
    mode: Literal["rtl", "loiter"] = "rtl"


class PauseIn(_Body):
    at_s: float | None = Field(default=None, ge=0.0, le=1e7)
    """Mission time (s) at which the rehearsal waits (default: now)."""


class ThreatIn(_Body):
    threat: Threat
    at_s: float | None = Field(default=None, ge=0.0, le=1e7)
    """Mission time it appears (default: its own ``appears``, else now)."""


class TeamTimeIn(_Body):
    arrival_s: float = Field(ge=0.0, le=1e7)
    """The team arrival, mission s (each vehicle's slot is it plus its offset)."""


class TeamTimeOut(BaseModel):
    team_time_s: float | None
    version: int


class TileSourceOut(BaseModel):
    """The map tile source, as TileJSON 3.0.0 (the tile URLs relative to the service)."""

    tilejson: Literal["3.0.0"] = "3.0.0"
    name: str
    format: Literal["png", "jpg", "webp"]
    tiles: list[str] = Field(examples=[["/v1/tiles/{z}/{x}/{y}.png"]])
    scheme: Literal["xyz"] = "xyz"
    """Rows counted from the north, as web maps name tiles (the file's TMS rows flipped)."""
    minzoom: int
    maxzoom: int
    bounds: list[float] = Field(min_length=4, max_length=4)
    """West, south, east, north (deg)."""
    attribution: str | None = None
