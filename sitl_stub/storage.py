"""Mission items in the form ArduPilot stores them, and the form it reads them back in.

ArduPilot does not keep the MISSION_ITEM_INT it was sent: ``AP_Mission::mavlink_int_to_mission_cmd``
packs each item into a 15-byte ``Mission_Command`` (a 16-bit ``p1``, a ``PackedLocation`` with a
24-bit altitude in centimetres, or a command-specific struct), and a download rebuilds the item
with ``AP_Mission::mission_cmd_to_mavlink_int``. :func:`stored_item` is that round trip, written
from libraries/AP_Mission/AP_Mission.cpp (ArduPlane build) with the arithmetic in float32 as the
C++ does it:

- Location commands (NAV_WAYPOINT, NAV_LOITER_*, NAV_LAND, NAV_TAKEOFF, DO_LAND_START): the
  frame reads back as MAV_FRAME_GLOBAL (0), GLOBAL_RELATIVE_ALT (3) or GLOBAL_TERRAIN_ALT (10),
  whichever variant (``_INT`` or not, or MAV_FRAME_MISSION) was sent; the altitude is
  ``int32(float32(z) * 100f)`` centimetres (truncated toward zero) and reads back as
  ``float32(alt_cm) * 0.01f``.
- Every other command (DO_CHANGE_SPEED, NAV_RETURN_TO_LAUNCH): frame 0, x = y = z = 0.
- Parameters, per command: see the table in :func:`stored_item`.
- ``autocontinue`` reads back as 1 and ``current`` as 0 (the mission server sets ``current``
  as ``MissionItemProtocol_Waypoints::get_item`` does, see there).

Float-to-integer conversions outside the integer's range are undefined in C; here they behave
as they do in SITL on x86-64 (truncate to int32, keep the low bits; NaN and out-of-range give
0x80000000). The mission server refuses most such values before they get here.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from sitl_stub.items import MissionItem

_F32 = np.float32
_HUNDRED_F = np.float32(100.0)
_CENTI_F = np.float32(0.01)
_E7_F = np.float32(1.0e7)
_E_7_F = np.float32(1.0e-7)
_FLT_EPSILON = float(np.finfo(np.float32).eps)

_WAYPOINT = int(mav.MAV_CMD_NAV_WAYPOINT)
_LOITER_UNLIM = int(mav.MAV_CMD_NAV_LOITER_UNLIM)
_LOITER_TURNS = int(mav.MAV_CMD_NAV_LOITER_TURNS)
_LOITER_TIME = int(mav.MAV_CMD_NAV_LOITER_TIME)
_LAND = int(mav.MAV_CMD_NAV_LAND)
_TAKEOFF = int(mav.MAV_CMD_NAV_TAKEOFF)
_CHANGE_SPEED = int(mav.MAV_CMD_DO_CHANGE_SPEED)
_LAND_START = int(mav.MAV_CMD_DO_LAND_START)

# AP_Mission::stored_in_location, restricted to the commands the stub accepts.
LOCATION_COMMANDS = frozenset(
    {_WAYPOINT, _LOITER_UNLIM, _LOITER_TURNS, _LOITER_TIME, _LAND, _TAKEOFF, _LAND_START}
)

_ABSOLUTE_FRAMES = frozenset(
    {int(mav.MAV_FRAME_MISSION), int(mav.MAV_FRAME_GLOBAL), int(mav.MAV_FRAME_GLOBAL_INT)}
)
_RELATIVE_FRAMES = frozenset(
    {int(mav.MAV_FRAME_GLOBAL_RELATIVE_ALT), int(mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)}
)
_TERRAIN_FRAMES = frozenset(
    {int(mav.MAV_FRAME_GLOBAL_TERRAIN_ALT), int(mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)}
)
STORABLE_FRAMES = _ABSOLUTE_FRAMES | _RELATIVE_FRAMES | _TERRAIN_FRAMES


def f32(value: float) -> float:
    """``value`` rounded to float32 (what a C ``float`` holds)."""
    return float(_F32(value))


def _c_int32(value: float) -> int:
    """C's float -> int32 conversion on x86-64: truncation; NaN/out of range -> INT32_MIN."""
    if not math.isfinite(value):
        return -(1 << 31)
    t = math.trunc(value)
    return t if -(1 << 31) <= t < (1 << 31) else -(1 << 31)


def c_unsigned(value: float, bits: int) -> int:
    """C's float -> uintN_t conversion as SITL on x86-64 does it (via int32, low bits kept)."""
    return _c_int32(value) & ((1 << bits) - 1)


def alt_cm(z_m: float) -> int:
    """``Location::alt`` from a packet's z: ``z * 100.0f`` in float32, truncated toward zero."""
    cm = _c_int32(float(_F32(z_m) * _HUNDRED_F))
    # PackedLocation keeps 24 bits (sign-extended on read).
    cm &= 0xFFFFFF
    return cm - (1 << 24) if cm & 0x800000 else cm


