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
