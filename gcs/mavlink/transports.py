"""Byte transports under a link: TCP client, UDP in/out and serial (POSIX), on asyncio.

Each transport hands received bytes to ``sink.feed(data, source)`` and resolves ``lost`` when
the connection is gone (the link then reconnects). ``write`` never raises: it returns False
when the bytes could not be queued. Only this module touches sockets and devices.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from typing import Any, Protocol

from gcs.mavlink.endpoints import Endpoint, Kind

# Stop queueing when a TCP peer stops reading (drop instead of growing without bound).
MAX_WRITE_BUFFER_BYTES = 1 << 20


class Sink(Protocol):
    def feed(self, data: bytes, source: Any = None) -> None: ...


class Transport:
    """What a link needs from a connection."""

    def __init__(self) -> None:
        self.lost: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def write(self, data: bytes, target_system: int = 0) -> bool:
        raise NotImplementedError

    def remember(self, system_id: int, source: Any) -> None:
        """Note where ``system_id`` is reached (datagram transports route by it)."""

    def close(self) -> None:
        raise NotImplementedError

    def _set_lost(self) -> None:
        if not self.lost.done():
            self.lost.set_result(None)


class _TcpProtocol(asyncio.Protocol):
    def __init__(self, sink: Sink) -> None:
        self.sink = sink
        self.owner: TcpTransport | None = None

    def data_received(self, data: bytes) -> None:
        self.sink.feed(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if self.owner is not None:
            self.owner._set_lost()


class TcpTransport(Transport):
    def __init__(self, transport: asyncio.Transport) -> None:
        super().__init__()
        self._transport = transport

    def write(self, data: bytes, target_system: int = 0) -> bool:
        if self._transport.is_closing():
            return False
        if self._transport.get_write_buffer_size() > MAX_WRITE_BUFFER_BYTES:
            return False
        self._transport.write(data)
        return True

    def close(self) -> None:
        self._transport.close()
        self._set_lost()


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, sink: Sink) -> None:
        self.sink = sink
        self.owner: UdpTransport | None = None

    def datagram_received(self, data: bytes, addr: Any) -> None:
        if self.owner is not None:
            self.owner.last_addr = addr
        self.sink.feed(data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable and the like: the peer may come up later; keep the socket.
        pass

    def connection_lost(self, exc: Exception | None) -> None:
        if self.owner is not None:
            self.owner._set_lost()


class UdpTransport(Transport):
    """``udpout`` sends to a fixed address; ``udpin`` replies to whoever sent to us.

    With several senders on one ``udpin`` port, a message addressed to a system goes to the
    address that system was last heard from; broadcasts (target 0) go to every known address.
    """

    def __init__(self, transport: asyncio.DatagramTransport, fixed: Any | None) -> None:
        super().__init__()
        self._transport = transport
        self._fixed = fixed
        self.last_addr: Any | None = None
        self._by_system: dict[int, Any] = {}

    def remember(self, system_id: int, source: Any) -> None:
        if self._fixed is None and source is not None:
            self._by_system[system_id] = source

    def write(self, data: bytes, target_system: int = 0) -> bool:
        if self._transport.is_closing():
            return False
        if self._fixed is not None:
            self._transport.sendto(data)  # a connected socket: the address is fixed
            return True
        addr = self._by_system.get(target_system) if target_system else None
        if addr is not None:
            self._transport.sendto(data, addr)
            return True
        addrs = set(self._by_system.values())
        if not addrs and self.last_addr is not None:
            addrs = {self.last_addr}
        for a in addrs:
            self._transport.sendto(data, a)
        return bool(addrs)

    def close(self) -> None:
        self._transport.close()
        self._set_lost()


class SerialTransport(Transport):
    """A raw serial device (POSIX termios), read through the event loop."""

    def __init__(self, fd: int) -> None:
        super().__init__()
        self._fd = fd
        self._loop = asyncio.get_running_loop()

    def start(self, sink: Sink) -> None:
        def readable() -> None:
            try:
                data = os.read(self._fd, 4096)
            except BlockingIOError:
                return
            except OSError:
                self.close()
                return
            if not data:
                self.close()
                return
            sink.feed(data)

        self._loop.add_reader(self._fd, readable)

    def write(self, data: bytes, target_system: int = 0) -> bool:
        if self._fd < 0:
            return False
        try:
            return os.write(self._fd, data) == len(data)
        except BlockingIOError:
            return False
        except OSError:
            self.close()
            return False

    def close(self) -> None:
        if self._fd >= 0:
            self._loop.remove_reader(self._fd)
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = -1
        self._set_lost()


def _open_serial_fd(device: str, baud: int) -> int:
    import termios
    import tty

    speed = getattr(termios, f"B{baud}", None)
    if speed is None:
        raise OSError(f"serial {device}: unsupported baud rate {baud}")
    fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        tty.setraw(fd)
        attrs = termios.tcgetattr(fd)
        attrs[4] = attrs[5] = speed
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except (OSError, termios.error) as exc:
        os.close(fd)
        raise OSError(f"serial {device}: {exc}") from exc
    return fd


async def open_transport(endpoint: Endpoint, sink: Sink) -> Transport:
    """Open ``endpoint``; OSError when it cannot be opened now (the caller retries)."""
    loop = asyncio.get_running_loop()
    if endpoint.kind is Kind.TCP:
        tcp_proto = _TcpProtocol(sink)
        async with asyncio.timeout(5.0):
            raw, _ = await loop.create_connection(lambda: tcp_proto, endpoint.host, endpoint.port)
        tcp = TcpTransport(raw)
        tcp_proto.owner = tcp
        return tcp
    if endpoint.kind in (Kind.UDPIN, Kind.UDPOUT):
        udp_proto = _UdpProtocol(sink)
        addr = (endpoint.host, endpoint.port)
        if endpoint.kind is Kind.UDPIN:
            raw_udp, _ = await loop.create_datagram_endpoint(lambda: udp_proto, local_addr=addr)
            udp = UdpTransport(raw_udp, None)
        else:
            raw_udp, _ = await loop.create_datagram_endpoint(lambda: udp_proto, remote_addr=addr)
            udp = UdpTransport(raw_udp, addr)
        udp_proto.owner = udp
        return udp
    fd = _open_serial_fd(endpoint.device, endpoint.baud)
    serial = SerialTransport(fd)
    serial.start(sink)
    return serial
