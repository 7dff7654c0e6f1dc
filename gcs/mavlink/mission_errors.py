"""Errors of the mission-transfer client: one class per MAV_MISSION_RESULT family.

Every error names the vehicle, the operation and, when known, the item, e.g.
``vehicle 1: mission upload rejected item 37: MAV_MISSION_INVALID_PARAM2 (param2 out of
range)``. :func:`error_for_result` builds the right subclass from a MISSION_ACK result.
"""

from __future__ import annotations

from gcs.errors import GcsError

__all__ = [
    "MAV_MISSION_RESULT_NAMES",
    "MissionCancelled",
    "MissionDenied",
    "MissionError",
    "MissionInputError",
    "MissionInvalidItem",
    "MissionInvalidSequence",
    "MissionMismatch",
    "MissionNoSpace",
    "MissionProtocolError",
    "MissionTimeout",
    "MissionUnsupported",
    "MissionUnsupportedFrame",
    "error_for_result",
    "mission_type_name",
    "result_name",
]

# MAV_MISSION_RESULT (common.xml); checked against pymavlink's dialect by the tests.
MAV_MISSION_ACCEPTED = 0
MAV_MISSION_ERROR = 1
MAV_MISSION_UNSUPPORTED_FRAME = 2
MAV_MISSION_UNSUPPORTED = 3
MAV_MISSION_NO_SPACE = 4
MAV_MISSION_INVALID = 5
MAV_MISSION_INVALID_PARAM1 = 6
MAV_MISSION_INVALID_PARAM7 = 12
MAV_MISSION_INVALID_SEQUENCE = 13
MAV_MISSION_DENIED = 14
MAV_MISSION_OPERATION_CANCELLED = 15

MAV_MISSION_RESULT_NAMES: dict[int, tuple[str, str]] = {
    0: ("MAV_MISSION_ACCEPTED", "accepted"),
    1: ("MAV_MISSION_ERROR", "generic error, or not accepting mission commands now"),
    2: ("MAV_MISSION_UNSUPPORTED_FRAME", "coordinate frame not supported"),
    3: ("MAV_MISSION_UNSUPPORTED", "command not supported"),
    4: ("MAV_MISSION_NO_SPACE", "more items than the vehicle can store"),
    5: ("MAV_MISSION_INVALID", "a parameter has an invalid value"),
    6: ("MAV_MISSION_INVALID_PARAM1", "param1 out of range"),
    7: ("MAV_MISSION_INVALID_PARAM2", "param2 out of range"),
    8: ("MAV_MISSION_INVALID_PARAM3", "param3 out of range"),
    9: ("MAV_MISSION_INVALID_PARAM4", "param4 out of range"),
    10: ("MAV_MISSION_INVALID_PARAM5_X", "x/param5 (latitude) out of range"),
    11: ("MAV_MISSION_INVALID_PARAM6_Y", "y/param6 (longitude) out of range"),
    12: ("MAV_MISSION_INVALID_PARAM7", "z/param7 (altitude) out of range"),
    13: ("MAV_MISSION_INVALID_SEQUENCE", "item out of sequence"),
    14: ("MAV_MISSION_DENIED", "not accepting mission commands from this GCS now"),
    15: ("MAV_MISSION_OPERATION_CANCELLED", "the vehicle cancelled the operation"),
}

_MISSION_TYPE_NAMES = {0: "mission", 1: "fence", 2: "rally", 255: "all-types"}


def result_name(result: int) -> str:
    """``MAV_MISSION_INVALID_PARAM2 (param2 out of range)``, or the bare number if unknown."""
    known = MAV_MISSION_RESULT_NAMES.get(result)
    if known is None:
        return f"MAV_MISSION_RESULT {result} (unknown result)"
    return f"{known[0]} ({known[1]})"


def mission_type_name(mission_type: int) -> str:
    """``mission``, ``fence``, ``rally`` (MAV_MISSION_TYPE 0, 1, 2), else ``type N``."""
    return _MISSION_TYPE_NAMES.get(mission_type, f"type-{mission_type}")


