"""The service's errors, and a scenario read from the text a client sent.

Errors are :class:`ServiceError` subclasses that name what is wrong; the API maps them to
status codes by their ``status``. A scenario is checked against the service's limits
(:class:`ScenarioLimits`: vehicles, grid nodes, hills) before any planning, so that one that
would take the machine's memory or minutes of work is a 422 at once. Its SRTM terrain is read
only from the folder the service keeps for it (:func:`confine_terrain`): a client names a
folder under it, never a path on the service's disk.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import yaml
from pydantic import ValidationError

from gcs.errors import GcsError
from planner.scenario import Scenario, SrtmTerrainSpec, SyntheticTerrainSpec, field_path

__all__ = [
    "Conflict",
    "Infeasible",
    "InvalidInput",
    "NotFound",
    "PreconditionFailed",
    "ScenarioLimits",
    "ServiceError",
    "TooBusy",
    "check_limits",
    "confine_terrain",
    "parse_scenario_text",
]


class ServiceError(GcsError):
    status = 400


class NotFound(ServiceError):
    status = 404


class Conflict(ServiceError):
    status = 409


class Infeasible(Conflict):
    """A time no vehicle set can make: names the earliest (or latest) feasible time and the
    vehicle that forces it."""

    def __init__(
        self,
        message: str,
        earliest_s: float | None,
        vehicle: str | None,
        latest_s: float | None = None,
    ) -> None:
        super().__init__(message)
        self.earliest_s = earliest_s
        self.latest_s = latest_s
        self.vehicle = vehicle


class PreconditionFailed(ServiceError):
    status = 412


class InvalidInput(ServiceError):
    """A body that does not validate: the field path and what is wrong with it."""

    status = 422

    def __init__(self, message: str, errors: Sequence[Mapping[str, Any]] = ()) -> None:
        super().__init__(message)
        self.errors = list(errors)


class TooBusy(ServiceError):
    """A quota is used up: try again after ``retry_after_s``."""

    status = 429

    def __init__(self, message: str, retry_after_s: int) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s


def parse_scenario_text(body: str, media_type: str) -> Scenario:
    """A scenario from YAML or JSON text.

    Raises
    ------
    InvalidInput
        Not YAML/JSON (with line and column), or a field that does not validate (its path).
    """
    try:
        data = json.loads(body) if "json" in media_type else yaml.safe_load(body)
    except json.JSONDecodeError as err:
        where = f"line {err.lineno} column {err.colno}"
        raise InvalidInput(f"not valid JSON: {err.msg} at {where}") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = "" if mark is None else f" at line {mark.line + 1} column {mark.column + 1}"
        problem = getattr(err, "problem", None) or type(err).__name__
        raise InvalidInput(f"not valid YAML: {problem}{where}") from None
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        errors = [
            {
                "loc": [str(x) for x in field_path(e["loc"], data)],
                "msg": e["msg"],
                "type": e["type"],
            }
            for e in err.errors(include_url=False, include_context=False, include_input=False)
        ]
        first = errors[0]
        raise InvalidInput(
            f"scenario: {'.'.join(first['loc']) or '(top level)'}: {first['msg']}", errors
        ) from None


@dataclass(frozen=True)
class ScenarioLimits:
    """The largest scenario the service plans (settings ``TCGCS_MAX_*``)."""

    vehicles: int = 1000
    grid_nodes: int = 1_000_000
    hills: int = 1000
    srtm_dir: Path | None = None
    """The folder SRTM terrain is read from (``TCGCS_SRTM_DIR``): a scenario's
    ``terrain.directory`` is a folder under it. None: SRTM terrain is refused."""


def check_limits(scenario: Scenario, limits: ScenarioLimits) -> None:
    """Raise :class:`InvalidInput` naming the first field over the service's limits."""
    n = len(scenario.vehicles)
    if n > limits.vehicles:
        raise InvalidInput(
            f"scenario: vehicles: {n} vehicles, over this service's limit of {limits.vehicles}"
        )
    a = scenario.area
    nodes = (a.width_m / a.resolution_m + 1) * (a.height_m / a.resolution_m + 1)
    if nodes > limits.grid_nodes:
        raise InvalidInput(
            f"scenario: area.resolution_m: {a.resolution_m:g} m gives {nodes:.0f} grid nodes, "
            f"over this service's limit of {limits.grid_nodes}"
        )
    t = scenario.terrain
    if isinstance(t, SyntheticTerrainSpec) and t.hills > limits.hills:
        raise InvalidInput(
            f"scenario: terrain.hills: {t.hills} hills, over this service's limit of {limits.hills}"
        )


def confine_terrain(scenario: Scenario, srtm_dir: Path | None) -> Scenario:
    """``scenario`` with its SRTM ``terrain.directory`` (a relative folder, ``.`` for the
    folder itself) made the absolute folder under ``srtm_dir`` it names; other terrain as it
    is. Raise :class:`InvalidInput` naming the field when the service keeps no SRTM folder, or
    the directory is absolute, climbs out of it (``..``, a link) or is not a folder there."""
    t = scenario.terrain
    if not isinstance(t, SrtmTerrainSpec):
        return scenario
    field = "scenario: terrain.directory"
    if srtm_dir is None:
        raise InvalidInput(
            f"{field}: this service reads no SRTM terrain (TCGCS_SRTM_DIR is not set)"
        )
    name = PurePosixPath(t.directory)
    if name.is_absolute() or ".." in name.parts or "\\" in t.directory:
        raise InvalidInput(
            f"{field}: {t.directory!r} must be a folder under the service's SRTM folder, "
            "relative to it (no absolute path, no '..')"
        )
    root = srtm_dir.resolve()
    folder = (root / name).resolve()
    if not folder.is_relative_to(root) or not folder.is_dir():
        raise InvalidInput(f"{field}: {t.directory!r} is not a folder of the service's SRTM folder")
    return scenario.model_copy(
        update={"terrain": SrtmTerrainSpec(kind="srtm", directory=str(folder))}
    )