def alt_m_from_cm(cm: int) -> float:
    """The z a download carries for a stored altitude: ``alt * 0.01f`` in float32."""
    return float(_F32(cm) * _CENTI_F)


def stored_alt_m(z_m: float) -> float:
    """The altitude (m) an item sent with ``z_m`` reads back with."""
    return alt_m_from_cm(alt_cm(z_m))


def legacy_x_to_int(x_deg: float) -> int:
    """MISSION_ITEM lat/lon (float32 degrees) to int 1e7: ``x * 1.0e7f``, truncated."""
    return _c_int32(float(_F32(x_deg) * _E7_F))


def legacy_x_from_int(x_e7: int) -> float:
    """Int 1e7 lat/lon to MISSION_ITEM's float32 degrees: ``x * 1.0e-7f``."""
    return float(_F32(x_e7) * _E_7_F)


def _stored_frame(frame: int) -> int:
    if frame in _RELATIVE_FRAMES:
        return int(mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
    if frame in _TERRAIN_FRAMES:
        return int(mav.MAV_FRAME_GLOBAL_TERRAIN_ALT)
    return int(mav.MAV_FRAME_GLOBAL)


def _loiter_turns_params(turns: float, radius: float, xtrack: float) -> tuple[float, float, float]:
    """NAV_LOITER_TURNS: turns in p1's low byte, radius in its high byte (x10 above 255 m)."""
    p1 = c_unsigned(min(255.0, turns), 16)
    abs_radius = abs(f32(radius))
    if abs_radius <= 255.0:
        radius_byte = c_unsigned(abs_radius, 8)
        times_ten = False
    else:
        radius_byte = c_unsigned(min(255.0, abs_radius * 0.1), 8)
        times_ten = True
    p1 |= radius_byte << 8
    read_radius = float(p1 >> 8 & 0xFF)
    if radius < 0.0:
        read_radius = -read_radius
    if times_ten:
        read_radius *= 10.0
    return float(p1 & 0xFF), read_radius, 1.0 if xtrack > 0.0 else 0.0


def stored_item(item: MissionItem) -> MissionItem:
    """``item`` as an ArduPlane stores it and reads it back (AP_Mission.cpp, see module doc).

    ================  ======================================================================
    command           parameters read back
    ================  ======================================================================
    NAV_WAYPOINT      param2 (acceptance) and param3 (pass-by) as whole metres capped at 255;
                      param1, param4 0
    NAV_LOITER_UNLIM  param3: the radius as a uint16, with its sign (direction)
    NAV_LOITER_TURNS  param1: whole turns (low byte); param3: the radius in whole metres up
                      to 255, above that in 10 m steps (tenths truncated, capped at 255),
                      signed; param4: 1 if it was > 0, else 0
    NAV_LOITER_TIME   param1: whole seconds (uint16); param3: -1 (counter-clockwise) or 1;
                      param4: 1 if it was > 0, else 0
    NAV_LAND          param1: uint16 (abort altitude); param4: -1 if it was negative, else 1
    NAV_TAKEOFF       param1: uint16 (minimum pitch)
    DO_CHANGE_SPEED   param1: uint8 (speed type); param2, param3 float32; param4 0
    others            all parameters 0 (DO_LAND_START keeps only its location)
    ================  ======================================================================
    """
    cmd = item.command
    p1 = p2 = p3 = p4 = 0.0
    if cmd == _WAYPOINT:
        p2 = float(min(0xFF, c_unsigned(item.param2, 16)))
        p3 = float(min(0xFF, c_unsigned(item.param3, 16)))
    elif cmd == _LOITER_UNLIM:
        p3 = float(c_unsigned(abs(item.param3), 16))
        if item.param3 < 0.0:
            p3 = -p3
    elif cmd == _LOITER_TURNS:
        p1, p3, p4 = _loiter_turns_params(item.param1, item.param3, item.param4)
    elif cmd == _LOITER_TIME:
        p1 = float(c_unsigned(item.param1, 16))
        p3 = -1.0 if item.param3 < 0.0 else 1.0
        p4 = 1.0 if item.param4 > 0.0 else 0.0
    elif cmd == _LAND:
        p1 = float(c_unsigned(item.param1, 16))
        ccw = not math.isnan(item.param4) and item.param4 <= -_FLT_EPSILON
        p4 = -1.0 if ccw else 1.0
    elif cmd == _TAKEOFF:
        p1 = float(c_unsigned(item.param1, 16))
    elif cmd == _CHANGE_SPEED:
        p1 = float(c_unsigned(item.param1, 8))
        p2 = f32(item.param2)
        p3 = f32(item.param3)
    if cmd in LOCATION_COMMANDS:
        frame = _stored_frame(item.frame)
        x, y, z = item.x, item.y, stored_alt_m(item.z)
    else:
        frame, x, y, z = int(mav.MAV_FRAME_GLOBAL), 0, 0, 0.0
    return replace(
        item,
        frame=frame,
        current=0,
        autocontinue=1,
        param1=p1,
        param2=p2,
        param3=p3,
        param4=p4,
        x=x,
        y=y,
        z=z,
    )
