"""Mission files operators use: QGC WPL 110 text (MAVProxy, Mission Planner) and QGC .plan JSON.

Both formats hold a MISSION_ITEM's seven params as decimal numbers, so x and y (int 1e7 in
:class:`~planner.mission.MissionItem`) become degrees. The conversion follows QGroundControl's
upload code: in MAV_FRAME_MISSION (2) param5/param6 are x/y unscaled; in every other frame
they are x/y x 1e-7. NaN in param5/param6 is MAVLink's "unset" and maps to INT32_MAX.

Degrees are written with 8 decimals: the 7 that x holds exactly, then a 1 pointing away from
zero (47.1234567 is written 47.12345671; whole degrees end in 0). Whoever reads the file gets x
back whether it rounds (``round(lat * 1e7)``: this module) or truncates (``int(lat * 1e7)``:
QGroundControl's and MAVProxy's uploads) the product, where a file with exactly 7 decimals
would lose 1e-7 deg on about half of the points read by a truncating reader. Params and
altitudes are written as Python's shortest repr, which reads back to the same double.

Every error is a :class:`~planner.mission.MissionError` whose one line names the file, the
line or item, and the field.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from planner.mission import (
    AMSL_FRAMES,
    GLOBAL_FRAMES,
    INT32_UNSET,
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_LOITER_TIME,
    MAV_CMD_NAV_LOITER_TURNS,
    MAV_CMD_NAV_LOITER_UNLIM,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_MISSION,
    MAV_MISSION_TYPE_MISSION,
    RELATIVE_FRAMES,
    TERRAIN_FRAMES,
    MissionError,
    MissionItem,
)

__all__ = [
    "PLAN_EXTENSIONS",
    "QGC_ALTITUDE_MODE_ABSOLUTE",
    "QGC_ALTITUDE_MODE_MIXED",
    "QGC_ALTITUDE_MODE_RELATIVE",
    "QGC_ALTITUDE_MODE_TERRAIN_FRAME",
    "WPL_EXTENSIONS",
    "WPL_HEADER",
    "from_qgc_plan",
    "from_wpl",
    "read_mission_file",
    "to_qgc_plan",
    "to_wpl",
    "write_mission_file",
]

WPL_HEADER = "QGC WPL 110"
WPL_EXTENSIONS = frozenset({".waypoints", ".wpl", ".txt"})
PLAN_EXTENSIONS = frozenset({".plan"})

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_TYPE_FIXED_WING = 1

# QGroundControlQmlGlobal::AltMode, the "AltitudeMode" of a SimpleItem.
QGC_ALTITUDE_MODE_MIXED = 0
QGC_ALTITUDE_MODE_RELATIVE = 1
QGC_ALTITUDE_MODE_ABSOLUTE = 2
QGC_ALTITUDE_MODE_TERRAIN_FRAME = 4

_QGC_DEFAULT_CRUISE_M_S = 15.0
_QGC_DEFAULT_HOVER_M_S = 5.0
_PLAN_FILE_VERSION = 1
_PLAN_MISSION_VERSION = 2
_PLAN_FENCE_VERSION = 2
_PLAN_RALLY_VERSION = 2

# Commands whose item carries a position and an altitude (QGC writes "Altitude" for them).
_POSITION_COMMANDS = frozenset(
    {
        MAV_CMD_NAV_WAYPOINT,
        MAV_CMD_NAV_LOITER_UNLIM,
        MAV_CMD_NAV_LOITER_TURNS,
        MAV_CMD_NAV_LOITER_TIME,
        MAV_CMD_NAV_LAND,
        MAV_CMD_NAV_TAKEOFF,
    }
)
_INT32_MIN = -(2**31)
_INT32_MAX = 2**31 - 1
_WPL_FIELDS = (
    "seq",
    "current",
    "frame",
    "command",
    "param1",
    "param2",
    "param3",
    "param4",
    "lat",
    "lon",
    "alt",
    "autocontinue",
)


# --- x/y <-> param5/param6 ------------------------------------------------------------------


def _xy_text(v: int, frame: int) -> str:
    """param5/param6 as text: 8 decimals; scaled values nudged away from zero (module doc)."""
    if v == INT32_UNSET:
        return "NaN"
    if frame == MAV_FRAME_MISSION:
        return f"{v:.8f}"
    sign = "-" if v < 0 else ""
    whole, frac = divmod(abs(v), 10**7)
    if frac == 0:  # whole degrees are exact in binary: every reader gets them back
        return f"{sign}{whole}.00000000"
    return f"{sign}{whole}.{frac:07d}1"


def _xy_json(v: int, frame: int) -> float | None:
    if v == INT32_UNSET:
        return None
    return float(_xy_text(v, frame))


def _param_to_xy(value: float, frame: int, field: str, where: str) -> int:
    """x or y from a file's param5/param6 (``field`` is "lat" or "lon")."""
    if math.isnan(value):
        return INT32_UNSET
    if not math.isfinite(value):
        raise MissionError(f"{where}: {field} {value} is not finite")
    if frame == MAV_FRAME_MISSION:
        if value != math.floor(value) or not _INT32_MIN <= value <= _INT32_MAX:
            raise MissionError(
                f"{where}: {field} {value!r} must be an int32 in frame 2 (MAV_FRAME_MISSION)"
            )
        return int(value)
    if frame in GLOBAL_FRAMES:
        limit = 90.0 if field == "lat" else 180.0
        if not -limit <= value <= limit:
            raise MissionError(f"{where}: {field} {value!r} is outside [{-limit:g}, {limit:g}]")
    v = round(value * 1e7)
    if not _INT32_MIN <= v <= _INT32_MAX:
        raise MissionError(f"{where}: {field} {value!r} x 1e7 does not fit in an int32")
    return v


