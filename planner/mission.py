"""A vehicle's route as an ArduPlane mission: the MAVLink mission items, compiled and checked.

:func:`compile_mission` turns a planned route (home, waypoints AMSL, speed changes, loiters)
into the items a ground station uploads with the MAVLink mission protocol, with ArduPlane's
semantics:

======  =====================  ==============================================================
seq     command                content
======  =====================  ==============================================================
0       NAV_WAYPOINT (home)    frame GLOBAL, z = home AMSL (ArduPilot keeps home at item 0)
1       NAV_TAKEOFF            param1 = minimum pitch (deg), z = climb-out altitude above home
                               (none for a vehicle taken over in the air: the route is item 1)
...     DO_CHANGE_SPEED        before a waypoint: param1 0 (airspeed), param2 m/s, param3 -1
...     NAV_WAYPOINT           one per waypoint; the last one is the goal
...     NAV_LOITER_TURNS       after a waypoint: param1 turns, param3 +-radius, param4 1
...     DO_LAND_START          (optional) at the last waypoint: where the landing begins
last    NAV_LAND (optional)    at home, or at a given touchdown point
last    NAV_LOITER_UNLIM (opt) without a landing: a hold at the last waypoint (no RTL home)
======  =====================  ==============================================================

ArduPlane runs the DO commands that follow a NAV command when that NAV command completes, so
a DO_CHANGE_SPEED placed right before waypoint ``i`` sets the airspeed of the leg that ends at
waypoint ``i`` (it takes effect when the vehicle reaches the previous waypoint, finishes the
previous loiter or, for waypoint 0, completes the takeoff).

A takeoff delay is not a mission item: ArduPlane skips NAV_DELAY while armed, so the
coordinator arms and starts each vehicle at its scheduled time instead.

The module is pure: no sockets and no pymavlink. The few MAV_CMD and MAV_FRAME numbers it uses
are constants here, checked against pymavlink's generated dialect by the tests.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from planner.errors import PlannerError

__all__ = [
    "AMSL_FRAMES",
    "GLOBAL_FRAMES",
    "INT32_UNSET",
    "MAV_CMD_DO_CHANGE_SPEED",
    "MAV_CMD_DO_LAND_START",
    "MAV_CMD_NAV_LAND",
    "MAV_CMD_NAV_LOITER_TIME",
    "MAV_CMD_NAV_LOITER_TURNS",
    "MAV_CMD_NAV_LOITER_UNLIM",
    "MAV_CMD_NAV_RETURN_TO_LAUNCH",
    "MAV_CMD_NAV_TAKEOFF",
    "MAV_CMD_NAV_WAYPOINT",
    "MAV_FRAME_GLOBAL",
    "MAV_FRAME_GLOBAL_INT",
    "MAV_FRAME_GLOBAL_RELATIVE_ALT",
    "MAV_FRAME_GLOBAL_RELATIVE_ALT_INT",
    "MAV_FRAME_GLOBAL_TERRAIN_ALT",
    "MAV_FRAME_GLOBAL_TERRAIN_ALT_INT",
    "MAV_FRAME_MISSION",
    "MAV_MISSION_TYPE_MISSION",
    "RELATIVE_FRAMES",
    "TERRAIN_FRAMES",
    "Autopilot",
    "Loiter",
    "MissionError",
    "MissionItem",
    "SpeedChange",
    "Waypoint",
    "ardupilot_alt_m",
    "arduplane_loiter_radius_m",
    "command_name",
    "compile_mission",
    "describe",
    "first_difference",
    "items_equal",
    "stored_alt_m",
    "stored_item",
]

MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_UNLIM = 17
MAV_CMD_NAV_LOITER_TURNS = 18
MAV_CMD_NAV_LOITER_TIME = 19
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_LAND_START = 189

MAV_FRAME_GLOBAL = 0
MAV_FRAME_MISSION = 2
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
MAV_FRAME_GLOBAL_INT = 5
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
MAV_FRAME_GLOBAL_TERRAIN_ALT = 10
MAV_FRAME_GLOBAL_TERRAIN_ALT_INT = 11

MAV_MISSION_TYPE_MISSION = 0

AMSL_FRAMES = frozenset({MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_INT})
"""Frames whose z is metres above mean sea level."""
RELATIVE_FRAMES = frozenset({MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
"""Frames whose z is metres above home."""
TERRAIN_FRAMES = frozenset({MAV_FRAME_GLOBAL_TERRAIN_ALT, MAV_FRAME_GLOBAL_TERRAIN_ALT_INT})
"""Frames whose z is metres above the terrain under the point."""
GLOBAL_FRAMES = AMSL_FRAMES | RELATIVE_FRAMES | TERRAIN_FRAMES
"""Frames whose x, y are latitude and longitude x 1e7."""
_INT_FRAMES = frozenset(
    {MAV_FRAME_GLOBAL_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, MAV_FRAME_GLOBAL_TERRAIN_ALT_INT}
)

INT32_UNSET = 2**31 - 1
"""x or y of MISSION_ITEM_INT meaning "not set" (MAVLink's INT32_MAX; NaN in a float param)."""

_ALT_MIN_M = -500.0
_ALT_MAX_M = 20_000.0
_TAKEOFF_PITCH_MAX_DEG = 45.0
_LOITER_TURNS_MAX = 255
_LOITER_RADIUS_FINE_MAX_M = 255
_LOITER_RADIUS_MAX_M = 2550
_SEQ_MAX = 65535

_COMMAND_NAMES = {
    MAV_CMD_NAV_WAYPOINT: "NAV_WAYPOINT",
    MAV_CMD_NAV_LOITER_UNLIM: "NAV_LOITER_UNLIM",
    MAV_CMD_NAV_LOITER_TURNS: "NAV_LOITER_TURNS",
    MAV_CMD_NAV_LOITER_TIME: "NAV_LOITER_TIME",
    MAV_CMD_NAV_RETURN_TO_LAUNCH: "NAV_RETURN_TO_LAUNCH",
    MAV_CMD_NAV_LAND: "NAV_LAND",
    MAV_CMD_NAV_TAKEOFF: "NAV_TAKEOFF",
    MAV_CMD_DO_CHANGE_SPEED: "DO_CHANGE_SPEED",
    MAV_CMD_DO_LAND_START: "DO_LAND_START",
}
_FRAME_NAMES = {
    MAV_FRAME_GLOBAL: "GLOBAL",
    MAV_FRAME_MISSION: "MISSION",
    MAV_FRAME_GLOBAL_RELATIVE_ALT: "REL_ALT",
    MAV_FRAME_GLOBAL_INT: "GLOBAL_INT",
    MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: "REL_ALT_INT",
    MAV_FRAME_GLOBAL_TERRAIN_ALT: "TERRAIN",
    MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: "TERRAIN_INT",
}


class MissionError(PlannerError, ValueError):
    """A mission, its input or a mission file is invalid; the message names the item and field."""


@dataclass(frozen=True, slots=True)
class MissionItem:
    """One MISSION_ITEM_INT as uploaded (lat/lon as int 1e7, z in metres in the frame's datum).

    The fields and their names are those of the MAVLink message (and of
    ``sitl_stub.items.MissionItem``). Params and z are Python floats; the wire carries float32,
    so compare items that went over a link with :func:`items_equal`.
    """

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    """Latitude x 1e7 in global frames (int32 on the wire)."""
    y: int
    """Longitude x 1e7 in global frames (int32 on the wire)."""
    z: float
    """Altitude (m): AMSL, above home or above terrain, by ``frame``."""
    mission_type: int = MAV_MISSION_TYPE_MISSION

    @property
    def lat_deg(self) -> float:
        return self.x * 1e-7

    @property
    def lon_deg(self) -> float:
        return self.y * 1e-7


@dataclass(frozen=True)
class Waypoint:
    """A point of the route: WGS84 degrees and metres above mean sea level."""

    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True)
