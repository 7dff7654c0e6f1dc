"""Flight-mode tables: ArduPlane and PX4 custom modes by name and by number.

ArduPilot puts the mode number in HEARTBEAT ``custom_mode`` and takes it as param2 of
MAV_CMD_DO_SET_MODE. PX4 packs a main mode and a sub mode into ``custom_mode``
(``(main << 16) | (sub << 24)``, ``px4_custom_mode.h``) and takes them apart in DO_SET_MODE
(param2 main, param3 sub). Names are looked up case-insensitively; PX4 names are QGroundControl's
and MAVSDK's (``AUTO.MISSION``), with pymavlink's short names (``MISSION``) as aliases.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Final

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

AUTOPILOT_ARDUPILOT: Final = int(mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA)
AUTOPILOT_PX4: Final = int(mavlink2.MAV_AUTOPILOT_PX4)
_CUSTOM_MODE_ENABLED: Final = int(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)

# ArduPlane's Mode::Number (ArduPlane/mode.h); names as ArduPilot GCSs show them.
ARDUPLANE_MODES: Final[MappingProxyType[str, int]] = MappingProxyType(
    {
        "MANUAL": 0,
        "CIRCLE": 1,
        "STABILIZE": 2,
        "TRAINING": 3,
        "ACRO": 4,
        "FBWA": 5,
        "FBWB": 6,
        "CRUISE": 7,
        "AUTOTUNE": 8,
        "AUTO": 10,
        "RTL": 11,
        "LOITER": 12,
        "TAKEOFF": 13,
        "AVOID_ADSB": 14,
        "GUIDED": 15,
        "INITIALISING": 16,
        "QSTABILIZE": 17,
        "QHOVER": 18,
        "QLOITER": 19,
        "QLAND": 20,
        "QRTL": 21,
        "QAUTOTUNE": 22,
        "QACRO": 23,
        "THERMAL": 24,
        "LOITERALTQLAND": 25,
        "AUTOLAND": 26,
    }
)
# Alternative spellings accepted on input (ArduPilot's own enum names).
_ARDUPLANE_ALIASES: Final = {
    "FLY_BY_WIRE_A": "FBWA",
    "FLY_BY_WIRE_B": "FBWB",
    "LOITER_ALT_QLAND": "LOITERALTQLAND",
}

# PX4 px4_custom_mode.h
PX4_MAIN_MANUAL: Final = 1
PX4_MAIN_ALTCTL: Final = 2
PX4_MAIN_POSCTL: Final = 3
PX4_MAIN_AUTO: Final = 4
PX4_MAIN_ACRO: Final = 5
PX4_MAIN_OFFBOARD: Final = 6
PX4_MAIN_STABILIZED: Final = 7
PX4_MAIN_RATTITUDE: Final = 8
PX4_MAIN_TERMINATION: Final = 10


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """HEARTBEAT ``custom_mode`` of a PX4 main/sub mode pair."""
    if not (0 <= main_mode <= 255 and 0 <= sub_mode <= 255):
        raise ValueError(f"PX4 main/sub mode {main_mode}/{sub_mode} outside 0..255")
    return (main_mode << 16) | (sub_mode << 24)


def px4_main_sub(custom_mode: int) -> tuple[int, int]:
    """(main mode, sub mode) of a PX4 HEARTBEAT ``custom_mode``."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