def _float_text(v: float, where: str, field: str) -> str:
    if math.isnan(v):
        return "NaN"
    if not math.isfinite(v):
        raise MissionError(f"{where}: {field} {v} is not finite")
    return repr(float(v))


def _check_items(items: Sequence[MissionItem], fmt: str) -> None:
    if not items:
        raise MissionError(f"{fmt}: no items; item 0 (home) is required")
    for k, it in enumerate(items):
        if it.seq != k:
            raise MissionError(f"item {k}: seq {it.seq} does not match its position {k}")
        if it.mission_type != MAV_MISSION_TYPE_MISSION:
            raise MissionError(
                f"item {k}: mission_type {it.mission_type} cannot be stored in a {fmt} file "
                "(missions only)"
            )
        for name, value, lo, hi in (
            ("current", it.current, 0, 1),
            ("autocontinue", it.autocontinue, 0, 1),
            ("frame", it.frame, 0, 255),
            ("command", it.command, 0, 65535),
            ("x", it.x, _INT32_MIN, _INT32_MAX),
            ("y", it.y, _INT32_MIN, _INT32_MAX),
        ):
            if not lo <= value <= hi:
                raise MissionError(f"item {k}: {name} {value} is outside [{lo}, {hi}]")
        if it.frame in GLOBAL_FRAMES:
            for name, value, limit in (("x", it.x, 900_000_000), ("y", it.y, 1_800_000_000)):
                if value != INT32_UNSET and not -limit <= value <= limit:
                    raise MissionError(
                        f"item {k}: {name} {value} is outside [{-limit}, {limit}] "
                        f"(+-{limit // 10**7} deg)"
                    )
    if items[0].command != MAV_CMD_NAV_WAYPOINT:
        raise MissionError(
            f"item 0: command {items[0].command} is not home (NAV_WAYPOINT {MAV_CMD_NAV_WAYPOINT})"
        )


# --- QGC WPL 110 ----------------------------------------------------------------------------