class SpeedChange:
    """Fly the leg that ends at ``waypoints[before_waypoint]`` at ``airspeed_m_s``."""

    before_waypoint: int
    airspeed_m_s: float


@dataclass(frozen=True)
class Loiter:
    """Circle ``turns`` times about a point after reaching ``waypoints[after_waypoint]``.

    ``alt_m`` is AMSL. ArduPlane stores the radius in whole metres up to 255 m and in 10 m steps
    up to 2550 m (see :func:`arduplane_loiter_radius_m`); other radii are refused so that the
    loiter flown is the loiter planned.
    """

    after_waypoint: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    turns: int
    radius_m: float
    clockwise: bool = True


def arduplane_loiter_radius_m(radius_m: float) -> float:
    """The loiter radius (m) ArduPlane stores for a requested one (AP_Mission's packing).

    Whole metres (truncated) up to 255 m; above that tenths of the radius, truncated and capped
    at 255, times 10 (so 10 m steps up to 2550 m).
    """
    r = abs(radius_m)
    if r <= _LOITER_RADIUS_FINE_MAX_M:
        return float(math.trunc(r))
    return 10.0 * min(_LOITER_RADIUS_FINE_MAX_M, math.trunc(r * 0.1))


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def _num(v: float) -> str:
    return f"{v:g}"


