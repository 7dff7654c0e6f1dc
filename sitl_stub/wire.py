"""MAVLink 2 framing for the stub's hot path: byte-identical to pymavlink's ``pack``, cheaper.

pymavlink builds a message object, a header object and a bytearray per packet (about 6-8 us);
telemetry at 100x for ten vehicles is over 10,000 packets per wall second, so the stub's
streams skip the objects: a builder returns the field values (in the order of the pymavlink
constructor) and :meth:`Packer.pack` frames them with the message's own ``struct`` layout and
CRC extra, taken from the pymavlink dialect class. ``tests/sitl_stub/test_wire.py`` checks the
bytes against pymavlink's for every streamed message.

Messages with array or char fields (HOME_POSITION, AUTOPILOT_VERSION, STATUSTEXT, ...) are
rare and go through pymavlink (:meth:`Packer.pack_message`). Both paths share the sequence
number of the source, which advances by one per packet (pymavlink's ``pack`` alone leaves it
at 0; ``MAVLink.send`` is what advances it).
"""

from __future__ import annotations

import inspect
import operator
import struct
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
_STX_V2 = 253

_mcrf4xx: Callable[..., int] | None = getattr(mavlink2, "mcrf4xx", None)


def _crc_slow(data: bytes, extra: bytes) -> int:
    crc = mavlink2.x25crc(data)
    crc.accumulate(extra)
    return int(crc.crc)


class MessageSpec:
    """Framing data of one MAVLink message type, from its pymavlink class."""

    __slots__ = (
        "_defaults",
        "_order",
        "cls",
        "crc_extra",
        "fast",
        "msg_id",
        "n_fields",
        "name",
        "struct",
    )

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.name: str = cls.msgname
        self.msg_id: int = int(cls.id)
        self.crc_extra = bytes([cls.crc_extra])
        self.n_fields = len(cls.fieldnames)
        # The wire layout (largest types first) is cls.unpacker; arrays and chars need
        # flattening or encoding, so those messages take pymavlink's path.
        self.fast: bool = not any(cls.array_lengths) and b"c" not in bytes(cls.native_format)
        self.struct: struct.Struct = cls.unpacker
        perm = [cls.fieldnames.index(n) for n in cls.ordered_fieldnames]
        self._order: Callable[[tuple[Any, ...]], tuple[Any, ...]] | None = (
            None if perm == list(range(len(perm))) else operator.itemgetter(*perm)
        )
        params = list(inspect.signature(cls.__init__).parameters.values())[1:]
        self._defaults = tuple(p.default for p in params)

    def complete(self, values: tuple[Any, ...]) -> tuple[Any, ...]:
        """``values`` with omitted trailing (extension) fields set to pymavlink's defaults."""
        if len(values) == self.n_fields:
            return values
        tail = self._defaults[len(values) :]
        if any(d is inspect.Parameter.empty for d in tail):
            raise TypeError(f"{self.name}: {len(values)} values for {self.n_fields} fields")
        return values + tail

    def message(self, values: tuple[Any, ...]) -> Any:
        """The pymavlink message object with these field values."""
        return self.cls(*values)

    def payload(self, values: tuple[Any, ...]) -> bytes:
        """The untruncated payload in wire order (``fast`` specs only)."""
        v = self.complete(values)
        if self._order is not None:
            v = self._order(v)
        return self.struct.pack(*v)


def spec_for(name: str) -> MessageSpec:
    """The spec of a message by its MAVLink name (``"GLOBAL_POSITION_INT"``)."""
    return MessageSpec(getattr(mavlink2, f"MAVLink_{name.lower()}_message"))


class Packer:
    """Frames packets from one source (system, component) with one sequence counter."""

    __slots__ = ("_mav", "_sys_comp")

    def __init__(self, system_id: int, component_id: int) -> None:
        self._mav = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._sys_comp = (system_id, component_id)

    @property
    def seq(self) -> int:
        """Sequence number of the next packet."""
        return int(self._mav.seq)

    def pack(self, spec: MessageSpec, values: tuple[Any, ...]) -> bytes:
        """One MAVLink 2 packet with these field values (constructor order)."""
        if not spec.fast:
            return self.pack_message(spec.message(values))
        if len(values) != spec.n_fields:
            values = spec.complete(values)
        order = spec._order
        if order is not None:
            values = order(values)
        # MAVLink 2 drops trailing zero bytes of the payload (keeping at least one).
        payload = spec.struct.pack(*values).rstrip(b"\x00") or b"\x00"
        mav = self._mav
        seq = mav.seq
        mav.seq = (seq + 1) & 0xFF
        sysid, compid = self._sys_comp
        msg_id = spec.msg_id
        frame = (
            _HEADER.pack(
                _STX_V2, len(payload), 0, 0, seq, sysid, compid, msg_id & 0xFFFF, msg_id >> 16
            )
            + payload
        )
        if _mcrf4xx is not None:
            crc = _mcrf4xx(spec.crc_extra, _mcrf4xx(frame[1:]))
        else:
            crc = _crc_slow(frame[1:], spec.crc_extra)
        return frame + _CRC.pack(crc)

    def pack_message(self, msg: Any) -> bytes:
        """A pymavlink message object, framed by pymavlink, on this source's sequence."""
        mav = self._mav
        data = bytes(msg.pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF
        return data
