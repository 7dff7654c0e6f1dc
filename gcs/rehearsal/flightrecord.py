"""The flight record (``tcgcs-flight/1``) as the rehearsal report reads it, and its scenario.

:func:`parse_flight` validates a record into a :class:`Flight`: a malformed record raises one
:class:`~gcs.errors.GcsError` naming the field (``vehicles[0].track: missing``).
:func:`flight_world` finds the scenario the record was flown in and builds its world.

Fields the report can do without are optional: ``arrival_utc_s``/``error_s`` (``null`` or
missing: not arrived; ``error_s`` defaults to arrival minus target), ``takeoff_utc_s``,
``landed_utc_s`` (landing slots: down and disarmed),
``system_id``, the speed limits, ``planned_paths``, ``loiters``, ``commanded``,
``planned_speeds``, ``events``, ``adjustments``, ``threats_appeared`` and the team summary
fields (separation, wall time, wind, loss, arrival source).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.errors import GcsError
from planner.errors import PlannerError
from planner.geo import FloatArray
from planner.plan import World, build_world
from planner.scenario import Scenario, load_scenario, parse_scenario

__all__ = [
    "FLIGHT_FORMAT",
    "Flight",
    "PlannedPath",
    "RecordedEvent",
    "RecordedLoiter",
    "RecordedVehicle",
    "flight_world",
    "parse_flight",
]

FLIGHT_FORMAT = "tcgcs-flight/1"


@dataclass(frozen=True)
class PlannedPath:
    """A route as planned, in local metres, and when (UTC s) it was planned."""

    label: str
    utc_s: float | None
    en_m: FloatArray  # (n, 2) local metres


@dataclass(frozen=True)
class RecordedLoiter:
    """A loiter circle: centre and radius in local metres, turns, buffer, when (UTC s)."""

    east_m: float
    north_m: float
    radius_m: float
    turns: float
    buffer_id: str | None
    utc_s: float | None


@dataclass(frozen=True)
class RecordedVehicle:
    """One vehicle's part of the record: its target, arrival, track, commands and plans."""

    id: str
    system_id: int | None
    speed_min_m_s: float | None
    speed_max_m_s: float | None
    target_utc_s: float
    arrival_utc_s: float | None
    error_s: float | None
    takeoff_utc_s: float | None
    planned_paths: tuple[PlannedPath, ...]
    loiters: tuple[RecordedLoiter, ...]
    track: FloatArray  # (n, 6): utc_s, east_m, north_m, alt_m, airspeed, groundspeed; by time
    commanded: tuple[tuple[float, float, str], ...]
    planned_speeds: tuple[tuple[float, float, float, str], ...]
    landed_utc_s: float | None = None


@dataclass(frozen=True)
class RecordedEvent:
    """An event or an adjustment (``kind`` is then its strategy), at a UTC time."""

    utc_s: float
    vehicle: str | None
    kind: str
    strategy: str | None
    value: float | None
    reason: str


@dataclass(frozen=True)
class Flight:
    """The record, validated: times are UTC s (:meth:`t` gives mission time)."""

    start_utc_s: float
    required_utc_s: float | None
    """The team time; None for arrival windows (each vehicle keeps a slot of its own)."""
    separation_m: float | None
    min_separation_m: float | None
    min_separation_pair: tuple[str, ...]
    min_separation_utc_s: float | None
    wall_s: float | None
    speedup: float | None
    wind_speed_m_s: float | None
    wind_from_deg: float | None
    loss: float | None
    arrival_source: str | None
    vehicles: tuple[RecordedVehicle, ...]
    events: tuple[RecordedEvent, ...]
    adjustments: tuple[RecordedEvent, ...]
    threats_appeared: tuple[tuple[str, float], ...]

    def t(self, utc_s: float) -> float:
        """Mission time (s) of a UTC time."""
        return utc_s - self.start_utc_s


def _bad(where: str, problem: str) -> GcsError:
    return GcsError(f"flight record: {where}: {problem}")