def _check_point(where: str, lat_deg: float, lon_deg: float, alt_m: float) -> None:
    for name, value, lo, hi in (
        ("lat_deg", lat_deg, -90.0, 90.0),
        ("lon_deg", lon_deg, -180.0, 180.0),
        ("alt_m", alt_m, _ALT_MIN_M, _ALT_MAX_M),
    ):
        if not math.isfinite(value) or not lo <= value <= hi:
            raise MissionError(f"{where}: {name} {_num(value)} is outside [{lo:g}, {hi:g}]")


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_speeds(
    speeds: Sequence[SpeedChange], n: int, limits: tuple[float, float] | None
) -> dict[int, SpeedChange]:
    by_wp: dict[int, SpeedChange] = {}
    for k, s in enumerate(speeds):
        i = s.before_waypoint
        if not _is_int(i) or not 0 <= i < n:
            raise MissionError(
                f"speed change {k}: before_waypoint {i!r} is not a waypoint index in [0, {n - 1}]"
            )
        where = f"speed change before waypoint {i}"
        if i in by_wp:
            raise MissionError(f"{where}: a second speed change for the same waypoint")
        v = s.airspeed_m_s
        if not math.isfinite(v) or v <= 0.0:
            raise MissionError(f"{where}: airspeed {_num(v)} m/s must be > 0")
        if limits is not None and not limits[0] <= v <= limits[1]:
            raise MissionError(
                f"{where}: airspeed {_num(v)} m/s is outside [{limits[0]:g}, {limits[1]:g}]"
            )
        by_wp[i] = s
    return by_wp


def _check_loiters(loiters: Sequence[Loiter], n: int) -> dict[int, Loiter]:
    by_wp: dict[int, Loiter] = {}
    for k, lo in enumerate(loiters):
        i = lo.after_waypoint
        if not _is_int(i) or not 0 <= i < n:
            raise MissionError(
                f"loiter {k}: after_waypoint {i!r} is not a waypoint index in [0, {n - 1}]"
            )
        where = f"loiter after waypoint {i}"
        if i in by_wp:
            raise MissionError(f"{where}: a second loiter after the same waypoint")
        _check_point(where, lo.lat_deg, lo.lon_deg, lo.alt_m)
        if not _is_int(lo.turns) or lo.turns < 1:
            raise MissionError(f"{where}: turns must be >= 1 (got {lo.turns!r})")
        if lo.turns > _LOITER_TURNS_MAX:
            raise MissionError(f"{where}: turns {lo.turns} is above {_LOITER_TURNS_MAX}")
        r = lo.radius_m
        if not math.isfinite(r) or r < 1.0:
            raise MissionError(f"{where}: radius_m {_num(r)} must be >= 1")
        if r > _LOITER_RADIUS_MAX_M:
            raise MissionError(
                f"{where}: radius_m {_num(r)} is above {_LOITER_RADIUS_MAX_M}, "
                "the largest loiter radius ArduPlane stores"
            )
        if arduplane_loiter_radius_m(r) != r:
            step = "whole metres" if r <= _LOITER_RADIUS_FINE_MAX_M else "10 m steps above 255 m"
            raise MissionError(
                f"{where}: radius_m {_num(r)} would fly as {arduplane_loiter_radius_m(r):g} "
                f"(ArduPlane stores loiter radii in {step})"
            )
        by_wp[i] = lo
    return by_wp


