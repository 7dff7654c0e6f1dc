"""The rehearsal report of a flight record (``tcgcs-flight/1``): figures and arrival tables.

:func:`write_report` recreates the reference paper's figures from what was flown:

* ``paths.png``: terrain, threats (pop-ups dashed, with their appearance time), buffers, the
  planned paths (initial dashed, replans solid), the flown tracks, loiter circles, starts, goals
  and goal crossings (Fig. 10a);
* ``speeds.png``: per vehicle, commanded airspeed, flown air- and groundspeed, the planned spans
  and the speed limits, with launch, pop-up and arrival markers (Figs. 7, 9 and 10c);
* ``timeline.png``: the events per vehicle on a time axis, with the required arrival;
* ``arrivals.md`` and ``index.html``: the arrival table, the events and the figures.

All times are shown as mission seconds, ``utc_s - start_utc_s``; maps are in km of the
scenario's local frame. The record is validated before anything is drawn: a malformed record
raises one :class:`~gcs.errors.GcsError` naming the field (``vehicles[0].track: missing``).

Fields the report can do without are optional: ``arrival_utc_s``/``error_s`` (``null`` or
missing: not arrived; ``error_s`` defaults to arrival minus target), ``takeoff_utc_s``,
``system_id``, the speed limits, ``planned_paths``, ``loiters``, ``commanded``,
``planned_speeds``, ``events``, ``adjustments``, ``threats_appeared`` and the team summary
fields (separation, wall time, wind, loss, arrival source).
"""

from __future__ import annotations

import html
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
from planner.plot import draw_world
from planner.scenario import Scenario, load_scenario, parse_scenario

__all__ = ["FLIGHT_FORMAT", "arrival_table", "write_report"]

FLIGHT_FORMAT = "tcgcs-flight/1"
KM = 1000.0
FIGURES = ("paths.png", "speeds.png", "timeline.png")


# --- the record, validated --------------------------------------------------------------------


@dataclass(frozen=True)
class _PlannedPath:
    label: str
    utc_s: float | None
    en_m: FloatArray  # (n, 2) local metres


@dataclass(frozen=True)
class _Loiter:
    east_m: float
    north_m: float
    radius_m: float
    turns: float
    buffer_id: str | None
    utc_s: float | None


@dataclass(frozen=True)
class _Vehicle:
    id: str
    system_id: int | None
    speed_min_m_s: float | None
    speed_max_m_s: float | None
    target_utc_s: float
    arrival_utc_s: float | None
    error_s: float | None
    takeoff_utc_s: float | None
    planned_paths: tuple[_PlannedPath, ...]
    loiters: tuple[_Loiter, ...]
    track: FloatArray  # (n, 6): utc_s, east_m, north_m, alt_m, airspeed, groundspeed; by time
    commanded: tuple[tuple[float, float, str], ...]
    planned_speeds: tuple[tuple[float, float, float, str], ...]


@dataclass(frozen=True)
class _Event:
    utc_s: float
    vehicle: str | None
    kind: str
    strategy: str | None
    value: float | None
    reason: str


@dataclass(frozen=True)
class _Flight:
    start_utc_s: float
    required_utc_s: float
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
    vehicles: tuple[_Vehicle, ...]
    events: tuple[_Event, ...]
    adjustments: tuple[_Event, ...]
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


def _planned_path(raw: Any, where: str) -> _PlannedPath:
    p = _mapping(raw, where)
    en = _rows(_get(p, "en_m", where), _at(where, "en_m"), 2, 2)
    label = _opt_text(p, "label", where) or ""
    return _PlannedPath(label, _opt_number(p, "utc_s", where), en)