PX4_MODES: Final[MappingProxyType[str, int]] = MappingProxyType(
    {
        "MANUAL": px4_custom_mode(PX4_MAIN_MANUAL),
        "ALTCTL": px4_custom_mode(PX4_MAIN_ALTCTL),
        "POSCTL": px4_custom_mode(PX4_MAIN_POSCTL),
        "POSCTL.ORBIT": px4_custom_mode(PX4_MAIN_POSCTL, 1),
        "AUTO.READY": px4_custom_mode(PX4_MAIN_AUTO, 1),
        "AUTO.TAKEOFF": px4_custom_mode(PX4_MAIN_AUTO, 2),
        "AUTO.LOITER": px4_custom_mode(PX4_MAIN_AUTO, 3),
        "AUTO.MISSION": px4_custom_mode(PX4_MAIN_AUTO, 4),
        "AUTO.RTL": px4_custom_mode(PX4_MAIN_AUTO, 5),
        "AUTO.LAND": px4_custom_mode(PX4_MAIN_AUTO, 6),
        "AUTO.RTGS": px4_custom_mode(PX4_MAIN_AUTO, 7),
        "AUTO.FOLLOW_TARGET": px4_custom_mode(PX4_MAIN_AUTO, 8),
        "AUTO.PRECLAND": px4_custom_mode(PX4_MAIN_AUTO, 9),
        "AUTO.VTOL_TAKEOFF": px4_custom_mode(PX4_MAIN_AUTO, 10),
        "ACRO": px4_custom_mode(PX4_MAIN_ACRO),
        "OFFBOARD": px4_custom_mode(PX4_MAIN_OFFBOARD),
        "STABILIZED": px4_custom_mode(PX4_MAIN_STABILIZED),
        "RATTITUDE": px4_custom_mode(PX4_MAIN_RATTITUDE),
        "TERMINATION": px4_custom_mode(PX4_MAIN_TERMINATION),
    }
)
# pymavlink's / MAVProxy's short names for the AUTO sub modes.
_PX4_ALIASES: Final = {
    "READY": "AUTO.READY",
    "TAKEOFF": "AUTO.TAKEOFF",
    "LOITER": "AUTO.LOITER",
    "MISSION": "AUTO.MISSION",
    "RTL": "AUTO.RTL",
    "LAND": "AUTO.LAND",
    "RTGS": "AUTO.RTGS",
    "FOLLOWME": "AUTO.FOLLOW_TARGET",
    "FOLLOW_TARGET": "AUTO.FOLLOW_TARGET",
    "PRECLAND": "AUTO.PRECLAND",
    "ORBIT": "POSCTL.ORBIT",
}

_ARDUPLANE_BY_NUMBER: Final = {n: name for name, n in ARDUPLANE_MODES.items()}
_PX4_BY_NUMBER: Final = {n: name for name, n in PX4_MODES.items()}
# PX4 ignores the sub mode of the main modes that have none.
_PX4_MAIN_NAMES: Final = {
    px4_main_sub(n)[0]: name for name, n in PX4_MODES.items() if "." not in name
}


def _table(autopilot: int) -> tuple[MappingProxyType[str, int], dict[str, str]]:
    if autopilot == AUTOPILOT_ARDUPILOT:
        return ARDUPLANE_MODES, _ARDUPLANE_ALIASES
    if autopilot == AUTOPILOT_PX4:
        return PX4_MODES, _PX4_ALIASES
    raise ValueError(
        f"no mode table for autopilot {autopilot} ({_autopilot_name(autopilot)}): "
        "only MAV_AUTOPILOT_ARDUPILOTMEGA and MAV_AUTOPILOT_PX4 are known"
    )


def _autopilot_name(autopilot: int) -> str:
    entry = mavlink2.enums["MAV_AUTOPILOT"].get(autopilot)
    return entry.name if entry is not None else f"MAV_AUTOPILOT({autopilot})"


def mode_names(autopilot: int) -> tuple[str, ...]:
    """The canonical mode names of an autopilot, in mode-number order."""
    table, _ = _table(autopilot)
    return tuple(sorted(table, key=table.__getitem__))


def mode_number(name: str, autopilot: int) -> int:
    """HEARTBEAT ``custom_mode`` of a mode name (case-insensitive); ValueError if unknown."""
    table, aliases = _table(autopilot)
    key = name.strip().upper()
    key = aliases.get(key, key)
    number = table.get(key)
    if number is None:
        valid = ", ".join(mode_names(autopilot))
        raise ValueError(
            f"unknown {_autopilot_name(autopilot)} mode {name!r}; valid modes: {valid}"
        )
    return number


def mode_name(custom_mode: int, autopilot: int, base_mode: int | None = None) -> str:
    """Canonical name of a HEARTBEAT mode; ``MODE(n)`` when unknown.

    With ``base_mode`` given and MAV_MODE_FLAG_CUSTOM_MODE_ENABLED clear, ``custom_mode`` means
    nothing and the result is ``BASE_MODE(0x..)``.
    """
    if base_mode is not None and not base_mode & _CUSTOM_MODE_ENABLED:
        return f"BASE_MODE(0x{base_mode:02x})"
    if autopilot == AUTOPILOT_ARDUPILOT:
        name = _ARDUPLANE_BY_NUMBER.get(custom_mode)
    elif autopilot == AUTOPILOT_PX4:
        name = _PX4_BY_NUMBER.get(custom_mode)
        if name is None and not custom_mode & 0xFFFF:
            main, _sub = px4_main_sub(custom_mode)
            name = _PX4_MAIN_NAMES.get(main) if main != PX4_MAIN_AUTO else None
    else:
        name = None
    return name if name is not None else f"MODE({custom_mode})"
