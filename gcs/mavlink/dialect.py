"""The MAVLink dialect gcs speaks (ArduPilot's, a superset of common) and name lookups."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

MESSAGE_BY_NAME: dict[str, Any] = {cls.msgname: cls for cls in mavlink2.mavlink_map.values()}
"""Message class by name, e.g. ``MESSAGE_BY_NAME["GLOBAL_POSITION_INT"].id == 33``."""


def message_id(name: str) -> int:
    """The id of message ``name``; ValueError names an unknown message."""
    cls = MESSAGE_BY_NAME.get(name.upper())
    if cls is None:
        raise ValueError(f"unknown MAVLink message {name!r}")
    return int(cls.id)


__all__ = ["MESSAGE_BY_NAME", "mavlink2", "message_id"]
