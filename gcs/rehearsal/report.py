"""The rehearsal report of a flight record (``tcgcs-flight/1``): figures and arrival tables.

:func:`write_report` writes the figures (:mod:`gcs.rehearsal.figures`: ``paths.png``,
``speeds.png``, ``timeline.png``) and, from here, ``arrivals.md`` and ``index.html``: the
arrival table, the adjustments, the events and the figures. :func:`arrival_table` is the table
as fixed-width text.

All times are shown as mission seconds, ``utc_s - start_utc_s``. The record is validated
(:mod:`gcs.rehearsal.flightrecord`, which says which fields are optional) before anything is
drawn: a malformed record raises one :class:`~gcs.errors.GcsError` naming the field
(``vehicles[0].track: missing``).
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from gcs.errors import GcsError
from gcs.rehearsal.figures import FIGURES, plot_paths, plot_speeds, plot_timeline
from gcs.rehearsal.flightrecord import Flight, flight_world, parse_flight
from planner.plan import World

__all__ = ["arrival_table", "write_figure", "write_report"]


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


def _strategies(flight: Flight, vehicle_id: str) -> list[str]:
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


def _arrival_rows(flight: Flight) -> list[list[str]]:
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


def _summary(flight: Flight) -> str:
    parts = [
        "arrival windows (a slot per vehicle)"
        if flight.required_utc_s is None
        else f"required arrival {flight.t(flight.required_utc_s):.2f} s"
    ]
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


def _conditions(flight: Flight) -> str:
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


def _arrival_table(flight: Flight) -> str:
    lines = _fixed_width(_HEADER, _arrival_rows(flight))
    return "\n".join([*lines, _summary(flight)]) + "\n"


def arrival_table(flight: Mapping[str, Any]) -> str:
    """The arrival table as fixed-width text, one row per vehicle, then a summary line.

    Columns: vehicle, target and arrival (mission s), error_s (+late/-early), takeoff (mission
    s), strategies used, loiter turns, min/max airspeed commanded; the last line gives the
    required arrival, the minimum separation against ``d_s`` and the wall time.
    """
    return _arrival_table(parse_flight(flight))


def _event_rows(flight: Flight) -> list[list[str]]:
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


def _adjustment_rows(flight: Flight) -> list[list[str]]:
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


def _markdown(flight: Flight, title: str) -> str:
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


def _html(flight: Flight, title: str) -> str:
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


# --- the report -------------------------------------------------------------------------------


def _write_text(path: Path, text: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as err:
        raise GcsError(f"{path}: cannot write ({err.strerror})") from None


def write_report(
    flight: Mapping[str, Any],
    out_dir: Path,
    *,
    scenario_path: Path | None = None,
    figures: bool = True,
) -> list[Path]:
    """Write paths.png, speeds.png, timeline.png, arrivals.md and index.html into ``out_dir``
    and return the paths written (without ``figures``, the two pages only: each figure then
    drawn when it is first asked for, :func:`write_figure`).

    The scenario is ``scenario_path`` when given, else the one the record carries
    (``scenario``, with the threats the operator added: ``operator_threats``), else, for a
    record without it, the record's ``scenario_file``: as is (absolute, or relative to the
    working directory), else relative to ``out_dir``'s parent.
    A malformed record raises one :class:`GcsError` naming the missing or bad field, before
    anything is written.
    """
    parsed = parse_flight(flight)
    out_dir = Path(out_dir)
    scenario, world = flight_world(flight, out_dir, scenario_path)
    title = scenario.name
    _make_folder(out_dir)
    written = []
    for name in FIGURES if figures else ():
        _draw(parsed, world, title, name, out_dir / name)
        written.append(out_dir / name)
    md = out_dir / "arrivals.md"
    _write_text(md, _markdown(parsed, f"{title}: rehearsal report"))
    index = out_dir / "index.html"
    _write_text(index, _html(parsed, f"{title}: rehearsal report"))
    return [*written, md, index]


def write_figure(
    flight: Mapping[str, Any], out_dir: Path, name: str, *, scenario_path: Path | None = None
) -> Path:
    """Draw one figure of the report (``name`` one of :data:`FIGURES`) into ``out_dir``, as
    :func:`write_report` would, and return its path."""
    if name not in FIGURES:
        raise GcsError(f"no report figure {name!r} (one of {', '.join(FIGURES)})")
    parsed = parse_flight(flight)
    out_dir = Path(out_dir)
    scenario, world = flight_world(flight, out_dir, scenario_path)
    _make_folder(out_dir)
    out = out_dir / name
    # Drawn beside and moved in whole: a reader never gets half a file.
    part = out.with_name(f".part.{name}")
    _draw(parsed, world, scenario.name, name, part)
    part.replace(out)
    return out


def _draw(parsed: Flight, world: World, title: str, name: str, out: Path) -> None:
    """Draw the figure ``name`` (one of :data:`FIGURES`) into ``out``."""
    if name == "paths.png":
        plot_paths(parsed, world, title, out)
    elif name == "speeds.png":
        plot_speeds(parsed, title, out)
    else:
        plot_timeline(parsed, title, out)


def _make_folder(out_dir: Path) -> None:
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise GcsError(f"{out_dir}: cannot create the report folder ({err.strerror})") from None