def compile_mission(
    *,
    home: Waypoint,
    waypoints: Sequence[Waypoint],
    takeoff_alt_m: float | None,
    speeds: Sequence[SpeedChange] = (),
    loiters: Sequence[Loiter] = (),
    frame: int = MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    takeoff_pitch_deg: float = 15.0,
    airspeed_limits_m_s: tuple[float, float] | None = None,
    land: bool | Waypoint = False,
    land_start: bool = False,
    terrain_alt_m: Callable[[float, float], float] | None = None,
    hold_radius_m: float | None = None,
) -> list[MissionItem]:
    """Compile a route into ArduPlane mission items, item 0 being home.

    Parameters
    ----------
    home
        Home (launch) position; ``alt_m`` AMSL (m). Relative altitudes are measured from it.
    waypoints
        The route in order, AMSL (m); the last one is the goal. At least one.
    takeoff_alt_m
        Altitude above home (m) at which NAV_TAKEOFF completes; > 0. None for a vehicle
        already flying: no NAV_TAKEOFF, the first waypoint is item 1 (ArduPlane starts a
        mission at item 1 and flies there from where it is).
    speeds
        Airspeed changes, at most one per waypoint: DO_CHANGE_SPEED right before that
        waypoint's NAV_WAYPOINT (so it governs the leg ending there).
    loiters
        NAV_LOITER_TURNS right after a waypoint, at most one per waypoint. param3 is the radius
        (m), positive for clockwise as ArduPlane reads it; param4 = 1 so that ArduPlane, after
        the turns and once headed at the next waypoint, tracks the next leg from the tangent
        exit point rather than from the loiter centre (the Dubins-like exit the planner flies).
    frame
        Frame of the NAV items (default GLOBAL_RELATIVE_ALT_INT). AMSL frames (0, 5) carry
        ``alt_m``; relative frames (3, 6) ``alt_m - home.alt_m``; terrain frames (10, 11)
        ``alt_m - terrain_alt_m(lat, lon)``. NAV_TAKEOFF is always in the relative frame of the
        same kind (6 for the ``_INT`` frames, else 3) since its altitude is above home;
        DO_CHANGE_SPEED is in MAV_FRAME_MISSION (2) with x = y = z = 0.
    takeoff_pitch_deg
        NAV_TAKEOFF param1: minimum climb pitch (deg), in (0, 45].
    airspeed_limits_m_s
        (min, max) airspeed (m/s); speed changes outside it are errors.
    land
        False: no landing (ArduPlane flies RTL when the mission ends). True: NAV_LAND at home.
        A :class:`Waypoint`: NAV_LAND there, ``alt_m`` being the touchdown ground AMSL (m).
    land_start
        With a landing: DO_LAND_START right before NAV_LAND, at the last waypoint (ArduPlane
        runs it as a marker; a DO_LAND_START command or RTL_AUTOLAND jumps to it).
    hold_radius_m
        Without a landing: NAV_LOITER_UNLIM at the last waypoint, a clockwise circle of this
        radius (m), so that the aircraft holds there once it has flown its route instead of
        flying home in RTL at RTL_ALTITUDE, across whatever terrain and zones lie between.
    terrain_alt_m
        Terrain elevation AMSL (m) at (lat_deg, lon_deg); required for the terrain frames.

    Returns
    -------
    list of MissionItem
        ``seq`` = list index; lat/lon rounded to the nearest 1e-7 deg; z in whole
        centimetres as ArduPilot stores it (:func:`stored_alt_m`); ``current`` = 0,
        ``autocontinue`` = 1 everywhere.

    Raises
    ------
    MissionError
        One line naming the input and field, e.g. ``waypoint 3: lat_deg 95 is outside
        [-90, 90]`` or ``speed change before waypoint 2: airspeed 45 m/s is outside [20, 30]``.
    """
    if frame not in GLOBAL_FRAMES:
        allowed = ", ".join(str(f) for f in sorted(GLOBAL_FRAMES))
        raise MissionError(f"frame {frame!r} is not supported; use one of {allowed}")
    if frame in TERRAIN_FRAMES and terrain_alt_m is None:
        raise MissionError(f"frame {frame} is a terrain frame: terrain_alt_m is required")
    _check_point("home", home.lat_deg, home.lon_deg, home.alt_m)
    if not waypoints:
        raise MissionError("waypoints: at least one waypoint (the goal) is required")
    for i, wp in enumerate(waypoints):
        _check_point(f"waypoint {i}", wp.lat_deg, wp.lon_deg, wp.alt_m)
    if takeoff_alt_m is not None and (
        not math.isfinite(takeoff_alt_m) or not 0.0 < takeoff_alt_m <= _ALT_MAX_M
    ):
        raise MissionError(f"takeoff_alt_m {_num(takeoff_alt_m)} is outside (0, {_ALT_MAX_M:g}]")
    if not math.isfinite(takeoff_pitch_deg) or not (
        0.0 < takeoff_pitch_deg <= _TAKEOFF_PITCH_MAX_DEG
    ):
        raise MissionError(
            f"takeoff_pitch_deg {_num(takeoff_pitch_deg)} is outside "
            f"(0, {_TAKEOFF_PITCH_MAX_DEG:g}]"
        )
    if airspeed_limits_m_s is not None:
        lo, hi = airspeed_limits_m_s
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo <= hi):
            raise MissionError(
                f"airspeed_limits_m_s ({_num(lo)}, {_num(hi)}) must satisfy 0 < min <= max"
            )
    landing: Waypoint | None = None
    if isinstance(land, Waypoint):
        _check_point("land", land.lat_deg, land.lon_deg, land.alt_m)
        landing = land
    elif land:
        landing = home
    if land_start and landing is None:
        raise MissionError("land_start: DO_LAND_START needs a landing (land)")
    speed_at = _check_speeds(speeds, len(waypoints), airspeed_limits_m_s)
    loiter_at = _check_loiters(loiters, len(waypoints))

    def z_of(where: str, lat_deg: float, lon_deg: float, alt_m: float) -> float:
        if frame in AMSL_FRAMES:
            return alt_m
        if frame in RELATIVE_FRAMES:
            return alt_m - home.alt_m
        assert terrain_alt_m is not None
        ground = terrain_alt_m(lat_deg, lon_deg)
        if not math.isfinite(ground):
            raise MissionError(f"{where}: terrain_alt_m gave {ground} at the point")
        return alt_m - ground

    items: list[MissionItem] = []

    def add(
        frame_: int,
        command: int,
        params: tuple[float, float, float, float],
        x: int,
        y: int,
        z: float,
    ) -> None:
        items.append(
            MissionItem(
                seq=len(items),
                frame=frame_,
                command=command,
                current=0,
                autocontinue=1,
                param1=float(params[0]),
                param2=float(params[1]),
                param3=float(params[2]),
                param4=float(params[3]),
                x=x,
                y=y,
                # The altitude the autopilot keeps (whole centimetres), so that what is
                # planned is what is flown and what a verifying download gives back.
                z=ardupilot_alt_m(float(z)),
            )
        )

    hx, hy = _e7(home.lat_deg), _e7(home.lon_deg)
    add(MAV_FRAME_GLOBAL, MAV_CMD_NAV_WAYPOINT, (0, 0, 0, 0), hx, hy, home.alt_m)
    # ArduPlane ignores NAV_TAKEOFF's lat/lon (it climbs out on the launch heading); home's
    # position keeps ground stations from drawing the takeoff at 0 N 0 E.
    takeoff_frame = (
        MAV_FRAME_GLOBAL_RELATIVE_ALT_INT if frame in _INT_FRAMES else MAV_FRAME_GLOBAL_RELATIVE_ALT
    )
    if takeoff_alt_m is not None:
        pitch = (takeoff_pitch_deg, 0.0, 0.0, 0.0)
        add(takeoff_frame, MAV_CMD_NAV_TAKEOFF, pitch, hx, hy, takeoff_alt_m)
    for i, wp in enumerate(waypoints):
        s = speed_at.get(i)
        if s is not None:
            add(MAV_FRAME_MISSION, MAV_CMD_DO_CHANGE_SPEED, (0, s.airspeed_m_s, -1, 0), 0, 0, 0.0)
        z = z_of(f"waypoint {i}", wp.lat_deg, wp.lon_deg, wp.alt_m)
        add(frame, MAV_CMD_NAV_WAYPOINT, (0, 0, 0, 0), _e7(wp.lat_deg), _e7(wp.lon_deg), z)
        lt = loiter_at.get(i)
        if lt is not None:
            radius = lt.radius_m if lt.clockwise else -lt.radius_m
            z = z_of(f"loiter after waypoint {i}", lt.lat_deg, lt.lon_deg, lt.alt_m)
            params = (float(lt.turns), 0.0, radius, 1.0)
            add(frame, MAV_CMD_NAV_LOITER_TURNS, params, _e7(lt.lat_deg), _e7(lt.lon_deg), z)
    if landing is not None and land_start:
        last = waypoints[-1]
        z = z_of("land start", last.lat_deg, last.lon_deg, last.alt_m)
        add(frame, MAV_CMD_DO_LAND_START, (0, 0, 0, 0), _e7(last.lat_deg), _e7(last.lon_deg), z)
    if landing is not None:
        z = z_of("land", landing.lat_deg, landing.lon_deg, landing.alt_m)
        add(frame, MAV_CMD_NAV_LAND, (0, 0, 0, 0), _e7(landing.lat_deg), _e7(landing.lon_deg), z)
    elif hold_radius_m is not None:
        if not (math.isfinite(hold_radius_m) and hold_radius_m > 0.0):
            raise MissionError(f"hold_radius_m {_num(hold_radius_m)} must be > 0")
        last = waypoints[-1]
        z = z_of("hold", last.lat_deg, last.lon_deg, last.alt_m)
        params = (0.0, 0.0, float(hold_radius_m), 0.0)
        add(frame, MAV_CMD_NAV_LOITER_UNLIM, params, _e7(last.lat_deg), _e7(last.lon_deg), z)
    if len(items) - 1 > _SEQ_MAX:
        raise MissionError(f"mission has {len(items)} items; MAVLink seq is at most {_SEQ_MAX}")
    return items


