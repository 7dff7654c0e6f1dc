"""Connection strings (pymavlink style) parsed into endpoint values; no I/O here.

Accepted forms::

    tcp:HOST:PORT          connect to a TCP server (ArduPilot SITL, the stub, a radio bridge)
    udpin:HOST:PORT        listen for UDP on HOST:PORT; replies go to whoever sent to us
    udp:HOST:PORT          same as udpin (pymavlink's meaning)
    udpout:HOST:PORT       send UDP to HOST:PORT (and receive the replies)
    serial:DEVICE[:BAUD]   a serial port, e.g. serial:/dev/ttyUSB0:57600
    DEVICE[,BAUD]          a path such as /dev/ttyACM0,115200 (MAVProxy style)
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from gcs.errors import ConnectionStringError

DEFAULT_BAUD = 57600


class Kind(enum.Enum):
    TCP = "tcp"
    UDPIN = "udpin"
    UDPOUT = "udpout"
    SERIAL = "serial"


@dataclass(frozen=True, slots=True)
class Endpoint:
    """Where a link goes: ``host``/``port`` for TCP and UDP, ``device``/``baud`` for serial."""

    kind: Kind
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = DEFAULT_BAUD

    def __str__(self) -> str:
        if self.kind is Kind.SERIAL:
            return f"serial:{self.device}:{self.baud}"
        return f"{self.kind.value}:{self.host}:{self.port}"


def _host_port(text: str, rest: str) -> tuple[str, int]:
    host, sep, port_text = rest.rpartition(":")
    if not sep or not host:
        raise ConnectionStringError(f"connection {text!r}: expected HOST:PORT after the scheme")
    try:
        port = int(port_text)
    except ValueError:
        raise ConnectionStringError(
            f"connection {text!r}: port {port_text!r} is not a number"
        ) from None
    if not 0 < port < 65536:
        raise ConnectionStringError(f"connection {text!r}: port {port} is outside 1..65535")
    return host.strip("[]"), port


def _baud(text: str, baud_text: str) -> int:
    try:
        baud = int(baud_text)
    except ValueError:
        raise ConnectionStringError(
            f"connection {text!r}: baud rate {baud_text!r} is not a number"
        ) from None
    if baud <= 0:
        raise ConnectionStringError(f"connection {text!r}: baud rate {baud} must be positive")
    return baud


def parse_connection(text: str) -> Endpoint:
    """Parse a connection string; :class:`ConnectionStringError` names what is wrong."""
    s = text.strip()
    if not s:
        raise ConnectionStringError("connection string is empty")
    scheme, sep, rest = s.partition(":")
    scheme = scheme.lower()
    if sep and scheme in ("tcp", "udp", "udpin", "udpout"):
        host, port = _host_port(text, rest)
        kind = {"tcp": Kind.TCP, "udp": Kind.UDPIN, "udpin": Kind.UDPIN}.get(scheme, Kind.UDPOUT)
        return Endpoint(kind, host=host, port=port)
    if sep and scheme == "serial":
        device, baud_sep, baud_text = rest.rpartition(":")
        if not baud_sep:
            device, baud_text = rest, ""
        if not device:
            raise ConnectionStringError(f"connection {text!r}: no serial device given")
        baud = _baud(text, baud_text) if baud_text else DEFAULT_BAUD
        return Endpoint(Kind.SERIAL, device=device, baud=baud)
    if s.startswith("/") or s.upper().startswith("COM"):
        device, comma, baud_text = s.partition(",")
        baud = _baud(text, baud_text) if comma else DEFAULT_BAUD
        return Endpoint(Kind.SERIAL, device=device, baud=baud)
    raise ConnectionStringError(
        f"connection {text!r}: expected tcp:HOST:PORT, udpin:HOST:PORT, udpout:HOST:PORT, "
        "serial:DEVICE[:BAUD] or a device path"
    )