def _kind(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _at(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _get(obj: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise _bad(_at(where, key), "missing")
    return obj[key]


def _mapping(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise _bad(where or "record", f"expected an object, got {_kind(value)}")
    return value


def _list(value: Any, where: str) -> Sequence[Any]:
    if not isinstance(value, list | tuple):
        raise _bad(where, f"expected a list, got {_kind(value)}")
    return value


def _opt_list(obj: Mapping[str, Any], key: str, where: str) -> Sequence[Any]:
    value = obj.get(key)
    return () if value is None else _list(value, _at(where, key))


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _bad(where, f"expected a number, got {_kind(value)}")
    if not math.isfinite(value):
        raise _bad(where, f"expected a finite number, got {value}")
    return float(value)


def _opt_number(obj: Mapping[str, Any], key: str, where: str) -> float | None:
    value = obj.get(key)
    return None if value is None else _number(value, _at(where, key))


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise _bad(where, f"expected a string, got {_kind(value)}")
    return value


def _opt_text(obj: Mapping[str, Any], key: str, where: str) -> str | None:
    value = obj.get(key)
    return None if value is None else _text(value, _at(where, key))


_NUMBER_TYPES = {int, float}


def _rows(value: Any, where: str, width: int, nullable_from: int) -> FloatArray:
    """A list of number rows as an (n, width) array; columns from ``nullable_from`` may be
    null (NaN). Extra columns are ignored."""
    rows = _list(value, where)
    allowed = _NUMBER_TYPES | {type(None)}
    for i, row in enumerate(rows):
        if not isinstance(row, list | tuple) or len(row) < width:
            raise _bad(f"{where}[{i}]", f"expected a list of {width} numbers, got {row!r:.60}")
        if not {type(x) for x in row[:width]} <= allowed:
            bad = next(x for x in row[:width] if type(x) not in allowed)
            raise _bad(f"{where}[{i}]", f"expected numbers, got {_kind(bad)}")
    if not rows:
        return np.zeros((0, width), dtype=np.float64)
    arr = np.array([row[:width] for row in rows], dtype=np.float64)
    bad_rows = np.flatnonzero(~np.isfinite(arr[:, :nullable_from]).all(axis=1))
    if bad_rows.size:
        i = int(bad_rows[0])
        raise _bad(f"{where}[{i}]", f"the first {nullable_from} values must be finite numbers")
    return arr


def _planned_path(raw: Any, where: str) -> PlannedPath:
    p = _mapping(raw, where)
    en = _rows(_get(p, "en_m", where), _at(where, "en_m"), 2, 2)
    label = _opt_text(p, "label", where) or ""
    return PlannedPath(label, _opt_number(p, "utc_s", where), en)


def _loiter(raw: Any, where: str) -> RecordedLoiter:
    lo = _mapping(raw, where)
    turns = _opt_number(lo, "turns", where)
    return RecordedLoiter(
        _number(_get(lo, "centre_east_m", where), _at(where, "centre_east_m")),
        _number(_get(lo, "centre_north_m", where), _at(where, "centre_north_m")),
        _number(_get(lo, "radius_m", where), _at(where, "radius_m")),
        0.0 if turns is None else turns,
        _opt_text(lo, "buffer_id", where),
        _opt_number(lo, "utc_s", where),
    )


def _commanded(raw: Sequence[Any], where: str) -> tuple[tuple[float, float, str], ...]:
    out: list[tuple[float, float, str]] = []
    for i, row in enumerate(raw):
        w = f"{where}[{i}]"
        if not isinstance(row, list | tuple) or len(row) < 2:
            raise _bad(w, f"expected [utc_s, airspeed_m_s, source], got {row!r:.60}")
        source = _text(row[2], f"{w}[2]") if len(row) > 2 and row[2] is not None else ""
        out.append((_number(row[0], f"{w}[0]"), _number(row[1], f"{w}[1]"), source))
    out.sort(key=lambda r: r[0])
    return tuple(out)


def _spans(raw: Sequence[Any], where: str) -> tuple[tuple[float, float, float, str], ...]:
    out: list[tuple[float, float, float, str]] = []
    for i, row in enumerate(raw):
        w = f"{where}[{i}]"
        if not isinstance(row, list | tuple) or len(row) < 3:
            raise _bad(w, f"expected [t0_utc_s, t1_utc_s, speed_m_s, kind], got {row!r:.60}")
        kind = _text(row[3], f"{w}[3]") if len(row) > 3 and row[3] is not None else "leg"
        nums = [_number(row[j], f"{w}[{j}]") for j in range(3)]
        out.append((nums[0], nums[1], nums[2], kind))
    return tuple(out)


def _vehicle(raw: Any, where: str) -> RecordedVehicle:
    v = _mapping(raw, where)
    vid = _text(_get(v, "id", where), _at(where, "id"))
    target = _number(_get(v, "target_arrival_utc_s", where), _at(where, "target_arrival_utc_s"))
    track = _rows(_get(v, "track", where), _at(where, "track"), 6, 3)
    track = track[np.argsort(track[:, 0], kind="stable")]
    arrival = _opt_number(v, "arrival_utc_s", where)
    error = _opt_number(v, "error_s", where)
    if arrival is None:
        error = None
    elif error is None:
        error = arrival - target
    sysid = v.get("system_id")
    if sysid is not None and (isinstance(sysid, bool) or not isinstance(sysid, int)):
        raise _bad(_at(where, "system_id"), f"expected an integer, got {_kind(sysid)}")
    paths = _opt_list(v, "planned_paths", where)
    loiters = _opt_list(v, "loiters", where)
    return RecordedVehicle(
        id=vid,
        system_id=sysid,
        speed_min_m_s=_opt_number(v, "speed_min_m_s", where),
        speed_max_m_s=_opt_number(v, "speed_max_m_s", where),
        target_utc_s=target,
        arrival_utc_s=arrival,
        error_s=error,
        takeoff_utc_s=_opt_number(v, "takeoff_utc_s", where),
        landed_utc_s=_opt_number(v, "landed_utc_s", where),
        planned_paths=tuple(
            _planned_path(p, f"{where}.planned_paths[{i}]") for i, p in enumerate(paths)
        ),
        loiters=tuple(_loiter(lo, f"{where}.loiters[{i}]") for i, lo in enumerate(loiters)),
        track=track,
        commanded=_commanded(_opt_list(v, "commanded", where), _at(where, "commanded")),
        planned_speeds=_spans(_opt_list(v, "planned_speeds", where), _at(where, "planned_speeds")),
    )


def _event(raw: Any, where: str, start_utc_s: float, kind_key: str) -> RecordedEvent:
    e = _mapping(raw, where)
    if "utc_s" not in e and e.get("t_s") is not None:
        utc = start_utc_s + _number(e["t_s"], _at(where, "t_s"))
    else:
        utc = _number(_get(e, "utc_s", where), _at(where, "utc_s"))
    kind = _text(_get(e, kind_key, where), _at(where, kind_key))
    return RecordedEvent(
        utc_s=utc,
        vehicle=_opt_text(e, "vehicle", where),
        kind=kind,
        strategy=_opt_text(e, "strategy", where),
        value=_opt_number(e, "value", where),
        reason=_opt_text(e, "reason", where) or "",
    )


def parse_flight(record: Mapping[str, Any]) -> Flight:
    """The record validated; one :class:`GcsError` naming the first bad or missing field."""
    rec = _mapping(record, "")
    fmt = _get(rec, "format", "")
    if fmt != FLIGHT_FORMAT:
        raise _bad("format", f"expected {FLIGHT_FORMAT!r}, got {fmt!r}")
    start = _number(_get(rec, "start_utc_s", ""), "start_utc_s")
    # Present always; null for arrival windows, which have no team time.
    _get(rec, "required_arrival_utc_s", "")
    required = _opt_number(rec, "required_arrival_utc_s", "")
    raw_vehicles = _list(_get(rec, "vehicles", ""), "vehicles")
    if not raw_vehicles:
        raise _bad("vehicles", "empty: the record has no vehicle")
    vehicles = tuple(_vehicle(v, f"vehicles[{i}]") for i, v in enumerate(raw_vehicles))
    seen: set[str] = set()
    for i, v in enumerate(vehicles):
        if v.id in seen:
            raise _bad(f"vehicles[{i}].id", f"duplicate vehicle {v.id!r}")
        seen.add(v.id)
    pair = _opt_list(rec, "min_separation_pair", "")
    wind = rec.get("wind")
    wind_map = _mapping(wind, "wind") if wind is not None else {}
    appeared: list[tuple[str, float]] = []
    for i, raw in enumerate(_opt_list(rec, "threats_appeared", "")):
        w = f"threats_appeared[{i}]"
        a = _mapping(raw, w)
        appeared.append(
            (_text(_get(a, "id", w), f"{w}.id"), _number(_get(a, "utc_s", w), f"{w}.utc_s"))
        )
    events = [
        _event(e, f"events[{i}]", start, "kind") for i, e in enumerate(_opt_list(rec, "events", ""))
    ]
    adjustments = [
        _event(a, f"adjustments[{i}]", start, "strategy")
        for i, a in enumerate(_opt_list(rec, "adjustments", ""))
    ]
    return Flight(
        start_utc_s=start,
        required_utc_s=required,
        separation_m=_opt_number(rec, "separation_m", ""),
        min_separation_m=_opt_number(rec, "min_separation_m", ""),
        min_separation_pair=tuple(
            _text(p, f"min_separation_pair[{i}]") for i, p in enumerate(pair)
        ),
        min_separation_utc_s=_opt_number(rec, "min_separation_utc_s", ""),
        wall_s=_opt_number(rec, "wall_s", ""),
        speedup=_opt_number(rec, "speedup", ""),
        wind_speed_m_s=_opt_number(wind_map, "speed_m_s", "wind"),
        wind_from_deg=_opt_number(wind_map, "from_deg", "wind"),
        loss=_opt_number(rec, "loss", ""),
        arrival_source=_opt_text(rec, "arrival_source", ""),
        vehicles=vehicles,
        events=tuple(sorted(events, key=lambda e: e.utc_s)),
        adjustments=tuple(sorted(adjustments, key=lambda e: e.utc_s)),
        threats_appeared=tuple(appeared),
    )


# --- its scenario -----------------------------------------------------------------------------


def _scenario_file(record: Mapping[str, Any], out_dir: Path) -> Path:
    name = _text(_get(record, "scenario_file", ""), "scenario_file")
    path = Path(name)
    candidates = [path] if path.is_absolute() else [path, out_dir.parent / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    looked = ", ".join(str(c) for c in candidates)
    raise _bad("scenario_file", f"{name!r} not found (looked for {looked})")


def _world(path: Path) -> tuple[Scenario, World]:
    try:
        scenario = load_scenario(path)
        return scenario, build_world(scenario)
    except PlannerError as err:
        raise GcsError(f"scenario: {err}") from None


def _recorded_world(record: Mapping[str, Any]) -> tuple[Scenario, World]:
    """The scenario a record carries, with the operator's threats, and its world."""
    extra = _opt_list(record, "operator_threats", "")
    try:
        scenario = parse_scenario(record["scenario"], "scenario")
        if extra:
            threats = [*record["scenario"].get("threats", []), *extra]
            scenario = parse_scenario({**record["scenario"], "threats": threats}, "scenario")
        return scenario, build_world(scenario)
    except PlannerError as err:
        raise GcsError(f"flight record: {err}") from None


def flight_world(
    record: Mapping[str, Any], out_dir: Path, scenario_path: Path | None = None
) -> tuple[Scenario, World]:
    """The scenario a record was flown in, and its world.

    ``scenario_path`` when given, else the one the record carries (``scenario``, with the
    threats the operator added: ``operator_threats``), else, for a record without it, the
    record's ``scenario_file``: as is (absolute, or relative to the working directory), else
    relative to ``out_dir``'s parent.
    """
    if scenario_path is None and "scenario" in record:
        return _recorded_world(record)
    path = scenario_path if scenario_path is not None else _scenario_file(record, out_dir)
    return _world(path)