def to_wpl(items: Sequence[MissionItem]) -> str:
    """The QGC WPL 110 text of a mission (item 0 = home), tab-separated, newline-terminated.

    Each line is ``seq current frame command p1 p2 p3 p4 lat lon alt autocontinue`` as MAVProxy
    (``wp save``) and Mission Planner write it; home keeps its own ``current`` flag (Mission
    Planner writes 1 there, ArduPilot reports 0).
    """
    _check_items(items, "WPL")
    lines = [WPL_HEADER]
    for it in items:
        where = f"item {it.seq}"
        params = [
            _float_text(v, where, f"param{k}")
            for k, v in enumerate((it.param1, it.param2, it.param3, it.param4), start=1)
        ]
        fields = [
            f"{it.seq:d}",
            f"{it.current:d}",
            f"{it.frame:d}",
            f"{it.command:d}",
            *params,
            _xy_text(it.x, it.frame),
            _xy_text(it.y, it.frame),
            _float_text(it.z, where, "alt"),
            f"{it.autocontinue:d}",
        ]
        lines.append("\t".join(fields))
    return "\n".join(lines) + "\n"


def _wpl_int(text: str, field: str, where: str, lo: int, hi: int) -> int:
    try:
        v = int(text)
    except ValueError:
        raise MissionError(f"{where}: {field} {text!r} is not an integer") from None
    if not lo <= v <= hi:
        raise MissionError(f"{where}: {field} {v} is outside [{lo}, {hi}]")
    return v


