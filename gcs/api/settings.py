"""The service's settings: environment variables ``TCGCS_*`` (or a ``.env`` file)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, FilePath, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["SCOPES", "Settings"]

SCOPES = ("observe", "plan", "operate", "admin")
"""observe: read everything; plan: scenarios and schedules; operate: vehicles and flights;
admin: all of them."""


class Settings(BaseSettings):
    """``TCGCS_DATABASE_URL``, ``TCGCS_HOST``, ``TCGCS_PORT``, ``TCGCS_TOKENS``,
    ``TCGCS_DATA_DIR``, ``TCGCS_TILES_MBTILES``."""

    model_config = SettingsConfigDict(env_prefix="TCGCS_", env_file=".env", extra="ignore")

    data_dir: Path = Path("tcgcs-data")
    """Flights' records, reports and truth logs; the default SQLite file; the admin token."""
    database_url: str | None = None
    """SQLAlchemy URL; default: ``sqlite:///DATA_DIR/tcgcs.db``."""
    host: str = "127.0.0.1"
    port: int = Field(default=8600, ge=1, le=65535)
    tokens: dict[str, list[str]] = Field(default_factory=dict, repr=False)
    """Bearer token -> its scopes (JSON in the environment). With none, the service makes one
    admin token and writes it to ``DATA_DIR/admin.token`` (mode 0600): it is never logged."""
    tiles_mbtiles: FilePath | None = None
    """A raster MBTiles file (png, jpg or webp tiles) served at ``/v1/tiles`` for the console's
    map; without one the map shows the scenario's hillshade only."""

    allowed_origins: list[str] = Field(default_factory=list)
    """Origins (``https://ops.example``) besides the service's own whose pages may open a
    flight's stream (JSON in the environment)."""
    max_body_bytes: int = Field(default=4 * 1024 * 1024, ge=1024)
    """The largest request body accepted; a larger one is answered 413 before it is read."""
    max_vehicles: int = Field(default=1000, ge=1)
    """The most vehicles in a scenario; more is a 422 before any planning."""
    max_grid_nodes: int = Field(default=1_000_000, ge=9)
    """The most planning-grid nodes (area over resolution) in a scenario; more is a 422."""
    max_hills: int = Field(default=1000, ge=0)
    """The most synthetic-terrain hills in a scenario; more is a 422."""
    srtm_dir: Path | None = None
    """The folder of SRTM ``.hgt`` tiles (folders of them) scenarios may name as their
    terrain, relative to it; without it a scenario with SRTM terrain is a 422."""
    jobs_running: int = Field(default=2, ge=1)
    """Planning jobs run at once, each in a process of its own; the others queue."""
    jobs_per_token: int = Field(default=8, ge=1)
    """Jobs one token may have queued or running; past it, 429 with Retry-After."""
    job_time_limit_s: float = Field(default=900.0, gt=0.0)
    """A planning job running longer (wall s) is stopped and failed."""
    job_niceness: int = Field(default=10, ge=0, le=19)
    """How much lower than the service's own its planning jobs' scheduling priority is
    (``nice``; a local Ray a job starts runs at the job's): planning is batch work, behind
    flights and requests."""
    plan_ray: str | None = Field(default=None, min_length=1)
    """Where planning jobs finish their vehicles' routes: unset, in the job's own process
    (and processes it forks, for a large team); ``local``, a Ray each job starts on this
    machine (loopback only; killed with the job); else a Ray cluster's address to join
    (``auto``, ``ray://head:10001``). A Ray not reached fails the job with a 503."""
    worker_silence_s: float = Field(default=15.0, gt=0.0, le=3600.0)
    """A flight worker that has told the service nothing for this long (wall s; it says the
    flight's state four times a second) is asked whether it still runs."""
    worker_answer_s: float = Field(default=10.0, gt=0.0, le=3600.0)
    """A flight worker asked (``worker_silence_s``) that has not answered within this long
    (wall s) is hung: it is killed and another flies its flight on from its checkpoint."""

    lockstep_dir: Path | None = None
    """A folder whose simulators' lock-step files (``sitl_stub --lockstep``) a flight on
    registered vehicles may join (``lockstep`` of ``POST /v1/flights``: a rehearsal on
    simulators started apart, which wait for the flight's worker); unset: none may."""
    worker_nice: int | None = Field(default=None, ge=-20, le=19)
    """The flight workers' scheduling priority (``nice``; their planning jobs run at it too):
    below the service's own (0) puts flights ahead of the API and of anything else on the
    machine, and needs the privilege to raise a priority (CAP_SYS_NICE; refused, a worker
    says so in its log and runs at the service's). Unset: 5 ahead of the service's where the
    service may raise a priority, else the service's
    (:func:`gcs.service.workers.ahead_of_service`)."""
    spare_worker: bool = True
    """Keep one flight worker started and loaded ahead of the next flight (or of a worker
    that dies): it takes its flight in a fifth of a second instead of the Python start-up
    (over a second). Off, each worker starts when it is needed and no process waits idle."""

    @field_validator("tokens")
    @classmethod
    def _scopes_known(cls, tokens: dict[str, list[str]]) -> dict[str, list[str]]:
        for scopes in tokens.values():
            unknown = sorted(set(scopes) - set(SCOPES))
            if unknown:
                raise ValueError(f"unknown scope(s) {', '.join(unknown)}: one of {SCOPES}")
        return tokens

    def db_url(self) -> str:
        return self.database_url or f"sqlite:///{self.data_dir / 'tcgcs.db'}"