def _loiter(raw: Any, where: str) -> _Loiter:
    lo = _mapping(raw, where)
    turns = _opt_number(lo, "turns", where)
    return _Loiter(
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


def _vehicle(raw: Any, where: str) -> _Vehicle:
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
    return _Vehicle(
        id=vid,
        system_id=sysid,
        speed_min_m_s=_opt_number(v, "speed_min_m_s", where),
        speed_max_m_s=_opt_number(v, "speed_max_m_s", where),
        target_utc_s=target,
        arrival_utc_s=arrival,
        error_s=error,
        takeoff_utc_s=_opt_number(v, "takeoff_utc_s", where),
        planned_paths=tuple(
            _planned_path(p, f"{where}.planned_paths[{i}]") for i, p in enumerate(paths)
        ),
        loiters=tuple(_loiter(lo, f"{where}.loiters[{i}]") for i, lo in enumerate(loiters)),
        track=track,
        commanded=_commanded(_opt_list(v, "commanded", where), _at(where, "commanded")),
        planned_speeds=_spans(_opt_list(v, "planned_speeds", where), _at(where, "planned_speeds")),
    )


def _event(raw: Any, where: str, start_utc_s: float, kind_key: str) -> _Event:
    e = _mapping(raw, where)
    if "utc_s" not in e and e.get("t_s") is not None:
        utc = start_utc_s + _number(e["t_s"], _at(where, "t_s"))
    else:
        utc = _number(_get(e, "utc_s", where), _at(where, "utc_s"))
    kind = _text(_get(e, kind_key, where), _at(where, kind_key))
    return _Event(
        utc_s=utc,
        vehicle=_opt_text(e, "vehicle", where),
        kind=kind,
        strategy=_opt_text(e, "strategy", where),
        value=_opt_number(e, "value", where),
        reason=_opt_text(e, "reason", where) or "",
    )


def _parse(record: Mapping[str, Any]) -> _Flight:
    rec = _mapping(record, "")
    fmt = _get(rec, "format", "")
    if fmt != FLIGHT_FORMAT:
        raise _bad("format", f"expected {FLIGHT_FORMAT!r}, got {fmt!r}")
    start = _number(_get(rec, "start_utc_s", ""), "start_utc_s")
    required = _number(_get(rec, "required_arrival_utc_s", ""), "required_arrival_utc_s")
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
    return _Flight(
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


# --- tables -----------------------------------------------------------------------------------

_HEADER = (
    "vehicle",
    "target_s",
    "arrival_s",
    "error_s",
    "takeoff_s",
    "strategies",
    "turns",
    "cmd_min/max_m_s",
)
_LEFT = {0, 5}  # text columns, left-aligned in the fixed-width table


def _fmt(x: float | None, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _strategies(flight: _Flight, vehicle_id: str) -> list[str]:
    """Strategies used by a vehicle, in order of first use (adjustments and events)."""
    found = sorted(
        (e.utc_s, e.strategy)
        for e in (*flight.adjustments, *flight.events)
        if e.vehicle == vehicle_id and e.strategy
    )
    out: list[str] = []
    for _, s in found:
        if s is not None and s not in out:
            out.append(s)
    return out


def _arrival_rows(flight: _Flight) -> list[list[str]]:
    rows: list[list[str]] = []
    for v in flight.vehicles:
        turns = sum(lo.turns for lo in v.loiters)
        speeds = [c[1] for c in v.commanded]
        rows.append(
            [
                v.id,
                _fmt(flight.t(v.target_utc_s)),
                "not arrived" if v.arrival_utc_s is None else _fmt(flight.t(v.arrival_utc_s)),
                "-" if v.error_s is None else f"{v.error_s:+.2f}",
                "-" if v.takeoff_utc_s is None else _fmt(flight.t(v.takeoff_utc_s)),
                ",".join(_strategies(flight, v.id)) or "-",
                f"{turns:g}",
                f"{min(speeds):.1f}/{max(speeds):.1f}" if speeds else "-",
            ]
        )
    return rows


def _summary(flight: _Flight) -> str:
    parts = [f"required arrival {flight.t(flight.required_utc_s):.2f} s"]
    if flight.min_separation_m is not None:
        sep = f"min separation {flight.min_separation_m:.1f} m"
        detail = []
        if flight.min_separation_pair:
            detail.append("-".join(flight.min_separation_pair))
        if flight.min_separation_utc_s is not None:
            detail.append(f"at {flight.t(flight.min_separation_utc_s):.2f} s")
        parts.append(sep + (f" ({' '.join(detail)})" if detail else ""))
    else:
        parts.append("min separation -")
    parts.append(f"d_s {_fmt(flight.separation_m, 1)} m")
    wall = f"wall time {_fmt(flight.wall_s, 1)} s"
    if flight.speedup is not None:
        wall += f" (x{flight.speedup:g})"
    parts.append(wall)
    if flight.arrival_source:
        parts.append(f"arrivals from {flight.arrival_source}")
    return "; ".join(parts)


def _conditions(flight: _Flight) -> str:
    parts = []
    if flight.wind_speed_m_s is not None:
        frm = "" if flight.wind_from_deg is None else f" from {flight.wind_from_deg:03.0f} deg"
        parts.append(f"wind {flight.wind_speed_m_s:g} m/s{frm}")
    if flight.loss is not None:
        parts.append(f"link loss {flight.loss:g}")
    return "; ".join(parts)


def _fixed_width(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in (header, *rows)) for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        out = [
            c.ljust(w) if i in _LEFT else c.rjust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        ]
        return "  ".join(out).rstrip()

    return [line(header), "  ".join("-" * w for w in widths), *(line(r) for r in rows)]


def _arrival_table(flight: _Flight) -> str:
    lines = _fixed_width(_HEADER, _arrival_rows(flight))
    return "\n".join([*lines, _summary(flight)]) + "\n"


def arrival_table(flight: Mapping[str, Any]) -> str:
    """The arrival table as fixed-width text, one row per vehicle, then a summary line.

    Columns: vehicle, target and arrival (mission s), error_s (+late/-early), takeoff (mission
    s), strategies used, loiter turns, min/max airspeed commanded; the last line gives the
    required arrival, the minimum separation against ``d_s`` and the wall time.
    """
    return _arrival_table(_parse(flight))


def _event_rows(flight: _Flight) -> list[list[str]]:
    return [
        [
            f"{flight.t(e.utc_s):.2f}",
            e.vehicle or "-",
            e.kind,
            e.strategy or "-",
            "-" if e.value is None else f"{e.value:g}",
            e.reason,
        ]
        for e in flight.events
    ]


def _adjustment_rows(flight: _Flight) -> list[list[str]]:
    return [
        [
            f"{flight.t(a.utc_s):.2f}",
            a.vehicle or "-",
            a.kind,
            "-" if a.value is None else f"{a.value:g}",
            a.reason,
        ]
        for a in flight.adjustments
    ]


_EVENT_HEADER = ("t_s", "vehicle", "kind", "strategy", "value", "reason")
_ADJUSTMENT_HEADER = ("t_s", "vehicle", "strategy", "value", "reason")


def _md_cell(text: str) -> str:
    text = text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
    return lines


def _markdown(flight: _Flight, title: str) -> str:
    lines = [f"# {title}", "", "## Arrivals", ""]
    lines += _md_table(_HEADER, _arrival_rows(flight))
    lines += ["", _md_cell(_summary(flight))]
    conditions = _conditions(flight)
    if conditions:
        lines += ["", _md_cell(conditions)]
    if flight.adjustments:
        lines += ["", "## Adjustments", ""]
        lines += _md_table(_ADJUSTMENT_HEADER, _adjustment_rows(flight))
    lines += ["", "## Events", ""]
    lines += _md_table(_EVENT_HEADER, _event_rows(flight)) if flight.events else ["(none)"]
    lines += ["", "## Figures", ""]
    lines += [f"![{name[:-4]}]({name})" for name in FIGURES]
    return "\n".join(lines) + "\n"


def _html_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    e = html.escape
    lines = ["<table>", "<tr>" + "".join(f"<th>{e(h)}</th>" for h in header) + "</tr>"]
    lines += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>" for r in rows]
    return [*lines, "</table>"]


def _html(flight: _Flight, title: str) -> str:
    e = html.escape
    lines = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>{e(title)}</title>",
        "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
        "th,td{border:1px solid #bbb;padding:2px 8px;text-align:right}"
        "td:first-child,th:first-child{text-align:left}img{max-width:100%}</style>",
        "</head>",
        "<body>",
        f"<h1>{e(title)}</h1>",
        "<h2>Arrivals</h2>",
        *_html_table(_HEADER, _arrival_rows(flight)),
        f"<p>{e(_summary(flight))}</p>",
    ]
    conditions = _conditions(flight)
    if conditions:
        lines.append(f"<p>{e(conditions)}</p>")
    lines.append("<h2>Figures</h2>")
    lines += [f'<p><img src="{e(name)}" alt="{e(name[:-4])}"></p>' for name in FIGURES]
    if flight.adjustments:
        lines.append("<h2>Adjustments</h2>")
        lines += _html_table(_ADJUSTMENT_HEADER, _adjustment_rows(flight))
    lines.append("<h2>Events</h2>")
    lines += _html_table(_EVENT_HEADER, _event_rows(flight)) if flight.events else ["<p>none</p>"]
    lines += ["</body>", "</html>"]
    return "\n".join(lines) + "\n"


# --- figures ----------------------------------------------------------------------------------


def _colours() -> list[str]:
    import matplotlib.pyplot as plt

    colours: list[str] = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return colours


def _save(fig: Any, out: Path) -> None:
    import matplotlib.pyplot as plt

    try:
        fig.savefig(out, dpi=110)
    except OSError as err:
        raise GcsError(f"{out}: cannot write figure ({err.strerror})") from None
    finally:
        plt.close(fig)


def _crossing(v: _Vehicle) -> tuple[float, float] | None:
    """Where the flown track was at the arrival time (the goal crossing)."""
    if v.arrival_utc_s is None or len(v.track) == 0:
        return None
    t = v.track[:, 0]
    return (
        float(np.interp(v.arrival_utc_s, t, v.track[:, 1])),
        float(np.interp(v.arrival_utc_s, t, v.track[:, 2])),
    )


def _plot_paths(flight: _Flight, world: World, title: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    scenario = world.scenario
    fig, ax = plt.subplots(figsize=(9, 8))
    appeared = {tid: flight.t(utc) for tid, utc in flight.threats_appeared}
    extent = draw_world(fig, ax, world, appeared)
    known = {v.id: v for v in scenario.vehicles}
    colours = _colours()
    for k, v in enumerate(flight.vehicles):
        c = colours[k % len(colours)]
        for i, p in enumerate(v.planned_paths):
            if len(p.en_m):
                xy = p.en_m / KM
                initial = i == 0
                ax.plot(xy[:, 0], xy[:, 1], "--" if initial else "-", color=c, lw=0.9, alpha=0.8)
        err = "not arrived" if v.error_s is None else f"{v.error_s:+.2f} s"
        if len(v.track):
            ax.plot(
                v.track[:, 1] / KM,
                v.track[:, 2] / KM,
                "-",
                color=c,
                lw=2.0,
                label=f"{v.id} ({err})",
            )
        else:
            ax.plot([], [], "-", color=c, lw=2.0, label=f"{v.id} ({err}, no track)")
        for lo in v.loiters:
            ax.plot(lo.east_m / KM, lo.north_m / KM, "o", color=c, ms=7, mfc="none", mew=1.5)
            ax.add_patch(
                Circle(
                    (lo.east_m / KM, lo.north_m / KM),
                    lo.radius_m / KM,
                    fill=False,
                    color=c,
                    lw=1.4,
                )
            )
            ax.text(
                (lo.east_m + lo.radius_m) / KM,
                lo.north_m / KM,
                f" {lo.turns:g} turn(s)",
                color=c,
                fontsize=7,
                va="center",
            )
        if v.id in known:
            se, sn = known[v.id].start.local(world.frame)
            ge, gn = known[v.id].goal.local(world.frame)
            ax.plot(se / KM, sn / KM, "^", color=c, ms=9, mec="black")
            ax.plot(ge / KM, gn / KM, "*", color=c, ms=12, mec="black")
        crossing = _crossing(v)
        if crossing is not None:
            ax.plot(crossing[0] / KM, crossing[1] / KM, "X", color=c, ms=8, mec="black")
    handles, _ = ax.get_legend_handles_labels()
    grey = "dimgray"
    handles += [
        Line2D([], [], color=grey, ls="--", lw=0.9, label="initial plan"),
        Line2D([], [], color=grey, ls="-", lw=0.9, label="replanned"),
        Line2D([], [], color=grey, ls="", marker="^", mec="black", label="start"),
        Line2D([], [], color=grey, ls="", marker="*", ms=10, mec="black", label="goal"),
        Line2D([], [], color=grey, ls="", marker="X", mec="black", label="goal crossing"),
        Line2D([], [], color=grey, ls="", marker="o", mfc="none", label="loiter"),
    ]
    ax.legend(handles=handles, loc="lower right", fontsize=7)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    ax.set_title(f"{title}: planned and flown paths")
    ax.set_aspect("equal")
    fig.tight_layout()
    _save(fig, out)


def _time_end(flight: _Flight) -> float:
    """The last mission time anything in the record refers to."""
    ends = [flight.required_utc_s]
    for v in flight.vehicles:
        ends.append(v.target_utc_s)
        if v.arrival_utc_s is not None:
            ends.append(v.arrival_utc_s)
        if len(v.track):
            ends.append(float(v.track[-1, 0]))
        ends += [s[1] for s in v.planned_speeds]
        ends += [c[0] for c in v.commanded]
    return flight.t(max(ends))


def _plot_speeds(flight: _Flight, title: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(flight.vehicles)
    fig, axes = plt.subplots(n, 1, figsize=(10.5, 2.6 * n + 0.6), sharex=True, squeeze=False)
    colours = _colours()
    end = _time_end(flight)
    popups = [(tid, flight.t(utc)) for tid, utc in flight.threats_appeared]
    for k, (ax, v) in enumerate(zip(axes[:, 0], flight.vehicles, strict=True)):
        c = colours[k % len(colours)]
        first = True
        for t0, t1, speed, kind in v.planned_speeds:
            x0, x1 = flight.t(t0), flight.t(t1)
            ax.plot(
                [x0, x1],
                [speed, speed],
                "-",
                color=c,
                lw=0.8,
                alpha=0.6,
                label="planned" if first else None,
            )
            if kind == "loiter":
                ax.axvspan(x0, x1, color=c, alpha=0.12)
            first = False
        if v.commanded:
            xs = [flight.t(cmd[0]) for cmd in v.commanded] + [end]
            ys = [cmd[1] for cmd in v.commanded]
            ax.step(xs, [*ys, ys[-1]], where="post", color=c, lw=2.0, label="commanded")
        if len(v.track):
            tx = v.track[:, 0] - flight.start_utc_s
            ax.plot(tx, v.track[:, 4], "-", color="black", lw=0.8, label="airspeed (flown)")
            ax.plot(
                tx, v.track[:, 5], "-", color="gray", lw=0.8, alpha=0.7, label="groundspeed (flown)"
            )
        for lim in (v.speed_min_m_s, v.speed_max_m_s):
            if lim is not None:
                ax.axhline(lim, color=c, lw=0.8, ls=":")
        if v.takeoff_utc_s is not None:
            ax.axvline(flight.t(v.takeoff_utc_s), color="green", ls="--", lw=1.0, label="launch")
        for i, (tid, t) in enumerate(popups):
            ax.axvline(t, color="red", ls=":", lw=1.2, label="pop-up" if i == 0 else None)
            ax.annotate(
                tid,
                (t, 1.0),
                xycoords=("data", "axes fraction"),
                fontsize=6,
                color="red",
                ha="left",
                va="top",
            )
        ax.axvline(flight.t(v.target_utc_s), color="gray", ls="-.", lw=1.0, label="target")
        if v.arrival_utc_s is not None:
            ax.axvline(flight.t(v.arrival_utc_s), color="black", lw=1.0, label="arrival")
        err = "not arrived" if v.error_s is None else f"error {v.error_s:+.2f} s"
        ax.set_title(f"{v.id}: {err}", fontsize=9)
        ax.set_ylabel("speed (m/s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    axes[-1, 0].set_xlabel("mission time (s)")
    fig.suptitle(f"{title}: commanded and flown speeds", fontsize=10)
    fig.tight_layout()
    _save(fig, out)


_MARKERS: dict[str, tuple[str, str]] = {
    "takeoff_delay": ("s", "tab:blue"),
    "speed": ("^", "tab:orange"),
    "loiter": ("o", "tab:green"),
    "launch": ("P", "black"),
    "arrival": ("*", "gold"),
    "late": ("v", "red"),
    "popup": ("X", "red"),
    "replan": ("D", "tab:purple"),
    "link": ("x", "gray"),
    "upload": ("|", "gray"),
}


def _plot_timeline(flight: _Flight, title: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [v.id for v in flight.vehicles]
    extra = sorted({e.vehicle for e in flight.events if e.vehicle and e.vehicle not in rows})
    rows += [*extra, "team"]
    y = {name: i for i, name in enumerate(rows)}
    fig, ax = plt.subplots(figsize=(10, 1.0 + 0.55 * len(rows)))
    marks = list(flight.events)
    if not any(e.strategy for e in marks):
        marks += flight.adjustments  # no strategy in the events: show the adjustments
    seen: set[str] = set()
    for e in marks:
        key = e.strategy or e.kind
        marker, colour = _MARKERS.get(key, (".", "gray"))
        ax.plot(
            flight.t(e.utc_s),
            y[e.vehicle or "team"],
            marker,
            color=colour,
            ms=8,
            mec="black",
            mew=0.5,
            ls="",
            label=None if key in seen else key,
        )
        seen.add(key)
    for v in flight.vehicles:
        ax.plot(flight.t(v.target_utc_s), y[v.id], "|", color="gray", ms=16, mew=1.5)
    ax.axvline(
        flight.t(flight.required_utc_s), color="black", ls="--", lw=1.0, label="required arrival"
    )
    ax.set_yticks(range(len(rows)), rows)
    ax.set_ylim(-0.7, len(rows) - 0.3)
    lo = min(0.0, *(flight.t(e.utc_s) for e in marks))
    hi = _time_end(flight)
    pad = 0.02 * (hi - lo) + 1.0
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_xlabel("mission time (s)")
    ax.set_title(f"{title}: events (| = vehicle's target arrival)", fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    _save(fig, out)


# --- the report -------------------------------------------------------------------------------


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


def _write_text(path: Path, text: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as err:
        raise GcsError(f"{path}: cannot write ({err.strerror})") from None


def write_report(
    flight: Mapping[str, Any], out_dir: Path, *, scenario_path: Path | None = None
) -> list[Path]:
    """Write paths.png, speeds.png, timeline.png, arrivals.md and index.html into ``out_dir``
    and return the paths written.

    The scenario is ``scenario_path`` when given, else the one the record carries
    (``scenario``, with the threats the operator added: ``operator_threats``), else, for a
    record without it, the record's ``scenario_file``: as is (absolute, or relative to the
    working directory), else relative to ``out_dir``'s parent.
    A malformed record raises one :class:`GcsError` naming the missing or bad field, before
    anything is written.
    """
    parsed = _parse(flight)
    out_dir = Path(out_dir)
    if scenario_path is None and "scenario" in flight:
        scenario, world = _recorded_world(flight)
    else:
        path = scenario_path if scenario_path is not None else _scenario_file(flight, out_dir)
        scenario, world = _world(path)
    title = scenario.name
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise GcsError(f"{out_dir}: cannot create the report folder ({err.strerror})") from None
    paths_png, speeds_png, timeline_png = (out_dir / name for name in FIGURES)
    _plot_paths(parsed, world, title, paths_png)
    _plot_speeds(parsed, title, speeds_png)
    _plot_timeline(parsed, title, timeline_png)
    md = out_dir / "arrivals.md"
    _write_text(md, _markdown(parsed, f"{title}: rehearsal report"))
    index = out_dir / "index.html"
    _write_text(index, _html(parsed, f"{title}: rehearsal report"))
    return [paths_png, speeds_png, timeline_png, md, index]