class MissionError(GcsError):
    """A mission transfer failed; also the class for MAV_MISSION_ERROR and unknown results.

    Attributes: ``result`` (the MAV_MISSION_RESULT of the vehicle's MISSION_ACK, or None when
    the vehicle did not give one), ``vehicle`` (system id), ``seq`` (item index or None),
    ``mission_type`` and ``operation`` (``upload``, ``download``, ``clear``, ``set-current``).
    """

    def __init__(
        self,
        message: str,
        *,
        vehicle: int,
        result: int | None = None,
        seq: int | None = None,
        mission_type: int = 0,
        operation: str = "",
    ) -> None:
        super().__init__(message)
        self.result = result
        self.vehicle = vehicle
        self.seq = seq
        self.mission_type = mission_type
        self.operation = operation


class MissionDenied(MissionError):
    """MAV_MISSION_DENIED: the vehicle is busy (e.g. another GCS is uploading)."""


class MissionUnsupported(MissionError):
    """MAV_MISSION_UNSUPPORTED: a command (or mission type) the vehicle does not support."""


class MissionUnsupportedFrame(MissionUnsupported):
    """MAV_MISSION_UNSUPPORTED_FRAME: a coordinate frame the vehicle does not support."""


class MissionNoSpace(MissionError):
    """MAV_MISSION_NO_SPACE: more items than the vehicle stores."""


class MissionInvalidItem(MissionError):
    """MAV_MISSION_INVALID, MAV_MISSION_INVALID_PARAM1..7: an item has an invalid field."""


class MissionInvalidSequence(MissionInvalidItem):
    """MAV_MISSION_INVALID_SEQUENCE: an item or request out of sequence."""


class MissionCancelled(MissionError):
    """MAV_MISSION_OPERATION_CANCELLED: the vehicle gave up (it timed out waiting for us)."""


class MissionTimeout(MissionError, TimeoutError):
    """The vehicle did not answer within the retries; the message names what was awaited."""


class MissionProtocolError(MissionError):
    """The vehicle broke the mission protocol (e.g. requested items that do not exist)."""


class MissionMismatch(MissionError):
    """A verifying download after an upload did not give back the items sent."""


class MissionInputError(MissionError, ValueError):
    """Items that cannot be sent (wrong seq, mission type or field range); names the item."""


_CLASS_BY_RESULT: dict[int, type[MissionError]] = {
    MAV_MISSION_ERROR: MissionError,
    MAV_MISSION_UNSUPPORTED_FRAME: MissionUnsupportedFrame,
    MAV_MISSION_UNSUPPORTED: MissionUnsupported,
    MAV_MISSION_NO_SPACE: MissionNoSpace,
    MAV_MISSION_INVALID_SEQUENCE: MissionInvalidSequence,
    MAV_MISSION_DENIED: MissionDenied,
    MAV_MISSION_OPERATION_CANCELLED: MissionCancelled,
}
_CLASS_BY_RESULT.update(
    {r: MissionInvalidItem for r in range(MAV_MISSION_INVALID, MAV_MISSION_INVALID_PARAM7 + 1)}
)


def describe_operation(vehicle: int, mission_type: int, operation: str) -> str:
    """``vehicle 1: fence upload`` (set-current has no mission type in its name)."""
    if operation == "set-current":
        return f"vehicle {vehicle}: mission set-current"
    return f"vehicle {vehicle}: {mission_type_name(mission_type)} {operation}"


def error_for_result(
    result: int,
    *,
    vehicle: int,
    seq: int | None,
    mission_type: int,
    operation: str,
) -> MissionError:
    """The typed error for a MISSION_ACK ``result`` that ended ``operation``.

    ``seq`` is the item the vehicle was processing (for an upload, the last item it
    requested), or None when the error is about the whole transfer.
    """
    cls = _CLASS_BY_RESULT.get(result, MissionError)
    if result == MAV_MISSION_DENIED:
        verb = "denied"
    elif result == MAV_MISSION_OPERATION_CANCELLED:
        verb = "cancelled by the vehicle"
    else:
        verb = "rejected"
    where = ""
    if seq is not None:
        where = f" item {seq}" if verb == "rejected" else f" at item {seq}"
    message = (
        f"{describe_operation(vehicle, mission_type, operation)} {verb}{where}: "
        f"{result_name(result)}"
    )
    return cls(
        message,
        vehicle=vehicle,
        result=result,
        seq=seq,
        mission_type=mission_type,
        operation=operation,
    )