def _wpl_float(text: str, field: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise MissionError(f"{where}: {field} {text!r} is not a number") from None
    if math.isinf(v):
        raise MissionError(f"{where}: {field} {text!r} is not finite")
    return v


def from_wpl(text: str, *, source: str = "WPL") -> list[MissionItem]:
    """Parse QGC WPL 110 text; ``source`` (a file name) starts every error message.

    Fields may be separated by tabs or spaces; blank lines and ``#`` comment lines (which
    pymavlink's loader accepts) are skipped. Lines must be numbered 0, 1, 2 ... in order.
    An item 0 with command 0 (older Mission Planner homes) is read as NAV_WAYPOINT, as
    pymavlink does.
    """
    lines = text.removeprefix("\ufeff").splitlines()
    header = lines[0].strip() if lines else ""
    if header != WPL_HEADER:
        raise MissionError(f"{source}: line 1: header {header!r} is not {WPL_HEADER!r}")
    items: list[MissionItem] = []
    for lineno, raw in enumerate(lines[1:], start=2):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{source}: line {lineno}"
        f = line.split()
        if len(f) != len(_WPL_FIELDS):
            raise MissionError(
                f"{where}: {len(f)} fields, expected {len(_WPL_FIELDS)} ({' '.join(_WPL_FIELDS)})"
            )
        seq = _wpl_int(f[0], "seq", where, 0, 65535)
        if seq != len(items):
            raise MissionError(f"{where}: seq {seq} is out of order (expected {len(items)})")
        current = _wpl_int(f[1], "current", where, 0, 1)
        frame = _wpl_int(f[2], "frame", where, 0, 255)
        command = _wpl_int(f[3], "command", where, 0, 65535)
        p = [_wpl_float(f[4 + k], f"param{k + 1}", where) for k in range(4)]
        lat = _wpl_float(f[8], "lat", where)
        lon = _wpl_float(f[9], "lon", where)
        alt = _wpl_float(f[10], "alt", where)
        autocontinue = _wpl_int(f[11], "autocontinue", where, 0, 1)
        if seq == 0 and command == 0:
            command = MAV_CMD_NAV_WAYPOINT
        items.append(
            MissionItem(
                seq=seq,
                frame=frame,
                command=command,
                current=current,
                autocontinue=autocontinue,
                param1=p[0],
                param2=p[1],
                param3=p[2],
                param4=p[3],
                x=_param_to_xy(lat, frame, "lat", where),
                y=_param_to_xy(lon, frame, "lon", where),
                z=alt,
            )
        )
    return items


# --- QGroundControl .plan -------------------------------------------------------------------


def _json_number(v: float, where: str, field: str) -> float | None:
    if math.isnan(v):
        return None
    if not math.isfinite(v):
        raise MissionError(f"{where}: {field} {v} is not finite (JSON has no infinity)")
    return float(v)


def _altitude_mode(frame: int) -> int | None:
    if frame in RELATIVE_FRAMES:
        return QGC_ALTITUDE_MODE_RELATIVE
    if frame in AMSL_FRAMES:
        return QGC_ALTITUDE_MODE_ABSOLUTE
    if frame in TERRAIN_FRAMES:
        return QGC_ALTITUDE_MODE_TERRAIN_FRAME
    return None


def to_qgc_plan(
    items: Sequence[MissionItem],
    *,
    vehicle_type: int = MAV_TYPE_FIXED_WING,
    firmware_type: int = MAV_AUTOPILOT_ARDUPILOTMEGA,
    cruise_speed_m_s: float | None = None,
) -> dict[str, Any]:
    """The QGroundControl plan document (``json.dump`` it) of a mission whose item 0 is home.

    Home becomes ``plannedHomePosition`` [lat, lon, AMSL alt]: a .plan keeps only those three
    numbers of it (QGC rebuilds home as a GLOBAL NAV_WAYPOINT), so home must be in an AMSL
    frame. The other items become ``SimpleItem`` objects with ``doJumpId`` = seq (QGC numbers
    them from 1 after home). A .plan has no ``current`` flag: imported items have 0. Positioned
    NAV items also get QGC's ``Altitude`` (= z), ``AltitudeMode`` (from the frame) and
    ``AMSLAltAboveTerrain`` (null) so QGC shows their altitude. ``cruiseSpeed`` defaults to the
    first DO_CHANGE_SPEED airspeed, else QGC's default of 15 m/s; QGC uses it for time
    estimates only. QGC edits items in frames 3, 0 and 10 with its forms and others (such as
    the default 6, GLOBAL_RELATIVE_ALT_INT) as raw numbers; both upload unchanged.
    """
    _check_items(items, "plan")
    home = items[0]
    if home.frame not in AMSL_FRAMES:
        raise MissionError(
            f"item 0 (home): frame {home.frame} is not AMSL (0 or 5); "
            "plannedHomePosition needs an AMSL altitude"
        )
    if home.x == INT32_UNSET or home.y == INT32_UNSET:
        raise MissionError("item 0 (home): lat/lon are unset; plannedHomePosition needs them")
    home_alt = _json_number(home.z, "item 0 (home)", "alt")
    if home_alt is None:
        raise MissionError("item 0 (home): alt is NaN; plannedHomePosition needs an altitude")
    out_items: list[dict[str, Any]] = []
    modes: set[int] = set()
    for it in items[1:]:
        where = f"item {it.seq}"
        params = [
            _json_number(v, where, f"param{k}")
            for k, v in enumerate((it.param1, it.param2, it.param3, it.param4), start=1)
        ]
        params += [
            _xy_json(it.x, it.frame),
            _xy_json(it.y, it.frame),
            _json_number(it.z, where, "alt"),
        ]
        obj: dict[str, Any] = {}
        mode = _altitude_mode(it.frame)
        if it.command in _POSITION_COMMANDS and mode is not None:
            modes.add(mode)
            obj["AMSLAltAboveTerrain"] = None
            obj["Altitude"] = params[6]
            obj["AltitudeMode"] = mode
        obj.update(
            {
                "autoContinue": bool(it.autocontinue),
                "command": it.command,
                "doJumpId": it.seq,
                "frame": it.frame,
                "params": params,
                "type": "SimpleItem",
            }
        )
        out_items.append(obj)
    if cruise_speed_m_s is None:
        cruise_speed_m_s = next(
            (
                it.param2
                for it in items
                if it.command == MAV_CMD_DO_CHANGE_SPEED
                and it.param1 == 0.0
                and math.isfinite(it.param2)
                and it.param2 > 0.0
            ),
            _QGC_DEFAULT_CRUISE_M_S,
        )
    if not math.isfinite(cruise_speed_m_s) or cruise_speed_m_s <= 0.0:
        raise MissionError(f"cruise_speed_m_s {cruise_speed_m_s} must be > 0")
    mission: dict[str, Any] = {
        "cruiseSpeed": float(cruise_speed_m_s),
        "firmwareType": firmware_type,
        "globalPlanAltitudeMode": modes.pop() if len(modes) == 1 else QGC_ALTITUDE_MODE_MIXED,
        "hoverSpeed": _QGC_DEFAULT_HOVER_M_S,
        "items": out_items,
        "plannedHomePosition": [
            _xy_json(home.x, home.frame),
            _xy_json(home.y, home.frame),
            home_alt,
        ],
        "vehicleType": vehicle_type,
        "version": _PLAN_MISSION_VERSION,
    }
    return {
        "fileType": "Plan",
        "geoFence": {"circles": [], "polygons": [], "version": _PLAN_FENCE_VERSION},
        "groundStation": "QGroundControl",
        "mission": mission,
        "rallyPoints": {"points": [], "version": _PLAN_RALLY_VERSION},
        "version": _PLAN_FILE_VERSION,
    }


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _get(obj: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise MissionError(f"{where}{key}: missing")
    return obj[key]


def _int_field(obj: Mapping[str, Any], key: str, where: str, lo: int, hi: int) -> int:
    v = _get(obj, key, where)
    if not _is_number(v) or not math.isfinite(v) or v != math.floor(v):
        raise MissionError(f"{where}{key}: {v!r} is not an integer")
    if not lo <= v <= hi:
        raise MissionError(f"{where}{key}: {v!r} is outside [{lo}, {hi}]")
    return int(v)


def _version(obj: Mapping[str, Any], where: str, expected: int) -> None:
    v = _get(obj, "version", where)
    if not _is_number(v) or v != expected:
        raise MissionError(f"{where}version: {v!r} is not supported (expected {expected})")


def _object(v: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(v, Mapping):
        raise MissionError(f"{where}: is not a JSON object")
    return v


def from_qgc_plan(doc: Mapping[str, Any], *, source: str = "plan") -> list[MissionItem]:
    """The items of a QGroundControl plan document, item 0 rebuilt from plannedHomePosition.

    Only ``SimpleItem`` mission items are read; ``ComplexItem`` (survey, landing pattern ...)
    and a non-empty geofence or rally point list are errors, since they would otherwise be
    dropped unseen. Items get ``seq`` = position (home 0, then 1, 2 ...), ``current`` 0;
    ``doJumpId`` is checked to be an integer and otherwise not used. ``params`` is
    authoritative for the altitude; QGC's ``Altitude``/``AltitudeMode`` are display values.
    """
    top = _object(doc, f"{source}: top level")
    pre = f"{source}: "
    file_type = _get(top, "fileType", pre)
    if file_type != "Plan":
        raise MissionError(f"{pre}fileType: {file_type!r} is not 'Plan'")
    _version(top, pre, _PLAN_FILE_VERSION)
    for key, lists in (("geoFence", ("circles", "polygons")), ("rallyPoints", ("points",))):
        if key in top:
            section = _object(top[key], f"{pre}{key}")
            for name in lists:
                if section.get(name):
                    raise MissionError(
                        f"{pre}{key}.{name}: not empty; only the mission of a plan is read "
                        "(remove the fence/rally points or upload them separately)"
                    )
    mission = _object(_get(top, "mission", pre), f"{pre}mission")
    mpre = f"{pre}mission."
    _version(mission, mpre, _PLAN_MISSION_VERSION)
    _int_field(mission, "firmwareType", mpre, 0, 255)
    home_pos = _get(mission, "plannedHomePosition", mpre)
    if (
        not isinstance(home_pos, list)
        or len(home_pos) != 3
        or not all(_is_number(v) for v in home_pos)
    ):
        raise MissionError(
            f"{mpre}plannedHomePosition: {home_pos!r} is not [lat_deg, lon_deg, alt_m]"
        )
    hwhere = f"{mpre}plannedHomePosition"
    for name, v in zip(("lat", "lon", "alt"), home_pos, strict=True):
        if not math.isfinite(v):
            raise MissionError(f"{hwhere}: {name} {v!r} is not finite")
    items = [
        MissionItem(
            seq=0,
            frame=MAV_FRAME_GLOBAL,
            command=MAV_CMD_NAV_WAYPOINT,
            current=0,
            autocontinue=1,
            param1=0.0,
            param2=0.0,
            param3=0.0,
            param4=0.0,
            x=_param_to_xy(float(home_pos[0]), MAV_FRAME_GLOBAL, "lat", hwhere),
            y=_param_to_xy(float(home_pos[1]), MAV_FRAME_GLOBAL, "lon", hwhere),
            z=float(home_pos[2]),
        )
    ]
    raw_items = _get(mission, "items", mpre)
    if not isinstance(raw_items, list):
        raise MissionError(f"{mpre}items: is not a list")
    for k, raw in enumerate(raw_items):
        where = f"{mpre}items[{k}]"
        obj = _object(raw, where)
        ipre = f"{where}."
        kind = _get(obj, "type", ipre)
        if kind == "ComplexItem":
            raise MissionError(
                f"{where}: ComplexItem {obj.get('complexItemType')!r} is not supported "
                "(save the plan as simple items, or export a .waypoints file from QGC)"
            )
        if kind != "SimpleItem":
            raise MissionError(f"{ipre}type: {kind!r} is not 'SimpleItem'")
        command = _int_field(obj, "command", ipre, 0, 65535)
        frame = _int_field(obj, "frame", ipre, 0, 255)
        auto = _get(obj, "autoContinue", ipre)
        if not isinstance(auto, bool):
            raise MissionError(f"{ipre}autoContinue: {auto!r} is not true or false")
        if "doJumpId" in obj:
            _int_field(obj, "doJumpId", ipre, 0, 65535)
        params = _get(obj, "params", ipre)
        if not isinstance(params, list) or len(params) != 7:
            n = len(params) if isinstance(params, list) else type(params).__name__
            raise MissionError(f"{ipre}params: {n} values, expected 7 (param1-4, lat, lon, alt)")
        values: list[float] = []
        for j, v in enumerate(params):
            if v is None:
                values.append(math.nan)
            elif _is_number(v) and math.isfinite(v):
                values.append(float(v))
            else:
                raise MissionError(f"{ipre}params[{j}]: {v!r} is not a number or null")
        items.append(
            MissionItem(
                seq=k + 1,
                frame=frame,
                command=command,
                current=0,
                autocontinue=int(auto),
                param1=values[0],
                param2=values[1],
                param3=values[2],
                param4=values[3],
                x=_param_to_xy(values[4], frame, "lat", f"{ipre}params[4]"),
                y=_param_to_xy(values[5], frame, "lon", f"{ipre}params[5]"),
                z=values[6],
            )
        )
    if len(items) - 1 > 65535:
        raise MissionError(f"{mpre}items: {len(raw_items)} items; MAVLink seq is at most 65535")
    return items


# --- files ----------------------------------------------------------------------------------


def _kind(path: Path) -> str:
    ext = path.suffix.lower()
    if ext in PLAN_EXTENSIONS:
        return "plan"
    if ext in WPL_EXTENSIONS:
        return "wpl"
    known = ", ".join(sorted(PLAN_EXTENSIONS | WPL_EXTENSIONS))
    raise MissionError(f"{path}: unknown mission file extension {ext!r} (use one of {known})")


def read_mission_file(path: str | Path) -> list[MissionItem]:
    """Read a mission file: ``.plan`` as QGC JSON, ``.waypoints``/``.wpl``/``.txt`` as WPL 110."""
    p = Path(path)
    kind = _kind(p)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise MissionError(f"{p}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise MissionError(f"{p}: byte {e.start}: not UTF-8 text") from None
    if kind == "wpl":
        return from_wpl(text, source=str(p))
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise MissionError(f"{p}: line {e.lineno}: invalid JSON: {e.msg}") from None
    return from_qgc_plan(doc, source=str(p))


def write_mission_file(path: str | Path, items: Sequence[MissionItem]) -> None:
    """Write a mission file, the format chosen by the extension as in :func:`read_mission_file`.

    A ``.plan`` gets :func:`to_qgc_plan`'s defaults (fixed wing, ArduPilot), indented as QGC
    writes it.
    """
    p = Path(path)
    if _kind(p) == "wpl":
        text = to_wpl(items)
    else:
        text = json.dumps(to_qgc_plan(items), indent=4, allow_nan=False) + "\n"
    try:
        p.write_text(text, encoding="utf-8", newline="\n")
    except OSError as e:
        raise MissionError(f"{p}: cannot write: {e.strerror or e}") from None