def _f32(v: float) -> float:
    try:
        return float(struct.unpack("<f", struct.pack("<f", v))[0])
    except OverflowError:
        return v


def _same_f32(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return _f32(a) == _f32(b)


# --- what the autopilot stores ------------------------------------------------------------


class Autopilot(enum.Enum):
    """Whose storage a mission is read back from (see :func:`stored_item`)."""

    EXACT = "exact"
    """Gives back what it was sent, at float32 resolution (a generic MAVLink peer)."""
    ARDUPILOT = "ardupilot"
    """ArduPlane's AP_Mission: packed 15-byte commands, altitudes in whole centimetres."""
    PX4 = "px4"
    """PX4's mission manager: mission_item_s (double lat/lon, float altitude)."""
    UNKNOWN = "unknown"
    """Not heard from: an item agrees when it comes back in any of the forms above."""

    @classmethod
    def from_heartbeat(cls, mav_autopilot: int | None) -> Autopilot:
        """MAV_AUTOPILOT of a HEARTBEAT: 3 (ARDUPILOTMEGA) or 12 (PX4), None (no HEARTBEAT)
        UNKNOWN, else EXACT."""
        if mav_autopilot is None:
            return cls.UNKNOWN
        return {3: cls.ARDUPILOT, 12: cls.PX4}.get(mav_autopilot, cls.EXACT)


# AP_Mission::stored_in_location: commands whose x, y, z are kept as a Location.
_AP_LOCATION_COMMANDS = frozenset(
    {16, 17, 18, 19, 21, 22, 30, 31, 82, 84, 85, 94, 179, 189, 191, 201}
)


_CENTI_F32 = _f32(0.01)


def _kept_cm(z_m: float) -> int:
    """``Location::alt`` for a sent z: ``(int32)(z * 100.0f)``, float32, truncated."""
    return math.trunc(_f32(_f32(z_m) * 100.0))


def stored_alt_m(z_m: float) -> float:
    """The altitude ArduPilot gives back for a sent ``z`` (m): whole centimetres, truncated.

    AP_Mission (libraries/AP_Mission/AP_Mission.cpp, mavlink_int_to_mission_cmd) keeps
    ``(int32)(z * 100.0f)`` in float32 arithmetic and sends back ``alt * 0.01f``. The value
    given back is not always kept as itself when sent again (``612.72`` comes back as
    ``612.71``): :func:`ardupilot_alt_m` gives altitudes that are.
    """
    if not math.isfinite(z_m):
        return z_m
    return _f32(_f32(float(_kept_cm(z_m))) * _CENTI_F32)


def ardupilot_alt_m(z_m: float) -> float:
    """An altitude (m) on ArduPilot's centimetre grid, within 1 cm of ``z_m``, that
    ArduPilot keeps as the same centimetre whenever it is sent (truncation towards zero of
    ``z_m``'s centimetres, nudged by float32 steps where ``z * 100.0f`` would fall short)."""
    if not math.isfinite(z_m):
        return z_m
    cm = _kept_cm(z_m)
    z = _f32(cm / 100.0)
    away = math.inf if cm >= 0 else -math.inf
    for _ in range(8):
        if _kept_cm(z) == cm:
            return z
        z = _f32(float(np.nextafter(np.float32(z), np.float32(away))))
    return z


def _u16(v: float) -> int:
    """C's float -> uint16_t conversion for the values missions use (negatives as 0)."""
    if not math.isfinite(v) or v <= 0.0:
        return 0
    return min(math.trunc(v), 0xFFFF)


def _ardupilot_params(it: MissionItem) -> tuple[float, float, float, float]:
    """Params back from AP_Mission's packing for ArduPlane (mission_cmd_to_mavlink_int)."""
    p1, p2, p3, p4 = it.param1, it.param2, it.param3, it.param4
    cmd = it.command
    if cmd == MAV_CMD_NAV_WAYPOINT:
        # Plane: acceptance radius and pass-by distance in the low/high byte of p1.
        return 0.0, float(min(0xFF, _u16(p2))), float(min(0xFF, _u16(p3))), 0.0
    if cmd == MAV_CMD_NAV_LOITER_UNLIM:
        r = float(_u16(abs(p3)))
        return 0.0, 0.0, -r if p3 < 0 else r, 0.0
    if cmd == MAV_CMD_NAV_LOITER_TURNS:
        r = arduplane_loiter_radius_m(p3) if math.isfinite(p3) else 0.0
        return float(_u16(p1) & 0xFF), 0.0, -r if p3 < 0 else r, 1.0 if p4 > 0 else 0.0
    if cmd == MAV_CMD_NAV_LOITER_TIME:
        return float(_u16(p1)), 0.0, -1.0 if p3 < 0 else 1.0, 1.0 if p4 > 0 else 0.0
    if cmd == MAV_CMD_NAV_LAND:
        return float(_u16(p1)), 0.0, 0.0, -1.0 if p4 < 0 else 1.0
    if cmd == MAV_CMD_NAV_TAKEOFF:
        return float(_u16(p1)), 0.0, 0.0, 0.0
    if cmd == MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return 0.0, 0.0, 0.0, 0.0
    if cmd == MAV_CMD_DO_CHANGE_SPEED:
        return float(_u16(p1) & 0xFF), _f32(p2), _f32(p3), 0.0
    return _f32(p1), _f32(p2), _f32(p3), _f32(p4)


def _ardupilot_item(it: MissionItem) -> MissionItem:
    if it.mission_type != MAV_MISSION_TYPE_MISSION:
        return _exact_item(it)
    p1, p2, p3, p4 = _ardupilot_params(it)
    base = replace(it, current=0, autocontinue=1, param1=p1, param2=p2, param3=p3, param4=p4)
    if it.command not in _AP_LOCATION_COMMANDS:
        # DO commands keep no location: x, y, z and the frame come back zero.
        return replace(base, frame=MAV_FRAME_GLOBAL, x=0, y=0, z=0.0)
    if it.frame in RELATIVE_FRAMES:
        frame = MAV_FRAME_GLOBAL_RELATIVE_ALT
    elif it.frame in TERRAIN_FRAMES:
        frame = MAV_FRAME_GLOBAL_TERRAIN_ALT
    else:
        frame = MAV_FRAME_GLOBAL
    return replace(base, frame=frame, z=stored_alt_m(it.z))


def _px4_item(it: MissionItem) -> MissionItem:
    base = _exact_item(it)
    if it.frame == MAV_FRAME_MISSION or it.mission_type != MAV_MISSION_TYPE_MISSION:
        return base
    # format_mavlink_mission_item: a global frame comes back as the _INT frame of its kind,
    # with the params that mission_item_s keeps for the command.
    frame = (
        MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        if it.frame in RELATIVE_FRAMES or it.frame in TERRAIN_FRAMES
        else MAV_FRAME_GLOBAL_INT
    )
    p1, p2, p3, p4 = base.param1, base.param2, base.param3, base.param4
    if it.command == MAV_CMD_NAV_WAYPOINT:
        p3 = 0.0
    elif it.command in (MAV_CMD_NAV_TAKEOFF,):
        p1, p2, p3 = 0.0, 0.0, 0.0
    elif it.command == MAV_CMD_NAV_LAND:
        p1, p3 = 0.0, 0.0
    return replace(base, frame=frame, param1=p1, param2=p2, param3=p3, param4=p4)


def _exact_item(it: MissionItem) -> MissionItem:
    return replace(
        it,
        current=0,
        param1=_f32(it.param1),
        param2=_f32(it.param2),
        param3=_f32(it.param3),
        param4=_f32(it.param4),
        z=_f32(it.z),
    )


_STORED = {
    Autopilot.EXACT: _exact_item,
    Autopilot.ARDUPILOT: _ardupilot_item,
    Autopilot.PX4: _px4_item,
    Autopilot.UNKNOWN: _exact_item,
}


_ANY_FORM = (Autopilot.EXACT, Autopilot.ARDUPILOT, Autopilot.PX4)


def stored_item(item: MissionItem, autopilot: Autopilot) -> MissionItem:
    """The item as ``autopilot`` gives it back when the mission is downloaded.

    ArduPilot (libraries/AP_Mission/AP_Mission.cpp): location commands come back in frame 0,
    3 or 10 whichever variant was sent, the altitude in whole centimetres (truncated), only
    the params the packed command keeps (on Plane NAV_WAYPOINT keeps its acceptance and
    pass-by radii as bytes, NAV_TAKEOFF its pitch as an integer, NAV_LOITER_TURNS its turns
    and stored radius); DO commands come back with frame 0 and no position. PX4
    (src/modules/mavlink/mavlink_mission.cpp): global frames come back as the _INT frame of
    their kind, altitudes as float32, the params mission_item_s keeps. ``current`` is always
    0 (the vehicle sets it) and float fields are float32. EXACT and UNKNOWN: as sent.
    """
    return _STORED[autopilot](item)


def first_difference(
    sent: Sequence[MissionItem],
    got: Sequence[MissionItem],
    *,
    autopilot: Autopilot = Autopilot.EXACT,
    alt_tol_m: float = 1e-3,
    compare_home: bool = True,
) -> int | None:
    """Index of the first item that ``got`` does not hold as ``autopilot`` stores ``sent``.

    None when they agree; ``min(len(sent), len(got))`` when one is a prefix of the other.
    Integers must match exactly, params as float32 (NaN equals NaN), z within ``alt_tol_m``
    (or four float32 steps, if more). An item also agrees when it comes back as sent.
    With ``compare_home=False`` item 0 is skipped (ArduPilot replaces it with its own home).
    """
    for k, (p, q) in enumerate(zip(sent, got, strict=False)):
        if k == 0 and not compare_home:
            continue
        # What the autopilot gives back, or (a vehicle that keeps more) what was sent.
        back = _exact_item(q)
        forms = _ANY_FORM if autopilot is Autopilot.UNKNOWN else (autopilot, Autopilot.EXACT)
        if not any(_item_same(stored_item(p, a), back, alt_tol_m) for a in forms):
            return k
    if len(sent) != len(got):
        return min(len(sent), len(got))
    return None


def _item_same(p: MissionItem, q: MissionItem, alt_tol_m: float) -> bool:
    ints_p = (p.seq, p.frame, p.command, p.current, p.autocontinue, p.x, p.y, p.mission_type)
    ints_q = (q.seq, q.frame, q.command, q.current, q.autocontinue, q.x, q.y, q.mission_type)
    if ints_p != ints_q:
        return False
    params = zip(
        (p.param1, p.param2, p.param3, p.param4),
        (q.param1, q.param2, q.param3, q.param4),
        strict=True,
    )
    if not all(_same_f32(u, v) for u, v in params):
        return False
    if math.isnan(p.z) or math.isnan(q.z):
        return math.isnan(p.z) and math.isnan(q.z)
    # A few float32 steps at least: above 8 km they are larger than a millimetre.
    return abs(p.z - q.z) <= max(alt_tol_m, abs(p.z) * 2.0**-21)


def items_equal(
    a: Sequence[MissionItem],
    b: Sequence[MissionItem],
    *,
    alt_tol_m: float = 1e-3,
    compare_home: bool = True,
    autopilot: Autopilot | None = None,
) -> bool:
    """True if two missions are the same on the wire (or, with ``autopilot``, the same once
    that autopilot has stored them: see :func:`first_difference`).

    Without ``autopilot``: integers must match exactly (``current`` included); params must be
    equal as float32 (NaN equals NaN); z within ``alt_tol_m``. With ``compare_home=False``
    item 0 is skipped (ArduPilot replaces it with its own home).
    """
    if autopilot is not None:
        found = first_difference(
            a, b, autopilot=autopilot, alt_tol_m=alt_tol_m, compare_home=compare_home
        )
        return found is None
    if len(a) != len(b):
        return False
    return all(
        (k == 0 and not compare_home) or _item_same(p, q, alt_tol_m)
        for k, (p, q) in enumerate(zip(a, b, strict=True))
    )


def command_name(command: int) -> str:
    """MAV_CMD name without the prefix for the commands this module knows, else the number."""
    return _COMMAND_NAMES.get(command, str(command))


def describe(items: Sequence[MissionItem]) -> str:
    """A fixed-width table of the items, one line each, for logs and the CLI."""
    head = (
        f"{'seq':>4} {'command':<16} {'frame':<11} {'param1':>8} {'param2':>8} {'param3':>8} "
        f"{'param4':>7} {'lat_deg':>12} {'lon_deg':>13} {'z_m':>9}"
    )
    lines = [head]
    for it in items:
        name = command_name(it.command)
        if it.seq == 0 and it.command == MAV_CMD_NAV_WAYPOINT:
            name = "HOME"
        frame = _FRAME_NAMES.get(it.frame, str(it.frame))
        if it.frame in GLOBAL_FRAMES:
            lat, lon = f"{it.x / 1e7:12.7f}", f"{it.y / 1e7:13.7f}"
        else:
            lat, lon = f"{it.x:12d}", f"{it.y:13d}"
        lines.append(
            f"{it.seq:>4} {name:<16} {frame:<11} {it.param1:8.6g} {it.param2:8.6g} "
            f"{it.param3:8.6g} {it.param4:7.6g} {lat} {lon} {it.z:9.2f}"
        )
    return "\n".join(lines)
